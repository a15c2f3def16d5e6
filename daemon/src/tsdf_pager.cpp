// TsdfPager (tsdf_pager.hpp): the scan-side decisions and the background worker that writes and
// reads tile files.

#include "tarmac/daemon/tsdf_pager.hpp"

#include <algorithm>
#include <array>
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
#include <set>
#include <thread>
#include <tuple>
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

std::string static_name(const core::StaticTileIndex& t) {
  return "static_" + std::to_string(t.x()) + "_" + std::to_string(t.y()) + ".occs";
}

std::optional<core::StaticTileIndex> parse_static_name(const std::string& name) {
  int x = 0, y = 0, n = 0;
  if (std::sscanf(name.c_str(), "static_%d_%d.occs%n", &x, &y, &n) != 2) return std::nullopt;
  if (static_cast<std::size_t>(n) != name.size()) return std::nullopt;
  if (static_name(core::StaticTileIndex(x, y)) != name) return std::nullopt;
  return core::StaticTileIndex(x, y);
}

/// A static tile's key: (y, x), the order OccupancyMap::static_tiles gives.
using StaticKey = std::pair<int, int>;
StaticKey static_key(const core::StaticTileIndex& t) {
  return {t.y(), t.x()};
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

core::Result<core::StaticTile> read_static(const std::filesystem::path& file, float voxel_size_m,
                                           const core::StaticTileIndex& t) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return core::Error{"static_tile.open", file.string() + ": cannot open"};
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
  core::Result<core::StaticTile> tile = core::StaticTile::decode(bytes, voxel_size_m, t);
  if (!tile) return core::Error{tile.error().code, file.string() + ": " + tile.error().message};
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

/// A static tile the pager knows of: on disk, or resident with a file (or once written).
struct StaticEntry {
  core::StaticTileIndex tile = core::StaticTileIndex::Zero();
  State state = State::kResident;
  bool stored = false;       // a file holds digest's voxels
  std::uint64_t digest = 0;  // of the voxels last read or written
  bool load_after_write = false;
};

struct Job {
  bool write = false;
  bool copy = false;  // write: a copy of a resident tile (store_changed), not an evicted one
  TileIndex tile = TileIndex::Zero();
  std::uint64_t version = 0;
  std::optional<TsdfTile> data;  // write: the tile
  // A static tile's job instead (data empty): its voxels to write, or its index to read. Not an
  // optional: GCC's -O1 (the ASan build) warned of its move as maybe uninitialised.
  core::StaticTile static_data;
  bool is_static = false;
  bool drop_statics = false;  // removes every static tile file (the occupancy was replaced)
  std::uint64_t generation = 0;
};

Job tsdf_job(bool write, bool copy, const TileIndex& tile, std::uint64_t version,
             std::optional<TsdfTile> data) {
  Job job;
  job.write = write;
  job.copy = copy;
  job.tile = tile;
  job.version = version;
  job.data = std::move(data);
  return job;
}

struct Done {
  bool write = false;
  bool copy = false;
  TileIndex tile = TileIndex::Zero();
  std::uint64_t version = 0;
  std::optional<TsdfTile> data;  // read: the tile; failed write: the tile back
  std::optional<core::Error> error;
  std::uint64_t bytes = 0;
  core::StaticTile static_data;  // read: the voxels; failed write: back
  bool is_static = false;
  bool drop_statics = false;
  std::uint64_t generation = 0;
};

}  // namespace

struct TsdfPager::Impl {
  const TsdfPagerParams params;
  std::map<TileKey, Entry> tiles;  // every tile of the site but those never stored nor resident
  std::uint64_t scans = 0;
  bool evict_stopped = false;
  TsdfPagerStats stats;
  std::map<TileKey, std::uint64_t> file_bytes;
  std::uint64_t file_bytes_total = 0;
  /// The tiles not resident (stored, being written or loading), by (x, y, z): the scans' queries
  /// look up the columns near the sensor, not the whole site.
  std::set<std::array<int, 3>> away;
  // Reused between scans (no allocation once grown).
  std::vector<TileIndex> touched;
  std::vector<core::TsdfTileInfo> resident;
  struct Candidate {
    double distance;
    TileKey key;
    TileIndex tile;
  };
  std::vector<Candidate> candidates;

  // The occupancy's static layer, paged when open() was given the map (null: not paged).
  core::OccupancyMap* map = nullptr;
  std::map<StaticKey, StaticEntry> statics;
  std::map<StaticKey, std::uint64_t> static_file_bytes;
  std::uint64_t static_file_bytes_total = 0;
  std::uint64_t generation = 0;  // bumped when the map's static layer is replaced
  Eigen::Vector2i static_ring_lo = Eigen::Vector2i::Zero(), static_ring_hi{-1, -1};
  std::vector<Eigen::Vector2i> static_resident;
  std::vector<Eigen::Vector3i> voxels;

  std::mutex mutex;
  std::condition_variable wake_worker, wake_scan;
  std::deque<Job> jobs;
  std::deque<Done> done;
  std::size_t busy = 0;  // jobs taken, not in done yet
  bool stopping = false;
  std::thread worker;

  explicit Impl(const TsdfPagerParams& p) : params(p) {}

  std::filesystem::path file_of(const TileIndex& t) const { return params.dir / tile_name(t); }

  /// Every tile of the site, resident (true) or in the store (false), in TileKey order:
  /// OpenVDB's iteration order of the whole.
  [[nodiscard]] std::map<TileKey, bool> site_tiles(const core::TsdfLayer& layer) const {
    std::map<TileKey, bool> site;
    for (const core::TsdfTileInfo& info : layer.resident_tiles()) {
      site[TileKey::of(info.tile)] = true;
    }
    for (const auto& [key, e] : tiles) {
      if (e.state != State::kResident) site.emplace(key, false);
    }
    return site;
  }

  /// fn(view) for each block of a site tile, in the layer's order: found in the layer when
  /// resident (for_each_block would walk the whole tree), else read back.
  core::Status for_each_tile_block(
      const core::TsdfLayer& layer, const TileIndex& t, bool resident,
      const std::function<void(const core::TsdfBlockView&)>& fn) const {
    if (!resident) {
      core::Result<TsdfTile> tile = read_tile(file_of(t), params, t);
      if (!tile) return tile.error();
      tile.value().for_each_block(fn);
      return core::Ok{};
    }
    const int b = core::kTsdfTileBlocks;
    for (int x = 0; x < b; ++x) {
      for (int y = 0; y < b; ++y) {
        for (int z = 0; z < b; ++z) {
          const core::BlockIndex bi(t.x() * b + x, t.y() * b + y, t.z() * b + z);
          if (const auto view = layer.find_block(bi)) fn(*view);
        }
      }
    }
    return core::Ok{};
  }

  /// A copy of a site tile: of the resident one, or read back from the store.
  core::Result<TsdfTile> site_tile(const core::TsdfLayer& layer, const TileIndex& t,
                                   bool resident) const {
    if (resident) return std::move(*layer.copy_tile(t));
    return read_tile(file_of(t), params, t);
  }

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
      Done d =
          job.is_static || job.drop_statics ? work_static(std::move(job)) : work(std::move(job));
      lock.lock();
      --busy;
      done.push_back(std::move(d));
      wake_scan.notify_all();
    }
  }

  Done work(Job job) {
    Done d;
    d.write = job.write;
    d.copy = job.copy;
    d.tile = job.tile;
    d.version = job.version;
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
    return d;
  }

  Done work_static(Job job) {
    Done d;
    d.is_static = true;
    d.drop_statics = job.drop_statics;
    d.write = job.write;
    d.copy = job.copy;
    d.generation = job.generation;
    std::error_code ec;
    if (job.drop_statics) {
      for (const auto& f : std::filesystem::directory_iterator(params.dir, ec)) {
        if (parse_static_name(f.path().filename().string())) std::filesystem::remove(f.path(), ec);
      }
      return d;
    }
    const core::StaticTileIndex t = job.static_data.index;
    const std::filesystem::path file = params.dir / static_name(t);
    if (job.write) {
      const std::vector<std::uint8_t> bytes = job.static_data.encode(params.occupancy_voxel_m);
      d.bytes = bytes.size();
      if (const core::Status s = write_atomic(file, bytes); !s) {
        d.error = s.error();
      }
      d.static_data = std::move(job.static_data);  // failed: back to the map; else its index
      return d;
    }
    core::Result<core::StaticTile> read = read_static(file, params.occupancy_voxel_m, t);
    if (read) {
      d.static_data = std::move(read).value();
    } else {
      d.error = read.error();
      d.static_data = core::StaticTile{t, {}};
      std::filesystem::rename(file, file.string() + ".refused", ec);
    }
    return d;
  }

  void submit(Job job) {
    {
      std::lock_guard lock(mutex);
      jobs.push_back(std::move(job));
    }
    wake_worker.notify_one();
  }

  /// Every TSDF entry's state changes here, so that `away` follows.
  void set_state(Entry& e, State state) {
    e.state = state;
    const std::array<int, 3> k{e.tile.x(), e.tile.y(), e.tile.z()};
    if (state == State::kResident) {
      away.erase(k);
    } else {
      away.insert(k);
    }
  }

  void set_file_bytes(const TileKey& key, std::uint64_t bytes) {
    auto [it, fresh] = file_bytes.emplace(key, 0);
    file_bytes_total -= it->second;
    it->second = bytes;
    file_bytes_total += bytes;
  }

  void erase_file_bytes(const TileKey& key) {
    if (const auto it = file_bytes.find(key); it != file_bytes.end()) {
      file_bytes_total -= it->second;
      file_bytes.erase(it);
    }
  }

  /// fn(entry) for each tile away within `radius` (x, y) of one of `sensors_W`; an entry may
  /// come more than once.
  template <typename Fn>
  void for_each_away_near(std::span<const Eigen::Vector3d> sensors_W, double radius, Fn&& fn) {
    const double tile_m = core::kTsdfTileEdge * static_cast<double>(params.voxel_size_m);
    for (const Eigen::Vector3d& p : sensors_W) {
      const int x0 = static_cast<int>(std::floor((p.x() - radius) / tile_m));
      const int x1 = static_cast<int>(std::floor((p.x() + radius) / tile_m));
      const int y0 = static_cast<int>(std::floor((p.y() - radius) / tile_m));
      const int y1 = static_cast<int>(std::floor((p.y() + radius) / tile_m));
      for (int x = x0; x <= x1; ++x) {
        const auto end = away.upper_bound({x, y1, std::numeric_limits<int>::max()});
        for (auto it = away.lower_bound({x, y0, std::numeric_limits<int>::min()}); it != end;
             ++it) {
          const TileIndex t((*it)[0], (*it)[1], (*it)[2]);
          if (xy_distance(t, p, tile_m) <= radius) {
            if (fn(tiles.at(TileKey::of(t)))) return;
          }
        }
      }
    }
  }

  void request_load(Entry& e) {
    if (e.state == State::kStored) {
      set_state(e, State::kLoading);
      submit(tsdf_job(false, false, e.tile, e.version, std::nullopt));
    } else if (e.state == State::kWriting) {
      e.load_after_write = true;
    }
  }

  void request_static_load(StaticEntry& e) {
    if (e.state == State::kStored) {
      e.state = State::kLoading;
      Job job;
      job.is_static = true;
      job.static_data = core::StaticTile{e.tile, {}};
      job.generation = generation;
      submit(std::move(job));
    } else if (e.state == State::kWriting) {
      e.load_after_write = true;
    }
  }

  void submit_static_write(core::StaticTile tile, bool copy) {
    Job job;
    job.is_static = true;
    job.write = true;
    job.copy = copy;
    job.static_data = std::move(tile);
    job.generation = generation;
    submit(std::move(job));
  }

  /// A static tile's job done (scan thread).
  void collect_static(Done& d) {
    if (d.drop_statics || d.generation != generation) return;  // for a replaced layer
    const StaticKey key = static_key(d.static_data.index);
    StaticEntry& e = statics[key];
    e.tile = d.static_data.index;
    if (d.write) {
      if (d.error) {
        ++stats.write_errors;
        evict_stopped = true;
        if (!d.copy) {
          map->put_static(d.static_data.voxels);
          e.state = State::kResident;
        }
        return;
      }
      ++stats.static_written;
      static_file_bytes_total += d.bytes - static_file_bytes[key];
      static_file_bytes[key] = d.bytes;
      e.stored = true;
      e.digest = core::static_voxels_digest(d.static_data.voxels);
      if (!d.copy) e.state = State::kStored;
      if (e.load_after_write) {
        e.load_after_write = false;
        request_static_load(e);
      }
    } else if (d.error) {
      ++stats.load_errors;
      static_file_bytes_total -= static_file_bytes[key];
      static_file_bytes.erase(key);
      statics.erase(key);
    } else {
      ++stats.static_loaded;
      map->put_static(d.static_data.voxels);
      e.state = State::kResident;
      e.stored = true;
      e.digest = core::static_voxels_digest(d.static_data.voxels);
    }
  }

  /// Static tiles [lo, hi] (inclusive) covering the window placed at `min` (voxels), widened by
  /// `margin` tiles.
  [[nodiscard]] std::pair<Eigen::Vector2i, Eigen::Vector2i> static_footprint(
      const core::VoxelIndex& min, int margin) const {
    const auto tile = [](int v) {
      return v >= 0 ? v / core::kStaticTileEdge
                    : -((-v + core::kStaticTileEdge - 1) / core::kStaticTileEdge);
    };
    const Eigen::Vector3i top = min + map->window_size() - Eigen::Vector3i::Ones();
    return {Eigen::Vector2i(tile(min.x()) - margin, tile(min.y()) - margin),
            Eigen::Vector2i(tile(top.x()) + margin, tile(top.y()) + margin)};
  }

  [[nodiscard]] bool static_needed_not_resident(const core::VoxelIndex& min) const {
    const auto [lo, hi] = static_footprint(min, 0);
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int x = lo.x(); x <= hi.x(); ++x) {
        const auto it = statics.find(StaticKey{y, x});
        if (it != statics.end() && it->second.state != State::kResident) return true;
      }
    }
    return false;
  }

  /// Static tiles beyond two tiles of the window leave the map: written when their voxels are
  /// not what their file holds.
  void evict_static() {
    if (evict_stopped) return;
    const auto [lo, hi] = static_footprint(map->window_min(), 2);
    // Only the window's moving into other tiles sends tiles beyond the ring (loads land within
    // it): a pass per footprint, not per scan.
    if (lo == static_ring_lo && hi == static_ring_hi) return;
    static_ring_lo = lo;
    static_ring_hi = hi;
    map->static_tiles(core::kStaticTileEdge, static_resident);
    for (const Eigen::Vector2i& t : static_resident) {
      if (t.x() >= lo.x() && t.x() <= hi.x() && t.y() >= lo.y() && t.y() <= hi.y()) continue;
      voxels.clear();
      const int e0x = t.x() * core::kStaticTileEdge, e0y = t.y() * core::kStaticTileEdge;
      if (!map->take_static_columns(e0x, e0y, e0x + core::kStaticTileEdge - 1,
                                    e0y + core::kStaticTileEdge - 1, voxels)) {
        continue;  // meets the window (not reached: the window is within the footprint)
      }
      const StaticKey key = static_key(t);
      const auto it = statics.find(key);
      const bool has_file = static_file_bytes.contains(key);
      if (voxels.empty() && !has_file) {
        if (it != statics.end()) statics.erase(it);
        continue;
      }
      StaticEntry& e = statics[key];
      e.tile = t;
      ++stats.static_evicted;
      if (e.stored && has_file && e.digest == core::static_voxels_digest(voxels)) {
        e.state = State::kStored;  // the file holds these voxels: dropped, not rewritten
        continue;
      }
      e.state = State::kWriting;
      submit_static_write(core::StaticTile{t, voxels}, false);
    }
  }

  /// Takes what the worker finished back into the layer (scan thread).
  void collect(core::TsdfLayer& layer, std::deque<Done>& finished) {
    for (Done& d : finished) {
      if (d.is_static) {
        collect_static(d);
        continue;
      }
      Entry& e = tiles[TileKey::of(d.tile)];
      if (d.write) {
        if (d.error) {
          ++stats.write_errors;
          evict_stopped = true;  // the disk is not to be trusted: nothing more leaves memory
          if (!d.copy) {         // an evicted tile: back into the layer
            layer.attach_tile(std::move(*d.data));
            set_state(e, State::kResident);
          }  // a copy (store_changed): the layer, or a later eviction's write, holds the tile
          continue;
        }
        ++stats.written;
        set_file_bytes(TileKey::of(d.tile), d.bytes);
        if (!d.copy) {
          set_state(e, State::kStored);
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
        erase_file_bytes(TileKey::of(d.tile));
        set_state(e, State::kResident);  // out of `away`; the entry goes
        tiles.erase(TileKey::of(d.tile));
      } else {
        ++stats.loaded;
        layer.attach_tile(std::move(*d.data));
        set_state(e, State::kResident);
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

  [[nodiscard]] bool needed_not_resident(std::span<const Eigen::Vector3d> sensors_W) {
    bool found = false;
    for_each_away_near(sensors_W, params.need_radius_m, [&found](const Entry&) {
      found = true;
      return true;
    });
    return found;
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
        set_state(e, State::kStored);  // unchanged since read or written: dropped, not rewritten
      } else {
        set_state(e, State::kWriting);
        submit(tsdf_job(true, false, c.tile, e.version, std::move(tile)));
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
  p.occupancy_voxel_m = static_cast<float>(mapping.occupancy.voxel_size_m);
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
                                                         core::TsdfLayer& layer,
                                                         core::OccupancyMap* occupancy) {
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
    if (const auto st = parse_static_name(name)) {
      if (occupancy == nullptr) continue;  // not paged here: left as they are
      if (!params.resume) {
        std::filesystem::remove(f.path(), ec);
        continue;
      }
      StaticEntry e;
      e.tile = *st;
      e.state = State::kStored;
      e.stored = true;
      impl.statics[static_key(*st)] = e;
      const std::uint64_t bytes = std::filesystem::file_size(f.path(), ec);
      impl.static_file_bytes[static_key(*st)] = bytes;
      impl.static_file_bytes_total += bytes;
      continue;
    }
    const std::optional<TileIndex> t = parse_tile_name(name);
    if (!t) {
      if (name.ends_with(".tsdft.tmp") || name.ends_with(".occs.tmp")) {
        std::filesystem::remove(f.path(), ec);  // a cut write
      }
      continue;
    }
    if (!params.resume) {
      std::filesystem::remove(f.path(), ec);
      continue;
    }
    Entry& e = impl.tiles[TileKey::of(*t)];
    e.tile = *t;
    impl.set_state(e, State::kStored);
    e.stored = true;
    impl.set_file_bytes(TileKey::of(*t), std::filesystem::file_size(f.path(), ec));
    layer.mark_absent(*t);
  }
  if (ec) return core::Error{"tsdf_pager.dir", params.dir.string() + ": " + ec.message()};
  layer.track_touched_tiles(true);
  impl.map = occupancy;
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
  impl.for_each_away_near(sensors_W, params_.load_radius_m, [&impl](Entry& e) {
    impl.request_load(e);  // a tile already loading stays so
    return false;
  });
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
    impl.set_state(e, State::kResident);
    e.stored = false;  // the file, if any, is stale now
    ++e.version;
    e.last_touched = impl.scans;
  }
  impl.evict(layer, sensor_W, hold);
}

void TsdfPager::before_occupancy(core::TsdfLayer& layer, const Eigen::Vector3d& base_W) {
  Impl& impl = *impl_;
  if (impl.map == nullptr) return;
  impl.poll(layer);
  const core::VoxelIndex min = impl.map->window_min_at(base_W);
  const auto [lo, hi] = impl.static_footprint(min, 1);
  for (int y = lo.y(); y <= hi.y(); ++y) {
    for (int x = lo.x(); x <= hi.x(); ++x) {
      const auto it = impl.statics.find(StaticKey{y, x});
      if (it != impl.statics.end()) impl.request_static_load(it->second);
    }
  }
  if (params_.wait_for_loads) {
    impl.wait_until(layer, [&] { return !impl.static_needed_not_resident(min); });
  } else if (impl.static_needed_not_resident(min)) {
    ++impl.stats.loads_late;  // its voxels read static once it is in (put_static)
  }
}

void TsdfPager::after_occupancy() {
  if (impl_->map != nullptr) impl_->evict_static();
}

void TsdfPager::occupancy_replaced() {
  Impl& impl = *impl_;
  if (impl.map == nullptr) return;
  ++impl.generation;
  impl.static_ring_hi = impl.static_ring_lo - Eigen::Vector2i::Ones();  // a pass on the next scan
  impl.statics.clear();
  impl.static_file_bytes.clear();
  impl.static_file_bytes_total = 0;
  Job job;
  job.drop_statics = true;
  job.generation = impl.generation;
  impl.submit(std::move(job));
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
    impl.set_state(e, State::kResident);
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
    impl.submit(tsdf_job(true, true, info.tile, e.version, layer.copy_tile(info.tile)));
    ++copies;
  }
  if (impl.map != nullptr) {
    impl.map->static_tiles(core::kStaticTileEdge, impl.static_resident);
    for (const Eigen::Vector2i& t : impl.static_resident) {
      impl.voxels.clear();
      const int x0 = t.x() * core::kStaticTileEdge, y0 = t.y() * core::kStaticTileEdge;
      impl.map->copy_static_columns(x0, y0, x0 + core::kStaticTileEdge - 1,
                                    y0 + core::kStaticTileEdge - 1, impl.voxels);
      const StaticKey key = static_key(t);
      const auto it = impl.statics.find(key);
      const bool has_file = impl.static_file_bytes.contains(key);
      if (impl.voxels.empty() && !has_file) continue;
      if (it != impl.statics.end() && it->second.stored && has_file &&
          it->second.digest == core::static_voxels_digest(impl.voxels)) {
        continue;  // its file holds these voxels
      }
      StaticEntry& e = impl.statics[key];
      e.tile = t;
      impl.submit_static_write(core::StaticTile{t, impl.voxels}, true);
      ++copies;
    }
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
  bool ok = true;
  for (const auto& [key, resident] : impl_->site_tiles(layer)) {
    const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
    if (!impl_->for_each_tile_block(layer, t, resident, fn)) ok = false;
  }
  return ok;
}

core::Status TsdfPager::mesh_site(
    const core::TsdfLayer& layer, float min_weight,
    const std::function<core::Status(const core::TriangleMesh&)>& piece) const {
  const std::map<TileKey, bool> site = impl_->site_tiles(layer);  // true: resident
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
          core::Result<TsdfTile> copy = impl_->site_tile(layer, n, it->second);
          if (!copy) return copy.error();
          piece_layer.attach_tile(std::move(copy).value());
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

core::Status TsdfPager::export_site(
    const core::TsdfLayer& layer, int region_tiles,
    const std::function<core::Status(const Eigen::Vector2i& region, const core::TsdfLayer& part)>&
        part) const {
  if (region_tiles < 1) return core::Error{"tsdf_pager.config", "region_tiles must be >= 1"};
  const auto region_of = [region_tiles](int t) {
    return t >= 0 ? t / region_tiles : -((-t + region_tiles - 1) / region_tiles);
  };
  // Every tile of the site, by region (y, x) then in key order.
  std::map<std::pair<int, int>, std::map<TileKey, bool>> regions;  // tile -> resident
  for (const auto& [key, resident] : impl_->site_tiles(layer)) {
    regions[{region_of(key.tile[1]), region_of(key.tile[0])}][key] = resident;
  }
  for (const auto& [r, tiles] : regions) {
    core::TsdfLayer piece(params_.voxel_size_m, params_.truncation_m);
    for (const auto& [key, resident] : tiles) {
      const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
      core::Result<TsdfTile> copy = impl_->site_tile(layer, t, resident);
      if (!copy) return copy.error();
      piece.attach_tile(std::move(copy).value());
    }
    if (auto s = part(Eigen::Vector2i(r.second, r.first), piece); !s) return s;
  }
  return core::Ok{};
}

core::Status TsdfPager::changes_site(
    const core::TsdfLayer& layer, const std::filesystem::path& prior_dir,
    const core::ChangeParams& params, core::ChangeCounts& counts,
    const std::function<core::Status(const core::GridGeometry2D&)>& begin,
    const std::function<core::Status(int y0, int rows, std::span<const float> cells)>& strip)
    const {
  if (auto s = params.validate(); !s) return s;
  counts = core::ChangeCounts{};
  // Both sites' tiles: the current one's (resident or stored) and the prior store's.
  const std::map<TileKey, bool> site = impl_->site_tiles(layer);  // true: resident
  std::map<TileKey, TileIndex> prior;
  std::error_code ec;
  for (const auto& f : std::filesystem::directory_iterator(prior_dir, ec)) {
    if (const auto t = parse_tile_name(f.path().filename().string())) prior[TileKey::of(*t)] = *t;
  }
  if (ec) return core::Error{"tsdf_changes.prior", prior_dir.string() + ": " + ec.message()};
  const auto read_prior = [&](const TileIndex& t) {
    return read_tile(prior_dir / tile_name(t), params_, t);
  };
  // The raster's extent, as detect_changes takes it: the union of both maps' blocks (x, y).
  Eigen::Vector2i lo(std::numeric_limits<int>::max(), std::numeric_limits<int>::max());
  Eigen::Vector2i hi(std::numeric_limits<int>::min(), std::numeric_limits<int>::min());
  const auto extend = [&](const core::TsdfBlockView& b) {
    lo = lo.cwiseMin(b.block.head<2>() * core::kTsdfBlockEdge);
    hi = hi.cwiseMax(b.block.head<2>() * core::kTsdfBlockEdge +
                     Eigen::Vector2i::Constant(core::kTsdfBlockEdge));
  };
  for (const auto& [key, resident] : site) {
    const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
    if (auto s = impl_->for_each_tile_block(layer, t, resident, extend); !s) return s;
  }
  for (const auto& [key, t] : prior) {
    core::Result<TsdfTile> tile = read_prior(t);
    if (!tile) return tile.error();
    tile.value().for_each_block(extend);
  }
  core::GridGeometry2D g;
  if (lo.x() >= hi.x()) return begin(g);
  const double v = params_.voxel_size_m;
  g.origin_x_m = lo.x() * v;
  g.origin_y_m = lo.y() * v;
  g.resolution_m = v;
  g.width = static_cast<std::uint32_t>(hi.x() - lo.x());
  g.height = static_cast<std::uint32_t>(hi.y() - lo.y());
  if (auto s = begin(g); !s) return s;

  // Strip by strip, one tile row (ty) at a time from the top down; in each, the current tiles
  // of that row that the prior also holds, compared block by block.
  const auto tile_of = [](int voxel) {
    return voxel >= 0 ? voxel / core::kTsdfTileEdge
                      : -((-voxel + core::kTsdfTileEdge - 1) / core::kTsdfTileEdge);
  };
  std::vector<float> cells;
  std::map<std::array<int, 3>, core::TsdfBlockView> before;
  for (int ty = tile_of(hi.y() - 1); ty >= tile_of(lo.y()); --ty) {
    const int y0 = std::max(lo.y(), ty * core::kTsdfTileEdge);
    const int y1 = std::min(hi.y(), (ty + 1) * core::kTsdfTileEdge);
    cells.assign(static_cast<std::size_t>(y1 - y0) * g.width, std::nanf(""));
    const Eigen::Vector2i origin(lo.x(), y0);
    for (const auto& [key, resident] : site) {
      if (key.tile[1] != ty) continue;
      const TileIndex t(key.tile[0], key.tile[1], key.tile[2]);
      const auto p = prior.find(key);
      if (p == prior.end()) continue;
      core::Result<TsdfTile> prior_tile = read_prior(t);
      if (!prior_tile) return prior_tile.error();
      before.clear();
      prior_tile.value().for_each_block([&before](const core::TsdfBlockView& b) {
        before.emplace(std::array<int, 3>{b.block.x(), b.block.y(), b.block.z()}, b);
      });
      const auto compare = [&](const core::TsdfBlockView& now) {
        const auto it = before.find({now.block.x(), now.block.y(), now.block.z()});
        if (it != before.end()) {
          core::compare_blocks(it->second, now, params, v, origin, g.width, cells, counts);
        }
      };
      if (auto s = impl_->for_each_tile_block(layer, t, resident, compare); !s) return s;
    }
    if (auto s = strip(y0 - lo.y(), y1 - y0, cells); !s) return s;
  }
  return core::Ok{};
}

bool TsdfPager::static_site_voxels(std::vector<Eigen::Vector3i>& out) const {
  out.clear();
  if (impl_->map == nullptr) return true;
  impl_->map->export_static(out);
  bool ok = true;
  for (const auto& [key, e] : impl_->statics) {
    if (e.state == State::kResident) continue;
    core::Result<core::StaticTile> read =
        read_static(params_.dir / static_name(e.tile), params_.occupancy_voxel_m, e.tile);
    if (!read) {
      ok = false;
      continue;
    }
    out.insert(out.end(), read.value().voxels.begin(), read.value().voxels.end());
  }
  std::sort(out.begin(), out.end(), [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  return ok;
}

std::uint64_t TsdfPager::site_digest(const core::TsdfLayer& layer) const {
  core::TsdfDigest digest;
  for_each_site_block(layer, [&digest](const core::TsdfBlockView& b) { digest.add(b); });
  return digest.value();
}

TsdfPagerStats TsdfPager::stats() const {
  TsdfPagerStats s = impl_->stats;
  s.resident_tiles = impl_->tiles.size() - impl_->away.size();
  s.stored_tiles = impl_->file_bytes.size();
  s.stored_bytes = impl_->file_bytes_total;
  if (impl_->map != nullptr) {
    s.static_resident_bytes = impl_->map->static_bytes();
    s.static_resident_voxels = impl_->map->static_count();
    s.static_tiles_stored = impl_->static_file_bytes.size();
    s.static_stored_bytes = impl_->static_file_bytes_total;
  }
  {
    std::lock_guard lock(impl_->mutex);
    s.io_queued = impl_->jobs.size() + impl_->busy;
  }
  return s;
}

}  // namespace tarmac::daemon
