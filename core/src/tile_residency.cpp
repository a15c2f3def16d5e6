// The residency policy of a paged site (tile_residency.hpp): the TSDF's tiles and the static
// occupancy's column tiles, as bookkeeping and decisions only.

#include "tarmac/core/tile_residency.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tarmac::core {

namespace {

/// The tiles of `entries` that are not resident, in the map's order, into `out`.
template <typename Entries, typename Index>
void tiles_away(const Entries& entries, std::vector<Index>& out) {
  out.clear();
  for (const auto& [key, e] : entries) {
    if (e.state != TileState::kResident) out.push_back(e.tile);
  }
}

}  // namespace

double tile_distance_xy_m(const TileIndex& t, const Eigen::Vector3d& p_W, double tile_m) {
  const auto axis = [&](int a) {
    const double lo = t[a] * tile_m, hi = lo + tile_m;
    return p_W[a] < lo ? lo - p_W[a] : (p_W[a] > hi ? p_W[a] - hi : 0.0);
  };
  return std::hypot(axis(0), axis(1));
}

// ---------------------------------------------------------------------------------------------
// TSDF tiles

void TsdfResidency::add_stored(const TileIndex& t, std::uint64_t bytes) {
  Entry& e = entry(t);
  set_state(e, TileState::kStored);
  e.stored = true;
  stored_.set(TileKey::of(t), bytes);
}

TsdfResidency::Entry& TsdfResidency::entry(const TileIndex& t) {
  Entry& e = tiles_[TileKey::of(t)];
  e.tile = t;
  return e;
}

void TsdfResidency::scan_changed(std::span<const TileIndex> touched) {
  ++scans_;
  mark_changed(touched, true);
}

void TsdfResidency::changed(std::span<const TileIndex> touched) {
  mark_changed(touched, false);
}

void TsdfResidency::mark_changed(std::span<const TileIndex> touched, bool by_scan) {
  for (const TileIndex& t : touched) {
    Entry& e = entry(t);
    set_state(e, TileState::kResident);
    e.stored = false;  // the store's copy, if any, is stale now
    ++e.version;
    if (by_scan) e.last_touched = scans_;
  }
}

/// Every state change goes through here, so that `away_` follows.
void TsdfResidency::set_state(Entry& e, TileState state) {
  e.state = state;
  const std::array<int, 3> k{e.tile.x(), e.tile.y(), e.tile.z()};
  if (state == TileState::kResident) {
    away_.erase(k);
  } else {
    away_.insert(k);
  }
}

/// fn(tile) for each tile away within `radius_m` (x, y) of one of `points_W`, until fn returns
/// true; a tile may come more than once.
template <typename Fn>
void TsdfResidency::for_each_away_near(std::span<const Eigen::Vector3d> points_W, double radius_m,
                                       Fn&& fn) const {
  const double tile_m = params_.tile_m();
  for (const Eigen::Vector3d& p : points_W) {
    const int x0 = static_cast<int>(std::floor((p.x() - radius_m) / tile_m));
    const int x1 = static_cast<int>(std::floor((p.x() + radius_m) / tile_m));
    const int y0 = static_cast<int>(std::floor((p.y() - radius_m) / tile_m));
    const int y1 = static_cast<int>(std::floor((p.y() + radius_m) / tile_m));
    for (int x = x0; x <= x1; ++x) {
      // The away tiles of column x with y in [y0, y1], by (y, z).
      const auto end = away_.upper_bound({x, y1, std::numeric_limits<int>::max()});
      for (auto it = away_.lower_bound({x, y0, std::numeric_limits<int>::min()}); it != end; ++it) {
        const TileIndex t((*it)[0], (*it)[1], (*it)[2]);
        if (tile_distance_xy_m(t, p, tile_m) <= radius_m && fn(t)) return;
      }
    }
  }
}

void TsdfResidency::ask_back(std::span<const Eigen::Vector3d> points_W,
                             std::vector<TileIndex>& reads) {
  for_each_away_near(points_W, params_.load_radius_m, [&](const TileIndex& t) {
    if (ask_back(tiles_.at(TileKey::of(t)))) reads.push_back(t);  // one loading stays so
    return false;
  });
}

/// True when the tile is to be read now (it is loading).
bool TsdfResidency::ask_back(Entry& e) {
  if (e.state == TileState::kStored) {
    set_state(e, TileState::kLoading);
    return true;
  }
  if (e.state == TileState::kWriting) e.load_after_write = true;
  return false;
}

bool TsdfResidency::needed_away(std::span<const Eigen::Vector3d> points_W) const {
  bool found = false;
  for_each_away_near(points_W, params_.need_radius_m, [&found](const TileIndex&) {
    found = true;
    return true;
  });
  return found;
}

void TsdfResidency::collect_candidates(std::span<const TsdfTileInfo> resident,
                                       const Eigen::Vector3d& sensor_W) {
  candidates_.clear();
  for (const TsdfTileInfo& info : resident) {
    const TileKey key = TileKey::of(info.tile);
    const auto it = tiles_.find(key);
    if (it != tiles_.end() && it->second.last_touched + params_.keep_scans > scans_) continue;
    const double d = tile_distance_xy_m(info.tile, sensor_W, params_.tile_m());
    if (d <= params_.load_radius_m) continue;
    candidates_.push_back(Candidate{d, key, info});
  }
  std::sort(candidates_.begin(), candidates_.end(), [](const Candidate& a, const Candidate& b) {
    return a.distance_m != b.distance_m ? a.distance_m > b.distance_m : a.key < b.key;
  });
}

std::size_t TsdfResidency::choose_evictions(std::span<const TsdfTileInfo> resident,
                                            std::size_t resident_bytes,
                                            const Eigen::Vector3d& sensor_W, bool hold,
                                            std::vector<TileEviction>& out) {
  std::size_t bytes = resident_bytes;
  if (bytes <= params_.limit_bytes || hold) return bytes;
  collect_candidates(resident, sensor_W);
  const std::size_t target = params_.limit_bytes / 10 * 9;
  for (const Candidate& c : candidates_) {
    if (bytes <= target) break;
    bytes -= kTsdfTileNodeBytes + kTsdfBlockBytes * c.info.blocks;
    Entry& e = entry(c.info.tile);
    // Unchanged since read or written: dropped, not rewritten.
    set_state(e, e.stored ? TileState::kStored : TileState::kWriting);
    out.push_back(TileEviction{c.info.tile, !e.stored, e.version});
  }
  return bytes;
}

void TsdfResidency::stale_copies(std::span<const TsdfTileInfo> resident,
                                 std::vector<TileCopy>& out) {
  for (const TsdfTileInfo& info : resident) {
    const Entry& e = entry(info.tile);
    if (e.state != TileState::kResident || e.stored) continue;
    // Marked stored once written, if the tile has not changed meanwhile.
    out.push_back(TileCopy{info.tile, e.version});
  }
}

bool TsdfResidency::written(const TileIndex& t, bool copy, std::uint64_t version,
                            std::uint64_t bytes) {
  Entry& e = entry(t);
  stored_.set(TileKey::of(t), bytes);
  if (!copy) {
    set_state(e, TileState::kStored);
    e.stored = true;
  } else if (e.state == TileState::kResident && e.version == version) {
    e.stored = true;  // a copy of a tile that has not changed since
  }
  if (!e.load_after_write) return false;
  e.load_after_write = false;
  return ask_back(e);
}

void TsdfResidency::write_failed(const TileIndex& t, bool copy) {
  // A copy's tile is in the layer still, or in a later eviction's write.
  if (!copy) set_state(entry(t), TileState::kResident);
}

void TsdfResidency::loaded(const TileIndex& t) {
  Entry& e = entry(t);
  set_state(e, TileState::kResident);
  e.stored = true;
}

void TsdfResidency::load_failed(const TileIndex& t) {
  stored_.erase(TileKey::of(t));
  set_state(entry(t), TileState::kResident);  // out of `away_`; the entry goes
  tiles_.erase(TileKey::of(t));
}

void TsdfResidency::stored_away(std::vector<TileIndex>& out) const {
  tiles_away(tiles_, out);
}

// ---------------------------------------------------------------------------------------------
// Static column tiles

StaticFootprint static_footprint(const Eigen::Vector3i& window_min,
                                 const Eigen::Vector3i& window_size, int margin) {
  const auto tile = [](int v) {
    return v >= 0 ? v / kStaticTileEdge : -((-v + kStaticTileEdge - 1) / kStaticTileEdge);
  };
  const Eigen::Vector3i top = window_min + window_size - Eigen::Vector3i::Ones();
  return {StaticTileIndex(tile(window_min.x()) - margin, tile(window_min.y()) - margin),
          StaticTileIndex(tile(top.x()) + margin, tile(top.y()) + margin)};
}

void StaticResidency::add_stored(const StaticTileIndex& t, std::uint64_t bytes) {
  Entry e;
  e.tile = t;
  e.state = TileState::kStored;
  e.stored = true;
  tiles_[key_of(t)] = e;
  stored_.set(key_of(t), bytes);
}

void StaticResidency::ask_back(const Eigen::Vector3i& window_min,
                               const Eigen::Vector3i& window_size,
                               std::vector<StaticTileIndex>& reads) {
  const StaticFootprint f = static_footprint(window_min, window_size, 1);
  for (int y = f.lo.y(); y <= f.hi.y(); ++y) {
    for (int x = f.lo.x(); x <= f.hi.x(); ++x) {
      const auto it = tiles_.find(Key{y, x});
      if (it != tiles_.end() && ask_back(it->second)) reads.push_back(it->second.tile);
    }
  }
}

/// True when the tile is to be read now (it is loading).
bool StaticResidency::ask_back(Entry& e) {
  if (e.state == TileState::kStored) {
    e.state = TileState::kLoading;
    return true;
  }
  if (e.state == TileState::kWriting) e.load_after_write = true;
  return false;
}

bool StaticResidency::needed_away(const Eigen::Vector3i& window_min,
                                  const Eigen::Vector3i& window_size) const {
  const StaticFootprint f = static_footprint(window_min, window_size, 0);
  for (int y = f.lo.y(); y <= f.hi.y(); ++y) {
    for (int x = f.lo.x(); x <= f.hi.x(); ++x) {
      const auto it = tiles_.find(Key{y, x});
      if (it != tiles_.end() && it->second.state != TileState::kResident) return true;
    }
  }
  return false;
}

bool StaticResidency::window_moved(const Eigen::Vector3i& window_min,
                                   const Eigen::Vector3i& window_size) {
  const StaticFootprint ring = static_footprint(window_min, window_size, 2);
  if (ring == ring_) return false;
  ring_ = ring;
  return true;
}

void StaticResidency::beyond_ring(std::span<const StaticTileIndex> resident,
                                  std::vector<StaticTileIndex>& out) const {
  for (const StaticTileIndex& t : resident) {
    if (!ring_.contains(t)) out.push_back(t);
  }
}

StaticLeave StaticResidency::leave(const StaticTileIndex& t,
                                   std::span<const Eigen::Vector3i> voxels) {
  const Key key = key_of(t);
  const auto it = tiles_.find(key);
  const bool has_file = stored_.contains(key);
  if (voxels.empty() && !has_file) {
    if (it != tiles_.end()) tiles_.erase(it);
    return StaticLeave::kForget;
  }
  Entry& e = tiles_[key];
  e.tile = t;
  ++evicted_;
  if (e.stored && has_file && e.digest == static_voxels_digest(voxels)) {
    e.state = TileState::kStored;
    return StaticLeave::kDrop;
  }
  e.state = TileState::kWriting;
  return StaticLeave::kWrite;
}

bool StaticResidency::needs_copy(const StaticTileIndex& t,
                                 std::span<const Eigen::Vector3i> voxels) {
  const Key key = key_of(t);
  const auto it = tiles_.find(key);
  const bool has_file = stored_.contains(key);
  if (voxels.empty() && !has_file) return false;
  if (it != tiles_.end() && it->second.stored && has_file &&
      it->second.digest == static_voxels_digest(voxels)) {
    return false;  // its stored copy holds these voxels
  }
  tiles_[key].tile = t;
  return true;
}

bool StaticResidency::written(const StaticTileIndex& t, bool copy,
                              std::span<const Eigen::Vector3i> voxels, std::uint64_t bytes) {
  const Key key = key_of(t);
  Entry& e = tiles_[key];
  e.tile = t;
  stored_.set(key, bytes);
  e.stored = true;
  e.digest = static_voxels_digest(voxels);
  if (!copy) e.state = TileState::kStored;
  if (!e.load_after_write) return false;
  e.load_after_write = false;
  return ask_back(e);
}

void StaticResidency::write_failed(const StaticTileIndex& t, bool copy) {
  Entry& e = tiles_[key_of(t)];
  e.tile = t;
  if (!copy) e.state = TileState::kResident;
}

void StaticResidency::loaded(const StaticTileIndex& t, std::span<const Eigen::Vector3i> voxels) {
  Entry& e = tiles_[key_of(t)];
  e.tile = t;
  e.state = TileState::kResident;
  e.stored = true;
  e.digest = static_voxels_digest(voxels);
}

void StaticResidency::load_failed(const StaticTileIndex& t) {
  const Key key = key_of(t);
  stored_.erase(key);
  tiles_.erase(key);
}

void StaticResidency::replaced() {
  ++generation_;
  ring_.hi = ring_.lo - StaticTileIndex::Ones();  // empty: no window's ring
  tiles_.clear();
  stored_.clear();
}

void StaticResidency::stored_away(std::vector<StaticTileIndex>& out) const {
  tiles_away(tiles_, out);
}

}  // namespace tarmac::core
