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

/// The obstacle_rule bit of the first column rule that fired (they are tried in this order).
std::uint8_t first_rule(bool voxel, bool drop, bool rise) {
  return voxel  ? obstacle_rule::kVoxel
         : drop ? obstacle_rule::kDrop
         : rise ? obstacle_rule::kRise
                : std::uint8_t{0};
}

std::uint8_t column_class(bool obstacle, bool known) {
  return static_cast<std::uint8_t>(obstacle ? ColumnClass::kObstacle
                                   : known  ? ColumnClass::kFree
                                            : ColumnClass::kUnknown);
}

/// A column's ground layer: its lowest occupied voxel when that lies within one voxel of the
/// local estimate (slopes, tilted world frames), otherwise the estimate.
int column_ground(int lowest, int estimate) {
  return lowest >= 0 && std::abs(lowest - estimate) <= 1 ? lowest : estimate;
}

/// What a column's test needs of its ground layer gl: the envelope's masks (observed,
/// obstacle), the ground height, the layers of the low-object test.
struct GroundEntry {
  std::uint64_t seen_mask, obstacle_mask;
  float z_m;
  int rise_begin, rise_end;
  bool in_window;  ///< the whole envelope lies inside the window's layers
};

/// The tests of step 6, set up once per call. An obstacle voxel starts at least
/// min_obstacle_height above the top of the ground voxel (so a ground surface that crosses a
/// voxel boundary is not an obstacle) and starts below ground + vehicle height + clearance.
/// With FreeRule::kWholeEnvelope a column is free only when every voxel of its envelope was
/// observed, so an envelope reaching out of the window (which holds no observation there) is
/// never free. Low objects: lower than the voxels that separate them from the ground (10 cm
/// debris shares a 20 cm voxel with the ground under it): a free column becomes an obstacle when
/// the latest returns of a voxel below the voxel rule's reach rise at least min_obstacle_height
/// above their own scan's ground next to them (OccupancyMap::ring_layer_rise_cm).
struct ColumnRules {
  explicit ColumnRules(const CostmapPass& pass)
      : map(pass.map),
        nz(pass.nz),
        lo_layers(1 +
                  static_cast<int>(std::ceil(pass.params.min_obstacle_height_m / pass.v - 1e-9))),
        // A voxel counts when its bottom lies below ground + envelope top (above − 0.5 < hi/v).
        top_layers(static_cast<int>(
            std::ceil((pass.params.vehicle_height_m + pass.params.clearance_m) / pass.v + 0.5))),
        min_rise_cm(static_cast<int>(std::ceil(pass.params.min_obstacle_height_m * 100.0 - 1e-9))),
        whole_envelope(pass.params.free_rule == FreeRule::kWholeEnvelope),
        drop_layers(static_cast<float>(pass.params.max_ground_step_m / pass.v)),
        v(pass.v),
        wmin_z(pass.wmin.z()),
        ground_first(-pass.nz),
        ground_count(pass.use_bits ? 3 * pass.nz : 0) {
    // The layers' rise pointers, looked up once per call (windows of at most 64 layers), and
    // the entries of grounds in [−nz, 2·nz) (computed when a ground lies outside).
    for (int z = 0; z < std::min(nz, 64); ++z) {
      rise_layers[static_cast<std::size_t>(z)] = map.ring_layer_rise_cm(z);
    }
    for (int k = 0; k < ground_count; ++k) {
      by_ground[static_cast<std::size_t>(k)] = compute_entry(ground_first + k);
    }
  }

  [[nodiscard]] GroundEntry compute_entry(int gl) const {
    return GroundEntry{bit_range(gl, gl + top_layers),
                       bit_range(gl + lo_layers, gl + top_layers),
                       static_cast<float>((wmin_z + gl + 0.5) * v),
                       std::max(0, gl),
                       std::min(nz, gl + lo_layers),
                       gl >= 0 && gl + top_layers <= nz};
  }
  [[nodiscard]] GroundEntry entry(int gl) const {
    const auto t = static_cast<unsigned>(gl - ground_first);
    return t < static_cast<unsigned>(ground_count) ? by_ground[t] : compute_entry(gl);
  }
  /// Whether a column with `known` envelope voxels (bits) reads as observed under the free rule.
  [[nodiscard]] bool observed(std::uint64_t known, const GroundEntry& e) const {
    return whole_envelope ? e.in_window && (known & e.seen_mask) == e.seen_mask
                          : (known & e.seen_mask) != 0;
  }
  /// The same with `known` counted envelope voxels.
  [[nodiscard]] bool observed_count(int known, int gl) const {
    return whole_envelope ? gl >= 0 && gl + top_layers <= nz && known == top_layers : known != 0;
  }
  /// Whether the column at ring slot `sl` falls away: observed (a return, or a ray passing) more
  /// than max_ground_step_m below its ground estimate, and nothing returned there from within
  /// that step below the estimate up to where obstacles start. The edge of a loading dock, a
  /// pit, a level below seen over a parapet: the ground did not spread there (no slope joins
  /// it), and a vehicle that drove on would fall, whether the bottom returned or not. A floor
  /// that returned at the estimate holds the vehicle, whatever its mirror images (a glossy
  /// floor, a puddle) showed under it. The lookups are made only for the rare columns seen that
  /// deep.
  [[nodiscard]] bool drops(std::size_t sl, int lowest_observed, int estimate) const {
    if (lowest_observed < 0 || static_cast<float>(estimate - lowest_observed) <= drop_layers) {
      return false;
    }
    const int z1 = std::min(nz, estimate + lo_layers);
    for (int z = std::max(0, estimate - static_cast<int>(drop_layers)); z < z1; ++z) {
      if (map.ring_layer(z)[sl] > 0.0f) return false;
    }
    return true;
  }
  /// Whether ring slot `sl` holds a low object in layers [z0, z1).
  [[nodiscard]] bool rises(std::size_t sl, int z0, int z1) const {
    bool rise = false;
    for (int z = z0; z < z1; ++z) {
      const std::uint8_t* layer =
          z < 64 ? rise_layers[static_cast<std::size_t>(z)] : map.ring_layer_rise_cm(z);
      rise |= layer[sl] >= min_rise_cm;
    }
    return rise;
  }

  const OccupancyMap& map;
  int nz, lo_layers, top_layers, min_rise_cm;
  bool whole_envelope;
  float drop_layers;
  double v;
  int wmin_z;
  std::array<const std::uint8_t*, 64> rise_layers{};
  std::array<GroundEntry, 3 * 64> by_ground{};
  int ground_first, ground_count;
};

/// Rows [y0, y1) of a window of at most 64 layers, one pass per column: its ground, the
/// envelope tests as bit masks, the low-object test. A column is an obstacle when any envelope
/// voxel at least lo_layers above its ground is occupied, free when its envelope is observed by
/// the free rule, unknown otherwise.
void classify_rows_by_bits(const CostmapPass& pass, const ColumnRules& rules,
                           const std::vector<float>& estimates, int y0, int y1) {
  const auto& map = pass.map;
  auto& out = pass.out;
  const int nx = pass.nx;
  float* __restrict ground_z = out.ground_z_m.cells().data();
  std::int16_t* __restrict ground_of = out.ground_layer.data();
  const std::int16_t* __restrict low_of = out.lowest_occupied.data();
  const std::int16_t* __restrict seen_of = out.lowest_observed.data();
  std::uint8_t* __restrict cls = out.column_class.cells().data();
  CellState* __restrict esdf_in = out.esdf_input.data();
  std::uint8_t* __restrict rule_of = out.obstacle_rule.data();
  const std::uint32_t* __restrict occ_bits = out.occupied_bits.data();
  const std::uint32_t* __restrict obs_bits = out.known_bits.data();
  for (int y = y0; y < y1; ++y) {
    const float* estimate_row = &estimates[static_cast<std::size_t>(y / pass.g) * pass.gx];
    const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
    int rx = map.ring_x(0);
    for (int x0 = 0, cx = 0; x0 < nx; x0 += pass.g, ++cx) {
      const int estimate = static_cast<int>(estimate_row[cx]);
      for (int x = x0, x1 = std::min(nx, x0 + pass.g); x < x1;
           ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
        const std::size_t i = static_cast<std::size_t>(y) * nx + x;
        const int gl = column_ground(low_of[i], estimate);
        const GroundEntry e = rules.entry(gl);
        ground_of[i] = static_cast<std::int16_t>(gl);
        ground_z[i] = e.z_m;
        const std::size_t sl = ring_row + static_cast<std::size_t>(rx);
        const std::uint64_t known = obs_bits[sl] | std::uint64_t{obs_bits[pass.cells_n + sl]} << 32;
        const std::uint64_t occupied = occ_bits[sl] | std::uint64_t{occ_bits[pass.cells_n + sl]}
                                                          << 32;
        const bool voxel = (occupied & e.obstacle_mask) != 0;
        const bool drop = !voxel && rules.drops(sl, seen_of[i], estimate);
        // A low object blocks whatever the free rule says of the rest of the envelope.
        const bool low = !voxel && !drop && (known & e.seen_mask) != 0 &&
                         rules.rises(sl, e.rise_begin, e.rise_end);
        cls[i] = column_class(voxel || drop || low, rules.observed(known, e));
        esdf_in[i] = esdf_state(cls[i]);
        rule_of[i] = first_rule(voxel, drop, low);
      }
    }
  }
}

/// Rows [y0, y1) of a taller window: the grounds, then layer by layer through the layers some
/// column's envelope reaches (so the result does not depend on the layer order), then the
/// low-object test per free column.
void classify_rows_by_layers(const CostmapPass& pass, const ColumnRules& rules,
                             const std::vector<float>& estimates, int y0, int y1) {
  const auto& map = pass.map;
  auto& out = pass.out;
  const int nx = pass.nx;
  auto& ground_layer = out.ground_layer;
  for (int y = y0; y < y1; ++y) {
    const float* estimate_row = &estimates[static_cast<std::size_t>(y / pass.g) * pass.gx];
    for (int x0 = 0, cx = 0; x0 < nx; x0 += pass.g, ++cx) {
      const int estimate = static_cast<int>(estimate_row[cx]);
      for (int x = x0, x1 = std::min(nx, x0 + pass.g); x < x1; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * nx + x;
        const int ground = column_ground(out.lowest_occupied[i], estimate);
        ground_layer[i] = static_cast<std::int16_t>(ground);
        out.ground_z_m.cells()[i] = static_cast<float>((pass.wmin.z() + ground + 0.5) * pass.v);
      }
    }
  }
  const std::size_t r0 = static_cast<std::size_t>(y0) * nx;
  const std::size_t r1 = static_cast<std::size_t>(y1) * nx;
  if (r0 == r1) return;
  const auto [gmin, gmax] =
      std::minmax_element(ground_layer.begin() + static_cast<std::ptrdiff_t>(r0),
                          ground_layer.begin() + static_cast<std::ptrdiff_t>(r1));
  auto& any_known = out.any_known;
  auto& any_obstacle = out.any_obstacle;
  std::fill(any_known.begin() + static_cast<std::ptrdiff_t>(r0),
            any_known.begin() + static_cast<std::ptrdiff_t>(r1), 0);
  std::fill(any_obstacle.begin() + static_cast<std::ptrdiff_t>(r0),
            any_obstacle.begin() + static_cast<std::ptrdiff_t>(r1), 0);
  const int z_begin = std::max(0, static_cast<int>(*gmin));
  const int z_end = std::min(pass.nz, static_cast<int>(*gmax) + rules.top_layers);
  for (int z = z_begin; z < z_end; ++z) {
    const float* layer = map.ring_layer(z);
    for (int y = y0; y < y1; ++y) {
      const std::size_t row = static_cast<std::size_t>(y) * nx;
      for_row_runs(map, layer, y, [&](int x0, const float* l, int count) {
        mark_envelope(&any_known[row + x0], &any_obstacle[row + x0], &ground_layer[row + x0], l,
                      count, z, rules.lo_layers, rules.top_layers);
      });
    }
  }
  auto& classes = out.column_class.cells();
  for (int y = y0; y < y1; ++y) {
    const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
    for (int x = 0, rx = map.ring_x(0); x < nx; ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
      const std::size_t i = static_cast<std::size_t>(y) * nx + x;
      const int gl = ground_layer[i];
      const bool seen = rules.observed_count(any_known[i], gl);
      const int estimate =
          static_cast<int>(estimates[static_cast<std::size_t>(y / pass.g) * pass.gx + x / pass.g]);
      const bool voxel = any_obstacle[i] != 0;
      const bool drop = !voxel && rules.drops(ring_row + rx, out.lowest_observed[i], estimate);
      // A low object blocks whatever the free rule says of the rest of the envelope.
      const bool low =
          !voxel && !drop && any_known[i] != 0 &&
          rules.rises(ring_row + rx, std::max(0, gl), std::min(pass.nz, gl + rules.lo_layers));
      classes[i] = column_class(voxel || drop || low, seen);
      out.esdf_input[i] = esdf_state(classes[i]);
      out.obstacle_rule[i] = first_rule(voxel, drop, low);
    }
  }
}

}  // namespace

void classify_columns(const CostmapPass& pass) {
  auto& out = pass.out;
  const std::size_t cells = pass.geometry.cell_count();
  out.ground_layer.resize(cells);
  out.obstacle_rule.resize(cells);
  out.any_known.resize(pass.use_bits ? 0 : cells);
  out.any_obstacle.resize(pass.use_bits ? 0 : cells);
  // The rounded estimate per coarse cell, once per coarse cell instead of once per column
  // (coarse_next is free after the fill; whole layers are exact in float).
  auto& estimates = out.coarse_next;
  for (std::size_t i = 0; i < out.coarse_filtered.size(); ++i) {
    estimates[i] = static_cast<float>(std::lround(out.coarse_filtered[i]));
  }
  const ColumnRules rules(pass);
  pass.runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int y0 = static_cast<int>(pass.ny * task / kRowTasks);
    const int y1 = static_cast<int>(pass.ny * (task + 1) / kRowTasks);
    if (pass.use_bits) {
      classify_rows_by_bits(pass, rules, estimates, y0, y1);
    } else {
      classify_rows_by_layers(pass, rules, estimates, y0, y1);
    }
  });
}

void mark_low_objects(const CostmapPass& pass) {
  const LowObjects& objects = pass.map.low_objects();
  auto& classes = pass.out.column_class.cells();
  for (const LowObject& o : objects.all()) {
    if (!objects.lethal(o)) continue;
    const std::int64_t c = standing_cell(o, pass.out.ground_z_m);
    if (c < 0) continue;
    const auto i = static_cast<std::size_t>(c);
    classes[i] = static_cast<std::uint8_t>(ColumnClass::kObstacle);
    pass.out.esdf_input[i] = CellState::kOccupied;
    pass.out.obstacle_rule[i] |= obstacle_rule::kLowObject;
  }
}

void fuse_peers(const CostmapPass& pass, CostmapPeers& peers) {
  auto& out = pass.out;
  std::span<std::uint8_t> classes(out.column_class.cells());
  peers.counts = peers.peers->fuse(pass.geometry, peers.own_observed_ns, peers.now_ns, classes);
  if (peers.counts.cells == 0) return;
  constexpr auto kObstacle = static_cast<std::uint8_t>(ColumnClass::kObstacle);
  for (std::size_t i = 0; i < classes.size(); ++i) {
    out.esdf_input[i] = esdf_state(classes[i]);
    // The own class is kept where the peers did not fill the cell.
    if (classes[i] != kObstacle) {
      out.obstacle_rule[i] = 0;
    } else if (out.own_column_class[i] != kObstacle) {
      out.obstacle_rule[i] = obstacle_rule::kPeer;
    }
  }
}

}  // namespace tarmac::core::costmap
