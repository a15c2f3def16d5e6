#pragma once
/// @file Motion compensation of a LiDAR sweep ("deskew"): a spinning LiDAR takes a 10 Hz sweep
/// over 100 ms, during which a vehicle at 10 m/s moves 1 m. With per-point times and the base
/// pose at the start and end of the sweep, every point is moved into the sensor frame at the
/// scan stamp, so the rest of the pipeline sees one rigid snapshot.

#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/point_cloud.hpp"

namespace tarmac::core {

/// The vehicle base pose at two times of the sweep, as offsets from the scan stamp (seconds,
/// t0_s < t1_s). Between them the pose is interpolated (translation linearly, rotation by
/// slerp), i.e. constant velocity over the sweep.
struct ScanMotion {
  double t0_s = 0.0;
  double t1_s = 0.0;
  Eigen::Isometry3d T_W_B_0 = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_W_B_1 = Eigen::Isometry3d::Identity();
};

/// Pose between `a` (f = 0) and `b` (f = 1): translation linear, rotation slerp.
Eigen::Isometry3d interpolate_pose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b,
                                   double f);

/// Time bins of a sweep: the pose is interpolated at the kDeskewBins + 1 bin edges only, and a
/// point is blended between the transforms of its bin's two edges (for a 100 ms sweep a bin is
/// 1.6 ms, 0.14° at 90 °/s, so the blend departs from the slerp by ~1e-7 of the range).
inline constexpr int kDeskewBins = 64;

/// Writes into `out_S` (cleared, capacity kept) every point of `cloud` expressed in the sensor
/// frame at the scan stamp, whose base pose is `T_W_B_stamp`; T_B_S is the sensor's extrinsic.
/// Point times are clamped to [t0_s, t1_s]; a non-finite time counts as the stamp.
/// @pre cloud.has_time(), motion.t1_s > motion.t0_s. RT-safe after warm-up; deterministic.
void deskew_points(const PointCloud& cloud, const ScanMotion& motion,
                   const Eigen::Isometry3d& T_W_B_stamp, const Eigen::Isometry3d& T_B_S,
                   std::vector<Eigen::Vector3f>& out_S);

}  // namespace tarmac::core
