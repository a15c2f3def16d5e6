#include "tarmac/core/mapper.hpp"

namespace tarmac::core {

Status MapperParams::validate() const {
  if (auto s = filters.validate(); !s) return s;
  if (auto s = occupancy.validate(); !s) return s;
  if (auto s = tsdf.validate(); !s) return s;
  return costmap.validate();
}

Mapper::Mapper(const MapperParams& params)
    : params_(params),
      map_(params.occupancy),
      tsdf_integrator_(params.tsdf),
      tsdf_(tsdf_integrator_.make_layer()) {
  TARMAC_ASSERT(params.validate().ok(), "MapperParams must be validated first");
}

FilterCounts Mapper::ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                            const Eigen::Isometry3d& T_B_S, const ScanMotion* motion) {
  const Eigen::Isometry3d T_W_S = T_W_B * T_B_S;
  sensor_W_ = T_W_S.translation();
  T_W_B_ = T_W_B;
  if (motion != nullptr && cloud.has_time() && cloud.consistent() && motion->t1_s > motion->t0_s) {
    deskewed_.stamp_ns = cloud.stamp_ns;
    deskew_points(cloud, *motion, T_W_B, T_B_S, deskewed_.points_S);
    return filter_scan(deskewed_, T_W_S, T_B_S, params_.filters, points_W_, filter_scratch_);
  }
  return filter_scan(cloud, T_W_S, T_B_S, params_.filters, points_W_, filter_scratch_);
}

OccupancyUpdateStats Mapper::integrate(TaskRunner& runner) {
  map_.recenter(T_W_B_.translation());
  return map_.integrate(sensor_W_, points_W_, {}, runner, T_W_B_.linear().col(2));
}

const TsdfUpdate& Mapper::integrate_tsdf(TaskRunner& runner) {
  if (!params_.tsdf.enabled) return no_tsdf_update_;
  return tsdf_integrator_.integrate(sensor_W_, points_W_, tsdf_, runner);
}

void Mapper::update_costmap(std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                            TaskRunner& runner) {
  build_costmap(map_, params_.costmap, T_W_B_, zones, stamp_ns, layers_, runner);
}

}  // namespace tarmac::core
