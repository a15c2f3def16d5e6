#include "tarmac/transport/outputs.hpp"

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "diagnostic_msgsPubSubTypes.h"
#include "nav_msgsPubSubTypes.h"
#include "tarmac_msgsPubSubTypes.h"

namespace tarmac::transport {

class MapOutputs::Impl {
 public:
  std::unique_ptr<Writer<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>> costmap;
  std::unique_ptr<Writer<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>> obstacle_grid;
  std::unique_ptr<Writer<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>> esdf_slice_grid;
  std::unique_ptr<Writer<tarmac_msgs::msg::dds_::DistanceMapSlice_PubSubType>> slice;
  std::unique_ptr<Writer<tarmac_msgs::msg::dds_::DistanceMapVolume_PubSubType>> band;
  std::unique_ptr<Writer<tarmac_msgs::msg::dds_::CycleReport_PubSubType>> report;
  std::unique_ptr<Writer<tarmac_msgs::msg::dds_::DebrisArray_PubSubType>> debris;
  std::unique_ptr<Writer<diagnostic_msgs::msg::dds_::DiagnosticArray_PubSubType>> diagnostics;
  // Kept and refilled: their buffers are reused from tick to tick.
  OccupancyGridMsg costmap_msg;
  OccupancyGridMsg obstacle_grid_msg;
  OccupancyGridMsg esdf_slice_grid_msg;
  DistanceMapSliceMsg slice_msg;
  DistanceMapVolumeMsg band_msg;
  CycleReportMsg report_msg;
  DebrisArrayMsg debris_msg;
  DiagnosticArrayMsg diagnostics_msg;
};

core::Result<std::unique_ptr<MapOutputs>> MapOutputs::create(const Participant& participant,
                                                             const OutputTopics& topics,
                                                             const OutputQos& qos) {
  auto impl = std::make_unique<Impl>();
  auto costmap =
      decltype(impl->costmap)::element_type::create(participant, topics.costmap, qos.costmap);
  if (!costmap) return costmap.error();
  impl->costmap = std::move(costmap).value();
  if (!topics.obstacle_grid.empty()) {
    auto grid = decltype(impl->obstacle_grid)::element_type::create(
        participant, topics.obstacle_grid, qos.obstacle_grid);
    if (!grid) return grid.error();
    impl->obstacle_grid = std::move(grid).value();
  }
  if (!topics.esdf_slice_grid.empty()) {
    auto grid = decltype(impl->esdf_slice_grid)::element_type::create(
        participant, topics.esdf_slice_grid, qos.esdf_slice_grid);
    if (!grid) return grid.error();
    impl->esdf_slice_grid = std::move(grid).value();
  }
  auto slice =
      decltype(impl->slice)::element_type::create(participant, topics.esdf_slice, qos.esdf_slice);
  if (!slice) return slice.error();
  impl->slice = std::move(slice).value();
  if (!topics.esdf_band.empty()) {
    auto band =
        decltype(impl->band)::element_type::create(participant, topics.esdf_band, qos.esdf_band);
    if (!band) return band.error();
    impl->band = std::move(band).value();
  }
  if (!topics.debris.empty()) {
    auto debris =
        decltype(impl->debris)::element_type::create(participant, topics.debris, qos.debris);
    if (!debris) return debris.error();
    impl->debris = std::move(debris).value();
  }
  auto report = decltype(impl->report)::element_type::create(participant, topics.cycle_report,
                                                             qos.cycle_report);
  if (!report) return report.error();
  impl->report = std::move(report).value();
  auto diagnostics = decltype(impl->diagnostics)::element_type::create(
      participant, topics.diagnostic_array, qos.diagnostic_array);
  if (!diagnostics) return diagnostics.error();
  impl->diagnostics = std::move(diagnostics).value();
  return std::unique_ptr<MapOutputs>(new MapOutputs(std::move(impl)));
}

MapOutputs::MapOutputs(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MapOutputs::~MapOutputs() = default;

bool MapOutputs::publish_costmap(const core::Costmap& costmap, std::int64_t stamp_ns,
                                 const std::string& frame_id) {
  fill_occupancy_grid(costmap, stamp_ns, frame_id, impl_->costmap_msg);
  return impl_->costmap->write(impl_->costmap_msg);
}

bool MapOutputs::publish_obstacle_grid(const core::Costmap& grid, std::int64_t stamp_ns,
                                       const std::string& frame_id) {
  if (!impl_->obstacle_grid) return false;
  fill_occupancy_grid(grid, stamp_ns, frame_id, impl_->obstacle_grid_msg);
  return impl_->obstacle_grid->write(impl_->obstacle_grid_msg);
}

bool MapOutputs::publish_esdf_slice_grid(const core::Costmap& grid, std::int64_t stamp_ns,
                                         const std::string& frame_id) {
  if (!impl_->esdf_slice_grid) return false;
  fill_occupancy_grid(grid, stamp_ns, frame_id, impl_->esdf_slice_grid_msg);
  return impl_->esdf_slice_grid->write(impl_->esdf_slice_grid_msg);
}

bool MapOutputs::publish_slice(const core::DistanceField& field,
                               const core::GridGeometry2D& geometry, std::int64_t stamp_ns,
                               const std::string& frame_id) {
  fill_distance_slice(field, geometry, stamp_ns, frame_id, impl_->slice_msg);
  return impl_->slice->write(impl_->slice_msg);
}

bool MapOutputs::publish_band(const core::EsdfBand& band, const Eigen::Vector2d& centre_W,
                              double radius_m, std::int64_t stamp_ns, const std::string& frame_id) {
  if (!impl_->band) return false;
  fill_distance_volume(band, centre_W, radius_m, stamp_ns, frame_id, impl_->band_msg);
  return impl_->band->write(impl_->band_msg);
}

void MapOutputs::reserve_debris(std::size_t pieces) {
  impl_->debris_msg.objects().reserve(pieces);
}

bool MapOutputs::publish_debris(std::span<const core::Debris> debris, std::int64_t stamp_ns,
                                const std::string& frame_id) {
  if (!impl_->debris) return false;
  fill_debris_array(debris, stamp_ns, frame_id, impl_->debris_msg);
  return impl_->debris->write(impl_->debris_msg);
}

bool MapOutputs::publish_report(const CycleReport& report) {
  fill_cycle_report(report, impl_->report_msg);
  return impl_->report->write(impl_->report_msg);
}

bool MapOutputs::publish_diagnostics(const DiagnosticReport& report) {
  fill_diagnostic_array(report, impl_->diagnostics_msg);
  return impl_->diagnostics->write(impl_->diagnostics_msg);
}

}  // namespace tarmac::transport
