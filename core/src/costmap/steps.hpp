#pragma once
/// @file build_costmap's steps (internal to core/src/costmap and costmap_builder.cpp), in the
/// order it runs them: the lowest occupied voxel per column; per coarse ground cell the lowest
/// of those; the vehicle's ground plane; coarse cells that cannot be ground rejected; gaps
/// filled; every column classified against the vehicle's envelope (obstacle, free, unknown);
/// virtual zones; the 2D distance field and Nav2's inflated costs.

#include <cstddef>
#include <cstdint>
#include <limits>

#include <Eigen/Geometry>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::core::costmap {

/// Rows (or cells) of the window split into this many tasks, in fixed ranges.
constexpr std::size_t kRowTasks = 16;
constexpr float kNoGround = std::numeric_limits<float>::quiet_NaN();

/// One build_costmap call: what every step reads. The steps write `out` only.
struct CostmapPass {
  const OccupancyMap& map;
  const CostmapParams& params;
  CostmapLayers& out;
  TaskRunner& runner;
  double v;  ///< voxel size, m
  int nx, ny, nz;
  VoxelIndex wmin;  ///< the window's lowest voxel
  GridGeometry2D geometry;
  std::size_t cells_n;  ///< columns (nx · ny)
  /// Windows of at most 64 layers: one pass over all layers builds per-column bit sets of the
  /// occupied and the observed layers; the lowest occupied layer and the envelope tests are then
  /// bit operations per column. Taller windows scan the layers (same results).
  bool use_bits;
  int g;       ///< columns per coarse ground cell, per axis
  int gx, gy;  ///< coarse ground cells
};

/// The vehicle's ground plane: through its base, normal to its z axis, raised by the median
/// offset of the coarse ground cells near it (the world frame need not be gravity-aligned).
struct GroundPlane {
  const CostmapPass& pass;
  Eigen::Vector3d base_W, up_W;
  double up_z;  ///< up_W.z(), at least 0.1: a vehicle on its side has no ground plane
  float offset = 0.0f;

  /// The map-frame centre of coarse cell (cx, cy).
  [[nodiscard]] Eigen::Vector2d coarse_center(int cx, int cy) const {
    return Eigen::Vector2d((pass.wmin.x() + (cx + 0.5) * pass.g) * pass.v,
                           (pass.wmin.y() + (cy + 0.5) * pass.g) * pass.v);
  }
  /// Height of the plane through the base at (x, y), in window layers.
  [[nodiscard]] float through_base(double x_m, double y_m) const {
    const double z_m =
        base_W.z() - (up_W.x() * (x_m - base_W.x()) + up_W.y() * (y_m - base_W.y())) / up_z;
    return static_cast<float>(z_m / pass.v - pass.wmin.z());
  }
  /// Expected ground layer (window layers, voxel bottom) at a map-frame (x, y).
  [[nodiscard]] float layer(double x_m, double y_m) const {
    return std::floor(through_base(x_m, y_m) + offset);
  }
};

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

/// 1. Per column, its ground candidate: out.lowest_occupied (and the layer bit sets).
void find_ground_candidates(const CostmapPass& pass);
/// 2. Per coarse ground cell, a low order statistic of its columns' candidates:
///    out.coarse_ground.
void find_coarse_ground(const CostmapPass& pass);
/// 3. The vehicle's ground plane, its offset the median over the coarse cells near the base.
GroundPlane fit_ground_plane(const CostmapPass& pass, const Eigen::Isometry3d& T_W_B);
/// 4. The coarse cells joined to the vehicle's own by steps of at most max_ground_step_m:
///    out.coarse_filtered (the others empty).
void grow_ground(const CostmapPass& pass, const GroundPlane& plane);
/// 5. Rejected and empty coarse cells filled from their neighbours, then from the plane.
void fill_ground_gaps(const CostmapPass& pass, const GroundPlane& plane);
/// 6. Every column's ground and class against the vehicle's envelope: out.ground_layer,
///    out.ground_z_m, out.column_class, out.esdf_input, out.obstacle_rule.
void classify_columns(const CostmapPass& pass);
/// 6b. The occupancy map's lethal low objects (debris kept across scans) block their cells,
/// whatever the voxels say (low_objects.hpp).
void mark_low_objects(const CostmapPass& pass);
/// 6b. Peers' cells where this vehicle's are unknown or older (BevPeers::fuse, the fleet's
///     rules): out.column_class and out.esdf_input of the cells they fill.
void fuse_peers(const CostmapPass& pass, CostmapPeers& peers);

}  // namespace tarmac::core::costmap
