#pragma once
/// @file Bounded resident memory for the site-wide TSDF (`tsdf.resident_limit_mb`): tiles
/// (core/tsdf_tiles.hpp) far from the vehicle leave the layer and go to a tile store on disk,
/// and come back as the vehicle nears them. Which tiles leave and which are asked back is decided
/// between scans, from the vehicle's position and the map alone (deterministic); the disk work
/// (encode and write, read and decode) runs on a background thread of its own, never in a scan.
///
/// Rules (docs/mapping.md, "Site-scale maps"):
///  - a scan can touch tiles within `need_radius_m` of its sensor (x, y): tsdf.max_range_m plus
///    the truncation; tiles on disk within `load_radius_m` (one tile further) are asked back;
///  - over the limit, tiles are evicted farthest first, never one within load_radius_m nor one a
///    scan of the last `keep_scans` touched; down to 90 % of the limit. A tile loaded and not
///    changed since is dropped without a write;
///  - a tile still loading is absent: the integrator refuses to build blocks there (counted), so
///    nothing in memory ever shadows a stored tile. `wait_for_loads` (tarmac-map) makes each scan
///    wait for the tiles it can touch instead: the map is then bit for bit the unlimited one;
///    tarmacd never waits, and a load later than the vehicle counts in `loads_late`;
///  - a failed write puts the tile back in memory (counted; eviction stops: the disk is not to be
///    trusted); a tile that fails to load is renamed `.refused`, counted, and its ground is mapped
///    afresh.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_changes.hpp"
#include "tarmac/core/tsdf_integrator.hpp"
#include "tarmac/core/tsdf_mesh.hpp"
#include "tarmac/core/tsdf_tiles.hpp"

namespace tarmac::daemon {

struct TsdfPagerParams {
  std::size_t limit_bytes = 0;  ///< resident tiles above this are evicted (> 0)
  std::filesystem::path dir;    ///< the tile store: one file per tile
  float voxel_size_m = 0.1f;
  float truncation_m = 0.3f;
  double need_radius_m = 50.3;     ///< tiles a scan can touch: within this of the sensor (x, y)
  double load_radius_m = 63.1;     ///< tiles on disk within this are asked back (>= need_radius_m)
  std::size_t keep_scans = 52;     ///< tiles touched by the last this many scans stay
  bool wait_for_loads = false;     ///< a scan waits for the tiles it can touch (tarmac-map)
  bool resume = true;              ///< false: tiles left in `dir` by an earlier run are removed
  float occupancy_voxel_m = 0.2f;  ///< the occupancy's voxel: static tiles are written for it

  /// For a mapper: need and load radius from the TSDF's max range and truncation; keep_scans
  /// covers the scans retained for a pose-correction rebuild (it erases their blocks).
  static TsdfPagerParams for_mapper(const core::MapperParams& mapping, std::filesystem::path dir);
};

struct TsdfPagerStats {
  std::size_t resident_bytes = 0;  ///< TsdfLayer::resident_bytes() after the last scan
  std::size_t peak_resident_bytes = 0;
  std::size_t resident_tiles = 0;
  std::size_t stored_tiles = 0;  ///< tiles with a file in the store
  std::uint64_t stored_bytes = 0;
  std::uint64_t evicted = 0;       ///< tiles taken out of memory
  std::uint64_t written = 0;       ///< tile files written
  std::uint64_t loaded = 0;        ///< tiles read back
  std::uint64_t loads_late = 0;    ///< scans that met a tile they could touch still on disk
  std::uint64_t over_limit = 0;    ///< scans left above the limit (all else in the working set)
  std::uint64_t write_errors = 0;  ///< writes that failed (the tile stayed in memory)
  std::uint64_t load_errors = 0;   ///< tiles refused on reading (renamed .refused)
  std::size_t io_queued = 0;       ///< writes and reads not done yet
  // The occupancy's static layer (paged when open() was given the map).
  std::size_t static_resident_bytes = 0;   ///< OccupancyMap::static_bytes()
  std::size_t static_resident_voxels = 0;  ///< its voxels in memory
  std::size_t static_tiles_stored = 0;     ///< static tiles with a file in the store
  std::uint64_t static_stored_bytes = 0;
  std::uint64_t static_evicted = 0;  ///< static tiles taken out of memory
  std::uint64_t static_written = 0;
  std::uint64_t static_loaded = 0;
};

class TsdfPager {
 public:
  /// Opens (creates) the tile store; with `resume`, its tiles are marked absent in `layer` and
  /// come back as the vehicle nears them. With `occupancy`, the static layer of that map is paged
  /// too, in column tiles of core::kStaticTileEdge voxels (x, y): a tile leaves the map beyond
  /// two tiles of the window and is asked back within one, and a scan waits for (or, when it
  /// may not wait, counts late in `loads_late`) those the window covers. `layer` and
  /// `occupancy` must outlive the pager.
  static core::Result<std::unique_ptr<TsdfPager>> open(const TsdfPagerParams& params,
                                                       core::TsdfLayer& layer,
                                                       core::OccupancyMap* occupancy = nullptr);
  ~TsdfPager();
  TsdfPager(const TsdfPager&) = delete;
  TsdfPager& operator=(const TsdfPager&) = delete;

  /// Before a scan's TSDF integration: takes the tiles the worker has read back, asks back the
  /// tiles on disk within the load radius, and (wait_for_loads) waits for those within the need
  /// radius.
  void before_scan(core::TsdfLayer& layer, const Eigen::Vector3d& sensor_W);
  /// The same for a pose-correction rebuild step: the tiles around every retained scan it will
  /// re-integrate (Mapper::rebuild_sensors).
  void before_rebuild(core::TsdfLayer& layer, std::span<const Eigen::Vector3d> sensors_W);
  /// After it: the tiles it changed are marked, then eviction down to the limit, unless `hold`
  /// (a pose-correction rebuild is running: it erases and rewrites the retained scans' blocks,
  /// wherever their corrected poses put them).
  void after_scan(core::TsdfLayer& layer, const Eigen::Vector3d& sensor_W, bool hold = false);
  /// Before a scan's occupancy integration, which places the window at `base_W`: asks back the
  /// static tiles within one tile of that window and (wait_for_loads) waits for those it covers.
  void before_occupancy(core::TsdfLayer& layer, const Eigen::Vector3d& base_W);
  /// After it: static tiles beyond two tiles of the window leave the map.
  void after_occupancy();
  /// The map's static layer was replaced (a pose-correction rebuild completed: the layer is the
  /// one re-derived from the retained scans): the stored static tiles are of the old one, and
  /// are removed.
  void occupancy_replaced();
  /// Waits until the worker has done every queued write and read (and takes the reads back).
  void flush(core::TsdfLayer& layer);
  /// Hands a copy of every resident tile changed since it was last stored to the worker (the
  /// layer keeps the tiles; the copies cost their memory until written); returns the copies.
  /// Between ticks: tarmacd's periodic save.
  std::size_t store_changed(core::TsdfLayer& layer);
  /// store_changed, then waits: the store alone is then the whole map (the save on exit).
  core::Status store_all(core::TsdfLayer& layer);

  /// Every block of the site (resident tiles and stored ones, each read and dropped in turn), in
  /// TsdfLayer::for_each_block's order; call flush() first. False when a stored tile cannot be
  /// read (its blocks are then missing from the visit).
  bool for_each_site_block(const core::TsdfLayer& layer,
                           const std::function<void(const core::TsdfBlockView&)>& fn) const;
  /// The site's mesh, tile by tile (core::extract_mesh of each tile, meshed with its 26
  /// neighbours present, read back from the store when away, so at most 27 tiles are in memory
  /// besides the layer): `piece` gets each tile's triangles, in site order; together they are the
  /// whole map's. Stops at the first error `piece` returns, or a tile that cannot be read.
  core::Status mesh_site(const core::TsdfLayer& layer, float min_weight,
                         const std::function<core::Status(const core::TriangleMesh&)>& piece) const;
  /// The site in parts for export: the tiles of each square of `region_tiles` × `region_tiles`
  /// tile columns (every height), copied or read back into a layer of their own, handed to
  /// `part` with the square's index (tile x, y floor-divided by region_tiles), squares by (y, x).
  /// At most one part is in memory besides the layer. Together the parts hold every block of the
  /// site once. Call flush() first.
  core::Status export_site(
      const core::TsdfLayer& layer, int region_tiles,
      const std::function<core::Status(const Eigen::Vector2i& region, const core::TsdfLayer& part)>&
          part) const;
  /// The change layer against a prior site held as a tile store (`prior_dir`: another run's
  /// tsdf_tiles, same voxel size and truncation), the same cells and counts core::detect_changes
  /// gives for the two maps held whole, delivered in strips so that neither map nor the raster is
  /// ever whole in memory: `begin` gets the raster's geometry (the union of both sites' blocks),
  /// then `strip(y0, rows, cells)` each band of up to one tile (128 rows; raster rows y0 ..
  /// y0 + rows - 1, row-major), from the top (north) down, every row once. Call flush() first.
  core::Status changes_site(
      const core::TsdfLayer& layer, const std::filesystem::path& prior_dir,
      const core::ChangeParams& params, core::ChangeCounts& counts,
      const std::function<core::Status(const core::GridGeometry2D&)>& begin,
      const std::function<core::Status(int y0, int rows, std::span<const float> cells)>& strip)
      const;
  /// The site's static voxels (the map's and the stored tiles'), sorted by (z, y, x): what
  /// OccupancyMap::export_static gives of the same layer held whole. Call flush() first. False
  /// when a stored tile cannot be read.
  bool static_site_voxels(std::vector<Eigen::Vector3i>& out) const;
  /// The site's digest: equal to TsdfLayer::digest() of the same map held whole.
  [[nodiscard]] std::uint64_t site_digest(const core::TsdfLayer& layer) const;

  [[nodiscard]] TsdfPagerStats stats() const;
  [[nodiscard]] const TsdfPagerParams& params() const { return params_; }

 private:
  struct Impl;
  explicit TsdfPager(const TsdfPagerParams& params);
  TsdfPagerParams params_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::daemon
