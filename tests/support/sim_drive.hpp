#pragma once
/// @file Drives the Mapper through a tarmac-sim scene, for the tests that judge its costmap on
/// the simulator's scenes (debris, terrain).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "sim_cloud.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/organised_scan.hpp"
#include "tarmac/core/task_runner.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene_catalog.hpp"

namespace tarmac::test {

using ScanFn = std::function<void(int, const core::PointCloud&, const Eigen::Isometry3d& T_W_B,
                                  const Eigen::Isometry3d& T_B_S)>;

/// Simulates `name` (64 beams) from x = start_x to x = stop_x and hands `each` every scan's
/// cloud (the organised sweep split into returns and beams without return), the base's pose and
/// the sensor's extrinsic.
inline void simulate(const char* name, double start_x, double stop_x, const ScanFn& each) {
  auto scene = sim::scene_drive(name, std::nullopt, 2.0);
  ASSERT_TRUE(scene.has_value());
  sim::SequenceParams seq;
  seq.path = scene->path;
  seq.path.start_W = {start_x, seq.path.start_W.y()};
  seq.lidar.beams = 64;
  const sim::Lidar lidar(seq.lidar);
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = seq.path.sensor_height_m;
  std::vector<sim::LidarReturn> returns;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  const int scans = static_cast<int>((stop_x - start_x) / seq.path.speed_mps * seq.rate_hz) + 1;
  for (int i = 0; i < scans; ++i) {
    const double t_s = seq.stamp_s(i);
    lidar.scan(scene->scene, seq.path.T_W_S(t_s), t_s, nullptr, returns);
    to_cloud(returns, seq.lidar, cloud, scratch);
    cloud.stamp_ns = static_cast<std::int64_t>(std::llround(t_s * 1e9));
    each(i, cloud, seq.path.T_W_base(t_s), T_B_S);
  }
}

/// One scan into `mapper` and its costmap.
inline void map_scan(core::Mapper& mapper, const core::PointCloud& cloud,
                     const Eigen::Isometry3d& T_W_B, const Eigen::Isometry3d& T_B_S) {
  core::SerialRunner runner;
  const auto scan = mapper.ingest(cloud, T_W_B, T_B_S);
  mapper.integrate(scan, runner);
  mapper.update_costmap(mapper.vehicle_pose(), {}, cloud.stamp_ns, runner);
}

/// `cloud` with its points in the reverse order (another driver's layout of the same sweep).
inline void reverse_points(const core::PointCloud& cloud, core::PointCloud& out) {
  out = cloud;
  std::reverse(out.points_S.begin(), out.points_S.end());
  std::reverse(out.intensity.begin(), out.intensity.end());
  std::reverse(out.ring.begin(), out.ring.end());
  std::reverse(out.no_return_S.begin(), out.no_return_S.end());
}

/// The mapper's defaults without the TSDF, which neither the costmap nor the debris read.
inline core::MapperParams without_tsdf() {
  core::MapperParams params;
  params.tsdf.enabled = false;
  return params;
}

}  // namespace tarmac::test
