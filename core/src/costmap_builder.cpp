#include "tarmac/core/costmap_builder.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include "costmap/steps.hpp"

namespace tarmac::core {

namespace {

using costmap::CostmapPass;
using costmap::kRowTasks;

/// 7. Virtual zones: active, and their z range meets the vehicle's envelope at that cell.
void add_virtual_zones(const CostmapPass& pass, std::span<const VirtualZone> zones,
                       std::int64_t stamp_ns) {
  const auto& params = pass.params;
  auto& out = pass.out;
  const auto nx = pass.nx;
  const auto& geometry = pass.geometry;
  const double hi_m = params.vehicle_height_m + params.clearance_m;
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
}

/// 8. Exact distance to the nearest obstacle cell (esdf_input was set with the classes), then
///    Nav2 inflation.
void inflate(const CostmapPass& pass) {
  const auto& params = pass.params;
  auto& out = pass.out;
  auto& runner = pass.runner;
  const auto v = pass.v;
  const auto nx = pass.nx;
  const auto ny = pass.ny;
  const auto cells_n = pass.cells_n;
  const auto& classes = out.column_class.cells();
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

std::int64_t standing_cell(const LowObject& o, const Grid2D<float>& ground_z_m) {
  const GridGeometry2D& g = ground_z_m.geometry();
  const auto c = g.cell_of(o.xy_W.x(), o.xy_W.y());
  if (!c) return -1;
  const std::int64_t i = static_cast<std::int64_t>(c->y()) * g.width + c->x();
  const auto ground = static_cast<double>(ground_z_m.cells()[static_cast<std::size_t>(i)]);
  return stands_on_ground(o, ground, g.resolution_m) ? i : -1;
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
                   std::int64_t stamp_ns, CostmapLayers& out, TaskRunner& runner,
                   CostmapPeers* peers) {
  using namespace costmap;  // NOLINT(google-build-using-namespace): the steps, in order
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
  const int g = std::max(1, static_cast<int>(std::lround(params.ground_cell_m / v)));
  const CostmapPass pass{map,
                         params,
                         out,
                         runner,
                         v,
                         nx,
                         ny,
                         nz,
                         wmin,
                         geometry,
                         geometry.cell_count(),
                         nz <= 64,
                         g,
                         (nx + g - 1) / g,
                         (ny + g - 1) / g};
  find_ground_candidates(pass);
  find_coarse_ground(pass);
  const GroundPlane plane = fit_ground_plane(pass, T_W_B);
  grow_ground(pass, plane);
  fill_ground_gaps(pass, plane);
  classify_columns(pass);
  mark_low_objects(pass);
  if (peers != nullptr) {
    out.own_column_class.assign(out.column_class.cells().begin(), out.column_class.cells().end());
    if (peers->peers != nullptr) fuse_peers(pass, *peers);
  }
  add_virtual_zones(pass, zones, stamp_ns);
  inflate(pass);
}

}  // namespace tarmac::core
