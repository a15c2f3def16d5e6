#pragma once
/// @file Bounded resident memory for the site-wide TSDF (`tsdf.resident_limit_mb`): tiles
/// (core/tsdf_tiles.hpp) far from the vehicle leave the layer and go to a tile store on disk,
/// and come back as the vehicle nears them; the occupancy's static layer likewise, in column
/// tiles. The pager carries out core::TsdfResidency's and core::StaticResidency's decisions
/// (core/tile_residency.hpp: which tiles leave and which are asked back, from the vehicle's
/// position and the map alone) between a scan's stages, hands the disk work (encode and write,
/// read and decode) to a thread of its own (tile_io), and gives the whole site to the tools
/// through a read-only SiteStore (site_store.hpp).
///
/// Beyond the policy (docs/mapping.md, "Site-scale maps"):
///  - a tile still loading is absent: the integrator refuses to build blocks there (counted), so
///    nothing in memory ever shadows a stored tile. `wait_for_loads` (tarmac-map) makes each
///    stage wait for the tiles it can touch instead: the map is then bit for bit the unlimited
///    one; tarmacd never waits, and a load later than the vehicle counts in `loads_late`;
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
#include "tarmac/core/tile_residency.hpp"
#include "tarmac/core/tsdf_integrator.hpp"
#include "tarmac/daemon/site_store.hpp"

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
  /// The policy's part.
  [[nodiscard]] core::TileResidencyParams residency() const;
  /// The tile store's part.
  [[nodiscard]] SiteStoreParams store() const;
};

/// A stage of Cycle::scan, as the pager's residency step sees it.
enum class ScanStage {
  kOccupancy,  ///< occupancy integration: places the window at the vehicle base
  kTsdf,       ///< TSDF integration of the scan
  kRebuild,    ///< a pose-correction rebuild step: re-integrates retained scans
  kEnd,        ///< none: the scan's stages are done
};

/// What TsdfPager::step needs to know of the stage about to run and of the map now.
struct ResidencyStep {
  ScanStage next = ScanStage::kEnd;
  /// kOccupancy: the vehicle base; kTsdf: the sensor; kRebuild: the sensor of every retained
  /// scan the step re-integrates (Mapper::rebuild_sensors). World frame.
  std::span<const Eigen::Vector3d> at_W;
  bool rebuilding = false;         ///< Mapper::rebuilding(): holds the TSDF's eviction
  bool rebuild_completed = false;  ///< the rebuild step just run completed
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

  /// One residency step, before each stage of a scan and once after its last (kEnd). It first
  /// settles what the stage before did: after the occupancy, the static tiles beyond two tiles
  /// of the window leave the map; after the TSDF, the tiles it changed are marked and the layer
  /// is evicted down to the limit, unless `rebuilding` (a pose-correction rebuild erases and
  /// rewrites the retained scans' blocks, wherever their corrected poses put them); after a
  /// rebuild step that completed, the stored static tiles, of the layer it replaced, are
  /// removed. Then it takes the tiles the worker has read back and asks back what the next stage
  /// can touch: the static tiles within one tile of the window it places (occupancy), the tiles
  /// within the load radius of its sensors (TSDF, rebuild), and (wait_for_loads) waits for
  /// those it covers, or counts them late.
  void step(core::TsdfLayer& layer, const ResidencyStep& step);
  /// Waits until the worker has done every queued write and read (and takes the reads back).
  void flush(core::TsdfLayer& layer);
  /// Hands a copy of every resident tile changed since it was last stored to the worker (the
  /// layer keeps the tiles; the copies cost their memory until written); returns the copies.
  /// Between ticks: tarmacd's periodic save.
  std::size_t store_changed(core::TsdfLayer& layer);
  /// store_changed, then waits: the store alone is then the whole map (the save on exit).
  core::Status store_all(core::TsdfLayer& layer);

  /// The whole site, read-only, for products and digests: the layer's tiles, the map's static
  /// voxels and the stored tiles. Call flush() first; valid while the layer, the map and the
  /// pager's store are left as they are.
  [[nodiscard]] SiteStore site(const core::TsdfLayer& layer) const;

  [[nodiscard]] TsdfPagerStats stats() const;
  [[nodiscard]] const TsdfPagerParams& params() const { return params_; }

 private:
  struct Impl;
  TsdfPager(const TsdfPagerParams& params, core::OccupancyMap* occupancy);
  /// The tiles an earlier run left in the store: taken (absent from `layer`) with `resume`,
  /// removed without.
  core::Status take_stored_tiles(core::TsdfLayer& layer);
  TsdfPagerParams params_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::daemon
