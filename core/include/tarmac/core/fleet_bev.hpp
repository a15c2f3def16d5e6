#pragma once
/// @file Fleet sharing of bird's-eye occupancy (issue 21): what one vehicle tells the others of
/// the cells it observed, encoded compactly, and what a vehicle keeps of its peers' summaries.
///
/// Cells lie on the global lattice of the shared `map` frame: cell (i, j) covers
/// [i·r, (i+1)·r) × [j·r, (j+1)·r) for the fleet's resolution r, so summaries of vehicles whose
/// windows sit anywhere line up cell for cell. A summary is cut into tiles of kBevTileEdge²
/// cells on that lattice; a message carries whole tiles, each as runs of cells with the same
/// state and observation time (BevTile). A keyframe carries every tile with something known; the
/// messages between carry only the tiles that changed since the message before, so a receiver
/// that missed one waits for the next keyframe (BevPeers).
///
/// Observation times travel as deciseconds of the map clock modulo 2^16 (109 minutes): a cell
/// that nothing touched since the last message encodes the same, so its tile is not resent.
/// Core code: stamps are arguments, nothing here reads a clock.

#include <cstdint>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::core {

/// What a vehicle knows of a cell.
enum class BevState : std::uint8_t { kUnknown = 0, kFree = 1, kOccupied = 2 };

/// Cells along a tile's edge: a tile holds 32 × 32 cells (6.4 m at 0.2 m).
constexpr int kBevTileEdge = 32;
constexpr int kBevTileCells = kBevTileEdge * kBevTileEdge;
/// The most tiles held of one peer (and carried by one message): 1024 tiles of 6.4 m are
/// ~42,000 m² at 0.2 m, more than a vehicle's window; 16 MB of decoded cells.
constexpr std::size_t kBevMaxPeerTiles = 1024;
/// The most vehicles kept track of: a message naming one more is refused ("too_many_peers"), so
/// a sender inventing ids cannot grow what a vehicle holds.
constexpr std::size_t kBevMaxPeers = 64;
/// Observation times are kept to this step (0.1 s).
constexpr std::int64_t kBevTimeStepNs = 100'000'000;

/// One tile of a message: tile (x, y) holds the lattice cells [x·E, (x+1)·E) × [y·E, (y+1)·E),
/// E = kBevTileEdge. `runs` are the tile's cells row by row (x fastest), as runs: a byte
/// (state << 6) | (length − 1), length 1..64, followed for a known state by the cells'
/// observation time, 16 bits little-endian (BevTime). Every tile covers its 1024 cells exactly.
struct BevTile {
  std::int32_t x = 0;
  std::int32_t y = 0;
  std::vector<std::uint8_t> runs;
  friend bool operator==(const BevTile&, const BevTile&) = default;
};

/// One message of a vehicle's summary (the IDL message tarmac_msgs/FleetBev in transport).
struct BevMessage {
  std::string vehicle_id;
  std::int64_t stamp_ns = 0;   ///< the summary's time, map clock
  std::uint32_t sequence = 0;  ///< +1 per message of this vehicle
  bool keyframe = false;       ///< every known tile; false: the tiles changed since sequence − 1
  double resolution_m = 0.2;
  /// The sender's horizontal position uncertainty (1σ, m) from its localiser; 0: not stated.
  double position_std_m = 0.0;
  std::vector<BevTile> tiles;
};

/// A vehicle's own cells, on its costmap's geometry (lattice-aligned: origin = k·resolution):
/// each cell's state and the time of its last observation (0: never).
struct BevSnapshot {
  GridGeometry2D geometry;
  std::span<const BevState> state;
  std::span<const std::int64_t> observed_ns;
};

/// A cell as decoded: its state and observation time (ns, to kBevTimeStepNs).
struct BevCell {
  BevState state = BevState::kUnknown;
  std::int64_t observed_ns = 0;
};

/// The encoder of one vehicle's messages: remembers the tiles it sent, to send only changes.
class BevEncoder {
 public:
  BevEncoder(std::string vehicle_id, double resolution_m);

  /// The message of `snapshot` at `stamp_ns`: every tile with a known cell when `keyframe`,
  /// else the snapshot's tiles whose encoding changed since they were last sent (a tile that
  /// became all unknown is sent once as unknown). What the vehicle observed and then left
  /// behind (cells beyond the snapshot, e.g. its window moved on) stays in its summary until it
  /// is older than `max_age_ns` — in keyframes; receivers age those cells alike. Cells observed
  /// more than `max_age_ns` before the stamp are sent as unknown. At most kBevMaxPeerTiles
  /// tiles are kept (the stalest retracted).
  /// @pre snapshot's resolution is the encoder's and its origin lies on the lattice.
  BevMessage encode(const BevSnapshot& snapshot, std::int64_t stamp_ns, bool keyframe,
                    std::int64_t max_age_ns);

  [[nodiscard]] std::uint32_t next_sequence() const { return sequence_; }

 private:
  /// A tile as this vehicle knows it (cells beyond its window kept until they age out) and as
  /// it was last sent.
  struct Held {
    std::vector<BevCell> cells;
    std::vector<std::uint8_t> sent;
  };
  static BevTile unknown_tile(std::pair<std::int32_t, std::int32_t> key);

  std::string vehicle_id_;
  double resolution_m_;
  std::uint32_t sequence_ = 0;
  std::map<std::pair<std::int32_t, std::int32_t>, Held> held_;
};

/// Decodes one tile's runs into its kBevTileCells cells (row by row), observation times resolved
/// as the latest time at or before `stamp_ns` with the same 16-bit value. An error names what is
/// malformed (a run past the tile's end, a short tile, a bad state, a truncated time).
Status decode_tile(std::span<const std::uint8_t> runs, std::int64_t stamp_ns,
                   std::span<BevCell, kBevTileCells> out);

/// What one peer has told, and how it went.
struct BevPeerStats {
  std::uint64_t messages = 0;  ///< applied
  std::uint64_t rejected = 0;  ///< malformed, stale, from the future, wrong resolution
  std::uint64_t gaps = 0;      ///< a change message after a lost one: ignored to the keyframe
  std::int64_t newest_stamp_ns = 0;
  std::size_t tiles = 0;  ///< held now
};

/// The freshest peer knowledge of one cell, and whose it is.
struct BevPeerCell {
  BevCell cell;
  const std::string* vehicle_id = nullptr;  ///< nullptr: no peer knows the cell
};

/// What fusing the peers' cells into a costmap's column classes did (BevPeers::fuse).
struct BevFusionCounts {
  std::uint64_t cells = 0;     ///< cells whose class came from a peer
  std::uint64_t occupied = 0;  ///< of which obstacles
  std::map<std::string, std::uint64_t> cells_by_peer;
  std::int64_t newest_observed_ns = 0;  ///< newest peer observation used (0: none)
};

/// What a vehicle keeps of its peers' summaries: per peer, its tiles as last told. Messages must
/// be applied in stamp order (as scans are) for the result to be deterministic.
class BevPeers {
 public:
  /// @param own_id messages with this vehicle id are refused (one's own, or a peer claiming it)
  /// @param max_age_ns peer observations older than this are forgotten (expire())
  /// @param max_future_ns a message stamped later than now + this is refused
  /// @param max_position_std_m a message whose sender states a position uncertainty (1σ) above
  ///        this is refused ("localisation"); 0: no bound
  BevPeers(std::string own_id, double resolution_m, std::int64_t max_age_ns,
           std::int64_t max_future_ns = 500'000'000, double max_position_std_m = 0.0);

  /// Applies one message received at `now_ns`. Refused (counted in the peer's stats, the peer's
  /// tiles unchanged) when malformed, stale (stamp older than now − max age), from the future,
  /// of another resolution, not newer than the peer's last, holding the peer to more than
  /// kBevMaxPeerTiles tiles, from a vehicle beyond the first kBevMaxPeers, or from a sender whose
  /// stated position uncertainty exceeds the bound; a change message
  /// whose sequence
  /// does not follow the last applied one is counted as a gap and ignored, and so is every
  /// change message after it until a keyframe. Returns the refusal, Ok otherwise.
  Status apply(const BevMessage& message, std::int64_t now_ns);

  /// Forgets the tiles whose every cell was observed before now − max age, and cells older than
  /// that inside the tiles kept.
  void expire(std::int64_t now_ns);

  /// The freshest observation of lattice cell (i, j) over all peers (ties: occupied first, then
  /// the smaller vehicle id).
  [[nodiscard]] BevPeerCell lookup(std::int64_t i, std::int64_t j) const;

  /// The fusion rules, on the column classes of a costmap (values of ColumnClass: 0 free,
  /// 1 obstacle, 2 unknown, 3 virtual) on lattice-aligned geometry `g`, with each cell's own
  /// last observation time (0: never). A cell takes the freshest peer observation not older than
  /// now − max age when its own class is unknown or its own observation is older than the
  /// peer's: the peer's occupied as an obstacle, its free as free. A cell observed here at or
  /// after the peer's time keeps its own class (a fresh own observation is never overridden);
  /// virtual-zone cells are never changed.
  BevFusionCounts fuse(const GridGeometry2D& g, std::span<const std::int64_t> own_observed_ns,
                       std::int64_t now_ns, std::span<std::uint8_t> column_class) const;

  [[nodiscard]] const std::map<std::string, BevPeerStats>& stats() const { return stats_; }
  /// Every tile some peer holds, sorted, each once (the site view's extent).
  [[nodiscard]] std::vector<std::pair<std::int32_t, std::int32_t>> tiles() const;
  [[nodiscard]] double resolution_m() const { return resolution_m_; }
  [[nodiscard]] std::int64_t max_age_ns() const { return max_age_ns_; }

 private:
  struct Peer {
    std::uint32_t last_sequence = 0;
    bool synced = false;  ///< a keyframe applied and no message lost since
    std::int64_t last_stamp_ns = 0;
    std::map<std::pair<std::int32_t, std::int32_t>, std::vector<BevCell>> tiles;
  };
  std::string own_id_;
  double resolution_m_;
  std::int64_t max_age_ns_;
  std::int64_t max_future_ns_;
  double max_position_std_m_;
  std::map<std::string, Peer> peers_;
  std::map<std::string, BevPeerStats> stats_;
};

/// The bytes of `message` on the wire as tarmac_msgs/FleetBev in a frame named with
/// `frame_id_length` characters: its CDR serialisation (XCDR1, little endian, 4-byte
/// encapsulation header), without the RTPS and UDP headers around it. For the fleet's traffic
/// figures; a transport test checks it against Fast DDS's own size.
std::size_t bev_wire_bytes(const BevMessage& message, std::size_t frame_id_length);

/// Sorts summaries into the order they are applied in: stamp, then vehicle id, then sequence
/// (tarmacd and tarmac-fleet alike, so both hold the same peers' cells).
void sort_in_apply_order(std::vector<BevMessage>& messages);

/// Lattice index of a cell coordinate of a lattice-aligned geometry's origin (origin / r).
std::int64_t bev_lattice_index(double origin_m, double resolution_m);

}  // namespace tarmac::core
