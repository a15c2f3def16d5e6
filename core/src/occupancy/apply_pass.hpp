#pragma once
/// @file integrate()'s apply pass (integrate.cpp, step 3): each task ORs and clears the ray
/// tasks' marks over its fixed range of mark words and gives every marked voxel that was not hit
/// one miss (log_odds.hpp), four lanes at a time where a word is dense. Internal to
/// core/src/occupancy; included by integrate.cpp only.

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "../lanes4.hpp"
#include "log_odds.hpp"
#include "ray_walk.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "window.hpp"

namespace tarmac::core::occupancy {

/// Words with at least this many voxels to miss take the four-lanes path.
constexpr int kDenseWord = 8;

/// The miss update's constants, four lanes each.
struct MissLanes {
  Float4 miss, min, zero, unknown;
  MissLanes(float l_miss, float l_min)
      : miss{l_miss, l_miss, l_miss, l_miss},
        min{l_min, l_min, l_min, l_min},
        zero{0.0f, 0.0f, 0.0f, 0.0f},
        unknown{OccupancyMap::kUnknown, OccupancyMap::kUnknown, OccupancyMap::kUnknown,
                OccupancyMap::kUnknown} {}
};

/// The window columns (one bit each, ring order) whose voxels the apply pass changed: ORed in by
/// every apply task, relaxed atomics (the union does not depend on the tasks' order).
struct ColumnMarks {
  std::uint64_t* bits;
  std::size_t plane;  ///< voxels per layer: slot s is in column s mod plane

  /// Columns [first, first + 64) of `cols` (bit k: column first + k), all inside the layer.
  void add_run(std::size_t first, std::uint64_t cols) const {
    if (cols == 0) return;
    const std::size_t w = first >> 6;
    const unsigned shift = first & 63;
    add_word(w, cols << shift);
    if (shift != 0) add_word(w + 1, cols >> (64 - shift));
  }
  void add_word(std::size_t w, std::uint64_t cols) const {
    if (cols == 0) return;
    std::atomic_ref<std::uint64_t> word(bits[w]);
    // Most words already hold these columns (layers above one another): read before writing.
    if ((word.load(std::memory_order_relaxed) & cols) != cols) {
      word.fetch_or(cols, std::memory_order_relaxed);
    }
  }
  /// The columns of mark word `wi`'s voxels in `voxels`: the word may run into the next layer
  /// (or layers, in a window smaller than 64 columns), whose columns start again at 0.
  void add(std::size_t wi, std::uint64_t voxels) const {
    std::size_t col = (wi << 6) % plane;
    while (voxels != 0) {
      const std::size_t in_layer = plane - col;
      if (in_layer >= 64) {
        add_run(col, voxels);
        return;
      }
      add_run(col, voxels & ((std::uint64_t{1} << in_layer) - 1));
      voxels >>= in_layer;
      col = 0;
    }
  }
};

/// The miss of every voxel of one mark word (64 consecutive slots at `l`, bit k of `marks`
/// for slot k) that reads free or unknown, four lanes at a time: the same arithmetic as one at a
/// time (kUnknown counts as 0, then max(l + miss, min)); unmarked and occupied lanes are
/// written back unchanged. Sets in `occupied` the marked voxels reading occupied (left to the
/// caller's static-layer logic), in `void_heights` those that reach the lower clamp now, in
/// `at_floor` every free one that reads the lower clamp after the miss and in `changed` those
/// whose log-odds the miss changed.
inline void miss_free_word(float* l, std::uint64_t marks, const MissLanes& c,
                           std::uint64_t& occupied, std::uint64_t& void_heights,
                           std::uint64_t& at_floor, std::uint64_t& changed) {
  const Int4 lane = {1, 2, 4, 8};
  for (int g = 0; g < 16; ++g) {
    const auto nibble = static_cast<std::int32_t>((marks >> (4 * g)) & 15);
    if (nibble == 0) continue;
    const Int4 marked = (lane & nibble) != 0;
    Float4 v;
    std::memcpy(&v, l + 4 * g, sizeof v);
    const Int4 free = marked & (v <= c.zero);
    const Float4 known = reinterpret_cast<Float4>(reinterpret_cast<Int4>(v) & ~(v == c.unknown));
    const Float4 sum = known + c.miss;
    const Int4 below = sum < c.min;
    const Float4 next = reinterpret_cast<Float4>((reinterpret_cast<Int4>(c.min) & below) |
                                                 (reinterpret_cast<Int4>(sum) & ~below));
    const Int4 voided = free & (next == c.min) & (v > c.min);
    const Float4 out = reinterpret_cast<Float4>((reinterpret_cast<Int4>(next) & free) |
                                                (reinterpret_cast<Int4>(v) & ~free));
    std::memcpy(l + 4 * g, &out, sizeof out);
    occupied |= std::uint64_t{lane_bits(marked & (v > c.zero))} << (4 * g);
    void_heights |= std::uint64_t{lane_bits(voided)} << (4 * g);
    at_floor |= std::uint64_t{lane_bits(free & (next == c.min))} << (4 * g);
    changed |= std::uint64_t{lane_bits(free & (next != v))} << (4 * g);
  }
}

/// One task of integrate()'s apply pass over its fixed range of mark words: the tasks' marks
/// ORed and cleared, voxels hit this scan left out, and one miss for each other marked voxel.
/// Voxels reading occupied are only collected (`candidates`): miss_occupied() decides them.
struct ApplyPass {
  std::array<std::uint64_t*, kRayTasks> task_bits;  ///< every ray task's marks
  const std::uint64_t* hit_bits;
  std::uint64_t* floor_bits;  ///< voxels at the lower clamp, their heights already void
  float* log_odds;
  std::uint8_t* rise_cm;
  const MissLanes& lanes;
  float l_miss, l_min;
  std::vector<std::uint32_t>& candidates;
  ColumnMarks changed_columns;  ///< the columns of the voxels whose log-odds a miss changed
  std::uint64_t updates = 0;    ///< misses given (voxels at the floor count: a miss holds them)
  /// Column observation times (OccupancyMap::track_column_observations), or nullptr: the
  /// columns of marked voxels in band layers get `stamp`. Two tasks may store the same stamp
  /// into one column (other layers): relaxed atomic stores.
  std::int64_t* column_stamp = nullptr;
  const std::uint8_t* in_band = nullptr;  ///< per ring layer
  std::size_t plane = 0;                  ///< voxels per layer
  std::int64_t stamp = 0;

  void stamp_columns(std::size_t wi, std::uint64_t marks) {
    // One division per word; a word may run into the next layer (then its column wraps to 0).
    const std::size_t base = wi << 6;
    const std::size_t z = base / plane;
    const std::size_t col0 = base - z * plane;
    for (; marks != 0; marks &= marks - 1) {
      const auto bit = static_cast<std::size_t>(std::countr_zero(marks));
      const bool next_layer = col0 + bit >= plane;
      if (in_band[z + (next_layer ? 1 : 0)] == 0) continue;
      const std::size_t col = next_layer ? col0 + bit - plane : col0 + bit;
      std::atomic_ref<std::int64_t>(column_stamp[col]).store(stamp, std::memory_order_relaxed);
    }
  }

  /// Words whose marks need an update (not hit, not at the lower clamp), collected with their
  /// log-odds lines prefetched, then updated together: the voxels are scattered over the
  /// window, and waiting for them one by one was most of this pass's time.
  static constexpr std::size_t kPending = 256;
  std::array<std::pair<std::size_t, std::uint64_t>, kPending> pending{};
  std::size_t n_pending = 0;

  /// The marks of words [w_begin, w_end). Voxels already at the lower clamp stay there, their
  /// heights already void: a miss changes nothing, so their log-odds are not even read.
  void gather(std::size_t w_begin, std::size_t w_end) {
    for (std::size_t wi = w_begin; wi < w_end; ++wi) {
      std::uint64_t m = 0;
      for (std::size_t t = 0; t < kRayTasks; ++t) {
        m |= task_bits[t][wi];
        task_bits[t][wi] = 0;
      }
      if (m == 0) continue;
      if (column_stamp != nullptr) stamp_columns(wi, m);
      m &= ~hit_bits[wi];
      updates += static_cast<std::uint64_t>(bit_count(m));
      m &= ~floor_bits[wi];
      if (m == 0) continue;
      for (int g = 0; g < 4; ++g) {  // 16 floats per 64-byte line
        if (((m >> (16 * g)) & 0xffff) != 0) {
          __builtin_prefetch(log_odds + (wi << 6) + 16 * g, 1);
        }
      }
      pending[n_pending++] = {wi, m};
      if (n_pending == kPending) flush();
    }
  }

  /// The misses of the pending words.
  void flush() {
    for (std::size_t p = 0; p < n_pending; ++p) miss_word(pending[p].first, pending[p].second);
    n_pending = 0;
  }

  /// The misses of one word's marked voxels (log_odds.hpp, after_miss).
  void miss_word(std::size_t wi, std::uint64_t marks) {
    std::uint64_t& at_floor = floor_bits[wi];
    const std::size_t base = wi << 6;
    std::uint64_t occupied = 0;  // marked voxels reading occupied: left to miss_occupied()
    std::uint64_t changed = 0;
    if (bit_count(marks) >= kDenseWord) {
      // Mostly free space near the sensor: the whole word's voxels four at a time.
      std::uint64_t void_heights = 0;
      miss_free_word(log_odds + base, marks, lanes, occupied, void_heights, at_floor, changed);
      for (; void_heights != 0; void_heights &= void_heights - 1) {
        rise_cm[base + static_cast<std::size_t>(std::countr_zero(void_heights))] = 0;
      }
    } else {
      for (; marks != 0; marks &= marks - 1) {
        const std::size_t s = base + static_cast<std::size_t>(std::countr_zero(marks));
        float& l = log_odds[s];
        if (l > 0.0f) {
          occupied |= std::uint64_t{1} << (s & 63);
          continue;
        }
        // Free or unknown (kUnknown < 0): no static state.
        const float next = after_miss(l, l_miss, l_min);
        // Reaching the lower clamp (observed free scan after scan): the sub-voxel heights of
        // older returns are void too (a tug's edge hit once leaves no ghost).
        if (next == l_min) {
          if (l > l_min) rise_cm[s] = 0;
          at_floor |= std::uint64_t{1} << (s & 63);
        }
        if (next != l) changed |= std::uint64_t{1} << (s & 63);
        l = next;  // a miss only lowers
      }
    }
    // (A rise is voided only with its log-odds lowered: the log-odds say what changed.)
    changed_columns.add(wi, changed);
    for (; occupied != 0; occupied &= occupied - 1) {
      candidates.push_back(
          static_cast<std::uint32_t>(base + static_cast<std::size_t>(std::countr_zero(occupied))));
    }
  }

  /// Large windows: the words the ray tasks flagged in blocks [b_begin, b_end) (flags cleared).
  void gather_flagged(std::size_t b_begin, std::size_t b_end,
                      std::vector<std::vector<std::uint64_t>>& dirty_words) {
    for (std::size_t b = b_begin; b < b_end; ++b) {
      std::uint64_t flags = 0;
      for (auto& d : dirty_words) {
        flags |= d[b];
        d[b] = 0;
      }
      for (; flags != 0; flags &= flags - 1) {
        const std::size_t wi =
            (b << kBlockShift) + static_cast<std::size_t>(std::countr_zero(flags));
        gather(wi, wi + 1);
      }
    }
  }

  /// Small windows: the words [w_begin, w_end) inside `box` (window-relative), row by row (a
  /// row: the voxels of one ring z and ring y), each row of the box as one or two runs of x in
  /// ring order.
  void gather_box(std::size_t w_begin, std::size_t w_end, const MarkBox& box,
                  const Eigen::Vector3i& dims, const std::array<int, 3>& ring_min) {
    const int nx = dims.x(), ny = dims.y(), nz = dims.z();
    const auto row_len = static_cast<std::size_t>(nx);
    const std::size_t r_first = (w_begin << 6) / row_len;
    const std::size_t r_last =
        std::min((w_end << 6) / row_len + 1, static_cast<std::size_t>(ny) * nz);
    const int x0 = wrap(ring_min[0] + box.lo[0], nx);
    const int x_count = box.hi[0] - box.lo[0] + 1;
    const auto run = [&](std::size_t first_slot, std::size_t last_slot) {
      gather(std::max(w_begin, first_slot >> 6), std::min(w_end, (last_slot >> 6) + 1));
    };
    // The row's ring y and z, and where they sit in the window, are stepped along with it: a
    // division per row (tens of thousands of rows per task and scan) was most of this pass's
    // time.
    auto ring_y = static_cast<int>(r_first % static_cast<std::size_t>(ny));
    int rel_y = wrap(ring_y - ring_min[1], ny);
    int rel_z = wrap(static_cast<int>(r_first / static_cast<std::size_t>(ny)) - ring_min[2], nz);
    for (std::size_t r = r_first; r < r_last; ++r) {
      if (box.holds(1, rel_y) && box.holds(2, rel_z)) {
        const std::size_t row = r * row_len;
        if (x0 + x_count <= nx) {
          run(row + static_cast<std::size_t>(x0), row + static_cast<std::size_t>(x0 + x_count - 1));
        } else {
          run(row + static_cast<std::size_t>(x0), row + row_len - 1);
          run(row, row + static_cast<std::size_t>(x0 + x_count - nx - 1));
        }
      }
      rel_y = rel_y + 1 == ny ? 0 : rel_y + 1;
      if (++ring_y == ny) {
        ring_y = 0;
        rel_z = rel_z + 1 == nz ? 0 : rel_z + 1;
      }
    }
  }
};

}  // namespace tarmac::core::occupancy
