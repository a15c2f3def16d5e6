#pragma once
/// @file The 3D ESDF band: the exact Euclidean distance field (with gradient) over the layers of
/// the occupancy window around the vehicle's height, for consumers that need distances in 3D
/// (a wing 0.5 m above the roof, a fuselage door beside a belt loader) rather than the 2D
/// projection the costmap and the ESDF slice give.
///
/// Obstacles follow the costmap's rules, voxel by voxel, so the band and the 2D slice agree:
///  - an occupied voxel at least min_obstacle_height above the top of its column's ground voxel
///    (CostmapLayers::ground_layer) is an obstacle, at any height in the band — above the
///    vehicle's envelope too (this is what the 2D projection cannot say);
///  - a voxel from the ground voxel up to that height is an obstacle when its latest returns rise
///    at least min_obstacle_height above their scan's ground (the 10 cm debris rule), and so are
///    the voxels from the ground voxel up to a confirmed low object's top where the costmap marks
///    it (standing_cell);
///  - the ground voxel and what lies below it are not obstacles (free when observed);
///  - unobserved voxels are unknown (UnknownPolicy: NaN distance, or obstacles);
///  - active virtual zones: every band voxel inside a no-go zone's polygon and z range is an
///    obstacle; inside a restricted zone, only the unknown ones.

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/distance_field.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::core {

struct EsdfBandParams {
  bool enabled = false;  ///< the daemon and tarmac-map compute the band every cycle / scan
  /// The band starts at the voxel holding world z = base − below_m (base = the vehicle base
  /// pose's z) and has esdf_band_max_layers() layers, so it covers [base − below_m, base +
  /// above_m) whatever the base's height; clipped to the window.
  double below_m = 0.2;
  double above_m = 3.0;  ///< default: vehicle height 2.5 + clearance 0.3 + one 0.2 m voxel
  UnknownPolicy unknown = UnknownPolicy::kReportUnknown;
  /// What the daemon publishes of the band: the voxels within this of the vehicle in x and y
  /// (a box; 0: the whole window's band). The band itself always covers the window, so the
  /// distances in the box are exact to obstacles anywhere in the window.
  double publish_radius_m = 10.0;

  [[nodiscard]] Status validate() const;
};

/// One band (reused across cycles: no allocation after the first call with a given size).
struct EsdfBand {
  /// dims (window x, window y, band layers); x fastest; cell (0,0,0) is voxel `min`.
  DistanceField field;
  VoxelIndex min{0, 0, 0};  ///< world voxel index of the band's first cell
  /// Per voxel, what the transform saw (virtual zones included), in the field's order.
  std::vector<CellState> states;
  DistanceFieldScratch scratch;
};

/// Layers of the band: ceil((below_m + above_m) / voxel) + 1, the most [base − below_m,
/// base + above_m) can meet, whatever the base's height, so the band's shape is fixed (unless
/// clipped by the window).
int esdf_band_max_layers(const EsdfBandParams& params, double voxel_size_m);

/// Window layers [z0, z1) of the band for a vehicle base at world height base_z_m (empty when
/// the band misses the window).
void esdf_band_layers(const OccupancyMap& map, const EsdfBandParams& params, double base_z_m,
                      int& z0, int& z1);

/// Obstacle voxels of the band (virtual zones included): a pass over its states, for tools and
/// tests, kept out of the cycle.
std::uint64_t esdf_band_obstacles(const EsdfBand& band);

/// Computes the band from the window and the costmap built from it in the same cycle
/// (build_costmap: its ground_layer). Deterministic for any runner. Leaves `out.field` with zero
/// layers when the band misses the window.
void build_esdf_band(const OccupancyMap& map, const CostmapLayers& layers,
                     const CostmapParams& costmap, const EsdfBandParams& params,
                     const Eigen::Isometry3d& T_W_B, std::span<const VirtualZone> zones,
                     std::int64_t stamp_ns, EsdfBand& out, TaskRunner& runner);

}  // namespace tarmac::core
