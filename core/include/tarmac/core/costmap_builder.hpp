#pragma once
/// @file The airside costmap: a height-filtered projection of the occupancy window that respects
/// the vehicle envelope, inflated in Nav2's cost convention, with virtual obstacle zones burned in.
///
/// Envelope rule: a cell blocks when an occupied voxel lies between (local ground + min obstacle
/// height) and (local ground + vehicle height + clearance). So a wing or a jet bridge above the
/// vehicle does not block, an object on the ground does. The filter decides marking only; free
/// space comes from the occupancy map's rays, which are never height-filtered.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "tarmac/core/distance_field.hpp"
#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::core {

/// What an unknown cell costs.
enum class UnknownCost : std::uint8_t {
  kUnknown,  ///< −1 in the OccupancyGrid (the planner decides)
  kLethal,   ///< 100 everywhere
  kFree,     ///< 0 (optimistic; for tests and open-apron demos only)
};

/// When a column without obstacle is free (else unknown). The column's envelope is its voxels
/// from its ground up to vehicle_height_m + clearance_m.
enum class FreeRule : std::uint8_t {
  /// Every voxel of the envelope observed (by a return, a ray through it, or a beam without
  /// return). Safe: an obstacle never seen (an overhang whose underside no ray touched) lies in
  /// voxels that stay unknown. Needs the beams without return (organised scans) where the
  /// envelope rises above the sensor and nothing above returns.
  kWholeEnvelope,
  /// Some voxel of the envelope observed: free space where only part of the envelope was seen
  /// (a wing above rays that passed under it reads free). For sensors that report no beams
  /// without return, with the risk stated in docs/mapping.md, "Safety argument".
  kAnyVoxel,
};

struct CostmapParams {
  /// Returns this far above the local ground surface mark an obstacle (sub-voxel: heights of the
  /// returns inside voxels are kept), so the brief's 10 cm debris blocks with margin.
  double min_obstacle_height_m = 0.08;
  double vehicle_height_m = 2.5;     ///< top of the vehicle above ground
  double clearance_m = 0.3;          ///< extra headroom above the vehicle
  double inscribed_radius_m = 1.0;   ///< cells within this of an obstacle are "inscribed" (99)
  double inflation_radius_m = 3.0;   ///< costs decay to 0 beyond this
  double cost_scaling_factor = 3.0;  ///< Nav2's exponential decay rate, 1/m
  double ground_cell_m = 1.0;        ///< horizontal size of a local ground estimate cell
  /// Ground spreads from the cells near the vehicle to neighbouring cells whose heights differ
  /// by at most this (grades, ramps, crowns, levels joined by a slope); a higher step (a dock,
  /// a truck roof, a wing with nothing seen under it) is not ground.
  double max_ground_step_m = 0.5;
  /// The seeds of that spread: cells within 4 m of the vehicle that lie within
  /// ground_tolerance_m + max_ground_slope · (horizontal distance) of the plane of its wheels.
  double max_ground_slope = 0.05;
  double ground_tolerance_m = 0.5;
  UnknownCost unknown_cost = UnknownCost::kUnknown;
  FreeRule free_rule = FreeRule::kWholeEnvelope;

  [[nodiscard]] Status validate() const;
};

/// A no-go polygon in the map frame (fleet operations: jet blast, engine intake, fuel spill).
struct VirtualZone {
  std::string id;
  std::vector<Eigen::Vector2d> polygon_W;  ///< vertices in order, map frame, m
  double min_z_m = -1e9;                   ///< z range in the map frame
  double max_z_m = 1e9;
  std::int64_t expiry_ns = 0;  ///< 0: never expires
  /// false: a no-go zone, every cell inside is lethal. true: a restricted area, only cells not
  /// observed (unknown) inside are lethal; observed free cells stay drivable.
  bool restricted = false;

  /// In force at stamp_ns: a polygon (3+ vertices), not expired.
  [[nodiscard]] bool active(std::int64_t stamp_ns) const {
    return polygon_W.size() >= 3 && (expiry_ns == 0 || expiry_ns > stamp_ns);
  }
};

/// Per-cell class before inflation.
enum class ColumnClass : std::uint8_t { kFree = 0, kObstacle = 1, kUnknown = 2, kVirtual = 3 };

/// Why a cell is an obstacle: the bits of CostmapLayers::obstacle_rule. The column's own rules
/// are tried in this order and only the first that fires is set (the later ones are not
/// evaluated); a confirmed low object and a peer's cell add theirs. For whoever asks why a cell
/// is lethal (tarmac-map's reports, docs/tools.md); the costs never read them.
namespace obstacle_rule {
/// An occupied voxel in the envelope, min_obstacle_height_m or more above the column's ground.
inline constexpr std::uint8_t kVoxel = 1;
/// The column falls away more than max_ground_step_m below its ground (a dock edge, a pit).
inline constexpr std::uint8_t kDrop = 2;
/// The latest returns of a voxel below the voxel rule's reach rise min_obstacle_height_m above
/// their own scan's ground next to them (OccupancyMap::ring_layer_rise_cm).
inline constexpr std::uint8_t kRise = 4;
/// A confirmed low object standing on the cell (debris kept across scans, low_objects.hpp).
inline constexpr std::uint8_t kLowObject = 8;
/// A peer's obstacle fused in where this vehicle's own cell was not one (docs/fleet.md).
inline constexpr std::uint8_t kPeer = 16;
}  // namespace obstacle_rule

/// Everything one costmap update produces (reused across cycles: no allocation after warm-up).
struct CostmapLayers {
  Costmap costmap;                    ///< 0..100, −1 unknown (OccupancyGrid values)
  Grid2D<float> ground_z_m;           ///< local ground height estimate per cell
  Grid2D<std::uint8_t> column_class;  ///< ColumnClass per cell
  /// Per cell, the obstacle_rule bits that made it an obstacle (0: none did). A virtual zone's
  /// cells are ColumnClass::kVirtual, whatever their bits say.
  std::vector<std::uint8_t> obstacle_rule;
  std::vector<CellState> esdf_input;  ///< obstacles (incl. virtual zones) for the 2D ESDF
  DistanceField obstacle_distance;    ///< exact 2D distance to the nearest obstacle cell
  DistanceFieldScratch scratch;
  std::vector<std::int16_t> lowest_occupied;  ///< per cell, window layer or −1
  std::vector<std::int16_t> lowest_observed;  ///< per cell, window layer or −1 (drops)
  std::vector<std::uint8_t>
      hovers;  ///< per cell: 1 when its candidate is the observed space under a hovering voxel
  std::vector<std::int16_t> ground_layer;  ///< per cell, window layer of the ground voxel
  std::vector<float> coarse_ground, coarse_filtered, coarse_next;  ///< ground estimate scratch
  std::vector<float> ground_offsets;  ///< coarse cells' offsets from the vehicle's plane
  /// The ground's spread: per coarse cell, the height it was reached at (NaN: not reached) and
  /// the empty cells crossed to reach it.
  std::vector<float> coarse_reach;
  std::vector<std::uint8_t> coarse_gap;
  /// Coarse gap cells ordered by fill level (level_cells[level_first[l] .. level_first[l + 1]])
  /// and the counting sort's cursor per level.
  std::vector<std::size_t> level_first, level_next;
  std::vector<std::uint32_t> level_cells;
  std::vector<std::uint8_t> any_known;     ///< per cell: envelope voxels observed (count)
  std::vector<std::uint8_t> any_obstacle;  ///< per cell: some envelope voxel is an obstacle
  /// Per cell in the occupancy window's ring (storage) order, bit z set when window layer z is
  /// occupied / observed (windows of <= 64 layers; layers 0..31 in the first cell-count words,
  /// 32..63 in the second).
  std::vector<std::uint32_t> occupied_bits, known_bits;
  std::vector<std::uint16_t> ground_scan;  ///< per cell: scan of those returns
  /// The column classes as this vehicle's own observations made them, before peers' cells and
  /// virtual zones (filled when build_costmap is given a CostmapPeers): what a fleet summary
  /// shares, never what it was told.
  std::vector<std::uint8_t> own_column_class;
};

/// Peers' bird's-eye cells to fuse into the column classes, before the virtual zones and the
/// inflation (fleet sharing, docs/fleet.md). Given, it also keeps the own classes
/// (CostmapLayers::own_column_class), peers or not.
struct CostmapPeers {
  const BevPeers* peers = nullptr;  ///< nullptr: none to fuse (yet)
  /// Each costmap cell's own last observation time, ns, row-major (OccupancyMap::
  /// export_column_observed); 0: never.
  std::span<const std::int64_t> own_observed_ns;
  std::int64_t now_ns = 0;
  BevFusionCounts counts;  ///< what the fusion did (set by build_costmap)
};

/// Builds the costmap of the occupancy window at the window's horizontal resolution.
/// @param T_W_B vehicle base pose: its xy plane is the ground prior (and the fallback ground
/// where nothing was seen), so tilted world frames work.
/// @param stamp_ns current time, for zone expiry only.
/// @param peers when given (and its `peers` set): the peers' cells fused into the classes.
void build_costmap(const OccupancyMap& map, const CostmapParams& params,
                   const Eigen::Isometry3d& T_W_B, std::span<const VirtualZone> zones,
                   std::int64_t stamp_ns, CostmapLayers& out, TaskRunner& runner,
                   CostmapPeers* peers = nullptr);

/// The index of the cell of `ground_z_m` (CostmapLayers::ground_z_m) whose column low object `o`
/// stands on (stands_on_ground, at the grid's resolution), or -1 when its centre lies outside
/// the grid or it does not stand on that cell's ground. Confirmed objects standing on their
/// cell's ground are what the costmap marks lethal, the 3D band occupied, and debris is made of.
std::int64_t standing_cell(const LowObject& o, const Grid2D<float>& ground_z_m);

/// Nav2 inflation cost (0..254 scale: 254 lethal, 253 inscribed) at a distance from an obstacle.
std::uint8_t nav2_cost(double distance_m, const CostmapParams& params);
/// Nav2's OccupancyGrid translation of a 0..254 cost: 0→0, 253→99, 254→100, 1..252→1..98.
std::int8_t to_occupancy_value(std::uint8_t nav2_cost);

/// The costmap without inflation, for a planner that inflates by its own footprint (Nav2's
/// StaticLayer + InflationLayer): lethal (100) and unknown (−1) cells as in `costmap`, every
/// other cell free (0). Which cells are lethal or unknown is decided by `build_costmap` alone
/// (obstacles, zones, the unknown policy), so both grids always agree on them. `out` takes
/// `costmap`'s geometry; allocates only when the size changes. RT-safe after warm-up.
void to_obstacle_grid(const Costmap& costmap, Costmap& out);

/// The 2D ESDF as an OccupancyGrid for display (rviz2's Map display, which shows no
/// DistanceMapSlice): 100 on obstacles, falling linearly to 0 at `range_m` and beyond, −1 where
/// the distance is unknown (NaN). `field` lies on `geometry`'s cells. For viewing only: the
/// exact distances and gradients are in the DistanceMapSlice. RT-safe after warm-up.
/// @pre range_m > 0
void to_distance_display(const DistanceField& field, const GridGeometry2D& geometry, double range_m,
                         Costmap& out);

/// True when the point lies inside the polygon (even-odd rule).
bool polygon_contains(std::span<const Eigen::Vector2d> polygon, const Eigen::Vector2d& p);

/// Calls fn(x, y) for every cell of `geometry` whose centre lies inside `polygon`, row by row.
/// Only the polygon's bounding box is visited, clamped in double first (a vertex may lie far
/// outside the int range of cell indices).
template <typename Fn>
void for_each_cell_inside(const GridGeometry2D& geometry, std::span<const Eigen::Vector2d> polygon,
                          Fn&& fn) {
  if (polygon.empty()) return;
  Eigen::Vector2d lo = polygon[0], hi = polygon[0];
  for (const auto& p : polygon) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double v = geometry.resolution_m;
  const int nx = static_cast<int>(geometry.width), ny = static_cast<int>(geometry.height);
  const int x0 = clamped_floor((lo.x() - geometry.origin_x_m) / v, 0, nx);
  const int x1 = clamped_floor((hi.x() - geometry.origin_x_m) / v, -1, nx - 1);
  const int y0 = clamped_floor((lo.y() - geometry.origin_y_m) / v, 0, ny);
  const int y1 = clamped_floor((hi.y() - geometry.origin_y_m) / v, -1, ny - 1);
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      if (polygon_contains(polygon, geometry.center_of(x, y))) fn(x, y);
    }
  }
}

}  // namespace tarmac::core
