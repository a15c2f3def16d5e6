#pragma once
/// @file Which tiles of a paged site stay in memory (docs/mapping.md, "Site-scale maps"): the
/// residency policy for the TSDF's tiles (tsdf_tiles.hpp) and the static occupancy's column
/// tiles. Decisions come from the vehicle's position, the resident set and the limit alone, so
/// the same calls give the same decisions on any machine. Nothing here moves a tile, touches a
/// file, runs a thread or reads a clock: the caller (the daemon's TsdfPager) carries the
/// decisions out and reports back what its disk work finished.
///
/// Rules:
///  - a scan can touch tiles within `need_radius_m` of its sensor (x, y); tiles away within
///    `load_radius_m` are asked back;
///  - over the limit, tiles are evicted farthest first (ties by TileKey), never one within
///    load_radius_m nor one a scan of the last `keep_scans` changed, down to 90 % of the limit;
///    a tile whose store copy is current is dropped, not written;
///  - a static column tile leaves beyond two tiles of the occupancy window and is asked back
///    within one; one whose stored voxels are its voxels is dropped, not written.

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <set>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/tsdf_tiles.hpp"

namespace tarmac::core {

struct TileResidencyParams {
  std::size_t limit_bytes = 0;  ///< resident TSDF tiles above this are evicted
  float voxel_size_m = 0.1f;    ///< the TSDF's voxel: a tile is kTsdfTileEdge of them
  double need_radius_m = 50.3;  ///< tiles a scan can touch: within this of the sensor (x, y)
  double load_radius_m = 63.1;  ///< tiles away within this are asked back (>= need_radius_m)
  std::size_t keep_scans = 52;  ///< tiles changed by the last this many scans stay

  [[nodiscard]] double tile_m() const { return kTsdfTileEdge * static_cast<double>(voxel_size_m); }
};

/// Where a tile is: in memory, on its way to the store, only in the store, on its way back.
enum class TileState { kResident, kWriting, kStored, kLoading };

/// Distance in (x, y) from a point to a tile's footprint (`tile_m` a side), m.
[[nodiscard]] double tile_distance_xy_m(const TileIndex& t, const Eigen::Vector3d& p_W,
                                        double tile_m);

/// A TSDF tile chosen to leave memory: `write` when the store's copy is not current (else the
/// tile is dropped). `version`: its changes so far, to tell a later write whether it is current.
struct TileEviction {
  TileIndex tile = TileIndex::Zero();
  bool write = false;
  std::uint64_t version = 0;
};

/// A resident TSDF tile whose store copy is not current: a copy of it is to be written.
struct TileCopy {
  TileIndex tile = TileIndex::Zero();
  std::uint64_t version = 0;
};

/// The sizes of the store's copies, by tile key, and their sum.
template <typename Key>
class StoredBytes {
 public:
  void set(const Key& key, std::uint64_t bytes) {
    auto [it, fresh] = bytes_.emplace(key, 0);
    total_ -= it->second;
    it->second = bytes;
    total_ += bytes;
  }
  void erase(const Key& key) {
    if (const auto it = bytes_.find(key); it != bytes_.end()) {
      total_ -= it->second;
      bytes_.erase(it);
    }
  }
  void clear() {
    bytes_.clear();
    total_ = 0;
  }
  [[nodiscard]] bool contains(const Key& key) const { return bytes_.contains(key); }
  [[nodiscard]] std::size_t count() const { return bytes_.size(); }
  [[nodiscard]] std::uint64_t total() const { return total_; }

 private:
  std::map<Key, std::uint64_t> bytes_;
  std::uint64_t total_ = 0;
};

/// The TSDF's tiles: which are resident and which away, and what leaves or comes back next.
class TsdfResidency {
 public:
  explicit TsdfResidency(const TileResidencyParams& params) : params_(params) {}

  /// A tile found in the store at start (`bytes` its copy's size): away until asked back.
  void add_stored(const TileIndex& t, std::uint64_t bytes);
  /// After a scan's integration, the tiles it changed (TsdfLayer::take_touched_tiles): resident,
  /// their store copies stale, kept for keep_scans scans.
  void scan_changed(std::span<const TileIndex> touched);
  /// Tiles changed outside a scan (taken before a save): their store copies are stale.
  void changed(std::span<const TileIndex> touched);

  /// Asks back the tiles away within load_radius_m of any of `points_W`: those only in the store
  /// are appended to `reads` (now loading); one being written is read once written.
  void ask_back(std::span<const Eigen::Vector3d> points_W, std::vector<TileIndex>& reads);
  /// True while a tile within need_radius_m of any of `points_W` is away.
  [[nodiscard]] bool needed_away(std::span<const Eigen::Vector3d> points_W) const;

  /// The resident tiles (TsdfLayer::resident_tiles, `resident_bytes` their cost) to evict after a
  /// scan with its sensor at `sensor_W`, appended to `out` in eviction order and now away. None
  /// when within the limit or `hold` (a rebuild running, or the store failing). Returns the
  /// bytes left resident once they are gone.
  std::size_t choose_evictions(std::span<const TsdfTileInfo> resident, std::size_t resident_bytes,
                               const Eigen::Vector3d& sensor_W, bool hold,
                               std::vector<TileEviction>& out);
  /// The resident tiles whose store copy is not current (a save), appended to `out`.
  void stale_copies(std::span<const TsdfTileInfo> resident, std::vector<TileCopy>& out);

  /// A write finished (`copy`: of a tile that stayed resident). True when the tile is to be read
  /// back now (it was asked back while being written): it is then loading.
  bool written(const TileIndex& t, bool copy, std::uint64_t version, std::uint64_t bytes);
  /// A write failed: an evicted tile is resident again (the caller puts it back in the layer).
  void write_failed(const TileIndex& t, bool copy);
  /// A read finished: the tile is resident (the caller attached it).
  void loaded(const TileIndex& t);
  /// A read failed: the tile is forgotten (its ground is mapped afresh).
  void load_failed(const TileIndex& t);

  /// The tiles only in the store, in TileKey order (the site's other tiles are resident).
  void stored_away(std::vector<TileIndex>& out) const;
  [[nodiscard]] std::size_t resident_count() const { return tiles_.size() - away_.size(); }
  [[nodiscard]] std::size_t stored_count() const { return stored_.count(); }
  [[nodiscard]] std::uint64_t stored_bytes() const { return stored_.total(); }
  [[nodiscard]] const TileResidencyParams& params() const { return params_; }

 private:
  struct Entry {
    TileIndex tile = TileIndex::Zero();
    TileState state = TileState::kResident;
    bool stored = false;  // the store's copy holds the tile's current values
    bool load_after_write = false;
    std::uint64_t last_touched = 0;  // scans counted when last changed by one
    std::uint64_t version = 0;       // changes seen: a copy written is current only if unchanged
  };
  struct Candidate {
    double distance_m;
    TileKey key;
    TsdfTileInfo info;
  };

  Entry& entry(const TileIndex& t);
  void mark_changed(std::span<const TileIndex> touched, bool by_scan);
  void set_state(Entry& e, TileState state);
  bool ask_back(Entry& e);
  void collect_candidates(std::span<const TsdfTileInfo> resident, const Eigen::Vector3d& sensor_W);
  template <typename Fn>
  void for_each_away_near(std::span<const Eigen::Vector3d> points_W, double radius_m,
                          Fn&& fn) const;

  TileResidencyParams params_;
  std::map<TileKey, Entry> tiles_;  // every tile of the site but those never stored nor resident
  std::uint64_t scans_ = 0;
  /// The tiles not resident, by (x, y, z): a scan's queries look up the columns near it only.
  std::set<std::array<int, 3>> away_;
  StoredBytes<TileKey> stored_;
  std::vector<Candidate> candidates_;  // reused between scans
};

/// Static column tile t covers voxels [kStaticTileEdge·t, kStaticTileEdge·t + kStaticTileEdge)
/// in x and y; a footprint is the inclusive range of tiles [lo, hi].
struct StaticFootprint {
  StaticTileIndex lo{0, 0};
  StaticTileIndex hi{-1, -1};
  [[nodiscard]] bool contains(const StaticTileIndex& t) const {
    return t.x() >= lo.x() && t.x() <= hi.x() && t.y() >= lo.y() && t.y() <= hi.y();
  }
  friend bool operator==(const StaticFootprint&, const StaticFootprint&) = default;
};

/// The static tiles an occupancy window of `window_size` voxels at `window_min` covers, widened
/// by `margin` tiles on each side.
[[nodiscard]] StaticFootprint static_footprint(const Eigen::Vector3i& window_min,
                                               const Eigen::Vector3i& window_size, int margin);

/// What becomes of a static tile leaving memory with its voxels.
enum class StaticLeave {
  kForget,  ///< no voxels and nothing stored: nothing to keep
  kDrop,    ///< the store holds these voxels: dropped unwritten
  kWrite,   ///< written
};

/// The occupancy's static column tiles: which are away, which leave, which come back.
class StaticResidency {
 public:
  /// A tile found in the store at start (`bytes` its copy's size): away until asked back.
  void add_stored(const StaticTileIndex& t, std::uint64_t bytes);

  /// Asks back the tiles away within one tile of the window at `window_min`: those only in the
  /// store are appended to `reads` (now loading); one being written is read once written.
  void ask_back(const Eigen::Vector3i& window_min, const Eigen::Vector3i& window_size,
                std::vector<StaticTileIndex>& reads);
  /// True while a tile the window at `window_min` covers is away.
  [[nodiscard]] bool needed_away(const Eigen::Vector3i& window_min,
                                 const Eigen::Vector3i& window_size) const;
  /// True when the window at `window_min` lies in other tiles than at the last call (the first
  /// call, and the first after replaced(), too): only then can resident tiles lie beyond two
  /// tiles of it, as a tile asked back lands within that ring.
  bool window_moved(const Eigen::Vector3i& window_min, const Eigen::Vector3i& window_size);
  /// The resident tiles (OccupancyMap::static_tiles) beyond two tiles of the window of the last
  /// window_moved(), appended to `out`: they leave memory.
  void beyond_ring(std::span<const StaticTileIndex> resident,
                   std::vector<StaticTileIndex>& out) const;
  /// A tile left memory with `voxels` (sorted by (z, y, x)): what becomes of it. kDrop and
  /// kWrite count in evicted().
  StaticLeave leave(const StaticTileIndex& t, std::span<const Eigen::Vector3i> voxels);
  /// Whether a save writes a copy of a resident tile holding `voxels`: not when the store holds
  /// them, nor when it has none and the store nothing.
  bool needs_copy(const StaticTileIndex& t, std::span<const Eigen::Vector3i> voxels);

  /// A write of `voxels` finished (`copy`: the tile stayed resident). True when the tile is to be
  /// read back now (it was asked back while being written): it is then loading.
  bool written(const StaticTileIndex& t, bool copy, std::span<const Eigen::Vector3i> voxels,
               std::uint64_t bytes);
  /// A write failed: an evicted tile is resident again (the caller puts its voxels back).
  void write_failed(const StaticTileIndex& t, bool copy);
  /// A read finished with `voxels` (the caller put them back in the map).
  void loaded(const StaticTileIndex& t, std::span<const Eigen::Vector3i> voxels);
  /// A read failed: the tile is forgotten.
  void load_failed(const StaticTileIndex& t);
  /// The map's static layer was replaced: every tile and stored copy of the old one is
  /// forgotten, reports of writes and reads begun before are to be ignored (generation()), and
  /// the next window_moved() is true.
  void replaced();
  /// Bumped by replaced(): a report of work begun under another generation is stale.
  [[nodiscard]] std::uint64_t generation() const { return generation_; }

  /// The tiles only in the store, by (y, x).
  void stored_away(std::vector<StaticTileIndex>& out) const;
  [[nodiscard]] std::size_t stored_count() const { return stored_.count(); }
  [[nodiscard]] std::uint64_t stored_bytes() const { return stored_.total(); }
  [[nodiscard]] std::uint64_t evicted() const { return evicted_; }

 private:
  /// A tile's key: (y, x), the order OccupancyMap::static_tiles gives.
  using Key = std::pair<int, int>;
  static Key key_of(const StaticTileIndex& t) { return {t.y(), t.x()}; }
  struct Entry {
    StaticTileIndex tile = StaticTileIndex::Zero();
    TileState state = TileState::kResident;
    bool stored = false;       // the store holds `digest`'s voxels
    std::uint64_t digest = 0;  // of the voxels last read or written
    bool load_after_write = false;
  };
  bool ask_back(Entry& e);

  std::map<Key, Entry> tiles_;
  StoredBytes<Key> stored_;
  std::uint64_t generation_ = 0;
  std::uint64_t evicted_ = 0;
  StaticFootprint ring_;  // two tiles round the window of the last window_moved()
};

}  // namespace tarmac::core
