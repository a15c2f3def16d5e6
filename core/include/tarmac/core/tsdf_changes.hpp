#pragma once
/// @file Change detection between a prior TSDF (e.g. last week's static map) and the current
/// one, for map maintenance: surfaces that appeared (new obstacles) and surfaces that vanished
/// (removed obstacles), with a confidence, projected to a 2D layer.
///
/// Per voxel observed in both maps (weight >= min_weight in each): a voxel is on a surface when
/// |d| <= surface_band_m, clearly off any surface when |d| >= off_surface_m. New: on a surface
/// now, clearly off before. Removed: on a surface before, clearly off now. Voxels seen in only
/// one map are not compared: unknown stays unknown. Confidence = min(w_prior, w_now) /
/// confident_weight, capped at 1.
///
/// @warning Without space carving a map observes only the band around its returns, so a removed
/// object is confirmed only where some other return's band covers the place it occupied (its
/// footprint on the ground, a wall behind it). Build the maps with tsdf.space_carving for
/// complete removal evidence.

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

struct ChangeParams {
  float min_weight = 2.0f;         ///< a voxel counts as observed from this weight on
  float confident_weight = 16.0f;  ///< weight of full confidence (1.0)
  float surface_band_m = 0.05f;    ///< |d| at most this: on a surface (half a 0.1 m voxel)
  float off_surface_m = 0.15f;     ///< |d| at least this: clearly not on a surface
  /// Only voxels whose centre lies in [min_z_m, max_z_m] (world frame) are compared.
  double min_z_m = -std::numeric_limits<double>::infinity();
  double max_z_m = std::numeric_limits<double>::infinity();

  [[nodiscard]] Status validate() const;
};

/// The 2D change layer at the maps' voxel size. Per column:
/// +c new surface with confidence c in (0, 1], −c removed surface, 0 compared and unchanged,
/// NaN no voxel of the column observed in both maps. Where a column holds both, the larger
/// confidence wins (new on a tie).
struct ChangeMap {
  GridGeometry2D geometry;
  std::vector<float> change;  ///< row-major, geometry.width × geometry.height
  std::uint64_t compared_voxels = 0;
  std::uint64_t new_voxels = 0;
  std::uint64_t removed_voxels = 0;
};

/// Counts of a comparison (ChangeMap's).
struct ChangeCounts {
  std::uint64_t compared_voxels = 0;
  std::uint64_t new_voxels = 0;
  std::uint64_t removed_voxels = 0;
};

/// Compares one block of the current map with the prior's block of the same index into
/// `raster`: row-major, `width` columns, its cell (0, 0) the voxel column `origin` (x, y); the
/// block's columns must lie in it. The same rules as detect_changes, which calls it per block:
/// a map held in tiles is compared block by block into strips of the raster
/// (daemon::SiteStore::changes). `params` must be valid.
void compare_blocks(const TsdfBlockView& prior, const TsdfBlockView& current,
                    const ChangeParams& params, double voxel_size_m, const Eigen::Vector2i& origin,
                    std::uint32_t width, std::span<float> raster, ChangeCounts& counts);

/// Compares `prior` and `current` over the union of their blocks' x/y extent.
/// Errors: "tsdf_changes.mismatch" (different voxel sizes), "tsdf_changes.invalid".
Status detect_changes(const TsdfLayer& prior, const TsdfLayer& current, const ChangeParams& params,
                      ChangeMap& out);

}  // namespace tarmac::core
