#pragma once
/// @file The occupancy window's layout and how its passes are split into tasks (internal to
/// core/src/occupancy). The window is a ring buffer: voxel (x, y, z) lives at slot
/// ((z mod nz)·ny + (y mod ny))·nx + (x mod nx), so moving the window rewrites only the slabs
/// that enter it.

#include <cstddef>
#include <cstdint>

namespace tarmac::core::occupancy {

/// Non-negative remainder.
inline int wrap(int i, int n) {
  const int r = i % n;
  return r < 0 ? r + n : r;
}

/// Ray tasks, each marking its own bit set (the rays it walks: see TaskRays), beside the hit
/// pass's one task; the marks are applied in fixed ranges of the window. Three: a task more is
/// a mark set more for the apply pass to OR, and more tasks were no faster on 2 or 4 threads.
constexpr std::size_t kRayTasks = 3;
/// Rays are taken by the ray tasks in chunks of this many, in direction order, each chunk by the
/// first task to ask for it (see TaskRays).
constexpr std::size_t kRayChunk = 64;
/// Fixed ranges of the window the apply pass splits into. The marks crowd into the layers near
/// the sensor's height, so a few ranges hold most of them; with few ranges one task takes most
/// of the pass, finer ranges even it out.
constexpr std::size_t kApplyTasks = 32;
/// Fixed ranges of slots (cut at multiples of 64) in which the window's scroll clears the ring
/// slabs that the entering voxels take over.
constexpr std::size_t kSlabTasks = 8;
/// Rows of bricks (OccupancyMap::refresh_bricks) whose flags each scan recomputes: a
/// 400×400×40 window has 250, so a brick emptied by misses stops flagging within 16 scans, for
/// 1.6 MB of log-odds read per scan.
constexpr int kBrickRowsPerScan = 16;
/// No slot: the return does not mark (beyond max range or outside the window).
constexpr std::uint32_t kNoSlot = ~std::uint32_t{0};

/// floor() to an integer for any finite double in int64 range, without a libm call.
inline std::int64_t floor_to_int(double v) {
  const auto i = static_cast<std::int64_t>(v);  // truncates toward zero
  return i - static_cast<std::int64_t>(static_cast<double>(i) > v);
}
/// Free-space marks are tracked per block of 64 bit words (4096 voxels).
constexpr int kBlockShift = 6;

/// Windows up to this many voxels (2 MB of marks per ray task) skip the per-visit word flags: the
/// apply pass reads their marks inside the box the rays spanned, which costs less than a flag
/// on each of millions of visits. Larger windows (0.1 m voxels over 100 m: 10 MB of marks per
/// task) flag each mark word the rays touch, so the apply pass reads only those (a flag per
/// block of 64 words alone still read megabytes per scan). Either way the same voxels are marked
/// and updated.
constexpr std::size_t kUnflaggedVoxels = std::size_t{16} << 20;

}  // namespace tarmac::core::occupancy
