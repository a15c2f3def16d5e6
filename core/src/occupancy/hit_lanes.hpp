#pragma once
/// @file The hit pass's first step in vector lanes: each return's window slot and column
/// (internal to core/src/occupancy; OccupancyMap::integrate_hits has the scalar form).

#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "ray_tasks.hpp"
#include "tarmac/core/occupancy_map.hpp"

#if defined(TARMAC_WIDE_WALK)
namespace tarmac::core::occupancy {

/// range, the window; each return's slot and window column out.
struct HitPass {
  std::span<const Eigen::Vector3f> points;
  const Eigen::Vector3d& origin_W;
  double max_range, voxel_size;
  const VoxelIndex& min;
  const Eigen::Vector3i& dims;
  const std::array<int, 3>& ring_min;
  std::uint32_t *slot_out, *column_out;
  /// Within this of max range, the scalar expression decides whether a return is in range.
  [[nodiscard]] double near_edge() const { return 1e-9 * std::max(1.0, max_range); }
};

/// Eight returns at a time (AVX-512F and DQ: lanes8_walk_supported()); returns how many fell
/// outside the window.
std::uint64_t hit_voxels_lanes8(const HitPass& h);
/// Four returns at a time (AVX2: lanes4_walk_supported()); returns how many fell outside the
/// window.
std::uint64_t hit_voxels_lanes4(const HitPass& h);

}  // namespace tarmac::core::occupancy
#endif
