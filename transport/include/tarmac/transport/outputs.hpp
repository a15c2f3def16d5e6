#pragma once
/// @file tarmacd's DDS outputs, in core types: the costmap (nav_msgs/OccupancyGrid), the ESDF
/// slice (tarmac_msgs/DistanceMapSlice), the 3D ESDF band (tarmac_msgs/DistanceMapVolume), the
/// per-tick tarmac_msgs/CycleReport, the debris (tarmac_msgs/DebrisArray) and a
/// diagnostic_msgs/DiagnosticArray. Each writer keeps its message and refills it, so publishing
/// does not allocate on our side after the first tick (Fast DDS serialises into its own pool).

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "tarmac/core/debris.hpp"
#include "tarmac/core/distance_field.hpp"
#include "tarmac/core/esdf_band.hpp"
#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/cycle_report.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

struct OutputTopics {
  std::string costmap;
  std::string esdf_slice;
  std::string esdf_band;  ///< empty: no band writer (esdf_band disabled)
  std::string cycle_report;
  std::string diagnostic_array;
  /// Empty: none. The costmap without inflation (100 / 0 / −1) for Nav2's own inflation.
  std::string obstacle_grid;
  /// Empty: none. The 2D ESDF shaded as an OccupancyGrid, for rviz2 (core::to_distance_display).
  std::string esdf_slice_grid;
  /// Empty: none. The debris for the ground crew (tarmac_msgs/DebrisArray).
  std::string debris;
};

struct OutputQos {
  QosSpec costmap = qos::kCostmap;
  QosSpec esdf_slice = qos::kEsdfSlice;
  QosSpec esdf_band = qos::kEsdfBand;
  QosSpec cycle_report = qos::kDiagnostics;
  QosSpec diagnostic_array = qos::kDiagnostics;
  QosSpec obstacle_grid = qos::kCostmap;
  QosSpec esdf_slice_grid = qos::kCostmap;  // as the costmap: rviz2's Map display reads it so
  QosSpec debris = qos::kDebris;
};

class MapOutputs {
 public:
  static core::Result<std::unique_ptr<MapOutputs>> create(const Participant& participant,
                                                          const OutputTopics& topics,
                                                          const OutputQos& qos);
  ~MapOutputs();
  MapOutputs(const MapOutputs&) = delete;
  MapOutputs& operator=(const MapOutputs&) = delete;

  /// Each returns false when Fast DDS refused the sample.
  bool publish_costmap(const core::Costmap& costmap, std::int64_t stamp_ns,
                       const std::string& frame_id);
  /// The uninflated grid (core::to_obstacle_grid). False also when no obstacle grid topic was
  /// given.
  bool publish_obstacle_grid(const core::Costmap& grid, std::int64_t stamp_ns,
                             const std::string& frame_id);
  /// The ESDF display grid (core::to_distance_display). False also when no topic was given.
  bool publish_esdf_slice_grid(const core::Costmap& grid, std::int64_t stamp_ns,
                               const std::string& frame_id);
  /// `field` is a 2D field laid out on `geometry` (same cells as the costmap).
  bool publish_slice(const core::DistanceField& field, const core::GridGeometry2D& geometry,
                     std::int64_t stamp_ns, const std::string& frame_id);
  /// The band's voxels within `radius_m` of `centre_W` in x and y (0: the whole band). False
  /// also when no band topic was given.
  bool publish_band(const core::EsdfBand& band, const Eigen::Vector2d& centre_W, double radius_m,
                    std::int64_t stamp_ns, const std::string& frame_id);
  /// Sizes the debris message for `pieces`, so publishing up to that many does not allocate
  /// (the low objects' capacity bounds the pieces).
  void reserve_debris(std::size_t pieces);
  /// The debris list (core::extract_debris), in id order. False also when no debris topic was
  /// given.
  bool publish_debris(std::span<const core::Debris> debris, std::int64_t stamp_ns,
                      const std::string& frame_id);
  bool publish_report(const CycleReport& report);
  bool publish_diagnostics(const DiagnosticReport& report);

  class Impl;

 private:
  explicit MapOutputs(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::transport
