#pragma once
/// @file A simulated sweep as the organised cloud a spinning LiDAR's driver publishes, for the
/// tests that map tarmac-sim's scenes through the Mapper.

#include <cstddef>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/organised_scan.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/sim/lidar.hpp"

namespace tarmac::test {

/// A sweep's returns as the organised cloud a spinning LiDAR's driver publishes (beams by
/// azimuth steps, NaN where nothing returned), split as tarmacd splits it: the returns and the
/// beams without return, which observe the envelope above the sensor (FreeRule::kWholeEnvelope).
inline void to_cloud(const std::vector<sim::LidarReturn>& returns, const sim::LidarParams& lidar,
                     core::PointCloud& cloud, core::OrganisedScratch& scratch) {
  const auto rows = static_cast<std::size_t>(lidar.beams);
  const auto cols = static_cast<std::size_t>(lidar.azimuth_steps);
  cloud.clear();
  cloud.points_S.assign(rows * cols,
                        Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN()));
  for (const auto& r : returns) {
    cloud.points_S[static_cast<std::size_t>(r.beam) * cols +
                   static_cast<std::size_t>(r.azimuth_step)] = r.point_S.cast<float>();
  }
  core::split_organised(cloud, rows, cols, scratch);
}

}  // namespace tarmac::test
