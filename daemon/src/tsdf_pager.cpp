// TsdfPager (tsdf_pager.hpp): the scan-side decisions and the background worker that writes and
// reads tile files.

#include "tarmac/daemon/tsdf_pager.hpp"

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

namespace tarmac::daemon {

namespace {

using core::TileIndex;
using core::TileKey;
using core::TsdfTile;

std::string tile_name(const TileIndex& t) {
  return "tile_" + std::to_string(t.x()) + "_" + std::to_string(t.y()) + "_" +
         std::to_string(t.z()) + ".tsdft";
}

std::optional<TileIndex> parse_tile_name(const std::string& name) {
  int x = 0, y = 0, z = 0, n = 0;
  if (std::sscanf(name.c_str(), "tile_%d_%d_%d.tsdft%n", &x, &y, &z, &n) != 3) return std::nullopt;
  if (static_cast<std::size_t>(n) != name.size()) return std::nullopt;
  if (tile_name(TileIndex(x, y, z)) != name) return std::nullopt;  // one spelling per tile
  return TileIndex(x, y, z);
}

bool sync_fd_path(const std::filesystem::path& p, bool dir) {
  const int fd = ::open(p.c_str(), (dir ? O_RDONLY | O_DIRECTORY : O_RDWR) | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
}

/// Writes `bytes` to `file` atomically: a temporary beside it, fsync, rename.
core::Status write_atomic(const std::filesystem::path& file,
                          const std::vector<std::uint8_t>& bytes) {
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    if (!out) return core::Error{"tsdf_tile.write", tmp.string() + ": write failed"};
  }
  if (!sync_fd_path(tmp, false))
    return core::Error{"tsdf_tile.write", tmp.string() + ": fsync failed"};
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) return core::Error{"tsdf_tile.write", file.string() + ": rename failed: " + ec.message()};
  sync_fd_path(file.parent_path(), true);  // best effort: the rename is atomic either way
  return core::Ok{};
}

core::Result<TsdfTile> read_tile(const std::filesystem::path& file, const TsdfPagerParams& p,
                                 const TileIndex& t) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return core::Error{"tsdf_tile.open", file.string() + ": cannot open"};
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
  core::Result<TsdfTile> tile = TsdfTile::decode(bytes, p.voxel_size_m, p.truncation_m, t);
  if (!tile) {
    return core::Error{tile.error().code, file.string() + ": " + tile.error().message};
  }
  return tile;
}

/// Distance in (x, y) from a point to a tile's footprint, m.
double xy_distance(const TileIndex& t, const Eigen::Vector3d& p, double tile_m) {
  const auto axis = [&](int a) {
    const double lo = t[a] * tile_m, hi = lo + tile_m;
    return p[a] < lo ? lo - p[a] : (p[a] > hi ? p[a] - hi : 0.0);
  };
  return std::hypot(axis(0), axis(1));
}

enum class State { kResident, kWriting, kStored, kLoading };

struct Entry {
  TileIndex tile = TileIndex::Zero();
  State state = State::kResident;
  bool stored = false;  // a file holds the tile's current values
  bool load_after_write = false;
  std::uint64_t last_touched = 0;  // scan count when last changed
  std::uint64_t version = 0;       // changes seen: a copy written is current only if unchanged
};

struct Job {
  bool write = false;
  bool copy = false;  // write: a copy of a resident tile (store_changed), not an evicted one
  TileIndex tile = TileIndex::Zero();
  std::uint64_t version = 0;
  std::optional<TsdfTile> data;  // write: the tile
};

struct Done {
  bool write = false;
  bool copy = false;
  TileIndex tile = TileIndex::Zero();
  std::uint64_t version = 0;
  std::optional<TsdfTile> data;  // read: the tile; failed write: the tile back
  std::optional<core::Error> error;
  std::uint64_t bytes = 0;
};

}  // namespace

struct TsdfPager::Impl {
  const TsdfPagerParams params;
  std::map<TileKey, Entry> tiles;  // every tile of the site but those never stored nor resident
  std::uint64_t scans = 0;
  bool evict_stopped = false;
  TsdfPagerStats stats;
  std::map<TileKey, std::uint64_t> file_bytes;
  // Reused between scans (no allocation once grown).
  std::vector<TileIndex> touched;
  std::vector<core::TsdfTileInfo> resident;
  struct Candidate {
    double distance;
    TileKey key;
    TileIndex tile;
  };
  std::vector<Candidate> candidates;

  std::mutex mutex;
  std::condition_variable wake_worker, wake_scan;
  std::deque<Job> jobs;
  std::deque<Done> done;
  std::size_t busy = 0;  // jobs taken, not in done yet
  bool stopping = false;
  std::thread worker;

  explicit Impl(const TsdfPagerParams& p) : params(p) {}

  std::filesystem::path file_of(const TileIndex& t) const { return params.dir / tile_name(t); }

  void run() {
    // The cycle's threads may run SCHED_FIFO; the disk work must never compete with them.
    sched_param sp{};
    pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
    std::unique_lock lock(mutex);
    while (true) {
      wake_worker.wait(lock, [&] { return stopping || !jobs.empty(); });
      if (jobs.empty()) return;
      Job job = std::move(jobs.front());
      jobs.pop_front();
      ++busy;
      lock.unlock();
      Done d{job.write, job.copy, job.tile, job.version, std::nullopt, std::nullopt, 0};
      if (job.write) {
        const std::vector<std::uint8_t> bytes =
            job.data->encode(params.voxel_size_m, params.truncation_m);
        d.bytes = bytes.size();
        if (const core::Status s = write_atomic(file_of(job.tile), bytes); !s) {
          d.error = s.error();
          d.data = std::move(job.data);  // back to the layer: nothing is lost
        }
        job.data.reset();  // written: the memory goes back now, on this thread
      } else {
        core::Result<TsdfTile> t = read_tile(file_of(job.tile), params, job.tile);
        if (t) {
          d.data = std::move(t).value();
        } else {
          d.error = t.error();
          std::error_code ec;
          std::filesystem::rename(file_of(job.tile), file_of(job.tile).string() + ".refused", ec);
        }
      }
      lock.lock();
      --busy;
      done.push_back(std::move(d));
      wake_scan.notify_all();
    }
  }

  void submit(Job job) {
    {
      std::lock_guard lock(mutex);
      jobs.push_back(std::move(job));
    }
    wake_worker.notify_one();
  }

  void request_load(Entry& e) {
    if (e.state == State::kStored) {
      e.state = State::kLoading;
      submit(Job{false, false, e.tile, e.version, std::nullopt});
    } else if (e.state == State::kWriting) {
      e.load_after_write = true;
    }
  }

  /// Takes what the worker finished back into the layer (scan thread).
  void collect(core::TsdfLayer& layer, std::deque<Done>& finished) {
    for (Done& d : finished) {
      Entry& e = tiles[TileKey::of(d.tile)];
      if (d.write) {
        if (d.error) {
          ++stats.write_errors;
          evict_stopped = true;  // the disk is not to be trusted: nothing more leaves memory
          if (!d.copy) {         // an evicted tile: back into the layer
            layer.attach_tile(std::move(*d.data));
            e.state = State::kResident;
          }  // a copy (store_changed): the layer, or a later eviction's write, holds the tile
          continue;
        }
        ++stats.written;
        file_bytes[TileKey::of(d.tile)] = d.bytes;
        if (!d.copy) {
          e.state = State::kStored;
          e.stored = true;
        } else if (e.state == State::kResident && e.version == d.version) {
          e.stored = true;  // a copy of a tile that has not changed since
        }
        if (e.load_after_write) {
          e.load_after_write = false;
          request_load(e);
        }
      } else if (d.error) {
        ++stats.load_errors;
        layer.forget_absent(d.tile);
        file_bytes.erase(TileKey::of(d.tile));
        tiles.erase(TileKey::of(d.tile));
      } else {
        ++stats.loaded;
        layer.attach_tile(std::move(*d.data));
        e.state = State::kResident;
        e.stored = true;
      }
    }
    finished.clear();
  }

  void poll(core::TsdfLayer& layer) {
    std::deque<Done> finished;
    {
      std::lock_guard lock(mutex);
      finished.swap(done);
    }
    collect(layer, finished);
  }

  /// Blocks until `ready` holds after taking what the worker finishes.
  template <typename Pred>
  void wait_until(core::TsdfLayer& layer, Pred ready) {
    poll(layer);
    while (!ready()) {
      std::deque<Done> finished;
      {
        std::unique_lock lock(mutex);
        wake_scan.wait(lock, [&] { return !done.empty() || (jobs.empty() && busy == 0); });
        finished.swap(done);
        if (finished.empty()) return;  // nothing left to wait for
      }
      collect(layer, finished);
    }
  }

  /// Distance in (x, y) from the nearest of `sensors_W` to a tile's footprint, m.
  [[nodiscard]] double distance(const TileIndex& t,
                                std::span<const Eigen::Vector3d> sensors_W) const {
    const double tile_m = core::kTsdfTileEdge * static_cast<double>(params.voxel_size_m);
    double d = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& p : sensors_W) d = std::min(d, xy_distance(t, p, tile_m));
    return d;
  }

  [[nodiscard]] bool needed_not_resident(std::span<const Eigen::Vector3d> sensors_W) const {
    for (const auto& [key, e] : tiles) {
      if (e.state != State::kResident && distance(e.tile, sensors_W) <= params.need_radius_m) {
        return true;
      }
    }
    return false;
  }

  void evict(core::TsdfLayer& layer, const Eigen::Vector3d& sensor_W, bool hold) {
    std::size_t bytes = layer.resident_bytes();
    stats.resident_bytes = bytes;
    stats.peak_resident_bytes = std::max(stats.peak_resident_bytes, bytes);
    if (bytes <= params.limit_bytes) return;
    if (hold || evict_stopped) {
      ++stats.over_limit;
      return;
    }
    const double tile_m = core::kTsdfTileEdge * static_cast<double>(params.voxel_size_m);
    candidates.clear();
    layer.resident_tiles(resident);
    for (const core::TsdfTileInfo& info : resident) {
      const TileKey key = TileKey::of(info.tile);
      const auto it = tiles.find(key);
      if (it != tiles.end() && it->second.last_touched + params.keep_scans > scans) continue;
      const double d = xy_distance(info.tile, sensor_W, tile_m);
      if (d <= params.load_radius_m) continue;
      candidates.push_back(Candidate{d, key, info.tile});
    }
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      return a.distance != b.distance ? a.distance > b.distance : a.key < b.key;
    });
    const std::size_t target = params.limit_bytes / 10 * 9;
    for (const Candidate& c : candidates) {
      if (bytes <= target) break;
      std::optional<TsdfTile> tile = layer.detach_tile(c.tile);
      if (!tile) continue;
      bytes -= core::kTsdfTileNodeBytes + core::kTsdfBlockBytes * tile->block_count();
      ++stats.evicted;
      Entry& e = tiles[c.key];
      e.tile = c.tile;
      if (e.stored) {
        e.state = State::kStored;  // unchanged since read or written: dropped, not rewritten
      } else {
        e.state = State::kWriting;
        submit(Job{true, false, c.tile, e.version, std::move(tile)});
      }
    }
    if (bytes > params.limit_bytes) ++stats.over_limit;
    stats.resident_bytes = bytes;
  }
};

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
  // A rebuild erases the blocks of every retained scan: their tiles stay (two scans of slack).
  p.keep_scans = mapping.corrections.enabled
                     ? static_cast<std::size_t>(mapping.corrections.retain_scans) + 2
                     : 2;
  return p;
}

TsdfPager::TsdfPager(const TsdfPagerParams& params)
    : params_(params), impl_(std::make_unique<Impl>(params)) {}

TsdfPager::~TsdfPager() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stopping = true;
  }
  impl_->wake_worker.notify_all();
  if (impl_->worker.joinable()) impl_->worker.join();  // queued writes finish first
}

core::Result<std::unique_ptr<TsdfPager>> TsdfPager::open(const TsdfPagerParams& params,
                                                         core::TsdfLayer& layer) {
  if (params.limit_bytes == 0)
    return core::Error{"tsdf_pager.config", "a limit of 0 pages nothing"};
  std::error_code ec;
  std::filesystem::create_directories(params.dir, ec);
  if (ec) {
    return core::Error{"tsdf_pager.dir", params.dir.string() + ": cannot create: " + ec.message()};
  }
  std::unique_ptr<TsdfPager> pager(new TsdfPager(params));
  Impl& impl = *pager->impl_;
  for (const auto& f : std::filesystem::directory_iterator(params.dir, ec)) {
    const std::string name = f.path().filename().string();
    const std::optional<TileIndex> t = parse_tile_name(name);
    if (!t) {
      if (name.ends_with(".tsdft.tmp")) std::filesystem::remove(f.path(), ec);  // a cut write
      continue;
    }
    if (!params.resume) {
      std::filesystem::remove(f.path(), ec);
      continue;
    }
    Entry e;
    e.tile = *t;
    e.state = State::kStored;
    e.stored = true;
    impl.tiles[TileKey::of(*t)] = e;
    impl.file_bytes[TileKey::of(*t)] = std::filesystem::file_size(f.path(), ec);
    layer.mark_absent(*t);
  }
  if (ec) return core::Error{"tsdf_pager.dir", params.dir.string() + ": " + ec.message()};
  layer.track_touched_tiles(true);
  impl.worker = std::thread([&impl] { impl.run(); });
  return pager;
}

void TsdfPager::before_scan(core::TsdfLayer& layer, const Eigen::Vector3d& sensor_W) {
  before_rebuild(layer, std::span<const Eigen::Vector3d>(&sensor_W, 1));
}

void TsdfPager::before_rebuild(core::TsdfLayer& layer, std::span<const Eigen::Vector3d> sensors_W) {
  Impl& impl = *impl_;
  impl.poll(layer);
  if (sensors_W.empty()) return;
  for (auto& [key, e] : impl.tiles) {
    if ((e.state == State::kStored || e.state == State::kWriting) &&
        impl.distance(e.tile, sensors_W) <= params_.load_radius_m) {
      impl.request_load(e);
    }
  }
  if (params_.wait_for_loads) {
    impl.wait_until(layer, [&] { return !impl.needed_not_resident(sensors_W); });
  } else if (impl.needed_not_resident(sensors_W)) {
    ++impl.stats.loads_late;
  }
}

void TsdfPager::after_scan(core::TsdfLayer& layer, const Eigen::Vector3d& sensor_W, bool hold) {
  Impl& impl = *impl_;
  ++impl.scans;
  layer.take_touched_tiles(impl.touched);
  for (const TileIndex& t : impl.touched) {
    Entry& e = impl.tiles[TileKey::of(t)];
    e.tile = t;
    e.state = State::kResident;
    e.stored = false;  // the file, if any, is stale now
    ++e.version;
    e.last_touched = impl.scans;
  }
  impl.evict(layer, sensor_W, hold);
}

void TsdfPager::flush(core::TsdfLayer& layer) {
  impl_->wait_until(layer, [] { return false; });
}

std::size_t TsdfPager::store_changed(core::TsdfLayer& layer) {
  Impl& impl = *impl_;
  impl.poll(layer);
  layer.take_touched_tiles(impl.touched);
  for (const TileIndex& t : impl.touched) {
    Entry& e = impl.tiles[TileKey::of(t)];
    e.tile = t;
    e.state = State::kResident;
    e.stored = false;
    ++e.version;
  }
  std::size_t copies = 0;
  layer.resident_tiles(impl.resident);
  for (const core::TsdfTileInfo& info : impl.resident) {
    Entry& e = impl.tiles[TileKey::of(info.tile)];
    e.tile = info.tile;
    if (e.state != State::kResident || e.stored) continue;
    // A copy goes to the worker; the layer keeps the tile. Marked stored once written, if the
    // tile has not changed meanwhile.
    impl.submit(Job{true, true, info.tile, e.version, layer.copy_tile(info.tile)});
    ++copies;
  }
  return copies;
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

bool TsdfPager::for_each_site_block(
    const core::TsdfLayer& layer, const std::function<void(const core::TsdfBlockView&)>& fn) const {
  // Resident tiles and stored ones, in TileKey order: OpenVDB's iteration order of the whole.
  std::map<TileKey, bool> order;  // true: resident
  for (const core::TsdfTileInfo& info : layer.resident_tiles())
    order[TileKey::of(info.tile)] = true;
  for (const auto& [key, e] : impl_->tiles) {
    if (e.state != State::kResident) order.emplace(key, false);
  }
  bool ok = true;
  for (const auto& [key, resident] : order) {
    const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
    if (resident) {
      const int b = core::kTsdfTileBlocks;
      // The tile's blocks in the layer's order: for_each_block would walk the whole tree.
      for (int x = 0; x < b; ++x) {
        for (int y = 0; y < b; ++y) {
          for (int z = 0; z < b; ++z) {
            const core::BlockIndex bi(t.x() * b + x, t.y() * b + y, t.z() * b + z);
            if (const auto view = layer.find_block(bi)) fn(*view);
          }
        }
      }
      continue;
    }
    core::Result<TsdfTile> tile = read_tile(impl_->file_of(t), params_, t);
    if (!tile) {
      ok = false;
      continue;
    }
    tile.value().for_each_block(fn);
  }
  return ok;
}

core::Status TsdfPager::mesh_site(
    const core::TsdfLayer& layer, float min_weight,
    const std::function<core::Status(const core::TriangleMesh&)>& piece) const {
  std::map<TileKey, bool> site;  // true: resident
  layer.resident_tiles(impl_->resident);
  for (const core::TsdfTileInfo& info : impl_->resident) site[TileKey::of(info.tile)] = true;
  for (const auto& [key, e] : impl_->tiles) {
    if (e.state != State::kResident) site.emplace(key, false);
  }
  core::TriangleMesh mesh;
  for (const auto& [key, resident] : site) {
    const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
    core::TsdfLayer piece_layer(params_.voxel_size_m, params_.truncation_m);
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const TileIndex n = t + TileIndex(dx, dy, dz);
          const auto it = site.find(TileKey::of(n));
          if (it == site.end()) continue;
          if (it->second) {
            piece_layer.attach_tile(std::move(*layer.copy_tile(n)));
            continue;
          }
          core::Result<TsdfTile> read = read_tile(impl_->file_of(n), params_, n);
          if (!read) return read.error();
          piece_layer.attach_tile(std::move(read).value());
        }
      }
    }
    const Eigen::Vector3i lo = t * core::kTsdfTileEdge;
    const Eigen::Vector3i hi = lo + Eigen::Vector3i::Constant(core::kTsdfTileEdge);
    if (auto s = core::extract_mesh(piece_layer, min_weight, lo, hi, mesh); !s) return s;
    if (auto s = piece(mesh); !s) return s;
  }
  return core::Ok{};
}

std::uint64_t TsdfPager::site_digest(const core::TsdfLayer& layer) const {
  core::TsdfDigest digest;
  for_each_site_block(layer, [&digest](const core::TsdfBlockView& b) { digest.add(b); });
  return digest.value();
}

TsdfPagerStats TsdfPager::stats() const {
  TsdfPagerStats s = impl_->stats;
  for (const auto& [key, e] : impl_->tiles) {
    s.resident_tiles += e.state == State::kResident ? 1 : 0;
  }
  s.stored_tiles = impl_->file_bytes.size();
  for (const auto& [key, bytes] : impl_->file_bytes) s.stored_bytes += bytes;
  {
    std::lock_guard lock(impl_->mutex);
    s.io_queued = impl_->jobs.size() + impl_->busy;
  }
  return s;
}

}  // namespace tarmac::daemon
