/// @file build_costmap's ground estimate (steps 1–5 of costmap/steps.hpp).

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "../lanes4.hpp"
#include "steps.hpp"

namespace tarmac::core::costmap {
namespace {

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

/// The layer of the ground a scan last returned densely round the column at ring slot
/// `ring_slot`, for a column with no occupied voxel; −1 where none did or it lies outside the
/// window. Far from the sensor a ring lands on a surface falling away (a ramp going down 30 m
/// off) where the same ring's rays, landing a little further in earlier scans, passed a few
/// centimetres over it: those misses emptied the voxels that hold the surface, and one return
/// does not make them occupied again. Without it the ground there is filled from the level
/// before it, and the rays beyond, which pass under that, read as a drop. A surface that has
/// gone (a trailer's bed) shows free space under it, and ground_candidate() then takes the
/// lowest observed voxel instead, as for any hovering surface.
int remembered_layer(const CostmapPass& pass, std::size_t ring_slot) {
  const float z = pass.map.remembered_ground_z(ring_slot);
  if (std::isnan(z)) return -1;
  const int layer = static_cast<int>(std::floor(z / pass.v)) - pass.wmin.z();
  return layer >= 0 && layer < pass.nz ? layer : -1;
}

/// The layer-bits pass reads the layers in groups of this many (four sequential streams, which
/// the prefetchers follow; all 40 at once were twice as slow).
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

}  // namespace

void find_ground_candidates(const CostmapPass& pass) {
  const auto& map = pass.map;
  auto& out = pass.out;
  auto& runner = pass.runner;
  const auto nx = pass.nx;
  const auto ny = pass.ny;
  const auto nz = pass.nz;
  const auto cells_n = pass.cells_n;
  const auto use_bits = pass.use_bits;
  // The candidate is the lowest occupied voxel, unless observed free space reaches more than a
  // voxel below it: rays that graze the ground clear the voxel that holds its surface, and where
  // they have, the lowest occupied voxel is whatever hovers above (an engine's underside at
  // 1.2 m), which must not be taken for the ground under a wing; the lowest observed voxel is
  // then the free one just over the ground.
  auto& lowest = out.lowest_occupied;
  auto& occupied_bits = out.occupied_bits;
  auto& known_bits = out.known_bits;
  // Layers 0..31 in the first cell_count() words, 32..63 in the second; ring (storage) order.
  occupied_bits.resize(use_bits ? 2 * cells_n : 0);
  known_bits.resize(use_bits ? 2 * cells_n : 0);
  out.hovers.resize(cells_n);  // every cell is written below
  if (use_bits) {
    lowest.resize(cells_n);  // every cell is written below
    out.lowest_observed.resize(cells_n);
  } else {
    lowest.assign(cells_n, -1);
    out.lowest_observed.assign(cells_n, -1);
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
    std::int16_t* observed = out.lowest_observed.data();
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
    for (int y = y0; y < y1; ++y) {
      const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
      for (int x = 0; x < nx; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * nx + static_cast<std::size_t>(x);
        const int occupied =
            lowest[i] >= 0
                ? lowest[i]
                : remembered_layer(pass, ring_row + static_cast<std::size_t>(map.ring_x(x)));
        const std::int16_t candidate = ground_candidate(occupied, observed[i]);
        out.hovers[i] = candidate != occupied ? 1 : 0;
        lowest[i] = candidate;
      }
    }
  });
  if (use_bits) {
    runner.parallel_for(kRowTasks, [&](std::size_t task) {
      const int y0 = static_cast<int>(ny * task / kRowTasks);
      const int y1 = static_cast<int>(ny * (task + 1) / kRowTasks);
      for (int y = y0; y < y1; ++y) {
        const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
        std::int16_t* low = &lowest[static_cast<std::size_t>(y) * nx];
        std::int16_t* seen = &out.lowest_observed[static_cast<std::size_t>(y) * nx];
        std::uint8_t* hover = &out.hovers[static_cast<std::size_t>(y) * nx];
        for (int x = 0, rx = map.ring_x(0); x < nx; ++x, rx = rx + 1 == nx ? 0 : rx + 1) {
          const std::size_t sl = ring_row + static_cast<std::size_t>(rx);
          const std::uint64_t b = occupied_bits[sl] | std::uint64_t{occupied_bits[cells_n + sl]}
                                                          << 32;
          const std::uint64_t k = known_bits[sl] | std::uint64_t{known_bits[cells_n + sl]} << 32;
          seen[x] = k == 0 ? std::int16_t{-1} : static_cast<std::int16_t>(std::countr_zero(k));
          const int occupied = b != 0 ? std::countr_zero(b) : remembered_layer(pass, sl);
          low[x] = ground_candidate(occupied, seen[x]);
          hover[x] = low[x] != occupied ? 1 : 0;
        }
      }
    });
  }
}

void find_coarse_ground(const CostmapPass& pass) {
  auto& out = pass.out;
  auto& runner = pass.runner;
  const auto nx = pass.nx;
  const auto ny = pass.ny;
  const auto g = pass.g;
  const auto gx = pass.gx;
  const auto gy = pass.gy;
  const auto& lowest = out.lowest_occupied;
  // Coarse ground buffers live in `out` and keep their capacity: no allocation after warm-up.
  auto& coarse = out.coarse_ground;
  coarse.assign(static_cast<std::size_t>(gx) * gy, kNoGround);
  // Per coarse cell, a low order statistic of its columns' candidates: the lowest after the
  // lowest tenth is set aside, so a few stray returns under the surface (a glossy floor's
  // mirror images, multipath) do not pull the ground down, while a cell with a little ground
  // seen beside an object still finds it. Where the candidates of the columns with a surface
  // (no observed space under their lowest occupied voxel) give a higher ground than all
  // candidates do, by more than a layer, that higher one: the others' observed space under a
  // returned floor was seen by rays to its mirror images (a glossy hall floor shows them over
  // whole metres), not by rays passing under something hovering, which end on the ground.
  // Integers, so the order they come in is irrelevant; tasks own whole coarse rows.
  const auto& hovers = out.hovers;
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int cy0 = static_cast<int>(static_cast<std::size_t>(gy) * task / kRowTasks);
    const int cy1 = static_cast<int>(static_cast<std::size_t>(gy) * (task + 1) / kRowTasks);
    std::array<std::int16_t, 64 * 64> heights, surfaces;  // g <= 64 (ground_cell_m / voxel)
    const auto low_tenth = [](std::array<std::int16_t, 64 * 64>& h, std::size_t count) {
      const auto k = static_cast<std::ptrdiff_t>(count / 10);
      std::nth_element(h.begin(), h.begin() + k, h.begin() + static_cast<std::ptrdiff_t>(count));
      return h[static_cast<std::size_t>(k)];
    };
    for (int cy = cy0; cy < cy1; ++cy) {
      for (int cx = 0; cx < gx; ++cx) {
        std::size_t count = 0, n_surfaces = 0;
        for (int y = cy * g, y1 = std::min(ny, (cy + 1) * g); y < y1; ++y) {
          const std::size_t row = static_cast<std::size_t>(y) * nx;
          for (int x = cx * g, x1 = std::min(nx, (cx + 1) * g); x < x1; ++x) {
            const std::int16_t low = lowest[row + x];
            if (low < 0 || count == heights.size()) continue;
            heights[count++] = low;
            if (hovers[row + x] == 0) surfaces[n_surfaces++] = low;
          }
        }
        if (count == 0) continue;
        const int all = low_tenth(heights, count);
        const int surface = n_surfaces == 0 ? all : low_tenth(surfaces, n_surfaces);
        coarse[static_cast<std::size_t>(cy) * gx + cx] =
            static_cast<float>(surface > all + 1 ? surface : all);
      }
    }
  });
}

GroundPlane fit_ground_plane(const CostmapPass& pass, const Eigen::Isometry3d& T_W_B) {
  auto& out = pass.out;
  const auto gx = pass.gx;
  const auto gy = pass.gy;
  const Eigen::Vector3d up_W = T_W_B.linear().col(2);
  GroundPlane plane{pass, T_W_B.translation(), up_W, std::max(up_W.z(), 0.1)};
  // The plane's height is taken from the data, not from the base frame's origin (base_link may
  // sit at the axle, or at the sensor when the extrinsic is identity): the median offset from
  // the plane through the base of the coarse cells within kPriorRadiusM, most of which are ground.
  constexpr double kPriorRadiusM = 20.0;
  const auto& coarse = out.coarse_ground;
  auto& offsets = out.ground_offsets;
  offsets.clear();
  for (int cy = 0; cy < gy; ++cy) {
    for (int cx = 0; cx < gx; ++cx) {
      const float z = coarse[static_cast<std::size_t>(cy) * gx + cx];
      const Eigen::Vector2d center = plane.coarse_center(cx, cy);
      if (std::isnan(z) || (center - plane.base_W.head<2>()).norm() > kPriorRadiusM) continue;
      offsets.push_back(z - plane.through_base(center.x(), center.y()));
    }
  }
  if (!offsets.empty()) {
    const auto mid = offsets.begin() + static_cast<std::ptrdiff_t>(offsets.size() / 2);
    std::nth_element(offsets.begin(), mid, offsets.end());
    plane.offset = *mid;
  }
  return plane;
}

void grow_ground(const CostmapPass& pass, const GroundPlane& plane) {
  const auto& params = pass.params;
  auto& out = pass.out;
  const auto v = pass.v;
  const auto gx = pass.gx;
  const auto gy = pass.gy;
  const auto& coarse = out.coarse_ground;
  auto& filtered = out.coarse_filtered;
  filtered.assign(coarse.size(), kNoGround);
  // The seeds: cells near the vehicle on the plane of its wheels (within ground_tolerance_m +
  // max_ground_slope × distance). Then ground spreads from cell to neighbouring cell while
  // their heights differ by at most max_ground_step_m: grades, ramps, crowns and levels reached
  // by a slope are ground, however far they leave the vehicle's plane; a wing or a fuselage seen
  // with nothing under it, a truck roof, a dock's top are not reached. Far from the sensor the
  // beams' rings leave empty cells between them: the spread crosses up to kMaxGapCells of them,
  // carrying the height it had, and the next cell seen may lie a step plus kGapGrade per cell
  // crossed from it. Breadth first from the seeds in a fixed order: the same cells
  // for the same map.
  constexpr double kSeedRadiusM = 4.0;
  constexpr std::uint8_t kMaxGapCells = 8;
  // The grade the ground may keep across the empty cells it crosses: a ramp seen only where a
  // far sensor's rings fall (6–7 cells apart on a 9 % ramp going down 30 m off) is reached, the
  // road 1.2 m below a dock's edge across the 3 m the edge hides from a sensor 2 m up 5 m
  // before it is not (0.5 + 3 × 0.15 < 1.2), and is marked as the drop it is.
  constexpr double kGapGrade = 0.15;
  const auto gap_grade = static_cast<float>(kGapGrade * pass.g);  // layers per crossed cell
  const float tolerance = static_cast<float>(params.ground_tolerance_m / v);
  const float step = static_cast<float>(params.max_ground_step_m / v);
  auto& reach = out.coarse_reach;  // the height each cell was reached at, NaN: not yet
  auto& gap = out.coarse_gap;
  reach.assign(coarse.size(), kNoGround);
  gap.assign(coarse.size(), 0);
  auto& queue = out.level_cells;  // scratch here; fill_ground_gaps reuses it after
  queue.clear();
  queue.reserve(coarse.size());
  const auto seed_pass = [&](double radius_m) {
    for (int cy = 0; cy < gy; ++cy) {
      for (int cx = 0; cx < gx; ++cx) {
        const std::size_t i = static_cast<std::size_t>(cy) * gx + cx;
        const Eigen::Vector2d center = plane.coarse_center(cx, cy);
        const double d = (center - plane.base_W.head<2>()).norm();
        if (std::isnan(coarse[i]) || !std::isnan(reach[i]) || d > radius_m) continue;
        const auto allowed = static_cast<float>(tolerance + params.max_ground_slope * d / v);
        if (std::abs(coarse[i] - plane.layer(center.x(), center.y())) > allowed) continue;
        filtered[i] = reach[i] = coarse[i];
        queue.push_back(static_cast<std::uint32_t>(i));
      }
    }
  };
  seed_pass(kSeedRadiusM);
  // Nothing seen near the vehicle (a blind start): the cells on its plane within 20 m.
  if (queue.empty()) seed_pass(20.0);
  // Rings lie one beyond the other: a gap is crossed away from the vehicle only, so the spread
  // does not wander round through unseen cells (beyond the data's edge, along a drop's shadow)
  // and come back onto a level no ring joins.
  const auto outward = [&](int fx, int fy, int tx, int ty) {
    const Eigen::Vector2d base = plane.base_W.head<2>();
    return (plane.coarse_center(tx, ty) - base).squaredNorm() >
           (plane.coarse_center(fx, fy) - base).squaredNorm();
  };
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const std::size_t i = queue[head];
    const int cx = static_cast<int>(i % static_cast<std::size_t>(gx));
    const int cy = static_cast<int>(i / static_cast<std::size_t>(gx));
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const int ux = cx + dx, uy = cy + dy;
        if ((dx == 0 && dy == 0) || ux < 0 || uy < 0 || ux >= gx || uy >= gy) continue;
        const std::size_t u = static_cast<std::size_t>(uy) * gx + ux;
        if (!std::isnan(reach[u])) continue;
        if (std::isnan(coarse[u])) {  // empty: crossed, carrying this cell's height
          if (gap[i] >= kMaxGapCells || !outward(cx, cy, ux, uy)) continue;
          reach[u] = reach[i];
          gap[u] = static_cast<std::uint8_t>(gap[i] + 1);
          queue.push_back(static_cast<std::uint32_t>(u));
          continue;
        }
        // Across a gap the ground may have gone on at a grade of up to kGapGrade.
        if (gap[i] > 0 && !outward(cx, cy, ux, uy)) continue;
        if (std::abs(coarse[u] - reach[i]) > step + gap_grade * static_cast<float>(gap[i])) {
          continue;
        }
        filtered[u] = reach[u] = coarse[u];
        queue.push_back(static_cast<std::uint32_t>(u));
      }
    }
  }
}

void fill_ground_gaps(const CostmapPass& pass, const GroundPlane& plane) {
  auto& out = pass.out;
  const auto gx = pass.gx;
  const auto gy = pass.gy;
  auto& filtered = out.coarse_filtered;
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
      float& z = filtered[static_cast<std::size_t>(cy) * gx + cx];
      if (!std::isnan(z)) continue;  // what stays empty gets the vehicle's plane
      const Eigen::Vector2d center = plane.coarse_center(cx, cy);
      z = plane.layer(center.x(), center.y());
    }
  }
}

}  // namespace tarmac::core::costmap
