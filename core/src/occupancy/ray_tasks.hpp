#pragma once
/// @file A scan's rays as the walks of its ray tasks, and the walks that run them: one at a time
/// (the reference, ray_walk.hpp), four at a time (walk_lanes4.cpp) or eight (walk_lanes8.cpp).
/// Internal to core/src/occupancy.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "ray_walk.hpp"

#if defined(__x86_64__) && defined(__GNUC__)
/// The lane walks exist (chosen at run time by what the processor supports).
#define TARMAC_WIDE_WALK 1
#endif

namespace tarmac::core::occupancy {

/// The rays of one ray task: returns (within max range: walked to their voxel, not marked;
/// beyond: walked up to the clearing range, end voxel included) then beams without a return
/// (clearing range, end included). The scan's rays are taken in `order` (by direction), in
/// chunks of kRayChunk: a task takes the next chunk nobody has taken when it needs one
/// (`next_chunk`, shared by the scan's ray tasks), so the tasks end together however the
/// threads are shared with the hit pass. Which task walks which ray changes nothing: the
/// apply pass reads the union of the tasks' marks (an OR), the box is the union of their
/// boxes and the visits their sum, so the map is the same bit for bit (the digest tests).
/// (With fixed thirds, on 2 threads the thread that ran the hit pass had to take a third as
/// well, and the others waited for it.)
struct TaskRays {
  std::span<const Eigen::Vector3f> points, dirs;
  /// The rays by direction (see sort_rays_by_direction); empty: in the scan's order.
  std::span<const std::uint32_t> order;
  Eigen::Vector3d origin;
  double max_range, clear_range;
  std::atomic<std::size_t>* next_chunk;
};

/// The rays of one ray task, one at a time, as walks to make: where each ends and whether its
/// end voxel is marked too (see TaskRays). Rays that mark nothing are passed over.
class TaskRayCursor {
 public:
  explicit TaskRayCursor(const TaskRays& rays)
      : rays_(rays),
        n_points_(rays.points.size()),
        n_rays_(rays.points.size() + rays.dirs.size()),
        first_(0),
        j_(0),
        end_(0) {}

  /// The next walk of the task; false when none is left.
  bool next(Eigen::Vector3d& end_W, bool& include_end) {
    const Eigen::Vector3d& origin_W = rays_.origin;
    while (true) {
      if (j_ >= end_) {
        first_ = kRayChunk * rays_.next_chunk->fetch_add(1, std::memory_order_relaxed);
        if (first_ >= n_rays_) return false;
        j_ = first_;
        end_ = std::min(n_rays_, first_ + kRayChunk);
      }
      const std::size_t j = j_++;
      const std::size_t i = rays_.order.empty() ? j : rays_.order[j];
      if (i < n_points_) {
        const Eigen::Vector3f& p = rays_.points[i];
        if (!p.allFinite()) continue;
        const Eigen::Vector3d pd = p.cast<double>();
        const double range = (pd - origin_W).norm();
        if (range <= rays_.max_range) {
          end_W = pd;
          include_end = false;
          return true;
        }
        if (rays_.clear_range > 0.0) {
          end_W = origin_W + (pd - origin_W) * (rays_.clear_range / range);
          include_end = true;
          return true;
        }
      } else {
        const Eigen::Vector3f& dir = rays_.dirs[i - n_points_];
        const double norm = dir.cast<double>().norm();
        if (!dir.allFinite() || norm == 0.0 || rays_.clear_range <= 0.0) continue;
        // A direction shorter than unit clears that fraction of the range (OccupancyMap::
        // integrate); ScanRays::build ends it at the same point.
        end_W = origin_W + dir.cast<double>() * (rays_.clear_range * std::min(norm, 1.0) / norm);
        include_end = true;
        return true;
      }
    }
  }

 private:
  const TaskRays& rays_;
  std::size_t n_points_, n_rays_;
  std::size_t first_, j_, end_;  ///< the current chunk [first_, end_), the next ray (in `order`)
};

/// Walks every ray of a task one after the other; returns the voxel visits.
template <bool kFlagWords>
std::uint64_t walk_rays(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                        FreeMarks marks, MarkBox& box) {
  TaskRayCursor cursor(rays);
  Eigen::Vector3d end_W;
  bool include_end = false;
  std::uint64_t visits = 0;
  while (cursor.next(end_W, include_end)) {
    visits += traverse<kFlagWords>(w, start, end_W, include_end, marks, box);
  }
  return visits;
}

#if defined(TARMAC_WIDE_WALK)
/// The task's walks eight at a time (AVX-512F and DQ; lanes8_walk_supported()), marks the same
/// bits as walk_rays.
std::uint64_t walk_rays_lanes8(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                               FreeMarks marks, MarkBox& box);
/// The task's walks four at a time (AVX2; lanes4_walk_supported()), marks the same bits as
/// walk_rays.
std::uint64_t walk_rays_lanes4(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                               FreeMarks marks, MarkBox& box);
/// Whether this processor runs walk_rays_lanes8 (checked once).
bool lanes8_walk_supported();
/// Whether this processor runs walk_rays_lanes4 (checked once).
bool lanes4_walk_supported();
#endif

/// The walks of one task, `lanes` at a time (8, 4 or 1: see OccupancyMap::walk_lanes), with
/// per-word flags (large windows: marks.dirty set) or without; returns the voxel visits and sets
/// `box` to the box of the voxels marked.
std::uint64_t walk_task(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                        FreeMarks marks, MarkBox& box, int lanes);

}  // namespace tarmac::core::occupancy
