#include "tarmac/core/scan_filter.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace tarmac::core {

Status FilterParams::validate() const {
  if (!(min_range_m >= 0.0)) return Error{"config.range", "filters.min_range_m: must be >= 0"};
  if (ego_box_enabled && !(ego_box_min_B.array() < ego_box_max_B.array()).all()) {
    return Error{"config.range", "filters.ego_box: min must be < max on every axis"};
  }
  if (outlier_min_neighbors < 0 || outlier_min_neighbors > 26) {
    return Error{"config.range", "filters.outlier_min_neighbors: must be in [0, 26]"};
  }
  if (!(outlier_cell_m >= 0.05 && outlier_cell_m <= 5.0)) {
    return Error{"config.range", "filters.outlier_cell_m: must be in [0.05, 5]"};
  }
  return Ok{};
}

namespace {

/// Fixed number of point ranges the filter splits a scan into, whatever the runner's threads
/// (the result does not depend on the split: every decision is per point).
constexpr std::size_t kFilterTasks = 8;

/// floor() to an integer for any finite float in int64 range, without a libm call.
std::int64_t floor_to_int(float v) {
  const auto i = static_cast<std::int64_t>(v);  // truncates toward zero
  return i - static_cast<std::int64_t>(static_cast<float>(i) > v);
}

constexpr std::uint64_t kField = 0x1fffff;

/// Packs a cell coordinate (each within ±2^20 cells) into a non-zero key.
std::uint64_t cell_key(const Eigen::Vector3f& p, float inv_cell) {
  const auto c = [&](float v) {
    return static_cast<std::uint64_t>(floor_to_int(v * inv_cell) + (1 << 20)) & kField;
  };
  return (c(p.x()) << 42) | (c(p.y()) << 21) | c(p.z()) | (1ull << 63);
}

/// Home slot of a key: linear in the cell coordinates with the z coordinate unscaled, so the
/// cells of one column sit in neighbouring slots and a point's 27 lookups touch about 9 cache
/// lines instead of 27.
std::size_t slot_of(std::uint64_t key, std::size_t mask) {
  return static_cast<std::size_t>(((key >> 42) & kField) * 0xC2B2AE3D27D4EB4Full +
                                  ((key >> 21) & kField) * 0x9E3779B97F4A7C15ull + (key & kField)) &
         mask;
}

/// Offsets of the 27 cells around a key, the point's own column first (most often enough to
/// decide, so the lookup stops early).
constexpr std::array<std::array<int, 2>, 9> kColumns{
    {{0, 0}, {-1, 0}, {1, 0}, {0, -1}, {0, 1}, {-1, -1}, {-1, 1}, {1, -1}, {1, 1}}};

std::uint64_t key_offset(int dx, int dy, int dz) {
  return (static_cast<std::uint64_t>(static_cast<std::int64_t>(dx)) << 42) +
         (static_cast<std::uint64_t>(static_cast<std::int64_t>(dy)) << 21) +
         static_cast<std::uint64_t>(static_cast<std::int64_t>(dz));
}

/// Slots of the outlier table for `points` candidates: a power of two, at least twice as many
/// (so linear probing stays short), at least 1024. reserve() sizes for it, filter_scan uses it.
std::size_t table_capacity(std::size_t points) {
  std::size_t capacity = 1024;
  while (capacity < 2 * points) capacity *= 2;
  return capacity;
}

// A slot is one aligned 16-byte unit: it never straddles two cache lines.
static_assert(sizeof(FilterScratch::Cell) == 16 && alignof(FilterScratch::Cell) == 16);

}  // namespace

void FilterScratch::reserve(std::size_t points) {
  cells.assign(table_capacity(points), Cell{});
  point_key.assign(points, 0);
  point_slot.assign(points, 0);
  point_near.assign(points, 0);
  candidates_S.assign(points, Eigen::Vector3f::Zero());
  candidates_W.assign(points, Eigen::Vector3f::Zero());
  keep.assign(points, 0);
}

FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W, FilterScratch& scratch) {
  SerialRunner serial;
  return filter_scan(cloud, T_W_S, T_B_S, params, points_W, scratch, serial);
}

FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W, FilterScratch& scratch,
                         TaskRunner& runner, std::vector<Eigen::Vector3f>* points_S) {
  const std::size_t n = cloud.size();
  const double min_sq = params.min_range_m * params.min_range_m;
  const Eigen::Matrix3f R_W_S = T_W_S.linear().cast<float>();
  const Eigen::Vector3f t_W_S = T_W_S.translation().cast<float>();
  const Eigen::Matrix3d R_B_S = T_B_S.linear();
  const Eigen::Vector3d t_B_S = T_B_S.translation();
  const bool outliers = params.outlier_min_neighbors > 0;
  const float inv_cell = static_cast<float>(1.0 / params.outlier_cell_m);
  const float near_sq = static_cast<float>(params.outlier_max_range_m * params.outlier_max_range_m);

  // 1. Per-point tests, each task compacting its candidates to the front of its own range.
  std::array<FilterCounts, kFilterTasks> task_counts{};
  std::array<std::size_t, kFilterTasks + 1> first{};  // candidates of task t: [first[t], …)
  std::array<std::size_t, kFilterTasks> last{};
  for (std::size_t t = 0; t <= kFilterTasks; ++t) first[t] = n * t / kFilterTasks;
  scratch.candidates_S.resize(n);
  scratch.point_key.resize(n);
  scratch.point_near.resize(n);
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    FilterCounts& c = task_counts[task];
    std::size_t out = first[task];
    for (std::size_t i = first[task]; i < first[task + 1]; ++i) {
      const Eigen::Vector3f& p = cloud.points_S[i];
      if (!p.allFinite()) {
        ++c.non_finite;
        continue;
      }
      if (static_cast<double>(p.squaredNorm()) < min_sq) {
        ++c.too_close;
        continue;
      }
      if (params.ego_box_enabled) {
        const Eigen::Vector3d p_B = R_B_S * p.cast<double>() + t_B_S;
        if ((p_B.array() >= params.ego_box_min_B.array()).all() &&
            (p_B.array() <= params.ego_box_max_B.array()).all()) {
          ++c.ego_vehicle;
          continue;
        }
      }
      scratch.candidates_S[out] = p;
      if (outliers) {
        scratch.point_key[out] = cell_key(p, inv_cell);
        scratch.point_near[out] = p.squaredNorm() < near_sq ? 1 : 0;
      }
      ++out;
    }
    last[task] = out;
  });
  // Task t's candidates are [first[t], last[t]): the passes below take the tasks' ranges in
  // order (no copy to close the gaps), so the survivors keep the input order.
  std::size_t m = 0;
  for (std::size_t t = 0; t < kFilterTasks; ++t) m += last[t] - first[t];
  const auto each_candidate = [&](std::size_t t, auto&& f) {
    for (std::size_t i = first[t]; i < last[t]; ++i) f(i);
  };

  // 2. Isolated outliers, counted in the sensor frame: a hash of occupied cells (built in one
  //    pass, each candidate noting its cell's slot), then each cell that holds a near candidate
  //    looks at its 27 cells once, for all the candidates it holds. Membership only, so the
  //    result does not depend on order.
  const auto& cand = scratch.candidates_S;
  std::size_t mask = 0;
  std::size_t capacity = 0;
  // The slot holding `key`, or the empty slot where it would go (linear probing).
  const auto find = [&](std::uint64_t key) {
    std::size_t s = slot_of(key, mask);
    while (scratch.cells[s].key != 0 && scratch.cells[s].key != key) s = (s + 1) & mask;
    return s;
  };
  // Sized for twice the last scan's distinct cells, not for every candidate: points share
  // cells (BALM hall: 3 k cells for 18 k points), and the table is cold at each scan, so its
  // emptying and its inserts cost by the line (64 k slots, 1 MB, took 0.16 ms to empty and
  // 0.17 ms to fill). A scan with more cells than half the table starts again with a table
  // for all its candidates, which always fits. The counts per cell, hence the result, do not
  // depend on the table's size.
  const auto build_table = [&] {
    const std::size_t full = table_capacity(m);
    capacity = std::min(full, table_capacity(2 * scratch.last_cells));
    while (true) {
      mask = capacity - 1;
      scratch.cells.resize(std::max(scratch.cells.size(), capacity));
      std::fill_n(scratch.cells.begin(), capacity, FilterScratch::Cell{});
      std::size_t distinct = 0;
      // The candidates' cells are scattered over the table (MulRan's 36 k points over 100 m):
      // their slots' lines are requested a few candidates ahead, so that the misses overlap.
      constexpr std::size_t kAhead = 8;
      for (std::size_t t = 0; t < kFilterTasks && 2 * distinct <= capacity; ++t) {
        for (std::size_t i = first[t]; i < last[t] && 2 * distinct <= capacity; ++i) {
          if (i + kAhead < last[t]) {
            __builtin_prefetch(&scratch.cells[slot_of(scratch.point_key[i + kAhead], mask)], 1);
          }
          const std::uint64_t key = scratch.point_key[i];
          const std::size_t s = find(key);
          FilterScratch::Cell& cell = scratch.cells[s];
          distinct += cell.key == 0 ? 1 : 0;
          cell.key = key;
          ++cell.count;
          cell.state |= scratch.point_near[i];
          scratch.point_slot[i] = static_cast<std::uint32_t>(s);
        }
      }
      if (2 * distinct <= capacity) {
        scratch.last_cells = distinct;
        return;
      }
      capacity = full;  // more than half full: again, with room for every candidate
    }
  };
  // The table is built on one thread (two tables side by side were no faster, the cells being
  // scattered: docs/perf-occ7.md); the candidates go into the world frame meanwhile, in ranges,
  // the survivors picked from them at the end.
  scratch.point_slot.resize(n);
  scratch.candidates_W.resize(n);
  runner.parallel_for(1 + kFilterTasks, [&](std::size_t job) {
    if (job == 0) {
      if (outliers) build_table();
      return;
    }
    each_candidate(job - 1,
                   [&](std::size_t i) { scratch.candidates_W[i] = R_W_S * cand[i] + t_W_S; });
  });
  const auto count_in = [&](std::uint64_t key) -> std::uint32_t {
    return scratch.cells[find(key)].count;  // an empty slot's count is 0
  };
  // Itself and outlier_min_neighbors others.
  const auto needed = static_cast<std::uint32_t>(params.outlier_min_neighbors) + 1;
  const auto has_neighbours = [&](std::uint64_t key) {
    std::uint32_t points = 0;
    for (const auto& [dx, dy] : kColumns) {
      for (int dz = -1; dz <= 1; ++dz) {
        points += count_in(key + key_offset(dx, dy, dz));
        if (points >= needed) return true;
      }
    }
    return false;
  };
  if (outliers) {
    // Each task owns a fixed range of slots: it writes only their bit 1.
    runner.parallel_for(kFilterTasks, [&](std::size_t task) {
      for (std::size_t s = capacity * task / kFilterTasks; s < capacity * (task + 1) / kFilterTasks;
           ++s) {
        FilterScratch::Cell& cell = scratch.cells[s];
        if (cell.state != 0 && has_neighbours(cell.key)) cell.state |= 2;
      }
    });
  }
  scratch.keep.resize(n);
  std::array<std::size_t, kFilterTasks + 1> kept_before{};
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    std::size_t kept = 0;
    each_candidate(task, [&](std::size_t i) {
      const bool keep = !outliers || scratch.point_near[i] == 0 ||
                        (scratch.cells[scratch.point_slot[i]].state & 2) != 0;
      scratch.keep[i] = keep ? 1 : 0;
      kept += keep ? 1 : 0;
    });
    kept_before[task + 1] = kept;
  });
  for (std::size_t t = 0; t < kFilterTasks; ++t) kept_before[t + 1] += kept_before[t];

  // 3. The survivors, in input order, each task writing its own range of the output.
  points_W.resize(kept_before[kFilterTasks]);
  if (points_S != nullptr) points_S->resize(points_W.size());
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    std::size_t out = kept_before[task];
    each_candidate(task, [&](std::size_t i) {
      if (scratch.keep[i] == 0) return;
      if (points_S != nullptr) (*points_S)[out] = cand[i];
      points_W[out++] = scratch.candidates_W[i];
    });
  });

  FilterCounts counts;
  counts.input = n;
  for (const FilterCounts& c : task_counts) {
    counts.non_finite += c.non_finite;
    counts.too_close += c.too_close;
    counts.ego_vehicle += c.ego_vehicle;
  }
  counts.kept = points_W.size();
  counts.isolated = m - counts.kept;
  return counts;
}

}  // namespace tarmac::core
