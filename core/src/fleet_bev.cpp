// Fleet BEV summaries (fleet_bev.hpp): the tile run encoding, the encoder that sends changed
// tiles, and the peers' store.

#include "tarmac/core/fleet_bev.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

namespace tarmac::core {

namespace {

using TileKey = std::pair<std::int32_t, std::int32_t>;

constexpr int kMaxRun = 64;
/// Tile indices stay far inside int32 (a lattice index / 32 of a map of ±2^25 m at 0.1 m).
constexpr std::int32_t kMaxTileIndex = 1 << 24;
/// The most bytes a tile's runs can take (every cell a known run of one).
constexpr std::size_t kMaxTileBytes = 3 * kBevTileCells;

/// floor(a / b) for b > 0.
std::int64_t floor_div(std::int64_t a, std::int64_t b) {
  const std::int64_t q = a / b;
  return (a % b != 0 && a < 0) ? q - 1 : q;
}

/// The 16-bit wire form of an observation time.
std::uint16_t wire_time(std::int64_t observed_ns) {
  return static_cast<std::uint16_t>(floor_div(observed_ns, kBevTimeStepNs) & 0xffff);
}

/// The latest time step at or before `stamp_ns` whose 16 bits are `wire`.
std::int64_t resolve_time(std::uint16_t wire, std::int64_t stamp_ns) {
  const std::int64_t now_step = floor_div(stamp_ns, kBevTimeStepNs);
  const std::int64_t back = (now_step - wire) & 0xffff;  // steps before the stamp, mod 2^16
  return (now_step - back) * kBevTimeStepNs;
}

/// Appends one tile's runs; returns false when every cell is unknown.
bool encode_tile(std::span<const BevCell, kBevTileCells> cells, std::vector<std::uint8_t>& out) {
  bool known = false;
  int i = 0;
  while (i < kBevTileCells) {
    const BevCell& c = cells[static_cast<std::size_t>(i)];
    const std::uint16_t t = c.state == BevState::kUnknown ? 0 : wire_time(c.observed_ns);
    int len = 1;
    while (i + len < kBevTileCells && len < kMaxRun) {
      const BevCell& d = cells[static_cast<std::size_t>(i + len)];
      if (d.state != c.state || (c.state != BevState::kUnknown && wire_time(d.observed_ns) != t)) {
        break;
      }
      ++len;
    }
    out.push_back(static_cast<std::uint8_t>((static_cast<int>(c.state) << 6) | (len - 1)));
    if (c.state != BevState::kUnknown) {
      known = true;
      out.push_back(static_cast<std::uint8_t>(t & 0xff));
      out.push_back(static_cast<std::uint8_t>(t >> 8));
    }
    i += len;
  }
  return known;
}

/// The rule between peers: `c` replaces `best` (null: none yet) when it was observed later, or
/// at the same time and occupied where `best` is not. Peers are visited in vehicle id order, so
/// remaining ties go to the smaller id.
bool fresher(const BevCell& c, const BevCell* best) {
  return best == nullptr || c.observed_ns > best->observed_ns ||
         (c.observed_ns == best->observed_ns && c.state == BevState::kOccupied &&
          best->state != BevState::kOccupied);
}

Error refused(const std::string& code, const std::string& message) {
  return Error{"fleet." + code, message};
}

}  // namespace

std::size_t bev_wire_bytes(const BevMessage& m, std::size_t frame_id_length) {
  std::size_t at = 0;  // offset in the CDR body (alignment counts from its start)
  const auto align = [&](std::size_t n) { at = (at + n - 1) / n * n; };
  const auto string = [&](std::size_t length) {
    align(4);
    at += 4 + length + 1;  // length (with the terminator), characters, terminator
  };
  at += 8;  // header.stamp: int32 sec, uint32 nanosec
  string(frame_id_length);
  string(m.vehicle_id.size());
  align(4);
  at += 4;  // sequence_number
  at += 1;  // keyframe
  align(8);
  at += 8;  // resolution
  at += 4;  // position_std_m (float32, aligned after the float64)
  align(4);
  at += 4;  // tiles: count
  for (const BevTile& t : m.tiles) {
    align(4);
    at += 4 + 4 + 4 + t.runs.size();  // x, y, runs: count and bytes
  }
  return 4 + at;  // encapsulation header
}

void sort_in_apply_order(std::vector<BevMessage>& messages) {
  std::sort(messages.begin(), messages.end(), [](const BevMessage& a, const BevMessage& b) {
    return std::tie(a.stamp_ns, a.vehicle_id, a.sequence) <
           std::tie(b.stamp_ns, b.vehicle_id, b.sequence);
  });
}

std::int64_t bev_lattice_index(double origin_m, double resolution_m) {
  return std::llround(origin_m / resolution_m);
}

Status decode_tile(std::span<const std::uint8_t> runs, std::int64_t stamp_ns,
                   std::span<BevCell, kBevTileCells> out) {
  std::size_t at = 0;
  int cell = 0;
  while (at < runs.size()) {
    const std::uint8_t head = runs[at++];
    const int state = head >> 6;
    const int len = (head & (kMaxRun - 1)) + 1;
    if (state > static_cast<int>(BevState::kOccupied)) {
      return refused("malformed", "tile run with state " + std::to_string(state));
    }
    if (cell + len > kBevTileCells) return refused("malformed", "tile runs past 1024 cells");
    BevCell c{static_cast<BevState>(state), 0};
    if (c.state != BevState::kUnknown) {
      if (at + 2 > runs.size()) return refused("malformed", "tile run without its time");
      const auto wire = static_cast<std::uint16_t>(runs[at] | (runs[at + 1] << 8));
      at += 2;
      c.observed_ns = resolve_time(wire, stamp_ns);
    }
    std::fill_n(out.begin() + cell, len, c);
    cell += len;
  }
  if (cell != kBevTileCells) {
    return refused("malformed", "tile covers " + std::to_string(cell) + " of 1024 cells");
  }
  return Ok{};
}

BevEncoder::BevEncoder(std::string vehicle_id, double resolution_m)
    : vehicle_id_(std::move(vehicle_id)), resolution_m_(resolution_m) {}

BevMessage BevEncoder::encode(const BevSnapshot& snapshot, std::int64_t stamp_ns, bool keyframe,
                              std::int64_t max_age_ns) {
  const GridGeometry2D& g = snapshot.geometry;
  TARMAC_ASSERT(g.resolution_m == resolution_m_, "BEV snapshot of another resolution");
  TARMAC_ASSERT(
      snapshot.state.size() == g.cell_count() && snapshot.observed_ns.size() == g.cell_count(),
      "BEV snapshot arrays must cover the geometry");
  BevMessage m;
  m.vehicle_id = vehicle_id_;
  m.stamp_ns = stamp_ns;
  m.sequence = sequence_++;
  m.keyframe = keyframe;
  m.resolution_m = resolution_m_;
  const auto fresh = [&](std::int64_t seen) {
    return seen > 0 && seen <= stamp_ns && stamp_ns - seen <= max_age_ns;
  };
  // Cells observed too long ago are forgotten, here as at the receivers.
  const auto age = [&](std::vector<BevCell>& cells) {
    bool any = false;
    for (BevCell& c : cells) {
      if (c.state != BevState::kUnknown && !fresh(c.observed_ns)) c = BevCell{};
      any = any || c.state != BevState::kUnknown;
    }
    return any;
  };
  const std::int64_t i0 = bev_lattice_index(g.origin_x_m, g.resolution_m);
  const std::int64_t j0 = bev_lattice_index(g.origin_y_m, g.resolution_m);
  const auto w = static_cast<std::int64_t>(g.width), h = static_cast<std::int64_t>(g.height);
  const std::int64_t tx0 = floor_div(i0, kBevTileEdge), tx1 = floor_div(i0 + w - 1, kBevTileEdge);
  const std::int64_t ty0 = floor_div(j0, kBevTileEdge), ty1 = floor_div(j0 + h - 1, kBevTileEdge);
  const auto in_snapshot = [&](const TileKey& k) {
    return w > 0 && h > 0 && k.first >= tx0 && k.first <= tx1 && k.second >= ty0 && k.second <= ty1;
  };
  // Tiles the snapshot covers: its cells over what was held (a tile the window's edge cuts keeps
  // its cells beyond the edge until they age out).
  for (std::int64_t ty = ty0; ty <= ty1 && w > 0 && h > 0; ++ty) {
    for (std::int64_t tx = tx0; tx <= tx1; ++tx) {
      const TileKey key{static_cast<std::int32_t>(tx), static_cast<std::int32_t>(ty)};
      auto it = held_.find(key);
      std::vector<BevCell> cells =
          it != held_.end() ? it->second.cells : std::vector<BevCell>(kBevTileCells);
      for (int cy = 0; cy < kBevTileEdge; ++cy) {
        const std::int64_t y = ty * kBevTileEdge + cy - j0;
        if (y < 0 || y >= h) continue;
        for (int cx = 0; cx < kBevTileEdge; ++cx) {
          const std::int64_t x = tx * kBevTileEdge + cx - i0;
          if (x < 0 || x >= w) continue;
          const auto k = static_cast<std::size_t>(y * w + x);
          BevCell& c = cells[static_cast<std::size_t>(cy * kBevTileEdge + cx)];
          c = snapshot.state[k] == BevState::kUnknown
                  ? BevCell{}
                  : BevCell{snapshot.state[k], snapshot.observed_ns[k]};
        }
      }
      if (!age(cells)) {
        if (it != held_.end()) {
          held_.erase(it);
          if (!keyframe) m.tiles.push_back(unknown_tile(key));  // retracted once
        }
        continue;
      }
      if (it == held_.end()) it = held_.emplace(key, Held{}).first;
      it->second.cells = std::move(cells);
    }
  }
  // Tiles beyond the snapshot (the vehicle drove on): kept while a cell is fresh, not resent
  // as they age (receivers age them alike) — only in keyframes.
  for (auto it = held_.begin(); it != held_.end();) {
    if (!in_snapshot(it->first) && !age(it->second.cells)) {
      it = held_.erase(it);
    } else {
      ++it;
    }
  }
  // At most kBevMaxPeerTiles, as a receiver holds of a peer: the stalest go (retracted).
  while (held_.size() > kBevMaxPeerTiles) {
    auto stalest = held_.begin();
    std::int64_t stalest_ns = INT64_MAX;
    for (auto it = held_.begin(); it != held_.end(); ++it) {
      std::int64_t newest = 0;
      for (const BevCell& c : it->second.cells) newest = std::max(newest, c.observed_ns);
      if (newest < stalest_ns) {
        stalest_ns = newest;
        stalest = it;
      }
    }
    if (!keyframe) m.tiles.push_back(unknown_tile(stalest->first));
    held_.erase(stalest);
  }
  for (auto& [key, tile] : held_) {
    std::vector<std::uint8_t> runs;
    encode_tile(std::span<const BevCell, kBevTileCells>(tile.cells.data(), kBevTileCells), runs);
    if (keyframe || (in_snapshot(key) && runs != tile.sent)) {
      m.tiles.push_back(BevTile{key.first, key.second, runs});
      tile.sent = std::move(runs);
    }
  }
  std::sort(m.tiles.begin(), m.tiles.end(), [](const BevTile& a, const BevTile& b) {
    return TileKey{a.x, a.y} < TileKey{b.x, b.y};
  });
  return m;
}

BevTile BevEncoder::unknown_tile(std::pair<std::int32_t, std::int32_t> key) {
  BevTile t{key.first, key.second, {}};
  for (int n = 0; n < kBevTileCells; n += kMaxRun) t.runs.push_back(kMaxRun - 1);
  return t;
}

BevPeers::BevPeers(std::string own_id, double resolution_m, std::int64_t max_age_ns,
                   std::int64_t max_future_ns, double max_position_std_m)
    : own_id_(std::move(own_id)),
      resolution_m_(resolution_m),
      max_age_ns_(max_age_ns),
      max_future_ns_(max_future_ns),
      max_position_std_m_(max_position_std_m) {}

Status BevPeers::apply(const BevMessage& m, std::int64_t now_ns) {
  if (m.vehicle_id.empty()) return refused("malformed", "message without a vehicle id");
  if (stats_.count(m.vehicle_id) == 0 && stats_.size() >= kBevMaxPeers) {
    return refused("too_many_peers", m.vehicle_id + ": already kBevMaxPeers peers");
  }
  BevPeerStats& st = stats_[m.vehicle_id];
  const auto refuse = [&](const std::string& code, const std::string& message) -> Status {
    ++st.rejected;
    return refused(code, m.vehicle_id + ": " + message);
  };
  if (m.vehicle_id == own_id_) return refuse("own_id", "a message with this vehicle's own id");
  if (m.resolution_m != resolution_m_) return refuse("resolution", "another resolution");
  if (max_position_std_m_ > 0.0 && !(m.position_std_m <= max_position_std_m_)) {
    // Its cells may sit further from where they are than the receiver's margin covers.
    return refuse("localisation", "position uncertainty beyond the fleet's bound");
  }
  if (m.stamp_ns > now_ns + max_future_ns_) return refuse("future", "stamped in the future");
  if (m.stamp_ns < now_ns - max_age_ns_) return refuse("stale", "older than fleet.max_age_s");
  Peer& peer = peers_[m.vehicle_id];
  if (peer.last_stamp_ns != 0 && m.stamp_ns <= peer.last_stamp_ns) {
    return refuse("order", "not newer than the last message applied");
  }
  if (!m.keyframe && (!peer.synced || m.sequence != peer.last_sequence + 1)) {
    // A change message after a lost one (or before any keyframe): the tiles it does not carry
    // may have changed in the lost one. Ignored until the next keyframe.
    peer.synced = false;
    ++st.gaps;
    return Ok{};
  }
  if (m.tiles.size() > kBevMaxPeerTiles) return refuse("too_large", "too many tiles");
  // Decode every tile first: a malformed message changes nothing.
  std::vector<std::vector<BevCell>> decoded(m.tiles.size(), std::vector<BevCell>(kBevTileCells));
  for (std::size_t t = 0; t < m.tiles.size(); ++t) {
    const BevTile& tile = m.tiles[t];
    if (std::abs(tile.x) > kMaxTileIndex || std::abs(tile.y) > kMaxTileIndex) {
      return refuse("malformed", "tile index out of range");
    }
    if (tile.runs.size() > kMaxTileBytes) return refuse("malformed", "tile runs too long");
    auto ok = decode_tile(tile.runs, m.stamp_ns,
                          std::span<BevCell, kBevTileCells>(decoded[t].data(), kBevTileCells));
    if (!ok) return refuse("malformed", ok.error().message);
  }
  std::vector<TileKey> keys(m.tiles.size());
  for (std::size_t t = 0; t < m.tiles.size(); ++t) keys[t] = {m.tiles[t].x, m.tiles[t].y};
  std::sort(keys.begin(), keys.end());
  if (std::adjacent_find(keys.begin(), keys.end()) != keys.end()) {
    return refuse("malformed", "a tile sent twice");
  }
  std::vector<char> known(m.tiles.size());
  for (std::size_t t = 0; t < m.tiles.size(); ++t) {
    known[t] = std::any_of(decoded[t].begin(), decoded[t].end(),
                           [](const BevCell& c) { return c.state != BevState::kUnknown; });
  }
  // A bound on what one peer can make this vehicle hold (its memory is locked), counted before
  // anything changes (a message's tiles are distinct: checked above).
  std::size_t held = m.keyframe ? 0 : peer.tiles.size();
  for (std::size_t t = 0; t < m.tiles.size(); ++t) {
    const bool had = !m.keyframe && peer.tiles.count({m.tiles[t].x, m.tiles[t].y}) != 0;
    held = held + (known[t] && !had ? 1 : 0) - (!known[t] && had ? 1 : 0);
  }
  if (held > kBevMaxPeerTiles) return refuse("too_large", "would hold too many tiles");
  if (m.keyframe) peer.tiles.clear();
  for (std::size_t t = 0; t < m.tiles.size(); ++t) {
    const TileKey key{m.tiles[t].x, m.tiles[t].y};
    if (known[t]) {
      peer.tiles[key] = std::move(decoded[t]);
    } else {
      peer.tiles.erase(key);
    }
  }
  peer.synced = true;
  peer.last_sequence = m.sequence;
  peer.last_stamp_ns = m.stamp_ns;
  ++st.messages;
  st.newest_stamp_ns = m.stamp_ns;
  st.tiles = peer.tiles.size();
  return Ok{};
}

void BevPeers::expire(std::int64_t now_ns) {
  const std::int64_t oldest = now_ns - max_age_ns_;
  for (auto& [id, peer] : peers_) {
    for (auto it = peer.tiles.begin(); it != peer.tiles.end();) {
      bool any = false;
      for (BevCell& c : it->second) {
        if (c.state != BevState::kUnknown && c.observed_ns < oldest) c = BevCell{};
        any = any || c.state != BevState::kUnknown;
      }
      it = any ? std::next(it) : peer.tiles.erase(it);
    }
    stats_[id].tiles = peer.tiles.size();
  }
}

std::vector<std::pair<std::int32_t, std::int32_t>> BevPeers::tiles() const {
  std::vector<TileKey> keys;
  for (const auto& [id, peer] : peers_) {
    for (const auto& [key, cells] : peer.tiles) keys.push_back(key);
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

BevPeerCell BevPeers::lookup(std::int64_t i, std::int64_t j) const {
  const TileKey key{static_cast<std::int32_t>(floor_div(i, kBevTileEdge)),
                    static_cast<std::int32_t>(floor_div(j, kBevTileEdge))};
  const auto offset =
      static_cast<std::size_t>((j - std::int64_t{key.second} * kBevTileEdge) * kBevTileEdge +
                               (i - std::int64_t{key.first} * kBevTileEdge));
  BevPeerCell best;
  for (const auto& [id, peer] : peers_) {  // vehicle id order: ties go to the smaller id
    const auto it = peer.tiles.find(key);
    if (it == peer.tiles.end()) continue;
    const BevCell& c = it->second[offset];
    if (c.state == BevState::kUnknown) continue;
    if (fresher(c, best.vehicle_id == nullptr ? nullptr : &best.cell)) best = BevPeerCell{c, &id};
  }
  return best;
}

BevFusionCounts BevPeers::fuse(const GridGeometry2D& g,
                               std::span<const std::int64_t> own_observed_ns, std::int64_t now_ns,
                               std::span<std::uint8_t> column_class) const {
  TARMAC_ASSERT(g.resolution_m == resolution_m_, "fusing BEV cells of another resolution");
  TARMAC_ASSERT(own_observed_ns.size() == g.cell_count() && column_class.size() == g.cell_count(),
                "fusion arrays must cover the geometry");
  // ColumnClass values (costmap_builder.hpp), kept numeric here: the costmap is not this
  // file's business beyond them.
  constexpr std::uint8_t kFree = 0, kObstacle = 1, kUnknown = 2, kVirtual = 3;
  BevFusionCounts counts;
  if (peers_.empty() || g.cell_count() == 0) return counts;
  const std::int64_t oldest = now_ns - max_age_ns_;
  const std::int64_t i0 = bev_lattice_index(g.origin_x_m, g.resolution_m);
  const std::int64_t j0 = bev_lattice_index(g.origin_y_m, g.resolution_m);
  const auto w = static_cast<std::int64_t>(g.width), h = static_cast<std::int64_t>(g.height);
  // Tile by tile: each peer's tile is looked up once, not once per cell.
  struct Held {
    const std::string* id;
    const std::vector<BevCell>* cells;
  };
  std::vector<Held> held;
  for (std::int64_t ty = floor_div(j0, kBevTileEdge); ty <= floor_div(j0 + h - 1, kBevTileEdge);
       ++ty) {
    for (std::int64_t tx = floor_div(i0, kBevTileEdge); tx <= floor_div(i0 + w - 1, kBevTileEdge);
         ++tx) {
      held.clear();
      const TileKey key{static_cast<std::int32_t>(tx), static_cast<std::int32_t>(ty)};
      for (const auto& [id, peer] : peers_) {  // vehicle id order: ties go to the smaller id
        const auto it = peer.tiles.find(key);
        if (it != peer.tiles.end()) held.push_back(Held{&id, &it->second});
      }
      if (held.empty()) continue;
      const std::int64_t y_lo = std::max<std::int64_t>(0, ty * kBevTileEdge - j0);
      const std::int64_t y_hi = std::min<std::int64_t>(h, (ty + 1) * kBevTileEdge - j0);
      const std::int64_t x_lo = std::max<std::int64_t>(0, tx * kBevTileEdge - i0);
      const std::int64_t x_hi = std::min<std::int64_t>(w, (tx + 1) * kBevTileEdge - i0);
      for (std::int64_t y = y_lo; y < y_hi; ++y) {
        for (std::int64_t x = x_lo; x < x_hi; ++x) {
          const auto k = static_cast<std::size_t>(y * w + x);
          const std::uint8_t own = column_class[k];
          if (own == kVirtual) continue;
          const auto offset = static_cast<std::size_t>((j0 + y - ty * kBevTileEdge) * kBevTileEdge +
                                                       (i0 + x - tx * kBevTileEdge));
          const BevCell* best = nullptr;
          const std::string* best_id = nullptr;
          for (const Held& p : held) {
            const BevCell& c = (*p.cells)[offset];
            if (c.state == BevState::kUnknown || c.observed_ns < oldest) continue;
            if (fresher(c, best)) {
              best = &c;
              best_id = p.id;
            }
          }
          if (best == nullptr) continue;
          if (own != kUnknown && own_observed_ns[k] >= best->observed_ns) continue;
          const bool occupied = best->state == BevState::kOccupied;
          column_class[k] = occupied ? kObstacle : kFree;
          ++counts.cells;
          counts.occupied += occupied ? 1 : 0;
          ++counts.cells_by_peer[*best_id];
          counts.newest_observed_ns = std::max(counts.newest_observed_ns, best->observed_ns);
        }
      }
    }
  }
  return counts;
}

}  // namespace tarmac::core
