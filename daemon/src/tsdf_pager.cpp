// TsdfPager (tsdf_pager.hpp): core's residency decisions carried out between a scan's stages,
// with the disk work handed to the tile store's thread (tile_io.hpp).

#include "tarmac/daemon/tsdf_pager.hpp"

#include <algorithm>
#include <deque>
#include <optional>
#include <utility>

#include "tarmac/core/assert.hpp"
#include "tile_files.hpp"
#include "tile_io.hpp"

namespace tarmac::daemon {

namespace {

using core::TileIndex;
using core::TsdfTile;

TileFiles tile_files(const TsdfPagerParams& p) {
  return TileFiles{p.dir, p.voxel_size_m, p.truncation_m, p.occupancy_voxel_m};
}

TileWork tsdf_write(const TileIndex& t, std::uint64_t version, std::optional<TsdfTile> data,
                    bool copy) {
  TileWork w;
  w.kind = TileWork::Kind::kWriteTsdf;
  w.copy = copy;
  w.tile = t;
  w.version = version;
  w.data = std::move(data);
  return w;
}

TileWork tsdf_read(const TileIndex& t) {
  TileWork w;
  w.kind = TileWork::Kind::kReadTsdf;
  w.tile = t;
  return w;
}

TileWork static_work(TileWork::Kind kind, core::StaticTile tile, bool copy,
                     std::uint64_t generation) {
  TileWork w;
  w.kind = kind;
  w.copy = copy;
  w.static_data = std::move(tile);
  w.generation = generation;
  return w;
}

}  // namespace

struct TsdfPager::Impl {
  Impl(const TsdfPagerParams& p, core::OccupancyMap* occupancy)
      : params(p), tiles(p.residency()), map(occupancy), io(tile_files(p)) {}

  const TsdfPagerParams params;
  core::TsdfResidency tiles;
  core::StaticResidency statics;
  core::OccupancyMap* map;  // null: the static layer is not paged
  TsdfPagerStats stats;     // the counts kept here (the rest comes from the residency)
  bool evict_stopped = false;
  ScanStage last = ScanStage::kEnd;        // the stage the next step settles
  Eigen::Vector3d tsdf_sensor_W{0, 0, 0};  // of the last TSDF stage
  // Reused between scans (no allocation once grown).
  std::vector<TileIndex> touched, reads;
  std::vector<core::TsdfTileInfo> resident;
  std::vector<core::TileEviction> evictions;
  std::vector<core::TileCopy> copies;
  std::vector<core::StaticTileIndex> static_resident, static_reads, leaving;
  std::vector<Eigen::Vector3i> voxels;
  std::deque<TileWork> finished;
  TileIo io;  // last: its thread finishes the queued writes before the rest goes

  void settle(core::TsdfLayer& layer, const ResidencyStep& step);
  void prepare(core::TsdfLayer& layer, const ResidencyStep& step);
  void prepare_occupancy(core::TsdfLayer& layer, const Eigen::Vector3d& base_W);
  void prepare_tsdf(core::TsdfLayer& layer, std::span<const Eigen::Vector3d> sensors_W);
  void evict(core::TsdfLayer& layer, bool hold);
  void evict_static();
  void replace_statics();
  std::size_t store_static_copies();
  void submit_static(TileWork::Kind kind, const core::StaticTileIndex& t,
                     std::vector<Eigen::Vector3i> voxels, bool copy);
  void poll(core::TsdfLayer& layer);
  void collect(core::TsdfLayer& layer);
  void collect_tsdf(core::TsdfLayer& layer, TileWork& w);
  void collect_static(TileWork& w);
  /// Blocks until `ready` holds, taking back what the worker finishes meanwhile.
  template <typename Pred>
  void wait_until(core::TsdfLayer& layer, Pred ready);
};

// ---------------------------------------------------------------------------------------------
// The residency step

void TsdfPager::Impl::settle(core::TsdfLayer& layer, const ResidencyStep& step) {
  switch (last) {
    case ScanStage::kOccupancy:
      if (map != nullptr) evict_static();
      break;
    case ScanStage::kTsdf:
      layer.take_touched_tiles(touched);
      tiles.scan_changed(touched);
      evict(layer, step.rebuilding);
      break;
    case ScanStage::kRebuild:
      // The window and static layer re-derived from the retained scans are the map now.
      if (step.rebuild_completed) replace_statics();
      break;
    case ScanStage::kEnd: break;
  }
}

void TsdfPager::Impl::prepare(core::TsdfLayer& layer, const ResidencyStep& step) {
  switch (step.next) {
    case ScanStage::kOccupancy: prepare_occupancy(layer, step.at_W.front()); break;
    case ScanStage::kTsdf:
      tsdf_sensor_W = step.at_W.front();
      prepare_tsdf(layer, step.at_W);
      break;
    case ScanStage::kRebuild: prepare_tsdf(layer, step.at_W); break;
    case ScanStage::kEnd: break;
  }
}

void TsdfPager::Impl::prepare_occupancy(core::TsdfLayer& layer, const Eigen::Vector3d& base_W) {
  if (map == nullptr) return;
  poll(layer);
  const core::VoxelIndex min = map->window_min_at(base_W);
  static_reads.clear();
  statics.ask_back(min, map->window_size(), static_reads);
  for (const core::StaticTileIndex& t : static_reads) {
    submit_static(TileWork::Kind::kReadStatic, t, {}, false);
  }
  if (params.wait_for_loads) {
    wait_until(layer, [&] { return !statics.needed_away(min, map->window_size()); });
  } else if (statics.needed_away(min, map->window_size())) {
    ++stats.loads_late;  // its voxels read static once it is in (put_static)
  }
}

void TsdfPager::Impl::prepare_tsdf(core::TsdfLayer& layer,
                                   std::span<const Eigen::Vector3d> sensors_W) {
  poll(layer);
  if (sensors_W.empty()) return;
  reads.clear();
  tiles.ask_back(sensors_W, reads);
  for (const TileIndex& t : reads) io.submit(tsdf_read(t));
  if (params.wait_for_loads) {
    wait_until(layer, [&] { return !tiles.needed_away(sensors_W); });
  } else if (tiles.needed_away(sensors_W)) {
    ++stats.loads_late;
  }
}

void TsdfPager::Impl::evict(core::TsdfLayer& layer, bool hold) {
  const std::size_t bytes = layer.resident_bytes();
  stats.peak_resident_bytes = std::max(stats.peak_resident_bytes, bytes);
  stats.resident_bytes = bytes;
  if (bytes <= params.limit_bytes) return;
  layer.resident_tiles(resident);
  evictions.clear();
  stats.resident_bytes =
      tiles.choose_evictions(resident, bytes, tsdf_sensor_W, hold || evict_stopped, evictions);
  for (const core::TileEviction& e : evictions) {
    std::optional<TsdfTile> tile = layer.detach_tile(e.tile);
    TARMAC_ASSERT(tile.has_value(), "TsdfPager: a tile chosen for eviction is resident");
    ++stats.evicted;
    if (e.write) io.submit(tsdf_write(e.tile, e.version, std::move(tile), false));
  }
  if (stats.resident_bytes > params.limit_bytes) ++stats.over_limit;
}

void TsdfPager::Impl::evict_static() {
  if (evict_stopped || !statics.window_moved(map->window_min(), map->window_size())) return;
  map->static_tiles(core::kStaticTileEdge, static_resident);
  leaving.clear();
  statics.beyond_ring(static_resident, leaving);
  for (const core::StaticTileIndex& t : leaving) {
    voxels.clear();
    const int x0 = t.x() * core::kStaticTileEdge, y0 = t.y() * core::kStaticTileEdge;
    if (!map->take_static_columns(x0, y0, x0 + core::kStaticTileEdge - 1,
                                  y0 + core::kStaticTileEdge - 1, voxels)) {
      continue;  // meets the window (not reached: the window is within the ring)
    }
    if (statics.leave(t, voxels) == core::StaticLeave::kWrite) {
      submit_static(TileWork::Kind::kWriteStatic, t, voxels, false);
    }
  }
}

void TsdfPager::Impl::replace_statics() {
  if (map == nullptr) return;
  statics.replaced();
  io.submit(static_work(TileWork::Kind::kDropStatics, {}, false, statics.generation()));
}

void TsdfPager::Impl::submit_static(TileWork::Kind kind, const core::StaticTileIndex& t,
                                    std::vector<Eigen::Vector3i> tile_voxels, bool copy) {
  io.submit(
      static_work(kind, core::StaticTile{t, std::move(tile_voxels)}, copy, statics.generation()));
}

// ---------------------------------------------------------------------------------------------
// What the worker finished

void TsdfPager::Impl::poll(core::TsdfLayer& layer) {
  io.take_done(finished);
  collect(layer);
}

void TsdfPager::Impl::collect(core::TsdfLayer& layer) {
  for (TileWork& w : finished) {
    if (w.kind == TileWork::Kind::kWriteTsdf || w.kind == TileWork::Kind::kReadTsdf) {
      collect_tsdf(layer, w);
    } else {
      collect_static(w);
    }
  }
  finished.clear();
}

void TsdfPager::Impl::collect_tsdf(core::TsdfLayer& layer, TileWork& w) {
  if (w.kind == TileWork::Kind::kWriteTsdf) {
    if (w.error) {
      ++stats.write_errors;
      evict_stopped = true;  // the disk is not to be trusted: nothing more leaves memory
      if (!w.copy) layer.attach_tile(std::move(*w.data));  // an evicted tile: back in the layer
      tiles.write_failed(w.tile, w.copy);
      return;
    }
    ++stats.written;
    if (tiles.written(w.tile, w.copy, w.version, w.bytes)) io.submit(tsdf_read(w.tile));
  } else if (w.error) {
    ++stats.load_errors;
    layer.forget_absent(w.tile);
    tiles.load_failed(w.tile);
  } else {
    ++stats.loaded;
    layer.attach_tile(std::move(*w.data));
    tiles.loaded(w.tile);
  }
}

void TsdfPager::Impl::collect_static(TileWork& w) {
  if (w.kind == TileWork::Kind::kDropStatics || w.generation != statics.generation()) return;
  const core::StaticTile& tile = w.static_data;
  if (w.kind == TileWork::Kind::kWriteStatic) {
    if (w.error) {
      ++stats.write_errors;
      evict_stopped = true;
      if (!w.copy) map->put_static(tile.voxels);
      statics.write_failed(tile.index, w.copy);
      return;
    }
    ++stats.static_written;
    if (statics.written(tile.index, w.copy, tile.voxels, w.bytes)) {
      submit_static(TileWork::Kind::kReadStatic, tile.index, {}, false);
    }
  } else if (w.error) {
    ++stats.load_errors;
    statics.load_failed(tile.index);
  } else {
    ++stats.static_loaded;
    map->put_static(tile.voxels);
    statics.loaded(tile.index, tile.voxels);
  }
}

template <typename Pred>
void TsdfPager::Impl::wait_until(core::TsdfLayer& layer, Pred ready) {
  poll(layer);
  while (!ready()) {
    if (!io.wait_done(finished)) return;  // nothing left to wait for
    collect(layer);
  }
}

// ---------------------------------------------------------------------------------------------
// Saves

std::size_t TsdfPager::Impl::store_static_copies() {
  std::size_t n = 0;
  map->static_tiles(core::kStaticTileEdge, static_resident);
  for (const core::StaticTileIndex& t : static_resident) {
    voxels.clear();
    const int x0 = t.x() * core::kStaticTileEdge, y0 = t.y() * core::kStaticTileEdge;
    map->copy_static_columns(x0, y0, x0 + core::kStaticTileEdge - 1, y0 + core::kStaticTileEdge - 1,
                             voxels);
    if (!statics.needs_copy(t, voxels)) continue;
    submit_static(TileWork::Kind::kWriteStatic, t, voxels, true);
    ++n;
  }
  return n;
}

// ---------------------------------------------------------------------------------------------
// TsdfPager

TsdfPagerParams TsdfPagerParams::for_mapper(const core::MapperParams& mapping,
                                            std::filesystem::path dir) {
  const core::TsdfParams& tsdf = mapping.tsdf;
  TsdfPagerParams p;
  p.limit_bytes = std::size_t{tsdf.resident_limit_mb} << 20;
  p.dir = std::move(dir);
  p.voxel_size_m = tsdf.voxel_size_m;
  p.truncation_m = tsdf.truncation_m;
  p.need_radius_m = static_cast<double>(tsdf.max_range_m) + static_cast<double>(tsdf.truncation_m);
  p.load_radius_m = p.need_radius_m + core::kTsdfTileEdge * static_cast<double>(tsdf.voxel_size_m);
  p.occupancy_voxel_m = static_cast<float>(mapping.occupancy.voxel_size_m);
  // A rebuild erases the blocks of every retained scan: their tiles stay (two scans of slack).
  p.keep_scans = mapping.corrections.enabled
                     ? static_cast<std::size_t>(mapping.corrections.retain_scans) + 2
                     : 2;
  return p;
}

core::TileResidencyParams TsdfPagerParams::residency() const {
  return core::TileResidencyParams{limit_bytes, voxel_size_m, need_radius_m, load_radius_m,
                                   keep_scans};
}

SiteStoreParams TsdfPagerParams::store() const {
  return SiteStoreParams{dir, voxel_size_m, truncation_m, occupancy_voxel_m};
}

TsdfPager::TsdfPager(const TsdfPagerParams& params, core::OccupancyMap* occupancy)
    : params_(params), impl_(std::make_unique<Impl>(params, occupancy)) {}

TsdfPager::~TsdfPager() = default;

core::Result<std::unique_ptr<TsdfPager>> TsdfPager::open(const TsdfPagerParams& params,
                                                         core::TsdfLayer& layer,
                                                         core::OccupancyMap* occupancy) {
  if (params.limit_bytes == 0)
    return core::Error{"tsdf_pager.config", "a limit of 0 pages nothing"};
  std::error_code ec;
  std::filesystem::create_directories(params.dir, ec);
  if (ec) {
    return core::Error{"tsdf_pager.dir", params.dir.string() + ": cannot create: " + ec.message()};
  }
  std::unique_ptr<TsdfPager> pager(new TsdfPager(params, occupancy));
  if (auto s = pager->take_stored_tiles(layer); !s) return s.error();
  layer.track_touched_tiles(true);
  return pager;
}

core::Status TsdfPager::take_stored_tiles(core::TsdfLayer& layer) {
  Impl& impl = *impl_;
  std::error_code ec;
  for (const auto& f : std::filesystem::directory_iterator(params_.dir, ec)) {
    const std::string name = f.path().filename().string();
    const std::optional<core::StaticTileIndex> st = parse_static_file_name(name);
    const std::optional<TileIndex> t = st ? std::nullopt : parse_tsdf_file_name(name);
    if (st && impl.map == nullptr) continue;  // not paged here: left as they are
    if (!st && !t) {
      if (name.ends_with(".tsdft.tmp") || name.ends_with(".occs.tmp")) {
        std::filesystem::remove(f.path(), ec);  // a cut write
      }
      continue;
    }
    if (!params_.resume) {
      std::filesystem::remove(f.path(), ec);
      continue;
    }
    const std::uint64_t bytes = std::filesystem::file_size(f.path(), ec);
    if (st) {
      impl.statics.add_stored(*st, bytes);
    } else {
      impl.tiles.add_stored(*t, bytes);
      layer.mark_absent(*t);
    }
  }
  if (ec) return core::Error{"tsdf_pager.dir", params_.dir.string() + ": " + ec.message()};
  return core::Ok{};
}

void TsdfPager::step(core::TsdfLayer& layer, const ResidencyStep& step) {
  impl_->settle(layer, step);
  impl_->prepare(layer, step);
  impl_->last = step.next;
}

void TsdfPager::flush(core::TsdfLayer& layer) {
  impl_->wait_until(layer, [] { return false; });
}

std::size_t TsdfPager::store_changed(core::TsdfLayer& layer) {
  Impl& impl = *impl_;
  impl.poll(layer);
  layer.take_touched_tiles(impl.touched);
  impl.tiles.changed(impl.touched);
  layer.resident_tiles(impl.resident);
  impl.copies.clear();
  impl.tiles.stale_copies(impl.resident, impl.copies);
  // Copies go to the worker; the layer keeps the tiles.
  for (const core::TileCopy& c : impl.copies) {
    impl.io.submit(tsdf_write(c.tile, c.version, layer.copy_tile(c.tile), true));
  }
  const std::size_t statics = impl.map != nullptr ? impl.store_static_copies() : 0;
  return impl.copies.size() + statics;
}

core::Status TsdfPager::store_all(core::TsdfLayer& layer) {
  const std::uint64_t errors_before = impl_->stats.write_errors;
  store_changed(layer);
  flush(layer);
  if (impl_->stats.write_errors != errors_before) {
    return core::Error{"tsdf_tile.write",
                       "some tiles could not be written to " + params_.dir.string()};
  }
  return core::Ok{};
}

SiteStore TsdfPager::site(const core::TsdfLayer& layer) const {
  StoredTiles stored;
  impl_->tiles.stored_away(stored.tsdf);
  impl_->statics.stored_away(stored.statics);
  return SiteStore(params_.store(), layer, std::move(stored), impl_->map);
}

TsdfPagerStats TsdfPager::stats() const {
  const Impl& impl = *impl_;
  TsdfPagerStats s = impl.stats;
  s.resident_tiles = impl.tiles.resident_count();
  s.stored_tiles = impl.tiles.stored_count();
  s.stored_bytes = impl.tiles.stored_bytes();
  s.static_evicted = impl.statics.evicted();
  if (impl.map != nullptr) {
    s.static_resident_bytes = impl.map->static_bytes();
    s.static_resident_voxels = impl.map->static_count();
    s.static_tiles_stored = impl.statics.stored_count();
    s.static_stored_bytes = impl.statics.stored_bytes();
  }
  s.io_queued = impl.io.queued();
  return s;
}

}  // namespace tarmac::daemon
