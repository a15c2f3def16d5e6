#pragma once
/// @file tarmacd's fixed-rate, time-triggered executor (DESIGN.md §3). One tick per period on
/// absolute deadlines (next += period; sleep until next); a late wake skips the missed ticks
/// (counted, never run in a burst). Each tick drains the DDS queues, selects scans by stamp
/// (ScanScheduler), runs ingest + integrate per scan and the costmap once on the worker pool,
/// publishes the costmap, the ESDF slice, a CycleReport (and now and then a DiagnosticArray),
/// and pings the systemd watchdog. Wall time is measured and reported, never used to decide.
/// Ticks are slept to on CLOCK_MONOTONIC and carry a time on the stamp clock (CLOCK_REALTIME);
/// when the stamp clock steps against the monotonic one (a wall-clock jump) the tick times
/// follow it in whole periods, while the schedule itself is untouched: no burst, no stall.
/// A stop is seen within kStopPollSlice while asleep, never inside a tick.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "tarmac/config/config.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::daemon {

/// Totals since start, for the exit log and for tests.
struct ExecutorTotals {
  std::uint64_t ticks = 0;
  std::uint64_t skipped_ticks = 0;
  std::uint64_t scans_integrated = 0;
  std::uint64_t overruns = 0;
  std::int64_t newest_stamp_ns = 0;
  std::uint64_t tsdf_scans = 0;       ///< scans integrated into the TSDF
  std::uint64_t tsdf_shed_scans = 0;  ///< scans whose TSDF stage was shed by the points quota
  std::uint64_t tsdf_saves = 0;       ///< periodic TSDF saves written (not the one on exit)
  std::uint64_t tsdf_save_failures = 0;
  std::uint64_t tsdf_saves_skipped = 0;      ///< periodic saves skipped: the previous still writing
  std::uint64_t pose_jumps = 0;              ///< jumps in the pose stream taken as corrections
  std::uint64_t trajectory_corrections = 0;  ///< corrected trajectories (nav_msgs/Path) applied
  std::uint64_t late_corrections = 0;    ///< of those, applied out of stamp order (arrived late)
  std::uint64_t rebuilds_completed = 0;  ///< rebuilt windows swapped in
  std::uint64_t scans_reintegrated = 0;  ///< retained scans re-integrated by rebuilds
  std::uint64_t clock_steps = 0;         ///< steps of the stamp clock the ticks followed
  std::int64_t last_clock_step_ns = 0;   ///< the last such step (+: the clock jumped ahead)
  std::uint64_t fleet_messages_published = 0;  ///< this vehicle's fleet summaries sent
  std::uint64_t fleet_bytes_published = 0;     ///< their serialized bytes
};

/// What load_tsdf() found in the state directory.
struct TsdfLoadResult {
  enum class Kind { kDisabled, kAbsent, kLoaded, kRefused };
  Kind kind = Kind::kDisabled;
  std::size_t voxels = 0;         ///< observed voxels loaded
  std::size_t static_voxels = 0;  ///< static occupancy voxels loaded
  std::string error;              ///< kRefused: the tsdf_io error ("code: message")
};

/// Instrumentation for tests and benchmarks, and tarmacd's stop handshake; empty by default.
struct RunHooks {
  std::function<void()> on_thread_start;  ///< on the executor and each worker thread
  /// On the executor thread after each tick, before its watchdog ping (a hook that blocks
  /// stalls the loop, and the pings stop).
  std::function<void(std::uint64_t)> on_tick_end;
  /// On the executor thread once the tick loop has ended, before run() waits for an in-flight
  /// periodic save (tarmacd: StopSignals::loop_ended()).
  std::function<void()> on_loop_end;
  /// The stamp clock (empty: CLOCK_REALTIME), read on the executor thread at start and once per
  /// tick; must be RT-safe. Tests step it to play a wall-clock jump, which the machine's own
  /// clock cannot do in a test.
  std::function<std::int64_t()> stamp_clock_ns;
};

class Executor {
 public:
  /// The longest the executor sleeps without checking its stop predicate: a stop reaches a
  /// loop asleep in a long period (rate_hz 0.1: 10 s) within this.
  static constexpr std::chrono::milliseconds kStopPollSlice{100};

  /// Creates the DDS participant, readers and writers and the mapper. Fails with the DDS or
  /// config error. After it returns, every DDS entity exists (READY=1 may be sent). Refuses,
  /// before any DDS entity exists, a schedule the loop could not keep ("config.range"): a rate
  /// that is not finite or outside [config::kMinRateHz, config::kMaxRateHz], a delay, phase or
  /// wait that is not finite or outside [0, 1 h] (the loader refuses them first; this guards
  /// configs built in code).
  static core::Result<std::unique_ptr<Executor>> create(const config::Config& config);
  ~Executor();
  Executor(const Executor&) = delete;
  Executor& operator=(const Executor&) = delete;

  /// Applies pinning / SCHED_FIFO / mlockall to the calling thread (failures logged once) and
  /// starts the worker pool and the periodic saver. Call it on the thread that will call run(),
  /// before READY=1: mlockall faults the whole process in (hundreds of ms with the window and a
  /// loaded TSDF), and scans that arrive meanwhile would pile up for the first tick. Idempotent;
  /// `hooks.on_thread_start` is taken from the first call.
  void prepare(const RunHooks& hooks = {});

  /// Runs ticks on the calling thread until `stop_requested()` returns true. It is checked
  /// after every tick and at least every kStopPollSlice while the loop sleeps, never inside a
  /// tick: the loop ends within kStopPollSlice, or when the current tick completes. Sends
  /// WATCHDOG=1 after each completed tick, and from nowhere else. Calls prepare(hooks) first if
  /// it has not run. `stop_requested` is called on the executor thread and must be RT-safe.
  void run(const std::function<bool()>& stop_requested, const RunHooks& hooks = {});

  /// Writes the occupancy window to state.dir/state.map_file. Not for the cycle.
  core::Status save_map() const;
  /// Writes the static map (the TSDF and the occupancy's static layer) to
  /// state.dir/state.tsdf_file with tsdf_io (atomic: .tmp, fsync, rename).
  /// Not for the cycle, and not while run() runs (call it after run() returns).
  core::Status save_tsdf() const;
  /// Before run(): loads state.dir/state.tsdf_file (TSDF and static occupancy, whose voxel size
  /// must match occupancy.voxel_size_m) into the mapper when tsdf.enabled and
  /// state.load_on_start. A file that tsdf_io refuses (truncated, corrupt, other format, other
  /// frame / voxel size / truncation) is renamed to <file>.refused and the map starts empty.
  /// Logs one line either way; never throws.
  TsdfLoadResult load_tsdf();
  /// The TSDF layer, for tests: only while run() is not running.
  [[nodiscard]] const core::TsdfLayer& tsdf() const;
  /// The occupancy map (window and static layer), for tests: only while run() is not running.
  [[nodiscard]] const core::OccupancyMap& occupancy() const;

  [[nodiscard]] ExecutorTotals totals() const;
  /// One line for systemd's STATUS= and the logs.
  [[nodiscard]] std::string status_line() const;
  /// The same into a caller's buffer (no allocation: the executor sends it every second).
  void format_status(char* buf, std::size_t size) const;

  class Impl;

 private:
  explicit Executor(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::daemon
