#include "tarmac/core/scan_filter.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "lanes4.hpp"
#include "scan_filter_lanes.hpp"

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
  if (!(outlier_max_range_m >= 0.0 && outlier_max_range_m <= 1000.0)) {
    return Error{"config.range", "filters.outlier_max_range_m: must be in [0, 1000]"};
  }
  return Ok{};
}

namespace {

using scan_filter_detail::kCellLimit;
using scan_filter_detail::kField;
using scan_filter_detail::OutlierRegion;
using scan_filter_detail::PointLanes;

/// Fixed number of point ranges the filter splits a scan into, whatever the runner's threads
/// (the result does not depend on the split: every decision is per point).
constexpr std::size_t kFilterTasks = 8;

/// floor() to an integer for any finite float in int64 range, without a libm call.
std::int64_t floor_to_int(float v) {
  const auto i = static_cast<std::int64_t>(v);  // truncates toward zero
  return i - static_cast<std::int64_t>(static_cast<float>(i) > v);
}

/// The cell of a point, floor(coordinate / cell) per axis; false (and `c` unset) when a
/// coordinate is beyond kCellLimit cells.
bool cell_of(const Eigen::Vector3f& p, float inv_cell, std::array<std::int64_t, 3>& c) {
  for (int a = 0; a < 3; ++a) {
    const float q = p[a] * inv_cell;
    if (!(std::abs(q) <= kCellLimit)) return false;
    c[static_cast<std::size_t>(a)] = floor_to_int(q);
  }
  return true;
}

/// A non-zero key from a cell's three 21-bit fields (coordinate + 2^20, wrapped).
std::uint64_t pack_key(std::uint64_t fx, std::uint64_t fy, std::uint64_t fz) {
  return (fx << 42) | (fy << 21) | fz | (1ull << 63);
}

/// Packs a cell coordinate (each within ±2^20 cells) into a non-zero key.
std::uint64_t cell_key(const std::array<std::int64_t, 3>& c) {
  const auto field = [](std::int64_t v) {
    return static_cast<std::uint64_t>(v + (1 << 20)) & kField;
  };
  return pack_key(field(c[0]), field(c[1]), field(c[2]));
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

/// Bits of FilterScratch::point_near: the candidate is near enough to be tested; its cell lies
/// in the region the test reads (OutlierRegion).
constexpr std::uint8_t kNear = 1, kInRegion = 4;

// A slot is one aligned 16-byte unit: it never straddles two cache lines.
static_assert(sizeof(FilterScratch::Cell) == 16 && alignof(FilterScratch::Cell) == 16);

/// A scan's candidates between the filter's passes: task t's are [first[t], last[t]) of the
/// scratch arrays (the passes take the tasks' ranges in order, and no copy closes the gaps, so
/// the survivors keep the input order).
struct CandidateRanges {
  std::array<std::size_t, kFilterTasks + 1> first{};
  std::array<std::size_t, kFilterTasks> last{};

  [[nodiscard]] std::size_t count() const {
    std::size_t m = 0;
    for (std::size_t t = 0; t < kFilterTasks; ++t) m += last[t] - first[t];
    return m;
  }

  /// f(i) for each of task t's candidates, in order.
  template <typename F>
  void each(std::size_t t, F&& f) const {
    for (std::size_t i = first[t]; i < last[t]; ++i) f(i);
  }
};

/// A scan's per-point tests (filter_scan's step 1): not finite, too close, in the ego box, or a
/// candidate, with what the outlier test reads of it (its cell, whether it is near).
class PointTests {
 public:
  PointTests(const FilterParams& params, const Eigen::Isometry3d& T_B_S,
             const OutlierRegion& region)
      : params_(params),
        region_(region),
        R_B_S_(T_B_S.linear()),
        t_B_S_(T_B_S.translation()),
        min_sq_(params.min_range_m * params.min_range_m),
        outliers_(params.outlier_min_neighbors > 0),
        inv_cell_(static_cast<float>(1.0 / params.outlier_cell_m)),
        near_sq_(near_sq_of(params, region)),
        lanes_(params, T_B_S, inv_cell_, near_sq_, region) {}

  /// Tests the points [begin, end), four at a time where it can, compacting the candidates to
  /// the front of the range in scratch's candidate arrays; returns the end of the candidates,
  /// `counts` the points rejected.
  std::size_t test_range(const Eigen::Vector3f* points, std::size_t begin, std::size_t end,
                         FilterScratch& scratch, FilterCounts& counts) const {
    // Locals rather than scratch's members, the counts and this object's: a byte store may
    // alias anything, and the compiler would reload them after each.
    FilterCounts c;
    Eigen::Vector3f* const cand_S = scratch.candidates_S.data();
    std::uint64_t* const keys = scratch.point_key.data();
    std::uint32_t* const cells = scratch.point_slot.data();
    std::uint8_t* const flags = scratch.point_near.data();
    const bool grid = region_.grid;
    std::size_t out = begin;
    std::size_t i = begin;
    for (; i + 4 <= end; i += 4) {
      const PointLanes::Found f = lanes_.test(points + i);
      c.non_finite += static_cast<std::uint64_t>(4 - bit_count(f.finite));
      c.too_close += static_cast<std::uint64_t>(bit_count(f.close));
      for (unsigned pass = f.finite & ~f.close; pass != 0; pass &= pass - 1) {
        const int l = std::countr_zero(pass);
        const Eigen::Vector3f& p = points[i + static_cast<std::size_t>(l)];
        if (((f.maybe_ego >> l) & 1u) != 0 && in_ego_box(p)) {
          ++c.ego_vehicle;
          continue;
        }
        cand_S[out] = p;
        if (outliers_) {
          if (grid) {
            cells[out] = f.index[l];  // read for candidates in the region only
          } else {
            // Beyond kCellLimit cells (not keyed): out of the region, the key is not read.
            keys[out] = ((f.keyed >> l) & 1u) != 0
                            ? pack_key(f.field[0][l], f.field[1][l], f.field[2][l])
                            : 0;
          }
          flags[out] = static_cast<std::uint8_t>((((f.near >> l) & 1u) != 0 ? kNear : 0) |
                                                 (((f.region >> l) & 1u) != 0 ? kInRegion : 0));
        }
        ++out;
      }
    }
    for (; i < end; ++i) test_point(points[i], scratch, c, out);
    counts = c;
    return out;
  }

 private:
  /// Near: within the outlier range, as far as the region reaches (the same range for valid
  /// parameters; a larger, unvalidated one would put near points outside the region the test
  /// reads).
  static float near_sq_of(const FilterParams& params, const OutlierRegion& region) {
    const double near_m = region.near_range_m(params);
    return static_cast<float>(near_m * near_m);
  }

  [[nodiscard]] bool in_ego_box(const Eigen::Vector3f& p) const {
    const Eigen::Vector3d p_B = R_B_S_ * p.cast<double>() + t_B_S_;
    return (p_B.array() >= params_.ego_box_min_B.array()).all() &&
           (p_B.array() <= params_.ego_box_max_B.array()).all();
  }

  /// `p` as the candidate at `out`, which moves on by one.
  void add_candidate(const Eigen::Vector3f& p, FilterScratch& scratch, std::size_t& out) const {
    scratch.candidates_S[out] = p;
    if (outliers_) {
      std::array<std::int64_t, 3> c{};
      const bool in_range = cell_of(p, inv_cell_, c);
      const bool in_region = in_range && region_.holds(c);
      const std::uint64_t key = in_range ? cell_key(c) : 0;  // not read out of the region
      if (!region_.grid) {
        scratch.point_key[out] = key;
      } else if (in_region) {  // the grid path reads the cell's index instead
        scratch.point_slot[out] =
            region_.index((key >> 42) & kField, (key >> 21) & kField, key & kField);
      }
      scratch.point_near[out] = static_cast<std::uint8_t>((p.squaredNorm() < near_sq_ ? kNear : 0) |
                                                          (in_region ? kInRegion : 0));
    }
    ++out;
  }

  /// The tests one point at a time: the reference (and the lanes' fallback).
  void test_point(const Eigen::Vector3f& p, FilterScratch& scratch, FilterCounts& c,
                  std::size_t& out) const {
    if (!p.allFinite()) {
      ++c.non_finite;
    } else if (static_cast<double>(p.squaredNorm()) < min_sq_) {
      ++c.too_close;
    } else if (params_.ego_box_enabled && in_ego_box(p)) {
      ++c.ego_vehicle;
    } else {
      add_candidate(p, scratch, out);
    }
  }

  const FilterParams& params_;
  const OutlierRegion& region_;
  Eigen::Matrix3d R_B_S_;
  Eigen::Vector3d t_B_S_;
  double min_sq_;
  bool outliers_;
  float inv_cell_;
  float near_sq_;
  PointLanes lanes_;  ///< the same tests four points at a time
};

/// Step 1: the per-point tests, each task compacting its candidates to the front of its own
/// range of the scan; returns the candidates' ranges, `task_counts` the points each task
/// rejected.
CandidateRanges find_candidates(const PointCloud& cloud, const PointTests& tests,
                                FilterScratch& scratch, TaskRunner& runner,
                                std::array<FilterCounts, kFilterTasks>& task_counts) {
  const std::size_t n = cloud.size();
  CandidateRanges ranges;
  for (std::size_t t = 0; t <= kFilterTasks; ++t) ranges.first[t] = n * t / kFilterTasks;
  scratch.candidates_S.resize(n);
  scratch.point_key.resize(n);
  scratch.point_slot.resize(n);
  scratch.point_near.resize(n);
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    ranges.last[task] = tests.test_range(cloud.points_S.data(), ranges.first[task],
                                         ranges.first[task + 1], scratch, task_counts[task]);
  });
  return ranges;
}

/// The isolated-outlier test in the grid of bytes around the sensor (OutlierRegion::grid): the
/// candidates counted per cell on one thread while the tasks run `to_world(task)`, then
/// `decide(task, passes)` per task with the grid's answer for near candidates. `needed`: the
/// candidate itself and outlier_min_neighbors others.
template <typename ToWorld, typename Decide>
void isolate_in_grid(const OutlierRegion& region, std::uint32_t needed,
                     const CandidateRanges& ranges, FilterScratch& scratch, TaskRunner& runner,
                     ToWorld&& to_world, Decide&& decide) {
  if (scratch.grid.size() != region.side * region.side * region.side) {
    scratch.grid.assign(region.side * region.side * region.side, 0);  // config changed
    scratch.n_grid_touched = 0;
  }
  std::uint8_t* const grid = scratch.grid.data();
  // One byte per cell, saturating (the test needs at most 27).
  const auto count = [&] {
    for (std::size_t k = 0; k < scratch.n_grid_touched; ++k) {
      grid[scratch.grid_touched[k]] = 0;  // the last scan's cells
    }
    scratch.grid_touched.resize(std::max(scratch.grid_touched.size(), ranges.count()));
    // Locals: a byte store may alias anything, and the compiler would reload each of these
    // after every count otherwise.
    std::uint32_t* const touched = scratch.grid_touched.data();
    const std::uint32_t* const cells = scratch.point_slot.data();
    const std::uint8_t* const flags = scratch.point_near.data();
    std::size_t n_touched = 0;
    // The cells are scattered over the grid: requested a few candidates ahead, and no branch
    // depends on a count (a cell's first candidate books it without one).
    constexpr std::size_t kAhead = 16;
    for (std::size_t t = 0; t < kFilterTasks; ++t) {
      const std::size_t begin = ranges.first[t], end = ranges.last[t];
      for (std::size_t i = begin; i < end; ++i) {
        if (i + kAhead < end) {
          const std::size_t j = i + kAhead;
          __builtin_prefetch(grid + ((flags[j] & kInRegion) != 0 ? cells[j] : 0), 1);
        }
        if ((flags[i] & kInRegion) == 0) continue;
        const std::size_t c = cells[i];
        const std::uint8_t g = grid[c];
        touched[n_touched] = static_cast<std::uint32_t>(c);
        n_touched += g == 0 ? 1 : 0;
        grid[c] = static_cast<std::uint8_t>(g + (g != 255 ? 1 : 0));
      }
    }
    scratch.n_grid_touched = n_touched;
  };
  runner.parallel_for(1 + kFilterTasks, [&](std::size_t job) {
    if (job == 0) {
      count();
    } else {
      to_world(job - 1);
    }
  });
  // A near candidate's cell and its neighbours are in the region (see OutlierRegion).
  const std::ptrdiff_t row = static_cast<std::ptrdiff_t>(region.side);
  const std::ptrdiff_t layer = row * row;
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    const std::uint32_t* const cells = scratch.point_slot.data();
    decide(task, [&](std::size_t i) {
      const std::uint8_t* const c = grid + cells[i];
      if (*c >= needed) return true;  // enough in its own cell: most of them (walls)
      std::uint32_t points = 0;
      for (const std::ptrdiff_t dz : {std::ptrdiff_t{0}, -layer, layer}) {
        for (const std::ptrdiff_t dy : {std::ptrdiff_t{0}, -row, row}) {
          const std::uint8_t* const x_row = c + dz + dy;  // x − 1, x, x + 1
          points += std::uint32_t{x_row[-1]} + x_row[0] + x_row[1];
          if (points >= needed) return true;
        }
      }
      return false;
    });
  });
}

/// The same test with the cells in a hash table (regions over FilterScratch::grid_cell_limit
/// cells), or, without the test (`outliers` false), the world frame and every candidate kept.
template <typename ToWorld, typename Decide>
void isolate_in_table(bool outliers, std::uint32_t needed, const CandidateRanges& ranges,
                      FilterScratch& scratch, TaskRunner& runner, ToWorld&& to_world,
                      Decide&& decide) {
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
    const std::size_t full = table_capacity(ranges.count());
    capacity = std::min(full, table_capacity(2 * scratch.last_cells));
    while (true) {
      mask = capacity - 1;
      scratch.cells.resize(std::max(scratch.cells.size(), capacity));
      std::fill_n(scratch.cells.begin(), capacity, FilterScratch::Cell{});
      std::size_t distinct = 0;
      // The candidates' cells are scattered over the table (MulRan's 36 k points over 100
      // m): their slots' lines are requested a few candidates ahead, so that the misses
      // overlap.
      constexpr std::size_t kAhead = 8;
      for (std::size_t t = 0; t < kFilterTasks && 2 * distinct <= capacity; ++t) {
        for (std::size_t i = ranges.first[t]; i < ranges.last[t] && 2 * distinct <= capacity; ++i) {
          if (i + kAhead < ranges.last[t]) {
            __builtin_prefetch(&scratch.cells[slot_of(scratch.point_key[i + kAhead], mask)], 1);
          }
          if ((scratch.point_near[i] & kInRegion) == 0) continue;
          const std::uint64_t key = scratch.point_key[i];
          const std::size_t s = find(key);
          FilterScratch::Cell& cell = scratch.cells[s];
          distinct += cell.key == 0 ? 1 : 0;
          cell.key = key;
          ++cell.count;
          cell.state |= scratch.point_near[i] & kNear;
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
  // The table is built on one thread (two tables side by side were no faster, the cells
  // being scattered).
  runner.parallel_for(1 + kFilterTasks, [&](std::size_t job) {
    if (job == 0) {
      if (outliers) build_table();
    } else {
      to_world(job - 1);
    }
  });
  const auto count_in = [&](std::uint64_t key) -> std::uint32_t {
    return scratch.cells[find(key)].count;  // an empty slot's count is 0
  };
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
        // A cell holding enough points on its own needs no lookup (most of them: walls).
        if (cell.state != 0 && (cell.count >= needed || has_neighbours(cell.key))) {
          cell.state |= 2;
        }
      }
    });
  }
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    decide(task,
           [&](std::size_t i) { return (scratch.cells[scratch.point_slot[i]].state & 2) != 0; });
  });
}

/// Where each task's survivors go in the output: task t's from index [t] on ([kFilterTasks]:
/// the survivors in all).
using SurvivorOffsets = std::array<std::size_t, kFilterTasks + 1>;

/// Step 2: isolated outliers, counted in the sensor frame: the candidates per cell of the
/// region (OutlierRegion), in a grid or a hash table, then each near candidate's 27 cells.
/// Membership only, so the result does not depend on order. Sets scratch.keep per candidate,
/// and beside the counting puts the candidates in the world frame (scratch.candidates_W);
/// returns where each task's survivors go.
SurvivorOffsets find_survivors(const FilterParams& params, const OutlierRegion& region,
                               const Eigen::Isometry3d& T_W_S, const CandidateRanges& ranges,
                               FilterScratch& scratch, TaskRunner& runner) {
  const Eigen::Matrix3f R_W_S = T_W_S.linear().cast<float>();
  const Eigen::Vector3f t_W_S = T_W_S.translation().cast<float>();
  const bool outliers = params.outlier_min_neighbors > 0;
  const auto& cand = scratch.candidates_S;
  // Itself and outlier_min_neighbors others.
  const auto needed = static_cast<std::uint32_t>(params.outlier_min_neighbors) + 1;
  scratch.candidates_W.resize(cand.size());  // the scan's points, as step 1 sized them
  scratch.keep.resize(cand.size());
  SurvivorOffsets kept_before{};  // task t's survivors at t + 1, summed at the end
  // The candidates go into the world frame beside the counting, in ranges, the survivors
  // picked from them at the end.
  const auto to_world = [&](std::size_t task) {
    ranges.each(task, [&](std::size_t i) { scratch.candidates_W[i] = R_W_S * cand[i] + t_W_S; });
  };
  // Whether candidate i survives, `passes` deciding for a near one; booked per task.
  // (Locals rather than scratch's members: a byte store may alias anything, and the compiler
  // would reload them after each.)
  const auto decide = [&](std::size_t task, auto&& passes) {
    const std::uint8_t* const flags = scratch.point_near.data();
    std::uint8_t* const keep = scratch.keep.data();
    const std::size_t begin = ranges.first[task], end = ranges.last[task];
    std::size_t kept = 0;
    for (std::size_t i = begin; i < end; ++i) {
      const bool k = !outliers || (flags[i] & kNear) == 0 || passes(i);
      keep[i] = k ? 1 : 0;
      kept += k ? 1 : 0;
    }
    kept_before[task + 1] = kept;
  };
  if (outliers && region.grid) {
    isolate_in_grid(region, needed, ranges, scratch, runner, to_world, decide);
  } else {
    isolate_in_table(outliers, needed, ranges, scratch, runner, to_world, decide);
  }
  for (std::size_t t = 0; t < kFilterTasks; ++t) kept_before[t + 1] += kept_before[t];
  return kept_before;
}

/// Step 3: the survivors, in input order, each task writing its own range of `points_W` (and
/// of `points_S`, when given).
void write_survivors(const CandidateRanges& ranges, const SurvivorOffsets& kept_before,
                     const FilterScratch& scratch, TaskRunner& runner,
                     std::vector<Eigen::Vector3f>& points_W,
                     std::vector<Eigen::Vector3f>* points_S) {
  points_W.resize(kept_before[kFilterTasks]);
  if (points_S != nullptr) points_S->resize(points_W.size());
  runner.parallel_for(kFilterTasks, [&](std::size_t task) {
    std::size_t out = kept_before[task];
    ranges.each(task, [&](std::size_t i) {
      if (scratch.keep[i] == 0) return;
      if (points_S != nullptr) (*points_S)[out] = scratch.candidates_S[i];
      points_W[out++] = scratch.candidates_W[i];
    });
  });
}

/// The scan's counts: `input` points, the tasks' rejections, then of the `candidates` those
/// `kept`.
FilterCounts total_counts(std::size_t input,
                          const std::array<FilterCounts, kFilterTasks>& task_counts,
                          std::size_t candidates, std::size_t kept) {
  FilterCounts counts;
  counts.input = input;
  for (const FilterCounts& c : task_counts) {
    counts.non_finite += c.non_finite;
    counts.too_close += c.too_close;
    counts.ego_vehicle += c.ego_vehicle;
  }
  counts.kept = kept;
  counts.isolated = candidates - kept;
  return counts;
}

}  // namespace

void FilterScratch::reserve(std::size_t points, const FilterParams& params) {
  const OutlierRegion region(params, grid_cell_limit);
  if (params.outlier_min_neighbors > 0 && region.grid) {
    grid.assign(region.side * region.side * region.side, 0);
  } else {
    grid.clear();  // a later grid-path scan allocates it anew, all zero
  }
  grid_touched.assign(points, 0);
  n_grid_touched = 0;
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
  const OutlierRegion region(params, scratch.grid_cell_limit);
  const PointTests tests(params, T_B_S, region);
  std::array<FilterCounts, kFilterTasks> task_counts{};
  const CandidateRanges ranges = find_candidates(cloud, tests, scratch, runner, task_counts);
  const SurvivorOffsets kept_before =
      find_survivors(params, region, T_W_S, ranges, scratch, runner);
  write_survivors(ranges, kept_before, scratch, runner, points_W, points_S);
  return total_counts(cloud.size(), task_counts, ranges.count(), points_W.size());
}

}  // namespace tarmac::core
