#include "tarmac/core/costmap_builder.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "lanes4.hpp"

namespace tarmac::core {

namespace {

constexpr std::size_t kRowTasks = 16;
constexpr float kNoGround = std::numeric_limits<float>::quiet_NaN();

/// Calls fn(window_x0, values, count) for window row `wy` of a ring layer as at most two
/// contiguous runs (the ring wraps once along x), so passes read memory in order.
template <typename Fn>
void for_row_runs(const OccupancyMap& map, const float* layer, int wy, Fn&& fn) {
  const int nx = map.window_size().x();
  const int rx0 = map.ring_x(0);
  const float* row = layer + static_cast<std::size_t>(map.ring_y(wy)) * nx;
  fn(0, row + rx0, nx - rx0);
  if (rx0 > 0) fn(nx - rx0, row, rx0);
}

/// lowest[k] = z where layer z is occupied, observed[k] = z where it is observed (called from
/// the top layer down).
void mark_lowest(std::int16_t* __restrict lowest, std::int16_t* __restrict observed,
                 const float* __restrict log_odds, int count, std::int16_t z) {
  for (int k = 0; k < count; ++k) {
    lowest[k] = log_odds[k] > 0.0f ? z : lowest[k];
    observed[k] = log_odds[k] != OccupancyMap::kUnknown ? z : observed[k];
  }
}

/// A column's ground candidate: its lowest occupied layer, or, when observed free space reaches
/// more than a layer below that (the occupied voxel hovers: an engine's underside), its lowest
/// observed layer; −1 without an occupied layer.
std::int16_t ground_candidate(int lowest_occupied, int lowest_observed) {
  if (lowest_occupied < 0) return -1;
  return static_cast<std::int16_t>(lowest_observed < lowest_occupied - 1 ? lowest_observed
                                                                         : lowest_occupied);
}

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

/// Layers per group of the layer-bits pass: a group's layers are read side by side (a few
/// sequential streams, which the prefetchers follow; all 40 at once were twice as slow).
constexpr int kLayerGroup = 4;
/// Columns per block of the layer-bits pass: a group's words for a block stay in L1.
constexpr std::size_t kBitsBlock = 2048;

/// Adds layers [zb, zt), from the top down, to the per-column words of layer bits (occupied:
/// log-odds > 0; observed) of 4·kVectors columns at `offset` of every layer: each layer shifts
/// the words up by one and adds its bit (a comparison is −1 or 0: subtracting it adds 1). The
/// words stay in registers across the group; `first` starts them at zero.
template <int kVectors>
void add_layer_bits(const float* const* layers, std::size_t offset, int zb, int zt, bool first,
                    std::uint32_t* __restrict occupied, std::uint32_t* __restrict known) {
  // Unsigned: each layer shifts the words left, and with 32 layers the top bit overflows (signed
  // overflow is undefined; UBSan found it). The bits are the same.
  using UInt4 = std::uint32_t __attribute__((vector_size(16)));
  UInt4 occ[kVectors] = {}, obs[kVectors] = {};
  if (!first) {
    std::memcpy(occ, occupied, sizeof occ);
    std::memcpy(obs, known, sizeof obs);
  }
  const Float4 zero = {0.0f, 0.0f, 0.0f, 0.0f};
  const Float4 unknown = zero + OccupancyMap::kUnknown;
  for (int z = zt - 1; z >= zb; --z) {
    const float* l = layers[z] + offset;
    for (int j = 0; j < kVectors; ++j) {
      Float4 v;
      std::memcpy(&v, l + 4 * j, sizeof v);
      occ[j] = (occ[j] + occ[j]) - reinterpret_cast<UInt4>(v > zero);
      obs[j] = (obs[j] + obs[j]) - reinterpret_cast<UInt4>(v != unknown);
    }
  }
  std::memcpy(occupied, occ, sizeof occ);
  std::memcpy(known, obs, sizeof obs);
}

/// The words of layers [z0, z1) (bit z − z0; z1 − z0 <= 32) for a run of `count` columns at
/// `offset` of every layer, written to occupied[0, count) and known[0, count): layer groups
/// from the top down, each over the run in blocks of 16, then 4, then single columns.
void layer_bits_run(const float* const* layers, std::size_t offset, int count, int z0, int z1,
                    std::uint32_t* __restrict occupied, std::uint32_t* __restrict known) {
  if (z0 >= z1) {
    std::fill(occupied, occupied + count, 0u);
    std::fill(known, known + count, 0u);
    return;
  }
  for (int zt = z1; zt > z0; zt -= kLayerGroup) {
    const int zb = std::max(z0, zt - kLayerGroup);
    const bool first = zt == z1;
    int k = 0;
    for (; k + 16 <= count; k += 16) {
      add_layer_bits<4>(layers, offset + k, zb, zt, first, occupied + k, known + k);
    }
    for (; k + 4 <= count; k += 4) {
      add_layer_bits<1>(layers, offset + k, zb, zt, first, occupied + k, known + k);
    }
    for (; k < count; ++k) {
      std::uint32_t occ = first ? 0u : occupied[k], obs = first ? 0u : known[k];
      for (int z = zt - 1; z >= zb; --z) {
        const float l = layers[z][offset + k];
        occ = 2 * occ + (l > 0.0f ? 1u : 0u);
        obs = 2 * obs + (l != OccupancyMap::kUnknown ? 1u : 0u);
      }
      occupied[k] = occ;
      known[k] = obs;
    }
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

Status CostmapParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) {
    return Error{"config.range", "costmap." + key + ": " + why};
  };
  if (!(min_obstacle_height_m >= 0.0)) return bad("min_obstacle_height_m", "must be >= 0");
  if (!(vehicle_height_m > min_obstacle_height_m)) {
    return bad("vehicle_height_m", "must be > min_obstacle_height_m");
  }
  if (!(clearance_m >= 0.0)) return bad("clearance_m", "must be >= 0");
  if (!(inscribed_radius_m >= 0.0)) return bad("inscribed_radius_m", "must be >= 0");
  if (!(inflation_radius_m >= inscribed_radius_m)) {
    return bad("inflation_radius_m", "must be >= inscribed_radius_m");
  }
  if (!(cost_scaling_factor > 0.0)) return bad("cost_scaling_factor", "must be > 0");
  if (!(ground_cell_m > 0.0)) return bad("ground_cell_m", "must be > 0");
  if (!(max_ground_step_m > 0.0)) return bad("max_ground_step_m", "must be > 0");
  if (!(max_ground_slope >= 0.0 && max_ground_slope <= 1.0)) {
    return bad("max_ground_slope", "must be in [0, 1]");
  }
  if (!(ground_tolerance_m >= 0.0)) return bad("ground_tolerance_m", "must be >= 0");
  return Ok{};
}

std::uint8_t nav2_cost(double distance_m, const CostmapParams& p) {
  if (distance_m <= 0.0) return 254;
  if (distance_m <= p.inscribed_radius_m) return 253;
  if (distance_m > p.inflation_radius_m) return 0;
  const double factor = std::exp(-p.cost_scaling_factor * (distance_m - p.inscribed_radius_m));
  return static_cast<std::uint8_t>(252.0 * factor);
}

std::int8_t to_occupancy_value(std::uint8_t cost) {
  if (cost == 0) return 0;
  if (cost == 253) return 99;
  if (cost == 254) return 100;
  if (cost == 255) return -1;
  return static_cast<std::int8_t>(1 + (97 * (cost - 1)) / 251);
}

void to_obstacle_grid(const Costmap& costmap, Costmap& out) {
  out.reset(costmap.geometry(), kCostFree);  // keeps the storage while the size holds
  const auto& in = costmap.cells();
  auto& cells = out.cells();
  for (std::size_t i = 0; i < in.size(); ++i) {
    cells[i] = in[i] == kCostLethal || in[i] == kCostUnknown ? in[i] : kCostFree;
  }
}

void to_distance_display(const DistanceField& field, const GridGeometry2D& geometry, double range_m,
                         Costmap& out) {
  out.reset(geometry, kCostUnknown);
  auto& cells = out.cells();
  const std::size_t n = std::min(cells.size(), field.distance_m.size());
  for (std::size_t i = 0; i < n; ++i) {
    const float d = field.distance_m[i];
    if (std::isnan(d)) continue;  // unknown stays −1
    const double shade = 100.0 * (1.0 - std::min(1.0, static_cast<double>(d) / range_m));
    cells[i] = static_cast<std::int8_t>(std::lround(shade));
  }
}

bool polygon_contains(std::span<const Eigen::Vector2d> polygon, const Eigen::Vector2d& p) {
  bool inside = false;
  for (std::size_t i = 0, j = polygon.size() - 1; i < polygon.size(); j = i++) {
    const auto& a = polygon[i];
    const auto& b = polygon[j];
    if ((a.y() > p.y()) != (b.y() > p.y()) &&
        p.x() < (b.x() - a.x()) * (p.y() - a.y()) / (b.y() - a.y()) + a.x()) {
      inside = !inside;
    }
  }
  return inside;
}

void build_costmap(const OccupancyMap& map, const CostmapParams& params,
                   const Eigen::Isometry3d& T_W_B, std::span<const VirtualZone> zones,
                   std::int64_t stamp_ns, CostmapLayers& out, TaskRunner& runner) {
  const double v = map.params().voxel_size_m;
  const Eigen::Vector3i dims = map.window_size();
  const VoxelIndex& wmin = map.window_min();
  const int nx = dims.x(), ny = dims.y(), nz = dims.z();
  const GridGeometry2D geometry{wmin.x() * v, wmin.y() * v, v, static_cast<std::uint32_t>(nx),
                                static_cast<std::uint32_t>(ny)};
  if (!(out.costmap.geometry() == geometry)) {
    out.costmap.reset(geometry, kCostUnknown);
    out.ground_z_m.reset(geometry, kNoGround);
    out.column_class.reset(geometry, 0);
  }
  out.esdf_input.resize(geometry.cell_count());

  // 1. Per column, its ground candidate (layer by layer, in memory order), then per coarse
  //    ground cell the lowest of those. The candidate is the lowest occupied voxel, unless
  //    observed free space reaches more than a voxel below it: rays that graze the ground clear
  //    the voxel that holds its surface, and where they have, the lowest occupied voxel is
  //    whatever hovers above (an engine's underside at 1.2 m), which must not be taken for the
  //    ground under a wing; the lowest observed voxel is then the free one just over the ground.
  auto& lowest = out.lowest_occupied;
  // Windows of at most 64 layers: one pass over all layers builds per-column bit sets of the
  // occupied and the observed layers; the lowest occupied layer and the envelope tests of step 3
  // are then bit operations per column. Taller windows scan the layers (same results).
  const bool use_bits = nz <= 64;
  auto& occupied_bits = out.occupied_bits;
  auto& known_bits = out.known_bits;
  // Layers 0..31 in the first cell_count() words, 32..63 in the second; ring (storage) order.
  const std::size_t cells_n = geometry.cell_count();
  occupied_bits.resize(use_bits ? 2 * cells_n : 0);
  known_bits.resize(use_bits ? 2 * cells_n : 0);
  if (use_bits) {
    lowest.resize(cells_n);  // every cell is written below
  } else {
    lowest.assign(cells_n, -1);
    out.ground_layer.assign(cells_n, -1);
  }
  // Each layer's storage, looked up once per call.
  std::array<const float*, 64> layer_data{};
  for (int z = 0; z < std::min(nz, 64); ++z)
    layer_data[static_cast<std::size_t>(z)] = map.ring_layer(z);
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int y0 = static_cast<int>(ny * task / kRowTasks);
    const int y1 = static_cast<int>(ny * (task + 1) / kRowTasks);
    if (use_bits) {
      // In storage (ring) order, so each layer is read as one contiguous stream per block; the
      // words are kept in ring order too. Written, not ORed: no zeroing pass.
      const std::size_t c0 = cells_n * task / kRowTasks, c1 = cells_n * (task + 1) / kRowTasks;
      for (std::size_t b0 = c0; b0 < c1; b0 += kBitsBlock) {
        const int count = static_cast<int>(std::min(kBitsBlock, c1 - b0));
        for (const std::size_t half : {std::size_t{0}, cells_n}) {
          layer_bits_run(layer_data.data(), b0, count, half == 0 ? 0 : 32,
                         half == 0 ? std::min(nz, 32) : nz, &occupied_bits[half + b0],
                         &known_bits[half + b0]);
        }
      }
      return;
    }
    // Top down, overwriting: what stays is the lowest occupied layer. A plain select per cell,
    // which the compiler vectorises (the "first occupied from below" test did not).
    std::int16_t* observed = out.ground_layer.data();  // scratch until step 3
    for (int z = nz - 1; z >= 0; --z) {
      const float* layer = map.ring_layer(z);
      const auto zz = static_cast<std::int16_t>(z);
      for (int y = y0; y < y1; ++y) {
        const std::size_t row = static_cast<std::size_t>(y) * nx;
        for_row_runs(map, layer, y, [&](int x0, const float* l, int count) {
          mark_lowest(&lowest[row + x0], observed + row + x0, l, count, zz);
        });
      }
    }
    for (std::size_t i = static_cast<std::size_t>(y0) * nx; i < static_cast<std::size_t>(y1) * nx;
         ++i) {
      lowest[i] = ground_candidate(lowest[i], observed[i]);
    }
  });
  if (use_bits) {
    runner.parallel_for(kRowTasks, [&](std::size_t task) {
      const int y0 = static_cast<int>(ny * task / kRowTasks);
      const int y1 = static_cast<int>(ny * (task + 1) / kRowTasks);
      for (int y = y0; y < y1; ++y) {
        const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
        std::int16_t* low = &lowest[static_cast<std::size_t>(y) * nx];
        for (int x = 0, rx = map.ring_x(0); x < nx; ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
          const std::size_t sl = ring_row + static_cast<std::size_t>(rx);
          const std::uint64_t b = occupied_bits[sl] | std::uint64_t{occupied_bits[cells_n + sl]}
                                                          << 32;
          const std::uint64_t k = known_bits[sl] | std::uint64_t{known_bits[cells_n + sl]} << 32;
          low[x] = b == 0 ? std::int16_t{-1}
                          : ground_candidate(std::countr_zero(b), std::countr_zero(k));
        }
      }
    });
  }
  const int g = std::max(1, static_cast<int>(std::lround(params.ground_cell_m / v)));
  const int gx = (nx + g - 1) / g, gy = (ny + g - 1) / g;
  // Coarse ground buffers live in `out` and keep their capacity: no allocation after warm-up.
  auto& coarse = out.coarse_ground;
  coarse.assign(static_cast<std::size_t>(gx) * gy, kNoGround);
  // Per coarse cell, the minimum over its g×g columns (an integer, so the order is irrelevant);
  // walked in blocks of g columns so no cell needs a division; tasks own whole coarse rows.
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int cy0 = static_cast<int>(static_cast<std::size_t>(gy) * task / kRowTasks);
    const int cy1 = static_cast<int>(static_cast<std::size_t>(gy) * (task + 1) / kRowTasks);
    for (int y = cy0 * g, y_end = std::min(ny, cy1 * g); y < y_end; ++y) {
      const std::int16_t* low = &lowest[static_cast<std::size_t>(y) * nx];
      float* coarse_row = &coarse[static_cast<std::size_t>(y / g) * gx];
      for (int x0 = 0, cx = 0; x0 < nx; x0 += g, ++cx) {
        int m = std::numeric_limits<int>::max();
        for (int x = x0, x1 = std::min(nx, x0 + g); x < x1; ++x) {
          const int z = low[x];
          m = z >= 0 ? std::min(m, z) : m;
        }
        float& c = coarse_row[cx];
        if (m != std::numeric_limits<int>::max() && (std::isnan(c) || m < c)) {
          c = static_cast<float>(m);
        }
      }
    }
  });

  // 2. Reject cells that cannot be ground: far off the plane of the vehicle's own wheels
  //    (extended with the steepest slope allowed; the world frame need not be gravity-aligned,
  //    the vehicle's z axis is the local "up") — a wing or a fuselage seen with no ground under
  //    it — or far above their neighbours (a truck roof). Then fill gaps from neighbours; what
  //    stays empty gets the vehicle's plane.
  const Eigen::Vector3d base_W = T_W_B.translation();
  const Eigen::Vector3d up_W = T_W_B.linear().col(2);
  const double up_z = std::max(up_W.z(), 0.1);  // a vehicle on its side has no ground plane
  // The plane's height is taken from the data, not from the base frame's origin (base_link may
  // sit at the axle, or at the sensor when the extrinsic is identity): the median offset from
  // the plane through the base of the coarse cells within kPriorRadiusM, most of which are ground.
  constexpr double kPriorRadiusM = 20.0;
  const auto coarse_center = [&](int cx, int cy) {
    return Eigen::Vector2d((wmin.x() + (cx + 0.5) * g) * v, (wmin.y() + (cy + 0.5) * g) * v);
  };
  const auto plane_through_base = [&](double x_m, double y_m) {
    const double z_m =
        base_W.z() - (up_W.x() * (x_m - base_W.x()) + up_W.y() * (y_m - base_W.y())) / up_z;
    return static_cast<float>(z_m / v - wmin.z());
  };
  auto& offsets = out.ground_offsets;
  offsets.clear();
  for (int cy = 0; cy < gy; ++cy) {
    for (int cx = 0; cx < gx; ++cx) {
      const float c = coarse[static_cast<std::size_t>(cy) * gx + cx];
      const Eigen::Vector2d center = coarse_center(cx, cy);
      if (std::isnan(c) || (center - base_W.head<2>()).norm() > kPriorRadiusM) continue;
      offsets.push_back(c - plane_through_base(center.x(), center.y()));
    }
  }
  float offset = 0.0f;
  if (!offsets.empty()) {
    const auto mid = offsets.begin() + static_cast<std::ptrdiff_t>(offsets.size() / 2);
    std::nth_element(offsets.begin(), mid, offsets.end());
    offset = *mid;
  }
  // Expected ground layer (window layers, voxel bottom) at a map-frame (x, y).
  const auto plane_layer = [&](double x_m, double y_m) {
    return std::floor(plane_through_base(x_m, y_m) + offset);
  };
  const float step_vox = static_cast<float>(params.max_ground_step_m / v);
  auto& filtered = out.coarse_filtered;
  filtered.assign(coarse.begin(), coarse.end());
  for (int cy = 0; cy < gy; ++cy) {
    for (int cx = 0; cx < gx; ++cx) {
      const float c = coarse[static_cast<std::size_t>(cy) * gx + cx];
      if (std::isnan(c)) continue;
      const Eigen::Vector2d center = coarse_center(cx, cy);
      const double reach_m =
          params.ground_tolerance_m + params.max_ground_slope * (center - base_W.head<2>()).norm();
      if (std::abs(c - plane_layer(center.x(), center.y())) > reach_m / v) {
        filtered[static_cast<std::size_t>(cy) * gx + cx] = kNoGround;
        continue;
      }
      float lowest = std::numeric_limits<float>::infinity();
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int ux = cx + dx, uy = cy + dy;
          if ((dx == 0 && dy == 0) || ux < 0 || uy < 0 || ux >= gx || uy >= gy) continue;
          const float n = coarse[static_cast<std::size_t>(uy) * gx + ux];
          if (!std::isnan(n)) lowest = std::min(lowest, n);
        }
      }
      if (c - lowest > step_vox) filtered[static_cast<std::size_t>(cy) * gx + cx] = kNoGround;
    }
  }
  // Fill gaps from neighbours. Defined as passes that each give every gap cell next to a filled
  // cell the mean of its filled neighbours (in the fixed neighbour order below). A gap cell is
  // therefore filled in pass L − 1, L its chessboard distance to the nearest cell filled
  // before the first pass, from its neighbours nearer than L. So L comes from a two-pass
  // chamfer transform (exact for the chessboard metric), then the cells are filled level by
  // level: the same values, with one neighbourhood evaluation per gap cell instead of one per
  // gap cell and pass.
  auto& level = out.coarse_next;  // chessboard level per coarse cell, +inf when unreachable
  const float kUnreached = std::numeric_limits<float>::infinity();
  level.resize(filtered.size());
  for (std::size_t i = 0; i < filtered.size(); ++i) {
    level[i] = std::isnan(filtered[i]) ? kUnreached : 0.0f;
  }
  const auto relax = [&](int cx, int cy, const int(*offsets)[2]) {
    float& l = level[static_cast<std::size_t>(cy) * gx + cx];
    for (int k = 0; k < 4; ++k) {
      const int ux = cx + offsets[k][0], uy = cy + offsets[k][1];
      if (ux < 0 || uy < 0 || ux >= gx || uy >= gy) continue;
      l = std::min(l, level[static_cast<std::size_t>(uy) * gx + ux] + 1.0f);
    }
  };
  constexpr int kBefore[4][2] = {{-1, 0}, {-1, -1}, {0, -1}, {1, -1}};
  constexpr int kAfter[4][2] = {{1, 0}, {1, 1}, {0, 1}, {-1, 1}};
  for (int cy = 0; cy < gy; ++cy) {
    for (int cx = 0; cx < gx; ++cx) relax(cx, cy, kBefore);
  }
  float max_level = 0.0f;
  for (int cy = gy - 1; cy >= 0; --cy) {
    for (int cx = gx - 1; cx >= 0; --cx) {
      relax(cx, cy, kAfter);
      const float l = level[static_cast<std::size_t>(cy) * gx + cx];
      if (l != kUnreached) max_level = std::max(max_level, l);
    }
  }
  // The gap cells by level (a counting sort, row-major within a level), so each pass visits its
  // own cells only instead of every coarse cell.
  const auto n_levels = static_cast<std::size_t>(max_level) + 1;
  auto& level_first = out.level_first;
  auto& level_cells = out.level_cells;
  // Sized for the most levels and gap cells a window can have, so no later scan grows them.
  level_first.reserve(filtered.size() + 2);
  out.level_next.reserve(filtered.size() + 2);
  level_cells.reserve(filtered.size());
  level_first.assign(n_levels + 1, 0);
  for (const float l : level) {
    if (l >= 1.0f && l != kUnreached) ++level_first[static_cast<std::size_t>(l) + 1];
  }
  for (std::size_t k = 1; k <= n_levels; ++k) level_first[k] += level_first[k - 1];
  level_cells.resize(level_first[n_levels]);
  {
    auto& next = out.level_next;
    next.assign(level_first.begin(), level_first.end() - 1);
    for (std::size_t i = 0; i < level.size(); ++i) {
      const float l = level[i];
      if (l >= 1.0f && l != kUnreached) {
        level_cells[next[static_cast<std::size_t>(l)]++] = static_cast<std::uint32_t>(i);
      }
    }
  }
  for (std::size_t pass_index = 1; pass_index < n_levels; ++pass_index) {
    const auto pass = static_cast<float>(pass_index);
    for (std::size_t k = level_first[pass_index]; k < level_first[pass_index + 1]; ++k) {
      const std::size_t i = level_cells[k];
      const int cx = static_cast<int>(i % static_cast<std::size_t>(gx));
      const int cy = static_cast<int>(i / static_cast<std::size_t>(gx));
      float sum = 0.0f;
      int count = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int ux = cx + dx, uy = cy + dy;
          if (ux < 0 || uy < 0 || ux >= gx || uy >= gy) continue;
          const std::size_t u = static_cast<std::size_t>(uy) * gx + ux;
          if (level[u] < pass) {  // filled in an earlier pass (or before the first)
            sum += filtered[u];
            ++count;
          }
        }
      }
      filtered[i] = sum / static_cast<float>(count);  // count >= 1: a neighbour is nearer
    }
  }
  for (int cy = 0; cy < gy; ++cy) {
    for (int cx = 0; cx < gx; ++cx) {
      float& c = filtered[static_cast<std::size_t>(cy) * gx + cx];
      if (!std::isnan(c)) continue;
      const Eigen::Vector2d center = coarse_center(cx, cy);
      c = plane_layer(center.x(), center.y());
    }
  }

  // 3. Classify columns against the envelope. A column's own ground is its lowest occupied voxel
  //    when that lies within one voxel of the local estimate (slopes, tilted world frames),
  //    otherwise the estimate. An obstacle voxel starts at least min_obstacle_height above the
  //    top of the ground voxel (so a ground surface that crosses a voxel boundary is not an
  //    obstacle) and starts below ground + vehicle height + clearance.
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
  // 3b. Objects lower than the voxels that separate them from the ground (10 cm debris shares a
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

  // 4. Virtual zones: active, and their z range meets the vehicle's envelope at that cell.
  for (const auto& zone : zones) {
    if (!zone.active(stamp_ns)) continue;
    for_each_cell_inside(geometry, zone.polygon_W, [&](int x, int y) {
      const double ground_m = out.ground_z_m.at(x, y);
      if (zone.max_z_m < ground_m || zone.min_z_m > ground_m + hi_m) return;
      auto& cls = out.column_class.at(x, y);
      // A no-go zone blocks every cell; a restricted zone blocks only what was not observed.
      if (!zone.restricted || cls == static_cast<std::uint8_t>(ColumnClass::kUnknown)) {
        cls = static_cast<std::uint8_t>(ColumnClass::kVirtual);
        out.esdf_input[static_cast<std::size_t>(y) * nx + x] = CellState::kOccupied;
      }
    });
  }

  // 5. Exact distance to the nearest obstacle cell (esdf_input was set with the classes), then
  //    Nav2 inflation.
  compute_distance_field(out.esdf_input, Eigen::Vector3i(nx, ny, 1), v,
                         UnknownPolicy::kReportUnknown, out.obstacle_distance, out.scratch, runner);
  const std::int8_t unknown_value = params.unknown_cost == UnknownCost::kLethal ? kCostLethal
                                    : params.unknown_cost == UnknownCost::kFree ? kCostFree
                                                                                : kCostUnknown;
  // Free cells within the inflation radius cost an exp each. Their distances are few distinct
  // values, sqrt(k)·v for integer squared distances k in cells (computed as the transform does),
  // so their values are tabulated once per call; a distance that does not match its table entry
  // bit for bit is costed directly, so the result never depends on the table.
  // (A fixed capacity on the stack, so the cycle does not allocate; beyond it, direct costs.)
  constexpr std::size_t kTableCapacity = 2048;
  std::array<float, kTableCapacity> table_distance;
  std::array<std::int8_t, kTableCapacity> table_value;
  const double inflation_cells = params.inflation_radius_m / v;
  const std::size_t table_size =
      std::min(kTableCapacity,
               static_cast<std::size_t>(std::min(inflation_cells * inflation_cells, 1e9)) + 2);
  for (std::size_t k = 0; k < table_size; ++k) {
    table_distance[k] = static_cast<float>(std::sqrt(static_cast<double>(k)) * v);
    table_value[k] = to_occupancy_value(nav2_cost(table_distance[k], params));
  }
  const auto free_value = [&](float distance) {
    if (distance > params.inflation_radius_m) return std::int8_t{0};
    const double r = distance / v;
    // Any k is safe (the entry is checked); this one is the nearest integer to r² >= 0.
    const auto k = static_cast<std::size_t>(r * r + 0.5);
    if (k < table_size && table_distance[k] == distance) return table_value[k];
    return to_occupancy_value(nav2_cost(distance, params));
  };
  auto& cells = out.costmap.cells();
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const std::size_t i0 = cells_n * task / kRowTasks, i1 = cells_n * (task + 1) / kRowTasks;
    for (std::size_t i = i0; i < i1; ++i) {
      switch (static_cast<ColumnClass>(classes[i])) {
        case ColumnClass::kObstacle:
        case ColumnClass::kVirtual: cells[i] = kCostLethal; break;
        case ColumnClass::kUnknown: cells[i] = unknown_value; break;
        case ColumnClass::kFree: cells[i] = free_value(out.obstacle_distance.distance_m[i]); break;
      }
    }
  });
}

}  // namespace tarmac::core
