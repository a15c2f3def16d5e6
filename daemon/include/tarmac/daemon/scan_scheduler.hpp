#pragma once
/// @file Which scans a tick integrates, decided from stamps and point counts only (DESIGN.md §3):
/// scans wait in a fixed pool of slots; a tick takes those stamped <= tick − input delay, in
/// (stamp, sensor) order, each with its pose interpolated at its stamp (and, for deskew, at its
/// first and last point time); a scan whose poses have not
/// arrived waits (and holds back the later ones, so order is kept) until pose_wait has passed,
/// then it is dropped; the points quota defers the rest to the next tick. The tick time is the
/// schedule's deadline, never a clock reading, so for inputs that arrive within the input delay
/// the integrated sequence is the same whatever the arrival jitter.

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/deskew.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/daemon/pose_buffer.hpp"
#include "tarmac/daemon/reason_counters.hpp"

namespace tarmac::daemon {

struct SchedulerParams {
  std::int64_t input_delay_ns = 20'000'000;
  std::int64_t pose_wait_ns = 100'000'000;
  std::int64_t max_future_ns = 200'000'000;
  std::vector<std::int64_t> max_age_ns;  ///< per sensor
  /// Per sensor: motion-compensate scans that carry per-point times (empty: none). Such a scan
  /// also waits for the poses at its earliest and latest point time.
  std::vector<bool> deskew;
  /// A scan whose point times span more than this is integrated without deskew (counted as
  /// "scan.deskew_span"): no LiDAR sweeps that long, so the times are not offsets in seconds.
  std::int64_t max_sweep_ns = 500'000'000;
  std::uint64_t points_per_cycle = 500'000;
  std::uint64_t points_per_scan = 262'144;
  std::uint32_t max_pending = 8;
  std::uint64_t reserve_points =
      0;  ///< reserved and touched per slot (every channel) at construction
};

class ScanScheduler {
 public:
  struct Selected {
    std::uint32_t slot = 0;
    std::uint32_t sensor = 0;
    Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
    bool deskew = false;  ///< `motion` holds the poses at the sweep's first and last point
    core::ScanMotion motion;
  };
  struct TickStats {
    std::uint64_t deferred_scans = 0;    ///< eligible but over the points quota: next tick
    std::uint64_t decimated_points = 0;  ///< removed by the per-scan quota
  };

  explicit ScanScheduler(const SchedulerParams& params);

  /// The slot the next scan is parsed into. When every slot holds a pending scan, the oldest
  /// pending scan is shed (counted in `drops` as "scan.shed_pending_full") and its slot reused.
  core::PointCloud& slot(ReasonCounters& drops);
  /// Keeps the scan just parsed into slot() as pending for `sensor`, unless its stamp is
  /// rejected at `tick_ns`: "scan.future", "scan.stale", "scan.late" (not after the last
  /// integrated scan of the order).
  void commit(std::uint32_t sensor, std::int64_t tick_ns, ReasonCounters& rejections);

  /// Fills `out` (cleared, capacity kept) with the scans to integrate at `tick_ns`, in
  /// (stamp, sensor) order, and marks them as integrated (call release() after use). RT-safe.
  TickStats select(std::int64_t tick_ns, const PoseBuffer& poses, std::vector<Selected>& out,
                   ReasonCounters& drops);

  /// The stamp clock stepped (a wall-clock jump) and ticks now sit at `tick_ns` on the new
  /// clock: each pending scan is judged again as commit() would judge it ("scan.future",
  /// "scan.stale", counted in `rejections`, its slot freed), and the stamp order and the
  /// per-sensor newest stamps that lie beyond tick + max_future (from the old clock, after a
  /// backward step) are forgotten, so scans stamped by the new clock are taken. Returns the
  /// pending scans rejected. RT-safe.
  std::size_t on_clock_step(std::int64_t tick_ns, ReasonCounters& rejections);

  [[nodiscard]] core::PointCloud& cloud(std::uint32_t slot) { return slots_[slot].cloud; }
  /// Frees a selected slot for reuse.
  void release(std::uint32_t slot) { slots_[slot].state = State::kFree; }

  [[nodiscard]] std::size_t pending() const;
  /// Stamp of the oldest pending scan (INT64_MAX when none).
  [[nodiscard]] std::int64_t oldest_pending_stamp() const;
  /// Newest committed stamp per sensor (0 when none yet).
  [[nodiscard]] std::int64_t newest_stamp(std::uint32_t sensor) const { return newest_[sensor]; }

 private:
  enum class State : std::uint8_t { kFree, kStaged, kPending, kSelected };
  struct Slot {
    core::PointCloud cloud;
    std::uint32_t sensor = 0;
    State state = State::kFree;
  };
  [[nodiscard]] bool before(std::uint32_t a, std::uint32_t b) const;
  void decimate(core::PointCloud& cloud, TickStats& stats) const;

  SchedulerParams params_;
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> order_;  // scratch: pending slots sorted
  std::vector<std::int64_t> newest_;
  std::uint32_t staged_ = 0;
  bool have_last_ = false;
  std::int64_t last_stamp_ = 0;  // last integrated (stamp, sensor)
  std::uint32_t last_sensor_ = 0;
};

}  // namespace tarmac::daemon
