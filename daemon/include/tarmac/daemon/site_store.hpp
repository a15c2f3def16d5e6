#pragma once
/// @file The whole site of a paged TSDF, read-only (docs/mapping.md, "Site-scale maps"): the
/// tiles still in memory and those only in the tile store, each stored tile read back and
/// dropped in turn, so that the tools' products (mesh, .vdb export, change layer, digest) are
/// made within the pager's memory bound and equal those of the same map held whole. Reads
/// files; no thread of its own. Get one from TsdfPager::site() once the pager is flushed.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_changes.hpp"
#include "tarmac/core/tsdf_integrator.hpp"
#include "tarmac/core/tsdf_mesh.hpp"
#include "tarmac/core/tsdf_tiles.hpp"

namespace tarmac::daemon {

/// Where the stored tiles are and what lattice they were encoded for.
struct SiteStoreParams {
  std::filesystem::path dir;  ///< the tile store
  float voxel_size_m = 0.1f;
  float truncation_m = 0.3f;
  float occupancy_voxel_m = 0.2f;  ///< the static tiles' voxel
};

/// The tiles only in the store, in TileKey order and by (y, x) (the others are resident).
struct StoredTiles {
  std::vector<core::TileIndex> tsdf;
  std::vector<core::StaticTileIndex> statics;
};

class SiteStore {
 public:
  /// The site: `layer`'s resident tiles, `occupancy`'s static voxels (null: no static layer) and
  /// `stored`. `layer` and `occupancy` must outlive the store and not change while it is used.
  SiteStore(SiteStoreParams params, const core::TsdfLayer& layer, StoredTiles stored,
            const core::OccupancyMap* occupancy);

  /// Every block of the site, in TsdfLayer::for_each_block's order. False when a stored tile
  /// cannot be read (its blocks are then missing from the visit).
  bool for_each_block(const std::function<void(const core::TsdfBlockView&)>& fn) const;
  /// The site's mesh, tile by tile (core::extract_mesh of each tile, meshed with its 26
  /// neighbours present, so at most 27 tiles are in memory besides the layer): `piece` gets each
  /// tile's triangles, in site order; together they are the whole map's. Stops at the first
  /// error `piece` returns, or a tile that cannot be read.
  core::Status mesh(float min_weight,
                    const std::function<core::Status(const core::TriangleMesh&)>& piece) const;
  /// The site in parts for export: the tiles of each square of `region_tiles` × `region_tiles`
  /// tile columns (every height) in a layer of their own, handed to `part` with the square's
  /// index (tile x, y floor-divided by region_tiles), squares by (y, x). At most one part is in
  /// memory besides the layer; together the parts hold every block of the site once.
  core::Status export_parts(
      int region_tiles,
      const std::function<core::Status(const Eigen::Vector2i& region, const core::TsdfLayer& part)>&
          part) const;
  /// The change layer against a prior site held as a tile store (`prior_dir`: another run's
  /// tsdf_tiles, same voxel size and truncation), the same cells and counts core::detect_changes
  /// gives for the two maps held whole, delivered in strips so that neither map nor the raster
  /// is ever whole in memory: `begin` gets the raster's geometry (the union of both sites'
  /// blocks), then `strip(y0, rows, cells)` each band of up to one tile (128 rows; raster rows
  /// y0 .. y0 + rows - 1, row-major), from the top (north) down, every row once.
  core::Status changes(
      const std::filesystem::path& prior_dir, const core::ChangeParams& params,
      core::ChangeCounts& counts,
      const std::function<core::Status(const core::GridGeometry2D&)>& begin,
      const std::function<core::Status(int y0, int rows, std::span<const float> cells)>& strip)
      const;
  /// The site's static voxels (the map's and the stored tiles'), sorted by (z, y, x): what
  /// OccupancyMap::export_static gives of the same layer held whole. False when a stored tile
  /// cannot be read.
  bool static_voxels(std::vector<Eigen::Vector3i>& out) const;
  /// The site's digest: equal to TsdfLayer::digest() of the same map held whole.
  [[nodiscard]] std::uint64_t digest() const;

 private:
  /// Every tile of the site, resident (true) or stored (false), in TileKey order: OpenVDB's
  /// iteration order of the whole.
  using Tiles = std::map<core::TileKey, bool>;
  struct ChangeRaster;

  [[nodiscard]] Tiles tiles() const;
  core::Status for_each_tile_block(const core::TileIndex& t, bool resident,
                                   const std::function<void(const core::TsdfBlockView&)>& fn) const;
  [[nodiscard]] core::Result<core::TsdfTile> tile(const core::TileIndex& t, bool resident) const;
  core::Status mesh_tile(const Tiles& site, const core::TileIndex& t, float min_weight,
                         core::TriangleMesh& mesh) const;
  core::Status change_extent(const Tiles& site,
                             const std::map<core::TileKey, core::TileIndex>& prior,
                             const std::filesystem::path& prior_dir, ChangeRaster& raster) const;
  core::Status change_strip(const Tiles& site,
                            const std::map<core::TileKey, core::TileIndex>& prior,
                            const std::filesystem::path& prior_dir,
                            const core::ChangeParams& params, int ty, ChangeRaster& raster,
                            core::ChangeCounts& counts) const;

  SiteStoreParams params_;
  const core::TsdfLayer& layer_;
  StoredTiles stored_;
  const core::OccupancyMap* occupancy_;
};

}  // namespace tarmac::daemon
