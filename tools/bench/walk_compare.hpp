#pragma once
/// @file tarmac-bench --walk-compare: the TSDF's band walk (core/src/tsdf_band_walk.hpp) against
/// OpenVDB's DDA (openvdb/math/DDA.h) on the same rays, to decide whether the TSDF could walk
/// with OpenVDB's instead of its own. Both visit each ray's segment [max(0, r − trunc), r + trunc]
/// on one thread, compute the projective signed distance of every voxel there and keep those in
/// the band; nothing is written to a map, so the figures are the walks alone.

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace tarmac::bench {

struct WalkCompare {
  std::vector<double> ours_ms, dda_ms;  ///< per scan
  std::uint64_t ours_voxels = 0, dda_voxels = 0;
  /// Scans' rays whose band voxels differ between the walks (count or sum of distances).
  std::uint64_t rays = 0, rays_differing = 0;

  /// Walks one scan's rays both ways and adds the figures.
  void add_scan(const Eigen::Vector3d& origin_W, std::span<const Eigen::Vector3f> points_W,
                double voxel_m, double truncation_m, double max_range_m);
  /// Prints the table (ms per scan) and the ratio.
  void print() const;
};

}  // namespace tarmac::bench
