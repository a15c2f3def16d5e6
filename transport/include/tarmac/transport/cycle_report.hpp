#pragma once
/// @file What tarmacd reports about one executor tick, as plain values. transport/ turns it into
/// tarmac_msgs/CycleReport (and a DiagnosticArray); the daemon fills it. Capacity is reused from
/// tick to tick (assign into existing elements; vectors keep their capacity).

#include <cstdint>
#include <string>
#include <vector>

namespace tarmac::transport {

/// One stage of one tick.
struct StageReport {
  std::string name;
  double duration_ms = 0.0;
  double budget_ms = 0.0;
  bool overrun = false;          ///< duration_ms > budget_ms
  std::uint64_t shed_items = 0;  ///< work shed by the stage's quota this tick
};

/// A counter by reason: drops and rejections.
struct ReasonReport {
  std::string reason;
  std::uint64_t count = 0;  ///< this tick
  std::uint64_t total = 0;  ///< since start
};

/// Age of the newest sample of one input at tick time.
struct InputAgeReport {
  std::string input;    ///< sensor id or "pose"
  double age_ms = 0.0;  ///< 0 if stamped at or after the tick; -1 when none yet
  bool stale = false;   ///< older than the input's limit (or never received)
};

/// What one peer vehicle's summaries gave this vehicle (fleet sharing).
struct FleetPeerReport {
  std::string vehicle_id;
  std::uint64_t cells = 0;  ///< costmap cells whose class came from this peer, this tick
  double age_ms = -1.0;     ///< tick time minus its newest applied summary's stamp
  std::uint64_t messages = 0, rejected = 0, gaps = 0;  ///< since start
};

struct CycleReport {
  std::int64_t stamp_ns = 0;  ///< newest integrated scan stamp (0 before the first)
  std::string frame_id;
  std::uint64_t cycle_index = 0;
  std::int64_t tick_ns = 0;  ///< the tick's deadline on the stamp clock, not its wake time
  double wake_jitter_ms = 0.0;
  std::uint32_t skipped_ticks = 0;  ///< ticks skipped before this one (late wake), never run
  std::vector<StageReport> stages;
  double cycle_duration_ms = 0.0;
  double cycle_budget_ms = 0.0;
  bool overrun = false;  ///< any stage or the whole tick over budget
  std::vector<ReasonReport> drops;
  std::vector<ReasonReport> rejections;
  std::vector<InputAgeReport> input_ages;
  std::uint64_t points_in = 0;
  std::uint64_t points_used = 0;
  std::uint64_t map_memory_bytes = 0;
  std::string config_hash;
  std::vector<FleetPeerReport> fleet_peers;  ///< empty with fleet sharing off
  double fleet_newest_age_ms = -1.0;         ///< tick time minus the newest peer cell used; -1 none
  std::uint32_t debris = 0;  ///< debris pieces in the latest costmap's debris report
  /// Window columns the tick's scans changed (each scan's summed): 0 while scans arrive says
  /// they add nothing to the map.
  std::uint32_t columns_changed = 0;
};

/// The DiagnosticArray tarmacd publishes now and then: one status with key/value pairs.
struct DiagnosticReport {
  std::int64_t stamp_ns = 0;
  std::uint8_t level = 0;  ///< 0 OK, 1 WARN, 2 ERROR, 3 STALE (diagnostic_msgs)
  std::string name;
  std::string message;
  std::string hardware_id;
  std::vector<std::pair<std::string, std::string>> values;
};

}  // namespace tarmac::transport
