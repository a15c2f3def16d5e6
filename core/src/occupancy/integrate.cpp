/// @file OccupancyMap::integrate: one scan into the window. 1. the hit pass (integrate_hits):
/// each return's voxel gets one hit; 2. the ray walks mark the voxels the rays pass through
/// (ray_tasks.hpp); 3. the apply pass gives each marked voxel that was not hit one miss, and
/// miss_occupied decides the misses of voxels reading occupied. The update rules are in
/// log_odds.hpp.

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>

#include "../lanes4.hpp"
#include "apply_pass.hpp"
#include "hit_lanes.hpp"
#include "log_odds.hpp"
#include "ray_order.hpp"
#include "ray_tasks.hpp"
#include "static_store.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "window.hpp"

namespace tarmac::core {
namespace {

using namespace occupancy;  // NOLINT(google-build-using-namespace): this file is the occupancy pass

/// A window column the scan has no return in: its lowest return is +inf.
constexpr float kNoGround = std::numeric_limits<float>::infinity();

/// The map-frame (x, y) of window column (x, y)'s centre, the window's lowest voxel `min`:
/// heights along a tilted up axis depend on it.
Eigen::Vector2f column_centre(const VoxelIndex& min, double v_m, int x, int y) {
  return {static_cast<float>((min.x() + x + 0.5) * v_m),
          static_cast<float>((min.y() + y + 0.5) * v_m)};
}

}  // namespace

void OccupancyMap::integrate_hits(const Eigen::Vector3d& origin_W,
                                  std::span<const Eigen::Vector3f> points_W,
                                  const Eigen::Vector3d& up_W, OccupancyUpdate& stats) {
  // a) Per return: its slot and window column, or none (beyond max range or outside the
  //    window), and its height along up_W; and the scan's own ground: the lowest return
  //    per window column (only the columns this scan touched are reset next time).
  // A zero or non-finite up axis is taken as +z: the heights must be numbers (a column's first
  // return is booked by its ground leaving +inf, in hit_heights).
  const double up_norm = up_W.norm();
  const Eigen::Vector3f up = std::isfinite(up_norm) && up_norm > 0.0
                                 ? Eigen::Vector3f((up_W / up_norm).cast<float>())
                                 : Eigen::Vector3f::UnitZ();
  hit_slot_.resize(points_W.size());
  hit_column_.resize(points_W.size());
  hit_height_.resize(points_W.size());
  hit_rise_.resize(points_W.size());
  stats.outside_window += hit_voxels(origin_W, points_W);
  up_ = up;
  hit_heights(points_W, up);
  // b) Each return's rise above the scan's ground near it; c) one hit per voxel.
  hit_rises(points_W.size());
  apply_hits(points_W, stats);
  // d) The low objects kept across scans, from the returns' rises.
  low_objects_.place(min_.x(), min_.y());
  LowObjects::Scan scan;
  scan.origin_W = origin_W.cast<float>();
  scan.up_W = up;
  scan.points_W = points_W;
  scan.voxel = std::span<const std::uint32_t>(hit_slot_.data(), points_W.size());
  scan.column = std::span<const std::uint32_t>(hit_column_.data(), points_W.size());
  scan.rise_cm = std::span<const std::uint8_t>(hit_rise_.data(), points_W.size());
  const ClearingGround clearing_ground(*this);
  scan.ground = &clearing_ground;
  scan.number = scans_integrated_;
  scan.stamp_ns = observation_stamp_ns_;
  low_objects_.update(scan);
}

std::uint64_t OccupancyMap::hit_voxels(const Eigen::Vector3d& origin_W,
                                       std::span<const Eigen::Vector3f> points_W) {
  const int nx = dims_.x();
  const std::size_t n_points = points_W.size();
  const double max_range = params_.max_range_m;
  const double v_m = params_.voxel_size_m;
  const std::array<int, 3> ring_min = ring_origin();
  std::uint64_t outside = 0;
  bool in_lanes = false;
#if defined(TARMAC_WIDE_WALK)
  const int lanes = walk_lanes();
  in_lanes = lanes > 1;
  const HitPass pass{points_W, origin_W,         max_range,         v_m, min_, dims_,
                     ring_min, hit_slot_.data(), hit_column_.data()};
  if (lanes == 8) {
    outside += hit_voxels_lanes8(pass);
  } else if (lanes == 4) {
    outside += hit_voxels_lanes4(pass);
  }
#endif
  if (!in_lanes) {
    for (std::size_t i = 0; i < n_points; ++i) {
      const Eigen::Vector3f& p = points_W[i];
      hit_slot_[i] = kNoSlot;
      if (!p.allFinite() || (p.cast<double>() - origin_W).norm() > max_range) continue;
      std::int64_t slot = 0;
      std::int64_t stride = 1;
      bool inside = true;
      int rel[3];
      for (int a = 0; a < 3; ++a) {
        rel[a] = static_cast<int>(floor_to_int(static_cast<double>(p[a]) / v_m)) - min_[a];
        inside = inside && static_cast<unsigned>(rel[a]) < static_cast<unsigned>(dims_[a]);
        int ring = ring_min[a] + rel[a];
        if (ring >= dims_[a]) ring -= dims_[a];
        slot += ring * stride;
        stride *= dims_[a];
      }
      if (!inside) {
        ++outside;
        continue;
      }
      hit_slot_[i] = static_cast<std::uint32_t>(slot);
      hit_column_[i] = static_cast<std::uint32_t>(rel[1] * nx + rel[0]);
    }
  }
  return outside;
}

void OccupancyMap::hit_heights(std::span<const Eigen::Vector3f> points_W,
                               const Eigen::Vector3f& up) {
  const int nx = dims_.x(), ny = dims_.y();
  const std::size_t n_points = points_W.size();
  for (std::size_t k = 0; k < n_ground_cols_; ++k) {
    scan_ground_z_[scan_ground_cols_[k]] = kNoGround;
    scan_ground2_z_[scan_ground_cols_[k]] = kNoGround;
  }
  n_ground_cols_ = 0;
  // Heights, and the lowest return per column, in point order. A column's first return books
  // it without a branch (whether a column was touched before is as good as random: the branch
  // was a fifth of integrate_hits' own time): every return writes its column at the list's
  // end, which moves on only for a first return, so the list has room for one entry more than
  // there can be columns.
  const std::uint32_t* const slot_of_hit = hit_slot_.data();
  const std::size_t columns = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  scan_ground_cols_.resize(std::max(scan_ground_cols_.size(), std::min(n_points, columns) + 1));
  std::uint32_t* const touched = scan_ground_cols_.data();
  std::size_t n_touched = 0;
  float* const ground = scan_ground_z_.data();
  float* const ground2 = scan_ground2_z_.data();
  float* const height_of_hit = hit_height_.data();
  const std::uint32_t* const column_of_hit = hit_column_.data();
  for (std::size_t i = 0; i < n_points; ++i) {
    if (slot_of_hit[i] == kNoSlot) continue;
    const std::uint32_t column = column_of_hit[i];
    const float height = up.dot(points_W[i]);
    height_of_hit[i] = height;
    const float g = ground[column];
    touched[n_touched] = column;
    n_touched += g == kNoGround ? 1 : 0;
    ground[column] = std::min(g, height);
    ground2[column] = std::min(ground2[column], std::max(g, height));
  }
  n_ground_cols_ = n_touched;
}

void OccupancyMap::hit_rises(std::size_t n_points) {
  const int nx = dims_.x(), ny = dims_.y();
  const std::uint32_t* const slot_of_hit = hit_slot_.data();
  // Rise above the second-lowest return of this scan within ground_radius_m (an object cannot
  // hide the ground around it): one stray return below the ground (a reflection off a glossy
  // floor, a mixed pixel) would otherwise lift every return round it by its depth; a ring
  // crossing the ground there gives many returns. The lowest where it is the only one. Once
  // per column the scan touched (returns stack up in columns: walls, poles), then per return;
  // a return's own column is among them, so its ground is at most its height unless it is the
  // lowest there (a rise below zero reads as none).
  //
  // Where the scan returned little round a column (fewer than kDenseColumns of its neighbours
  // hold a return), the ground there may not have been returned at all: a beam grazing a 10 cm
  // object at range d from a sensor h up would have landed 0.1·d/h further on, and the ring
  // below lands d²·Δθ/h nearer (0.7 m at 15 m), so the object's own returns are the lowest
  // there. The ground remembered from a recent scan that returned densely round the spot
  // (ground_memory_z_, a world height re-read along today's up axis, so a vehicle pitching onto
  // a ramp does not tilt it) is the reference then, when lower.
  const int r = static_cast<int>(std::lround(params_.ground_radius_m / params_.voxel_size_m));
  const std::uint32_t scan = ++scans_integrated_;
  const double v_m = params_.voxel_size_m;
  const auto ring = [&](int x, int y) {
    return static_cast<std::size_t>(ring_y(y)) * nx + static_cast<std::size_t>(ring_x(x));
  };
  // Two passes, so that no column's ground depends on the order the scan's points came in: the
  // first takes every column's own ground and remembers the dense ones'; the second lowers the
  // sparse columns' to the ground remembered round them, this scan's included. The sparse
  // columns are gathered at the list's front as the first pass meets them.
  std::uint32_t* const cols = scan_ground_cols_.data();
  std::size_t n_sparse = 0;
  for (std::size_t k = 0; k < n_ground_cols_; ++k) {
    const std::uint32_t c = cols[k];
    const int cx = static_cast<int>(c % static_cast<std::uint32_t>(nx));
    const int cy = static_cast<int>(c / static_cast<std::uint32_t>(nx));
    float lowest = kNoGround, second = kNoGround;
    int returned = 0;
    for (int y = std::max(0, cy - r); y <= std::min(ny - 1, cy + r); ++y) {
      const std::size_t row = static_cast<std::size_t>(y) * nx;
      for (int x = std::max(0, cx - r); x <= std::min(nx - 1, cx + r); ++x) {
        const float g = scan_ground_z_[row + x];
        returned += g == kNoGround ? 0 : 1;
        second = std::min(second, std::max(lowest, g));
        lowest = std::min(lowest, g);
        second = std::min(second, scan_ground2_z_[row + x]);
      }
    }
    scan_ground_near_z_[c] = second == kNoGround ? lowest : second;
    if (returned < kDenseColumns) {
      std::swap(cols[k], cols[n_sparse++]);
      continue;
    }
    // Remembered only where the two lowest returns round it agree (a floor's mirror images
    // scatter in depth under it; a ground returns at one height). (Not on a vehicle on its
    // side: the world height along its up axis is undefined.)
    if (second != kNoGround && second - lowest <= kGroundAgreeM && up_.z() > 0.1f) {
      const Eigen::Vector2f xy = column_centre(min_, v_m, cx, cy);
      ground_memory_z_[ring(cx, cy)] =
          (scan_ground_near_z_[c] - up_.x() * xy.x() - up_.y() * xy.y()) / up_.z();
      ground_memory_scan_[ring(cx, cy)] = scan;
    }
  }
  for (std::size_t k = 0; k < n_sparse; ++k) {
    const std::uint32_t c = cols[k];
    const int cx = static_cast<int>(c % static_cast<std::uint32_t>(nx));
    const int cy = static_cast<int>(c / static_cast<std::uint32_t>(nx));
    scan_ground_near_z_[c] = lowest_remembered(cx, cy, kGroundMemoryScans, scan_ground_near_z_[c]);
  }
  // The loops that store bytes read through locals: a byte store may alias anything, and the
  // compiler would reload every member after each.
  std::uint8_t* const rise_of_hit = hit_rise_.data();
  const float* const height = hit_height_.data();
  const std::uint32_t* const column = hit_column_.data();
  const float* const ground_near = scan_ground_near_z_.data();
  for (std::size_t i = 0; i < n_points; ++i) {
    if (slot_of_hit[i] == kNoSlot) continue;
    const float ground_z = ground_near[column[i]];
    rise_of_hit[i] = static_cast<std::uint8_t>(
        std::clamp(static_cast<int>((height[i] - ground_z) * 100.0f), 0, 255));
  }
}

float OccupancyMap::lowest_remembered(int cx, int cy, std::uint32_t max_age, float z) const {
  const int nx = dims_.x(), ny = dims_.y();
  const double v_m = params_.voxel_size_m;
  for (int y = std::max(0, cy - 1); y <= std::min(ny - 1, cy + 1); ++y) {
    for (int x = std::max(0, cx - 1); x <= std::min(nx - 1, cx + 1); ++x) {
      const std::size_t q = static_cast<std::size_t>(ring_y(y)) * nx + ring_x(x);
      if (ground_memory_scan_[q] == 0 || scans_integrated_ - ground_memory_scan_[q] > max_age) {
        continue;
      }
      const Eigen::Vector2f xy = column_centre(min_, v_m, x, y);
      z = std::min(z, up_.x() * xy.x() + up_.y() * xy.y() + up_.z() * ground_memory_z_[q]);
    }
  }
  return z;
}

float OccupancyMap::ClearingGround::ground_z(std::uint32_t column) const {
  const auto nx = static_cast<std::uint32_t>(map_.dims_.x());
  return map_.lowest_remembered(static_cast<int>(column % nx), static_cast<int>(column / nx),
                                std::numeric_limits<std::uint32_t>::max(),
                                map_.scan_ground_near_z_[column]);
}

void OccupancyMap::apply_hits(std::span<const Eigen::Vector3f> points_W, OccupancyUpdate& stats) {
  const std::size_t n_points = points_W.size();
  const double v_m = params_.voxel_size_m;
  const std::uint32_t* const slot_of_hit = hit_slot_.data();
  const std::uint8_t* const rise_of_hit = hit_rise_.data();
  // One hit per voxel, in point order (promotions enter the static layer in that order).
  const int promote = params_.static_promote_scans;
  hit_slots_.resize(std::max(hit_slots_.size(), n_points));
  hit_before_.resize(hit_slots_.size());
  hit_rise_before_.resize(hit_slots_.size());
  std::uint32_t* const first_hits = hit_slots_.data();
  float* const before = hit_before_.data();
  std::uint8_t* const rise_before = hit_rise_before_.data();
  std::size_t n_first = 0;
  float* const log_odds = log_odds_.data();
  std::uint8_t* const state = state_.data();
  std::uint8_t* const rise_cm = rise_cm_.data();
  std::uint8_t* const hit_floor = hit_floor_.data();
  std::uint64_t* const hit_bits = hit_bits_.data();
  std::uint64_t* const floor_bits = floor_bits_.data();
  const float l_hit = l_hit_, l_min = l_min_, l_max = l_max_;
  std::uint64_t promotions = 0;
  // The voxels of a scan's returns are scattered over the window: their lines are requested a
  // few returns ahead, so that the misses overlap instead of stalling this loop one by one.
  constexpr std::size_t kAhead = 16;
  for (std::size_t i = 0; i < n_points; ++i) {
    if (i + kAhead < n_points && slot_of_hit[i + kAhead] != kNoSlot) {
      const std::uint32_t a = slot_of_hit[i + kAhead];
      __builtin_prefetch(log_odds + a, 1);
      __builtin_prefetch(state + a, 1);
      __builtin_prefetch(rise_cm + a, 1);
      __builtin_prefetch(hit_bits + (a >> 6), 1);
      __builtin_prefetch(floor_bits + (a >> 6), 1);
    }
    const std::uint32_t s = slot_of_hit[i];
    if (s == kNoSlot) continue;
    const std::uint8_t rise = rise_of_hit[i];
    std::uint64_t& word = hit_bits[s >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (s & 63);
    const std::uint8_t here = sub_voxel(points_W[i].z(), v_m);
    if ((word & bit) == 0) {
      word |= bit;
      floor_bits[s >> 6] &= ~bit;  // a hit lifts it off the lower clamp
      float& l = log_odds[s];
      before[n_first] = l;
      rise_before[n_first] = rise_cm[s];
      first_hits[n_first++] = s;
      // Reading free or unknown until now: its lowest return starts again from this one.
      const bool was_occupied = l > 0.0f;
      hit_floor[s] = was_occupied ? std::min(hit_floor[s], here) : here;
      l = after_hit(l, l_hit, l_min, l_max);
      if (!was_occupied && l > 0.0f) flag_brick(s);
      std::uint8_t& st = state[s];
      if ((st & kStatic) != 0) {
        st = kStatic;  // a return: the run of free observations restarts
      } else if (l <= 0.0f || promote == 0) {
        st = 0;  // not reading occupied yet: no run
      } else if ((st & kCount) + 1 >= promote) {
        st = kStatic;
        static_->insert(voxel_of_slot(s));
        ++promotions;
      } else {
        ++st;
      }
      rise_cm[s] = rise;  // the latest scan's returns replace older ones
    } else {
      rise_cm[s] = std::max(rise_cm[s], rise);
      hit_floor[s] = std::min(hit_floor[s], here);
    }
  }
  n_hit_slots_ = n_first;
  // The columns the hits changed: a voxel at the upper clamp hit again with the same highest
  // return did not change.
  const std::size_t plane = static_cast<std::size_t>(dims_.x()) * dims_.y();
  std::uint64_t* const changed = changed_columns_.data();
  for (std::size_t k = 0; k < n_first; ++k) {
    const std::uint32_t s = first_hits[k];
    if (log_odds[s] != before[k] || rise_cm[s] != rise_before[k]) {
      const std::size_t col = s % plane;
      changed[col >> 6] |= std::uint64_t{1} << (col & 63);
    }
  }
  if (!column_observed_ns_.empty()) {
    for (std::size_t k = 0; k < n_first; ++k) {
      const std::size_t z = first_hits[k] / plane;
      if (in_band_[z] != 0) column_observed_ns_[first_hits[k] - z * plane] = observation_stamp_ns_;
    }
  }
  stats.hit_updates += n_first;
  stats.promotions += promotions;
}

OccupancyUpdate OccupancyMap::integrate(const Eigen::Vector3d& origin_W,
                                        std::span<const Eigen::Vector3f> points_W,
                                        std::span<const Eigen::Vector3f> clearing_dirs_W,
                                        TaskRunner& runner, const Eigen::Vector3d& up_W) {
  OccupancyUpdate stats;
  if (!placed_) recenter(origin_W);
  std::fill(changed_columns_.begin(), changed_columns_.end(), std::uint64_t{0});
  const double max_range = params_.max_range_m;
  const double clear_range = params_.clearing_range_m;

  // 1. Hits (integrate_hits), in one task beside the ray walks of 2.: they touch disjoint data
  //    (the hit pass the per-return arrays, the hit bits and the hit voxels' state; the walks
  //    their own mark bit sets). Applied before any miss in 3., so that a voxel hit by any ray
  //    of this scan is never also cleared by it.
  const std::size_t n_points = points_W.size();
  const std::array<int, 3> ring_min = ring_origin();
  // 2. Free space: each ray task marks the voxels its rays pass through in its own bit set
  //    (chunks of rays as the tasks ask for them; their union does not depend on who took
  //    which, see TaskRays).
  const std::size_t n_rays = n_points + clearing_dirs_W.size();
  const WindowGeometry w{dims_, min_, params_.voxel_size_m};
  const RayStart start(w, origin_W);
  std::array<std::uint64_t, kRayTasks> task_visits{};
  std::array<MarkBox, kRayTasks> task_boxes{};
  const bool flag_words = !dirty_words_.empty();
  // The order helps the one-at-a-time walk's branch prediction, and the four-lane walk's
  // lockstep (neighbours in direction end near each other). The eight-lane walk refills a lane
  // as its walk ends and needs neither, so it skips the sort (docs/mapping.md).
  std::atomic<std::size_t> next_chunk{0};
  const int lanes = walk_lanes();
  const bool wide = lanes == 8;
  if (!wide) {
    sort_rays_by_direction(origin_W, points_W, clearing_dirs_W, ray_bucket_, ray_bucket_count_,
                           ray_order_, runner);
  }
  const std::span<const std::uint32_t> order =
      wide ? std::span<const std::uint32_t>{} : std::span<const std::uint32_t>(ray_order_);
  has_no_returns_ = !clearing_dirs_W.empty();
  runner.parallel_for(1 + kRayTasks, [&](std::size_t job) {
    if (job == 0) {
      integrate_hits(origin_W, points_W, up_W, stats);
      scan_rays_.build(origin_W, points_W, clearing_dirs_W, max_range, clear_range);
      return;
    }
    const std::size_t task = job - 1;
    MarkBox& box = task_boxes[task];
    const FreeMarks marks{free_bits_[task].data(),
                          flag_words ? dirty_words_[task].data() : nullptr};
    const std::uint64_t visits = walk_task(
        w, start,
        TaskRays{points_W, clearing_dirs_W, order, origin_W, max_range, clear_range, &next_chunk},
        marks, box, lanes);
    task_visits[task] = visits;
  });

  // 3. Apply: fixed ranges of mark words, each voxel marked by any task and not hit gets one
  //    miss. Only the words inside the box of all marks are read (small windows) or only the
  //    blocks a ray flagged (large ones). The marks are cleared as they are read, ready for the
  //    next scan. Only voxels reading occupied carry static-layer state (free space costs no
  //    extra memory access). A word may be visited twice (rows share words); the second visit
  //    finds its marks cleared, so every marked voxel gets exactly one miss.
  MarkBox marked_box;
  for (const MarkBox& b : task_boxes) marked_box.add(b);
  const std::size_t n_words = hit_bits_.size();
  const std::size_t n_blocks = (n_words >> kBlockShift) + 1;
  std::array<std::uint64_t*, kRayTasks> task_bits{};
  for (std::size_t t = 0; t < kRayTasks; ++t) task_bits[t] = free_bits_[t].data();
  std::array<std::uint64_t, kApplyTasks> task_updates{};
  const MissLanes miss_lanes(l_miss_, l_min_);

  runner.parallel_for(kApplyTasks, [&](std::size_t task) {
    candidates_[task].clear();
    ApplyPass pass{
        task_bits,
        hit_bits_.data(),
        floor_bits_.data(),
        log_odds_.data(),
        rise_cm_.data(),
        miss_lanes,
        l_miss_,
        l_min_,
        candidates_[task],
        ColumnMarks{changed_columns_.data(), static_cast<std::size_t>(dims_.x()) * dims_.y()}};
    if (!column_observed_ns_.empty()) {
      pass.column_stamp = column_observed_ns_.data();
      pass.in_band = in_band_.data();
      pass.plane = static_cast<std::size_t>(dims_.x()) * static_cast<std::size_t>(dims_.y());
      pass.stamp = observation_stamp_ns_;
    }
    if (flag_words) {
      pass.gather_flagged(n_blocks * task / kApplyTasks, n_blocks * (task + 1) / kApplyTasks,
                          dirty_words_);
    } else if (!marked_box.empty()) {
      pass.gather_box(n_words * task / kApplyTasks, n_words * (task + 1) / kApplyTasks, marked_box,
                      dims_, ring_min);
    }
    pass.flush();
    task_updates[task] = pass.updates;
  });
  for (std::size_t k = 0; k < n_hit_slots_; ++k) hit_bits_[hit_slots_[k] >> 6] = 0;
  miss_occupied(runner, stats);
  // The walks of the next scan's beams without return (first_occupied) read the bricks.
  refresh_bricks(kBrickRowsPerScan);
  if (bricks_dirty_) update_brick_skips();

  stats.rays = n_rays;
  for (const auto v : task_visits) stats.voxel_visits += v;
  for (const auto u : task_updates) stats.miss_updates += u;
  stats.changed = ChangedColumns(changed_columns_, dims_.x(), dims_.y(), ring_min[0], ring_min[1]);
  return stats;
}

void OccupancyMap::miss_occupied(TaskRunner& runner, OccupancyUpdate& stats) {
  // a) Decide, reading only (so that no decision sees another's write): which of the occupied
  //    voxels a ray crossed this scan get a miss. A voxel with observed free space below it and
  //    none above (unknown, or occupied) is the underside of something: an aircraft's belly,
  //    an engine, a truck bed. Rays that cross such a voxel under its lowest return only pass
  //    under the surface; they miss it only when one passes through the voxel at or above its
  //    lowest return and goes on more than a voxel (ScanRays::any_passes). Every other
  //    occupied voxel a ray crossed gets its miss, as any free voxel does: the top of a tug
  //    that drove away has free space above it, and clears as fast as before.
  const std::size_t n_tasks = candidates_.size();
  std::array<std::size_t, kApplyTasks + 1> first{};
  for (std::size_t t = 0; t < n_tasks; ++t) first[t + 1] = first[t] + candidates_[t].size();
  const std::size_t n = first[n_tasks];
  miss_decision_.resize(std::max(miss_decision_.size(), n));
  const double v = params_.voxel_size_m;
  const int nz = dims_.z();
  const std::size_t layer = static_cast<std::size_t>(dims_.x()) * dims_.y();
  const int ring_z0 = wrap(min_.z(), nz);
  const auto reads_free = [&](std::size_t s) {
    const float l = log_odds_[s];
    return l != kUnknown && l <= 0.0f;
  };
  runner.parallel_for(n_tasks, [&](std::size_t task) {
    const std::vector<std::uint32_t>& list = candidates_[task];
    for (std::size_t k = 0; k < list.size(); ++k) {
      const std::size_t s = list[k];
      bool miss = true;
      const std::uint8_t floor32 = hit_floor_[s];
      const int rel_z = wrap(static_cast<int>(s / layer) - ring_z0, nz);
      const Eigen::Vector3d corner = voxel_of_slot(s).cast<double>() * v;
      if (floor32 != kNoHitFloor && rel_z > 0) {
        const std::size_t below = s >= layer ? s - layer : s + layer * (nz - 1);
        const bool above_free =
            rel_z + 1 < nz &&
            reads_free(s + layer < layer * nz ? s + layer : s + layer - layer * nz);
        if (reads_free(below) && !above_free) {
          const Eigen::Vector3d lo(corner.x(), corner.y(), corner.z() + floor32 * v / kFloorSteps);
          miss = scan_rays_.any_passes(lo, corner + Eigen::Vector3d::Constant(v), v, true);
        }
      }
      // Beams without a return never empty an occupied voxel: a black or mirror-like surface
      // returns nothing too. Only a ray that ended at a return shows it empty.
      if (miss && has_no_returns_) {
        miss = scan_rays_.any_passes(corner, corner + Eigen::Vector3d::Constant(v), 0.0, true);
      }
      miss_decision_[first[task] + k] = miss ? 1 : 0;
    }
  });
  // b) Apply, in the lists' order: the misses, and the static layer's runs of free
  //    observations (a static voxel leaves the layer after static_demote_scans in a row).
  const int demote = params_.static_demote_scans;
  for (std::size_t t = 0; t < n_tasks; ++t) {
    const std::vector<std::uint32_t>& list = candidates_[t];
    for (std::size_t k = 0; k < list.size(); ++k) {
      if (miss_decision_[first[t] + k] == 0) continue;
      const std::size_t s = list[k];
      float& l = log_odds_[s];
      std::uint8_t& st = state_[s];
      const float l_before = l;
      const std::uint8_t rise_before = rise_cm_[s];
      if ((st & kStatic) == 0) {
        l = after_miss(l, l_miss_, l_min_);  // reads occupied: never kUnknown
        if (l <= 0.0f) {  // reads free: the run of hits is broken, the heights are void
          st = 0;
          rise_cm_[s] = 0;
        }
      } else if ((st & kCount) + 1 >= demote) {
        st = 0;  // strong free evidence: leaves the static layer and reads free
        l = std::max(l_miss_, l_min_);
        rise_cm_[s] = 0;
        static_->erase(voxel_of_slot(s));
        ++stats.demotions;
      } else {
        ++st;
        l = std::max(l + l_miss_, l_hit_);  // a static voxel reads at least one hit
      }
      if (l != l_before || rise_cm_[s] != rise_before) {
        const std::size_t col = s % layer;
        changed_columns_[col >> 6] |= std::uint64_t{1} << (col & 63);
      }
    }
  }
}

}  // namespace tarmac::core
