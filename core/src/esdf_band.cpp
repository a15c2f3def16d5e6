#include "tarmac/core/esdf_band.hpp"

#include <algorithm>
#include <cmath>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

/// Rows of the window per state task: fixed, so the split does not depend on the runner.
constexpr std::size_t kRowTasks = 16;

}  // namespace

Status EsdfBandParams::validate() const {
  const auto bad = [](const char* key, const char* why) {
    return Status{Error{"config.range", std::string("esdf_band.") + key + ": " + why}};
  };
  if (!(below_m >= 0.0 && below_m <= 1000.0)) return bad("below_m", "must be in 0..1000");
  if (!(above_m > 0.0 && above_m <= 1000.0)) return bad("above_m", "must be in (0, 1000]");
  if (!(publish_radius_m >= 0.0 && publish_radius_m <= 10000.0)) {
    return bad("publish_radius_m", "must be in 0..10000");
  }
  return Ok{};
}

int esdf_band_max_layers(const EsdfBandParams& params, double voxel_size_m) {
  return static_cast<int>(std::ceil((params.below_m + params.above_m) / voxel_size_m - 1e-9)) + 1;
}

void esdf_band_layers(const OccupancyMap& map, const EsdfBandParams& params, double base_z_m,
                      int& z0, int& z1) {
  const double v = map.params().voxel_size_m;
  const int nz = map.window_size().z();
  const int wz = map.window_min().z();
  // 1e-9: a bound on a voxel boundary stays there despite rounding of base − below.
  const int first = static_cast<int>(std::floor((base_z_m - params.below_m) / v + 1e-9)) - wz;
  z0 = std::clamp(first, 0, nz);
  z1 = std::clamp(first + esdf_band_max_layers(params, v), z0, nz);
}

std::uint64_t esdf_band_obstacles(const EsdfBand& band) {
  return static_cast<std::uint64_t>(
      std::count(band.states.begin(), band.states.end(), CellState::kOccupied));
}

void build_esdf_band(const OccupancyMap& map, const CostmapLayers& layers,
                     const CostmapParams& costmap, const EsdfBandParams& params,
                     const Eigen::Isometry3d& T_W_B, std::span<const VirtualZone> zones,
                     std::int64_t stamp_ns, EsdfBand& out, TaskRunner& runner) {
  const Eigen::Vector3i wdims = map.window_size();
  const int nx = wdims.x(), ny = wdims.y();
  const double v = map.params().voxel_size_m;
  const VoxelIndex wmin = map.window_min();
  TARMAC_ASSERT(layers.ground_layer.size() == static_cast<std::size_t>(nx) * ny,
                "build_costmap must run on this window first");
  int z0 = 0, z1 = 0;
  esdf_band_layers(map, params, T_W_B.translation().z(), z0, z1);
  const int nb = z1 - z0;
  out.min = VoxelIndex(wmin.x(), wmin.y(), wmin.z() + z0);
  if (nb == 0) {
    out.field.dims = Eigen::Vector3i(nx, ny, 0);
    out.field.cell_size_m = v;
    out.field.distance_m.clear();
    out.field.gradient_x.clear();
    out.field.gradient_y.clear();
    out.field.gradient_z.clear();
    return;
  }
  const std::size_t plane = static_cast<std::size_t>(nx) * ny;
  out.states.resize(plane * static_cast<std::size_t>(nb));
  // A band clipped by the window edge is smaller; the first call reserves for the full one, so
  // the cycle does not allocate when the band comes back whole.
  const std::size_t full = plane * static_cast<std::size_t>(esdf_band_max_layers(params, v));
  for (auto* buffer : {&out.field.distance_m, &out.field.gradient_x, &out.field.gradient_y,
                       &out.field.gradient_z}) {
    buffer->reserve(full);
  }
  out.states.reserve(full);
  out.scratch.off.reserve(full);

  // The costmap's split of a column (costmap_builder.cpp, step 3): obstacles start lo_layers
  // above the ground voxel; the layers from the ground voxel up to there take the rise rule.
  const int lo_layers = 1 + static_cast<int>(std::ceil(costmap.min_obstacle_height_m / v - 1e-9));
  const auto min_rise_cm =
      static_cast<int>(std::ceil(costmap.min_obstacle_height_m * 100.0 - 1e-9));
  // One run of window cells whose ring slots are contiguous: branch-free, so it vectorises.
  const auto classify = [lo_layers, min_rise_cm](int z, int n, const float* __restrict lo,
                                                 const std::uint8_t* __restrict rise,
                                                 const std::int16_t* __restrict ground,
                                                 CellState* __restrict st) {
    for (int x = 0; x < n; ++x) {
      const float l = lo[x];
      const int above = z - ground[x];  // layers above the column's ground voxel
      // Bitwise, not logical, operators: no branches.
      const int occupied = static_cast<int>(above >= lo_layers) & static_cast<int>(l > 0.0f);
      const int low = static_cast<int>(above >= 0) & static_cast<int>(above < lo_layers) &
                      static_cast<int>(rise[x] >= min_rise_cm);
      const int obstacle = occupied | low;
      const int unknown = static_cast<int>(l == OccupancyMap::kUnknown) & (obstacle ^ 1);
      st[x] = static_cast<CellState>(obstacle | (unknown << 1));
    }
  };
  static_assert(static_cast<int>(CellState::kOccupied) == 1 &&
                static_cast<int>(CellState::kUnknown) == 2);
  // Window x maps to ring x = (min.x + x) mod nx: two contiguous runs per row.
  const int r0 = map.ring_x(0);
  const int split = nx - r0;  // window x where the ring wraps to slot 0
  runner.parallel_for(kRowTasks, [&](std::size_t task) {
    const int y0 = static_cast<int>(ny * task / kRowTasks);
    const int y1 = static_cast<int>(ny * (task + 1) / kRowTasks);
    for (int lz = 0; lz < nb; ++lz) {
      const int z = z0 + lz;
      const float* lo = map.ring_layer(z);
      const std::uint8_t* rise = map.ring_layer_rise_cm(z);
      for (int y = y0; y < y1; ++y) {
        const std::size_t ring_row = static_cast<std::size_t>(map.ring_y(y)) * nx;
        const std::size_t row = static_cast<std::size_t>(y) * nx;
        const std::int16_t* ground = layers.ground_layer.data() + row;
        CellState* st = out.states.data() + lz * plane + row;
        classify(z, split, lo + ring_row + r0, rise + ring_row + r0, ground, st);
        classify(z, nx - split, lo + ring_row, rise + ring_row, ground + split, st + split);
      }
    }
  });

  // Lethal low objects, as the costmap marks them (standing_cell): occupied from their
  // column's ground voxel up to the voxel of their top, so a 10 cm piece of debris the voxels
  // lost is in the band as it is in the slice.
  const LowObjects& objects = map.low_objects();
  for (const LowObject& o : objects.all()) {
    if (!objects.lethal(o)) continue;
    const std::int64_t c = standing_cell(o, layers.ground_z_m);
    if (c < 0) continue;
    const int top = static_cast<int>(std::floor(static_cast<double>(o.top_z_W) / v)) - wmin.z();
    const int lz0 = std::max(0, layers.ground_layer[static_cast<std::size_t>(c)] - z0);
    const int lz1 = std::min(nb - 1, top - z0);
    for (int lz = lz0; lz <= lz1; ++lz) {
      out.states[static_cast<std::size_t>(lz) * plane + static_cast<std::size_t>(c)] =
          CellState::kOccupied;
    }
  }

  // Virtual zones, in their order (each voxel's result does not depend on it: zones only add),
  // on the cells the costmap burns them into (its geometry is the window's).
  for (const auto& zone : zones) {
    if (!zone.active(stamp_ns)) continue;
    // Layers whose voxel [bottom, top) meets the zone's [min_z, max_z].
    // Clamped in double first: a zone spanning all heights may say ±1e9 m or ±inf.
    const int lz0 = clamped_floor(zone.min_z_m / v - out.min.z(), 0, nb);
    const int lz1 = clamped_floor(zone.max_z_m / v - out.min.z(), -1, nb - 1) + 1;
    if (lz0 >= lz1) continue;
    for_each_cell_inside(layers.costmap.geometry(), zone.polygon_W, [&](int x, int y) {
      for (int lz = lz0; lz < lz1; ++lz) {
        CellState& s = out.states[lz * plane + static_cast<std::size_t>(y) * nx + x];
        if (!zone.restricted || s == CellState::kUnknown) s = CellState::kOccupied;
      }
    });
  }

  compute_distance_field(out.states, Eigen::Vector3i(nx, ny, nb), v, params.unknown, out.field,
                         out.scratch, runner);
}

}  // namespace tarmac::core
