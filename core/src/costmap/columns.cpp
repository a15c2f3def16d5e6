/// @file build_costmap's column classes (step 6 of costmap/steps.hpp).

#include <algorithm>
#include <array>
#include <cmath>

#include "steps.hpp"

namespace tarmac::core::costmap {
namespace {

/// Accumulates, for one layer z of a row run, whether each column's envelope holds a known
/// voxel and an obstacle voxel (occupied, at least lo_layers above the column's ground).
void mark_envelope(std::uint8_t* __restrict known, std::uint8_t* __restrict obstacle,
                   const std::int16_t* __restrict ground, const float* __restrict log_odds,
                   int count, int z, int lo_layers, int top_layers) {
  for (int k = 0; k < count; ++k) {
    const int above = z - ground[k];
    const bool envelope = above >= 0 && above < top_layers;
    const float l = log_odds[k];
    // A count (saturating): the whole-envelope rule compares it with the envelope's layers.
    known[k] +=
        static_cast<std::uint8_t>(envelope & (l != OccupancyMap::kUnknown) & (known[k] != 255));
    obstacle[k] |= static_cast<std::uint8_t>(envelope & (above >= lo_layers) & (l > 0.0f));
  }
}

/// Bits [0, k) of a 64-bit set, k clamped to [0, 64].
std::uint64_t bits_below(int k) {
  k = std::clamp(k, 0, 64);
  return k == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << k) - 1;
}

/// Bits [a, b) of a 64-bit set, clamped to [0, 64) (empty when a >= b).
std::uint64_t bit_range(int a, int b) {
  return bits_below(b) & ~bits_below(a);
}

/// What the 2D ESDF sees of a column class: obstacles and virtual zones are sites.
CellState esdf_state(std::uint8_t column_class) {
  const auto c = static_cast<ColumnClass>(column_class);
  return c == ColumnClass::kObstacle || c == ColumnClass::kVirtual ? CellState::kOccupied
         : c == ColumnClass::kUnknown                              ? CellState::kUnknown
                                                                   : CellState::kFree;
}

}  // namespace

void classify_columns(const CostmapPass& pass) {
  const auto& map = pass.map;
  const auto& params = pass.params;
  auto& out = pass.out;
  auto& runner = pass.runner;
  const auto v = pass.v;
  const auto nx = pass.nx;
  const auto ny = pass.ny;
  const auto nz = pass.nz;
  const auto& wmin = pass.wmin;
  const auto& geometry = pass.geometry;
  const auto cells_n = pass.cells_n;
  const auto use_bits = pass.use_bits;
  const auto g = pass.g;
  const auto gx = pass.gx;
  const auto& lowest = out.lowest_occupied;
  const auto& occupied_bits = out.occupied_bits;
  const auto& known_bits = out.known_bits;
  const auto& filtered = out.coarse_filtered;
  // A column's own ground is its lowest occupied voxel when that lies within one voxel of the
  // local estimate (slopes, tilted world frames), otherwise the estimate. An obstacle voxel
  // starts at least min_obstacle_height above the top of the ground voxel (so a ground surface
  // that crosses a voxel boundary is not an obstacle) and starts below ground + vehicle height
  // + clearance.
  const double hi_m = params.vehicle_height_m + params.clearance_m;
  const int lo_layers = 1 + static_cast<int>(std::ceil(params.min_obstacle_height_m / v - 1e-9));
  // A voxel counts when its bottom lies below ground + envelope top.
  const int top_layers = static_cast<int>(std::ceil(hi_m / v + 0.5));  // above − 0.5 < hi/v
  auto& ground_layer = out.ground_layer;
  ground_layer.resize(geometry.cell_count());
  auto& classes = out.column_class.cells();
  auto& any_known = out.any_known;
  auto& any_obstacle = out.any_obstacle;
  any_known.resize(use_bits ? 0 : geometry.cell_count());
  any_obstacle.resize(use_bits ? 0 : geometry.cell_count());
  // The rounded estimate per coarse cell, once per coarse cell instead of once per column
  // (coarse_next is free after the fill; whole layers are exact in float).
  auto& estimates = out.coarse_next;
  for (std::size_t i = 0; i < filtered.size(); ++i) {
    estimates[i] = static_cast<float>(std::lround(filtered[i]));
  }
  // Low objects: lower than the voxels that separate them from the ground (10 cm debris shares a
  //     20 cm voxel with the ground under it): a free column becomes an obstacle when the latest
  //     returns of a voxel below the voxel rule's reach rise at least min_obstacle_height above
  //     their own scan's ground next to them (OccupancyMap::ring_layer_rise_cm).
  const auto min_rise_cm = static_cast<int>(std::ceil(params.min_obstacle_height_m * 100.0 - 1e-9));
  // The layers' rise pointers, looked up once per call (windows of at most 64 layers).
  std::array<const std::uint8_t*, 64> rise_layers{};
  for (int z = 0; z < std::min(nz, 64); ++z)
    rise_layers[static_cast<std::size_t>(z)] = map.ring_layer_rise_cm(z);
  // Whether a free column (ring slot sl, ground layer gz) holds such a low object.
  const auto low_object = [&](std::size_t sl, int gz) {
    bool rises = false;
    for (int z = std::max(0, gz), z1 = std::min(nz, gz + lo_layers); z < z1; ++z) {
      const std::uint8_t* rise =
          z < 64 ? rise_layers[static_cast<std::size_t>(z)] : map.ring_layer_rise_cm(z);
      rises |= rise[sl] >= min_rise_cm;
    }
    return rises;
  };
  const auto column_class = [](bool obstacle, bool known) {
    return static_cast<std::uint8_t>(obstacle ? ColumnClass::kObstacle
                                     : known  ? ColumnClass::kFree
                                              : ColumnClass::kUnknown);
  };
  // What a column's test needs of its ground layer gl: the envelope's masks (observed, obstacle),
  // the ground height, the layers of the low-object test. Tabulated once per call for gl in
  // [−nz, 2·nz) (computed when a ground lies outside).
  // With FreeRule::kWholeEnvelope a column is free only when every voxel of its envelope was
  // observed, so an envelope reaching out of the window (which holds no observation there) is
  // never free.
  const bool whole_envelope = params.free_rule == FreeRule::kWholeEnvelope;
  struct GroundEntry {
    std::uint64_t seen_mask, obstacle_mask;
    float z_m;
    int rise_begin, rise_end;
    bool in_window;  ///< the whole envelope lies inside the window's layers
  };
  const auto ground_entry = [&](int gl) {
    return GroundEntry{bit_range(gl, gl + top_layers),
                       bit_range(gl + lo_layers, gl + top_layers),
                       static_cast<float>((wmin.z() + gl + 0.5) * v),
                       std::max(0, gl),
                       std::min(nz, gl + lo_layers),
                       gl >= 0 && gl + top_layers <= nz};
  };
  // Whether a column with `known` envelope voxels (of the entry's mask, or counted) reads as
  // observed under the free rule.
  const auto observed = [whole_envelope](std::uint64_t known, const GroundEntry& e) {
    return whole_envelope ? e.in_window && (known & e.seen_mask) == e.seen_mask
                          : (known & e.seen_mask) != 0;
  };
  const auto observed_count = [whole_envelope, top_layers, nz](int known, int gl) {
    return whole_envelope ? gl >= 0 && gl + top_layers <= nz && known == top_layers : known != 0;
  };
  std::array<GroundEntry, 3 * 64> by_ground;
  const int ground_first = -nz;
  const int ground_count = use_bits ? 3 * nz : 0;
  for (int k = 0; k < ground_count; ++k) {
    by_ground[static_cast<std::size_t>(k)] = ground_entry(ground_first + k);
  }
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int y0 = static_cast<int>(ny * task / kRowTasks);
    const int y1 = static_cast<int>(ny * (task + 1) / kRowTasks);
    float* __restrict ground_z = out.ground_z_m.cells().data();
    std::int16_t* __restrict ground_of = ground_layer.data();
    const std::int16_t* __restrict low_of = lowest.data();
    if (use_bits) {
      // One pass per column: its ground, the envelope tests as bit masks, the low-object test.
      // A column is an obstacle when any envelope voxel at least lo_layers above its ground is
      // occupied, free when its envelope is observed by the free rule, unknown otherwise.
      std::uint8_t* __restrict cls = classes.data();
      CellState* __restrict esdf_in = out.esdf_input.data();
      const std::uint32_t* __restrict occ_bits = occupied_bits.data();
      const std::uint32_t* __restrict obs_bits = known_bits.data();
      for (int y = y0; y < y1; ++y) {
        const float* estimate_row = &estimates[static_cast<std::size_t>(y / g) * gx];
        const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
        int rx = map.ring_x(0);
        for (int x0 = 0, cx = 0; x0 < nx; x0 += g, ++cx) {
          const int estimate = static_cast<int>(estimate_row[cx]);
          for (int x = x0, x1 = std::min(nx, x0 + g); x < x1; ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
            const std::size_t i = static_cast<std::size_t>(y) * nx + x;
            // The column's ground: its lowest occupied voxel if within one voxel of the estimate.
            const int low = low_of[i];
            const int gl = low >= 0 && std::abs(low - estimate) <= 1 ? low : estimate;
            const auto t = static_cast<unsigned>(gl - ground_first);
            const GroundEntry e =
                t < static_cast<unsigned>(ground_count) ? by_ground[t] : ground_entry(gl);
            ground_of[i] = static_cast<std::int16_t>(gl);
            ground_z[i] = e.z_m;
            const std::size_t sl = ring_row + static_cast<std::size_t>(rx);
            const std::uint64_t known = obs_bits[sl] | std::uint64_t{obs_bits[cells_n + sl]} << 32;
            const std::uint64_t occupied = occ_bits[sl] | std::uint64_t{occ_bits[cells_n + sl]}
                                                              << 32;
            const bool obstacle = (occupied & e.obstacle_mask) != 0;
            const bool seen = observed(known, e);
            bool low_obj = false;
            // A low object blocks whatever the free rule says of the rest of the envelope.
            if (!obstacle && (known & e.seen_mask) != 0) {
              for (int z = e.rise_begin; z < e.rise_end; ++z) {
                low_obj |= rise_layers[static_cast<std::size_t>(z)][sl] >= min_rise_cm;
              }
            }
            cls[i] = column_class(obstacle || low_obj, seen);
            esdf_in[i] = esdf_state(cls[i]);
          }
        }
      }
      return;
    }
    for (int y = y0; y < y1; ++y) {
      const float* estimate_row = &estimates[static_cast<std::size_t>(y / g) * gx];
      for (int x0 = 0, cx = 0; x0 < nx; x0 += g, ++cx) {
        const int estimate = static_cast<int>(estimate_row[cx]);
        for (int x = x0, x1 = std::min(nx, x0 + g); x < x1; ++x) {
          const std::size_t i = static_cast<std::size_t>(y) * nx + x;
          const int low = low_of[i];
          const int ground = low >= 0 && std::abs(low - estimate) <= 1 ? low : estimate;
          ground_of[i] = static_cast<std::int16_t>(ground);
          ground_z[i] = static_cast<float>((wmin.z() + ground + 0.5) * v);
        }
      }
    }
    // Layer by layer, only through the layers some column's envelope reaches (so the result
    // does not depend on the layer order), then the low-object test per free column.
    const std::size_t r0 = static_cast<std::size_t>(y0) * nx;
    const std::size_t r1 = static_cast<std::size_t>(y1) * nx;
    if (r0 == r1) return;
    const auto [gmin, gmax] =
        std::minmax_element(ground_layer.begin() + static_cast<std::ptrdiff_t>(r0),
                            ground_layer.begin() + static_cast<std::ptrdiff_t>(r1));
    std::fill(any_known.begin() + static_cast<std::ptrdiff_t>(r0),
              any_known.begin() + static_cast<std::ptrdiff_t>(r1), 0);
    std::fill(any_obstacle.begin() + static_cast<std::ptrdiff_t>(r0),
              any_obstacle.begin() + static_cast<std::ptrdiff_t>(r1), 0);
    const int z_begin = std::max(0, static_cast<int>(*gmin));
    const int z_end = std::min(nz, static_cast<int>(*gmax) + top_layers);
    for (int z = z_begin; z < z_end; ++z) {
      const float* layer = map.ring_layer(z);
      for (int y = y0; y < y1; ++y) {
        const std::size_t row = static_cast<std::size_t>(y) * nx;
        for_row_runs(map, layer, y, [&](int x0, const float* l, int count) {
          mark_envelope(&any_known[row + x0], &any_obstacle[row + x0], &ground_layer[row + x0], l,
                        count, z, lo_layers, top_layers);
        });
      }
    }
    for (int y = y0; y < y1; ++y) {
      const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
      for (int x = 0, rx = map.ring_x(0); x < nx; ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
        const std::size_t i = static_cast<std::size_t>(y) * nx + x;
        const bool seen = observed_count(any_known[i], ground_layer[i]);
        // A low object blocks whatever the free rule says of the rest of the envelope.
        const bool low =
            any_obstacle[i] == 0 && any_known[i] != 0 && low_object(ring_row + rx, ground_layer[i]);
        classes[i] = column_class(any_obstacle[i] != 0 || low, seen);
        out.esdf_input[i] = esdf_state(classes[i]);
      }
    }
  });
}

}  // namespace tarmac::core::costmap
