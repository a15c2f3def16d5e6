#include "tarmac/daemon/executor.hpp"

#include "tarmac/daemon/clock.hpp"

#include <time.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>
#include <utility>

#include <sys/resource.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include "tarmac/core/assert.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/daemon/pose_buffer.hpp"
#include "tarmac/daemon/realtime.hpp"
#include "tarmac/daemon/reason_counters.hpp"
#include "tarmac/daemon/scan_scheduler.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/transport/inputs.hpp"
#include "tarmac/transport/outputs.hpp"

namespace tarmac::daemon {

namespace {

using Clock = std::chrono::steady_clock;
constexpr std::int64_t kNsPerMs = 1'000'000;

std::int64_t ms_to_ns(double ms) {
  return static_cast<std::int64_t>(std::llround(ms * 1e6));
}

double ms_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

std::int64_t monotonic_ns() {
  return clock_now_ns(CLOCK_MONOTONIC);
}

std::int64_t realtime_ns() {
  return clock_now_ns(CLOCK_REALTIME);
}

void sleep_until_monotonic(std::int64_t deadline_ns) {
  clock_sleep_until_ns(CLOCK_MONOTONIC, deadline_ns);
}

/// Sleeps until `deadline_ns` (CLOCK_MONOTONIC, absolute) in slices of at most
/// Executor::kStopPollSlice, checking `stop_requested` before each; false when it asked to stop.
/// The last slice ends on the deadline itself, so the wake is as precise as one long sleep.
bool sleep_until_or_stopped(std::int64_t deadline_ns, const std::function<bool()>& stop_requested) {
  constexpr std::int64_t kSliceNs =
      std::chrono::duration_cast<std::chrono::nanoseconds>(Executor::kStopPollSlice).count();
  while (!stop_requested()) {
    const std::int64_t now = monotonic_ns();
    if (now >= deadline_ns) return true;
    sleep_until_monotonic(std::min(deadline_ns, now + kSliceNs));
  }
  return false;
}

/// What the tick schedule is computed from, checked before anything is created: a rate that is
/// not finite (NaN fails every comparison) or a NaN delay would give a loop that never ticks,
/// so it would never see a stop or ping the watchdog either.
core::Status check_schedule(const config::ExecutorConfig& e) {
  if (!std::isfinite(e.rate_hz) || e.rate_hz < config::kMinRateHz ||
      e.rate_hz > config::kMaxRateHz) {
    return core::Error{"config.range",
                       fmt::format("executor.rate_hz: must be a finite number in [{}, {}], got {}",
                                   config::kMinRateHz, config::kMaxRateHz, e.rate_hz)};
  }
  const std::pair<const char*, double> ms[] = {{"executor.input_delay_ms", e.input_delay_ms},
                                               {"executor.pose_wait_ms", e.pose_wait_ms},
                                               {"executor.max_future_ms", e.max_future_ms},
                                               {"executor.sensor_phase_ms", e.sensor_phase_ms}};
  for (const auto& [key, value] : ms) {
    if (!std::isfinite(value) || value < 0.0 || value > 3.6e6) {
      return core::Error{
          "config.range",
          fmt::format("{}: must be a finite number in [0, 3600000], got {}", key, value)};
    }
  }
  return core::Ok{};
}

/// Below this the stamp clock's drift against CLOCK_MONOTONIC is left alone (slew, read noise).
constexpr std::int64_t kClockStepMinNs = 50'000'000;

/// How far the tick times must move on the stamp clock when it has drifted `drift_ns` from the
/// offset the ticks were placed with: whole periods (the ticks stay on their grid), once the
/// drift reaches kClockStepMinNs and half a period; otherwise 0.
std::int64_t clock_step_ns(std::int64_t drift_ns, std::int64_t period_ns) {
  if (std::abs(drift_ns) < std::max(kClockStepMinNs, period_ns / 2)) return 0;
  const std::int64_t half = drift_ns >= 0 ? period_ns / 2 : -period_ns / 2;
  return (drift_ns + half) / period_ns * period_ns;
}

/// A period longer than half the systemd watchdog interval leaves no margin: one late tick and
/// the service is restarted. Said once at start, naming both.
void warn_if_watchdog_too_short(std::int64_t period_ns) {
  std::uint64_t watchdog_us = 0;
  if (sd_watchdog_enabled(0, &watchdog_us) <= 0) return;
  if (2 * period_ns > static_cast<std::int64_t>(watchdog_us) * 1000) {
    spdlog::warn(
        "executor: the period ({} ms) is more than half the systemd watchdog interval ({} ms), "
        "which is pinged once per tick: raise WatchdogSec= or executor.rate_hz",
        period_ns / kNsPerMs, watchdog_us / 1000);
  }
}

/// Fixed window of recent values with percentiles computed on a stack copy (no allocation).
class RecentWindow {
 public:
  void add(double v) {
    values_[next_ % values_.size()] = v;
    ++next_;
  }
  [[nodiscard]] double percentile(double q) const {
    const std::size_t n = std::min<std::size_t>(next_, values_.size());
    if (n == 0) return 0.0;
    std::array<double, 256> copy{};
    std::copy_n(values_.begin(), n, copy.begin());
    const auto k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n))) - 1;
    const auto at = std::min(k, n - 1);
    std::nth_element(copy.begin(), copy.begin() + static_cast<std::ptrdiff_t>(at),
                     copy.begin() + static_cast<std::ptrdiff_t>(n));
    return copy[at];
  }

 private:
  std::array<double, 256> values_{};
  std::size_t next_ = 0;
};

enum Stage : std::size_t {
  kDrain,
  kIngest,
  kIntegrate,
  kTsdf,
  kRebuild,
  kCostmap,
  kEsdfBand,
  kPublish,
  kStageCount
};
constexpr const char* kStageNames[kStageCount] = {"drain",   "ingest",  "integrate", "tsdf",
                                                  "rebuild", "costmap", "esdf_band", "publish"};

}  // namespace

class Executor::Impl {
 public:
  /// Parses each sensor's scans into the scheduler's slots.
  class SensorSink final : public transport::ScanSink {
   public:
    SensorSink(Impl& owner, std::uint32_t sensor) : owner_(owner), sensor_(sensor) {}
    core::PointCloud& slot() override { return owner_.scheduler.slot(owner_.drops); }
    void commit() override { owner_.scheduler.commit(sensor_, owner_.tick_ns, owner_.rejections); }
    void reject(std::string_view reason) override { owner_.rejections.add(reason); }

   private:
    Impl& owner_;
    std::uint32_t sensor_;
  };

  class PoseSinkImpl final : public transport::PoseSink {
   public:
    explicit PoseSinkImpl(Impl& owner) : owner_(owner) {}
    void pose(const transport::PoseSample& sample) override {
      // Judged like a scan's stamp: a pose from the future (a clock stepped back, or a sender
      // whose clock is ahead) would refuse every later pose as out of order.
      if (sample.stamp_ns > owner_.tick_ns + owner_.max_future_ns) {
        owner_.rejections.add("pose.future");
        return;
      }
      switch (owner_.poses.insert(sample)) {
        case PoseBuffer::Insert::kOk:
          if (owner_.config.mapping.corrections.enabled) {
            if (const auto jump = owner_.jumps.feed({sample.stamp_ns, sample.T_W_B})) {
              owner_.on_pose_jump(*jump, sample.stamp_ns);
            }
          }
          break;
        case PoseBuffer::Insert::kOutOfOrder: owner_.rejections.add("pose.out_of_order"); break;
        case PoseBuffer::Insert::kDuplicate: owner_.rejections.add("pose.duplicate_stamp"); break;
      }
    }
    void reject(std::string_view reason) override { owner_.rejections.add(reason); }

   private:
    Impl& owner_;
  };

  class TrajectorySinkImpl final : public transport::TrajectorySink {
   public:
    explicit TrajectorySinkImpl(Impl& owner) : owner_(owner) {}
    void trajectory(std::int64_t stamp_ns, std::span<const transport::PoseSample> poses) override {
      owner_.queue_trajectory(stamp_ns, poses);
    }
    void reject(std::string_view reason) override { owner_.rejections.add(reason); }

   private:
    Impl& owner_;
  };

  Impl(const config::Config& cfg, transport::Participant p)
      : config(cfg),
        participant(std::move(p)),
        hash(config::config_hash(cfg)),
        poses(cfg.pose.buffer_size, ms_to_ns(cfg.pose.max_gap_ms)),
        scheduler(scheduler_params(cfg)),
        mapper(cfg.mapping),
        jumps(cfg.mapping.corrections),
        pose_sink(*this),
        trajectory_sink(*this),
        max_future_ns(ms_to_ns(cfg.executor.max_future_ms)) {
    trajectory_scratch.reserve(1024);
    mapper.reserve_retained(cfg.quotas.reserve_points_per_scan);
  }

  static SchedulerParams scheduler_params(const config::Config& cfg) {
    SchedulerParams p;
    p.input_delay_ns = ms_to_ns(cfg.executor.input_delay_ms);
    p.pose_wait_ns = ms_to_ns(cfg.executor.pose_wait_ms);
    p.max_future_ns = ms_to_ns(cfg.executor.max_future_ms);
    for (const auto& s : cfg.sensors) {
      p.max_age_ns.push_back(ms_to_ns(s.max_age_ms));
      p.deskew.push_back(s.deskew);
    }
    p.points_per_cycle = cfg.quotas.points_per_cycle;
    p.points_per_scan = cfg.quotas.points_per_scan;
    p.max_pending = cfg.quotas.max_pending_scans;
    p.reserve_points = cfg.quotas.reserve_points_per_scan;
    return p;
  }

  void prepare_report() {
    report.frame_id = config.outputs.frame_id;
    report.config_hash = hash;
    report.cycle_budget_ms = config.budgets.cycle_ms;
    report.stages.resize(kStageCount);
    const double budgets[kStageCount] = {config.budgets.drain_ms,     config.budgets.ingest_ms,
                                         config.budgets.integrate_ms, config.budgets.tsdf_ms,
                                         config.budgets.rebuild_ms,   config.budgets.costmap_ms,
                                         config.budgets.esdf_band_ms, config.budgets.publish_ms};
    for (std::size_t i = 0; i < kStageCount; ++i) {
      report.stages[i].name = kStageNames[i];
      report.stages[i].budget_ms = budgets[i];
    }
    report.input_ages.resize(config.sensors.size() + 1);
    for (std::size_t i = 0; i < config.sensors.size(); ++i) {
      report.input_ages[i].input = config.sensors[i].id;
    }
    report.input_ages.back().input = "pose";
    // Every reason the cycle can count, reported from the first tick (0 until it happens).
    for (const char* r :
         {"queue.scan_overflow", "queue.pose_overflow", "scan.shed_pending_full",
          "scan.pose_timeout", "scan.pose_before_buffer", "scan.pose_gap", "points.non_finite",
          "points.too_close", "points.ego_vehicle", "points.isolated", "points.no_return_refused",
          "scan.tsdf_shed_quota", "scan.deskew_span", "pose.clock_step"}) {
      drops.declare(r);
    }
    for (const char* r : {"scan.unknown_frame",
                          "scan.future",
                          "scan.stale",
                          "scan.late",
                          "scan.duplicate_stamp",
                          "pointcloud.missing_xyz",
                          "pointcloud.bad_datatype",
                          "pointcloud.bad_count",
                          "pointcloud.field_outside_point",
                          "pointcloud.bad_row_step",
                          "pointcloud.bad_size",
                          "pose.unknown_frame",
                          "pose.non_finite",
                          "pose.bad_quaternion",
                          "pose.out_of_order",
                          "pose.duplicate_stamp",
                          "pose.future",
                          "correction.clock_step",
                          "zones.polygon",
                          "zones.non_finite",
                          "zones.z_range",
                          "correction.unknown_frame",
                          "correction.empty",
                          "correction.unsorted"}) {
      rejections.declare(r);
    }
    drops.declare("transport.pose_lost");
    transport_seen.resize(config.sensors.size());
    for (std::size_t i = 0; i < config.sensors.size(); ++i) {
      transport_seen[i].lost_reason = "transport.scan_lost." + config.sensors[i].id;
      transport_seen[i].rejected_reason = "transport.scan_rejected." + config.sensors[i].id;
      drops.declare(transport_seen[i].lost_reason);
      drops.declare(transport_seen[i].rejected_reason);
    }
    report.drops.reserve(32 + 2 * config.sensors.size());
    report.rejections.reserve(32);
    selected.reserve(config.quotas.max_pending_scans + 1);
    overflow_seen.assign(config.sensors.size(), 0);
    diag.name = "tarmacd: executor";
    diag.hardware_id = config.dds.participant.name;
    prepare_diagnostics();
  }

  /// The DiagnosticArray's keys, set once; each tick only rewrites the values and the message
  /// in place (capacity reserved here, so publishing them does not allocate).
  void prepare_diagnostics() {
    static constexpr const char* kKeys[kDiagFixed] = {"cycle_ms",
                                                      "wake_jitter_ms",
                                                      "integrate_ms",
                                                      "costmap_ms",
                                                      "scans_integrated_total",
                                                      "drops_total",
                                                      "rejections_total",
                                                      "skipped_ticks_total",
                                                      "stamp_to_publish_p99_ms",
                                                      "tsdf_ms",
                                                      "rebuild_ms",
                                                      "esdf_band_ms",
                                                      "costmap_age_ms",
                                                      "costmap_stale",
                                                      "pending_scans",
                                                      "pose_buffer_samples",
                                                      "clock_steps_total"};
    diag.values.resize(kDiagFixed + 2 * report.input_ages.size());
    for (std::size_t i = 0; i < kDiagFixed; ++i) diag.values[i].first = kKeys[i];
    for (std::size_t i = 0; i < report.input_ages.size(); ++i) {
      const std::string prefix = "input." + report.input_ages[i].input;
      diag.values[kDiagFixed + 2 * i].first = prefix + ".age_ms";
      diag.values[kDiagFixed + 2 * i + 1].first = prefix + ".stale";
    }
    for (auto& v : diag.values) v.second.reserve(32);
    diag.message.reserve(kDiagMessageSize);
  }

  /// Fills the DiagnosticArray from this tick's report: ERROR while the costmap is stale (older
  /// than outputs.costmap_max_age_ms, or none yet: the planner is driving on an old map),
  /// WARN while an input is stale or the tick ran over budget, OK otherwise; the message names
  /// what is wrong, with ages.
  void fill_diagnostics(const double* stage_ms, double jitter_ms, bool overrun);

  /// One tick at `tick_time_ns` (stamp clock); `clock_step_ns` != 0: the stamp clock stepped by
  /// that much since the last tick (on_clock_step() runs first).
  void tick(std::int64_t tick_time_ns, double jitter_ms, std::uint32_t skipped,
            std::int64_t clock_step_ns);
  /// The stamp clock stepped by `step_ns` (a whole number of periods) and ticks now sit at
  /// `tick_time_ns` on it: what was stamped by the old clock beyond the new tick + max_future
  /// (after a backward step) is forgotten — pending scans judged again ("scan.future" /
  /// "scan.stale"), poses ("pose.clock_step"), queued corrections ("correction.clock_step"),
  /// the scan order and the costmap's stamp — so scans stamped by the new clock are taken.
  void on_clock_step(std::int64_t step_ns, std::int64_t tick_time_ns);
  /// The stamp clock (RunHooks::stamp_clock_ns, else CLOCK_REALTIME).
  [[nodiscard]] std::int64_t stamp_now() const {
    return stamp_clock ? stamp_clock() : realtime_ns();
  }
  /// Adds sensor `sensor`'s scans lost or rejected in DDS transport since the last tick to the
  /// drops (`transport.scan_lost.<id>`, `transport.scan_rejected.<id>`) and logs them,
  /// rate-limited.
  void count_transport_losses(std::size_t sensor);
  /// A jump in the pose stream (DESIGN.md §4, pose corrections): the pose samples before it and
  /// the mapper's retained scans are re-expressed in the corrected frame (T ← Δ · T), and the
  /// mapper starts rebuilding its window from the retained scans (rebuild stage, per tick).
  void on_pose_jump(const Eigen::Isometry3d& delta, std::int64_t stamp_ns);
  /// A corrected trajectory (nav_msgs/Path on pose.correction_topic): the pose samples it
  /// covers are replaced (newer ones re-expressed by the correction at its end), the mapper's
  /// retained scans within it take the revised poses and the rebuild starts.
  void on_trajectory(std::int64_t made_ns, std::span<const transport::PoseSample> samples);
  /// A corrected trajectory made at `stamp_ns` waits for its place in the stamp order
  /// (DESIGN.md §3): it is applied after every scan stamped up to `stamp_ns` and before any later
  /// one, whenever it arrived within the input delay. One that arrives after a later scan was
  /// integrated is applied at once (still a full rebuild) and counted as late.
  void queue_trajectory(std::int64_t stamp_ns, std::span<const transport::PoseSample> samples);
  /// Applies, in stamp order, the queued corrections stamped before `stamp_ns`.
  void apply_corrections_before(std::int64_t stamp_ns);
  void real_time_setup(const RunHooks& hooks);
  [[nodiscard]] bool periodic_save() const {
    return config.mapping.tsdf.enabled && config.state.save_period_s > 0.0;
  }

  [[nodiscard]] std::filesystem::path tsdf_path() const {
    return std::filesystem::path(config.state.dir) / config.state.tsdf_file;
  }
  [[nodiscard]] core::TsdfMapInfo tsdf_info() const {
    core::TsdfMapInfo info;
    info.frame_id = config.outputs.frame_id;  // the lattice lives in the pose / map frame
    info.config_hash = hash;
    // A save made before the first scan after a restart holds the loaded map: its stamp.
    info.stamp_ns = std::max(newest_stamp_ns, loaded_stamp_ns);
    return info;
  }
  /// The occupancy window's static layer, saved in the same .vdb as the TSDF.
  [[nodiscard]] core::StaticOccupancy static_occupancy() const {
    core::StaticOccupancy s;
    s.voxel_size_m = static_cast<float>(config.mapping.occupancy.voxel_size_m);
    mapper.occupancy().export_static(s.voxels);
    return s;
  }
  /// Periodic save: between ticks, on the executor thread, copies the TSDF and hands the copy
  /// to the saver thread (skipped, counted, when the previous copy is still being written).
  void snapshot_tsdf();
  void saver_loop();
  void start_saver();
  void stop_saver();

  config::Config config;
  transport::Participant participant;
  std::string hash;
  std::vector<std::unique_ptr<transport::ScanInput>> scans;
  std::vector<SensorSink> sinks;
  std::unique_ptr<transport::PoseInput> pose_input;
  std::unique_ptr<transport::ZoneInput> zone_input;
  std::unique_ptr<transport::MapOutputs> outputs;
  std::vector<Eigen::Isometry3d> T_B_S;

  PoseBuffer poses;
  ScanScheduler scheduler;
  core::Mapper mapper;
  core::PoseJumpDetector jumps;
  PoseSinkImpl pose_sink;
  TrajectorySinkImpl trajectory_sink;
  std::unique_ptr<transport::TrajectoryInput> trajectory_input;
  std::vector<core::StampedPose> trajectory_scratch;
  struct PendingCorrection {
    std::int64_t stamp_ns = 0;
    std::vector<transport::PoseSample> samples;
  };
  std::vector<PendingCorrection> pending_corrections;  ///< by stamp; corrections are rare
  std::unique_ptr<ThreadPool> pool;
  std::vector<core::VirtualZone> zones;
  std::string zone_rejection;
  core::Costmap obstacle_grid;    // outputs.obstacle_grid_topic: the costmap without inflation
  core::Costmap esdf_slice_grid;  // outputs.esdf_slice_grid_topic: the 2D ESDF for display

  ReasonCounters drops, rejections;
  std::vector<ScanScheduler::Selected> selected;
  std::vector<std::uint64_t> overflow_seen;
  std::uint64_t pose_overflow_seen = 0;
  struct TransportLosses {
    std::string lost_reason, rejected_reason;
    std::uint64_t lost = 0, rejected = 0;
    std::uint64_t logged_tick = 0;  // cycle index of the last log line (0: never)
  };
  static constexpr std::uint64_t kLossLogTicks = 100;
  std::vector<TransportLosses> transport_seen;  // per sensor
  std::uint64_t pose_lost_seen = 0;
  transport::CycleReport report;
  transport::DiagnosticReport diag;
  std::int64_t tick_ns = 0;  // the current tick's time on the stamp clock
  std::int64_t newest_stamp_ns = 0;
  bool have_costmap = false;
  std::int64_t max_future_ns = 0;
  std::int64_t loaded_stamp_ns = 0;           // stamp of the TSDF loaded at start (0: none)
  std::function<std::int64_t()> stamp_clock;  // RunHooks::stamp_clock_ns, set by run()
  static constexpr std::size_t kDiagFixed = 17;
  static constexpr std::size_t kDiagMessageSize = 256;

  mutable std::mutex totals_mutex;  // totals and windows are read by status_line() from main
  ExecutorTotals totals;
  RecentWindow cycle_ms, jitter_ms_window, stamp_to_publish;
  std::uint64_t cycle_index = 0;

  // The periodic TSDF saver: a SCHED_OTHER, unpinned, niced thread started by run() before the
  // real-time setup. The executor only swaps a pointer under saver_mutex (never while the saver
  // writes: the saver takes the snapshot out first and writes it without the lock).
  std::thread saver;
  std::mutex saver_mutex;
  std::condition_variable saver_wake;
  std::unique_ptr<core::TsdfLayer> saver_snapshot;  // guarded by saver_mutex
  core::StaticOccupancy saver_static;               // guarded by saver_mutex
  core::TsdfMapInfo saver_info;                     // guarded by saver_mutex
  bool saver_stop = false;                          // guarded by saver_mutex
  std::atomic<bool> saver_busy{false};
};

void Executor::Impl::on_pose_jump(const Eigen::Isometry3d& delta, std::int64_t stamp_ns) {
  const std::size_t rebased = poses.rebase_before(stamp_ns, delta);
  const std::uint64_t revised = mapper.correct_rigid(delta, stamp_ns);
  {
    std::lock_guard lock(totals_mutex);
    ++totals.pose_jumps;
  }
  // Rare (a loop closure or a GPS fix), so one log line each.
  spdlog::warn(
      "corrections: pose jump at stamp {} ns ({:.3f} m, {:.2f} deg from the prediction): {} "
      "pose samples and {} retained scans re-expressed, rebuilding",
      stamp_ns, delta.translation().norm(),
      Eigen::AngleAxisd(delta.linear()).angle() * 180.0 / M_PI, rebased, revised);
}

void Executor::Impl::on_trajectory(std::int64_t made_ns,
                                   std::span<const transport::PoseSample> samples) {
  trajectory_scratch.clear();
  for (const auto& p : samples) trajectory_scratch.push_back({p.stamp_ns, p.T_W_B});
  const std::size_t replaced = poses.apply_trajectory(trajectory_scratch, made_ns);
  const std::uint64_t revised = mapper.correct_trajectory(trajectory_scratch);
  // Later live samples are predicted from the corrected ones.
  core::StampedPose tail[2];
  jumps.reset(std::span<const core::StampedPose>(tail, poses.newest_two(tail)));
  {
    std::lock_guard lock(totals_mutex);
    ++totals.trajectory_corrections;
  }
  spdlog::warn(
      "corrections: corrected trajectory of {} poses ({} .. {} ns): {} pose samples and {} "
      "retained scans revised{}",
      samples.size(), samples.front().stamp_ns, samples.back().stamp_ns, replaced, revised,
      revised > 0 ? ", rebuilding" : " (none retained in its span: nothing to rebuild)");
}

void Executor::Impl::queue_trajectory(std::int64_t stamp_ns,
                                      std::span<const transport::PoseSample> samples) {
  if (newest_stamp_ns > stamp_ns) {
    spdlog::warn(
        "corrections: trajectory made at stamp {} ns arrived after scan {} ns was integrated: "
        "applied now, out of stamp order",
        stamp_ns, newest_stamp_ns);
    {
      std::lock_guard lock(totals_mutex);
      ++totals.late_corrections;
    }
    on_trajectory(stamp_ns, samples);
    return;
  }
  auto at =
      std::upper_bound(pending_corrections.begin(), pending_corrections.end(), stamp_ns,
                       [](std::int64_t t, const PendingCorrection& c) { return t < c.stamp_ns; });
  pending_corrections.insert(at, PendingCorrection{stamp_ns, {samples.begin(), samples.end()}});
}

void Executor::Impl::apply_corrections_before(std::int64_t stamp_ns) {
  std::size_t n = 0;
  while (n < pending_corrections.size() && pending_corrections[n].stamp_ns < stamp_ns) {
    on_trajectory(pending_corrections[n].stamp_ns, pending_corrections[n].samples);
    ++n;
  }
  if (n > 0)
    pending_corrections.erase(pending_corrections.begin(), pending_corrections.begin() + n);
}

void Executor::Impl::real_time_setup(const RunHooks& hooks) {
  const auto& e = config.executor;
  if (!e.cpus.empty()) {
    if (auto why = pin_current_thread(e.cpus[0]); !why.empty()) {
      spdlog::warn("executor: pinning to CPU {} refused ({}); running unpinned", e.cpus[0], why);
    }
  }
  if (e.realtime_priority > 0) {
    if (auto why = set_fifo_priority(e.realtime_priority); !why.empty()) {
      spdlog::warn("executor: SCHED_FIFO priority {} refused ({}); running SCHED_OTHER",
                   e.realtime_priority, why);
    } else {
      spdlog::info("executor: SCHED_FIFO priority {} (workers inherit it)", e.realtime_priority);
    }
  }
  if (e.lock_memory) {
    if (auto why = lock_all_memory(); !why.empty()) {
      spdlog::warn("executor: memory lock refused ({}); pages may fault in the cycle", why);
    } else {
      spdlog::info("executor: all memory locked (mlockall)");
    }
  }
  std::vector<int> worker_cpus;
  for (std::uint32_t i = 1; i < e.workers && !e.cpus.empty(); ++i) {
    worker_cpus.push_back(e.cpus[i % e.cpus.size()]);
  }
  pool = std::make_unique<ThreadPool>(e.workers, worker_cpus, hooks.on_thread_start);
  if (pool->pin_failures() > 0) {
    spdlog::warn("executor: {} of {} workers could not be pinned; they run unpinned",
                 pool->pin_failures(), worker_cpus.size());
  }
}

void Executor::Impl::count_transport_losses(std::size_t sensor) {
  TransportLosses& seen = transport_seen[sensor];
  const std::uint64_t lost = scans[sensor]->transport_lost();
  const std::uint64_t rejected = scans[sensor]->transport_rejected();
  if (lost == seen.lost && rejected == seen.rejected) return;
  drops.add(seen.lost_reason, lost - seen.lost);
  drops.add(seen.rejected_reason, rejected - seen.rejected);
  seen.lost = lost;
  seen.rejected = rejected;
  // At most one line per sensor per kLossLogTicks ticks: a lossy link must not flood the log.
  if (seen.logged_tick != 0 && cycle_index < seen.logged_tick + kLossLogTicks) return;
  seen.logged_tick = std::max<std::uint64_t>(cycle_index, 1);
  spdlog::warn(
      "input {}: {} scan(s) lost and {} rejected in DDS transport so far (UDP receive buffer "
      "too small? see dds.udp_receive_buffer_bytes and net.core.rmem_max)",
      config.sensors[sensor].id, lost, rejected);
}

void Executor::Impl::tick(std::int64_t tick_time_ns, double jitter_ms, std::uint32_t skipped,
                          std::int64_t clock_step_ns) {
  const auto t_start = Clock::now();
  tick_ns = tick_time_ns;
  drops.begin_tick();
  rejections.begin_tick();
  if (clock_step_ns != 0) on_clock_step(clock_step_ns, tick_time_ns);
  double stage_ms[kStageCount] = {};
  std::uint64_t shed[kStageCount] = {};

  // ---- drain: queues -> scheduler slots, pose buffer, zones; then select by stamp ----
  for (std::size_t i = 0; i < scans.size(); ++i) {
    scans[i]->drain(sinks[i]);
    const std::uint64_t overflow = scans[i]->overflow_drops();
    drops.add("queue.scan_overflow", overflow - overflow_seen[i]);
    overflow_seen[i] = overflow;
    count_transport_losses(i);
  }
  pose_input->drain(pose_sink);
  const std::uint64_t pose_overflow = pose_input->overflow_drops();
  drops.add("queue.pose_overflow", pose_overflow - pose_overflow_seen);
  pose_overflow_seen = pose_overflow;
  const std::uint64_t pose_lost = pose_input->transport_lost();
  drops.add("transport.pose_lost", pose_lost - pose_lost_seen);
  pose_lost_seen = pose_lost;
  // After the poses: a correction applies to the samples already in the buffer.
  if (trajectory_input) trajectory_input->drain(trajectory_sink);
  zone_rejection.clear();
  const bool zones_changed = zone_input->take_latest(zones, zone_rejection);
  if (!zone_rejection.empty()) rejections.add(zone_rejection);
  const auto stats = scheduler.select(tick_ns, poses, selected, drops);
  shed[kDrain] = stats.deferred_scans;
  shed[kIngest] = stats.decimated_points;
  const auto t_drained = Clock::now();
  stage_ms[kDrain] = ms_between(t_start, t_drained);

  // ---- ingest + integrate, scan by scan in (stamp, sensor) order ----
  std::uint64_t points_in = 0, points_used = 0, tsdf_points = 0, tsdf_scans = 0;
  std::uint64_t reintegrated = 0, rebuilds_completed = 0;
  bool rebuilt = false;
  const bool tsdf_enabled = config.mapping.tsdf.enabled;
  for (const auto& sel : selected) {
    const core::PointCloud& cloud = scheduler.cloud(sel.slot);
    if (!pending_corrections.empty()) apply_corrections_before(cloud.stamp_ns);
    const auto t0 = Clock::now();
    const core::FilterCounts counts = mapper.ingest(cloud, sel.T_W_B, T_B_S[sel.sensor], *pool,
                                                    sel.deskew ? &sel.motion : nullptr);
    const auto t1 = Clock::now();
    mapper.integrate(*pool);
    const auto t2 = Clock::now();
    stage_ms[kIngest] += ms_between(t0, t1);
    stage_ms[kIntegrate] += ms_between(t1, t2);
    if (tsdf_enabled) {
      // Shed first (DESIGN.md §3), by the points quota only: the same scans skip the TSDF
      // whatever the machine's speed.
      const std::uint64_t n = mapper.points_W().size();
      if (tsdf_points + n <= config.quotas.tsdf_points_per_cycle) {
        tsdf_points += n;
        mapper.integrate_tsdf(*pool);
        ++tsdf_scans;
        stage_ms[kTsdf] += ms_between(t2, Clock::now());
      } else {
        ++shed[kTsdf];
        drops.add("scan.tsdf_shed_quota");
      }
    }
    points_in += counts.input;
    points_used += counts.kept;
    drops.add("points.non_finite", counts.non_finite);
    drops.add("points.too_close", counts.too_close);
    drops.add("points.ego_vehicle", counts.ego_vehicle);
    drops.add("points.isolated", counts.isolated);
    drops.add("points.no_return_refused", counts.no_returns_refused);
    newest_stamp_ns = std::max(newest_stamp_ns, cloud.stamp_ns);
    scheduler.release(sel.slot);
    // ---- rebuild after a pose correction: a points quota of retained scans per scan, so
    // its progress is a function of the scan sequence, not of how scans fall into ticks ----
    if (mapper.rebuilding()) {
      const auto t3 = Clock::now();
      const core::RebuildStep step = mapper.rebuild_step(*pool);
      stage_ms[kRebuild] += ms_between(t3, Clock::now());
      rebuilt = rebuilt || step.completed;
      reintegrated += step.scans;
      rebuilds_completed += step.completed ? 1 : 0;
    }
  }

  // Corrections stamped up to the input horizon (no scan up to their stamp is still pending):
  // every scan before them is in, every later one is to come.
  if (!pending_corrections.empty()) {
    const std::int64_t horizon = std::min(tick_ns - ms_to_ns(config.executor.input_delay_ms),
                                          scheduler.oldest_pending_stamp() - 1);
    apply_corrections_before(horizon + 1);
  }

  {
    std::lock_guard lock(totals_mutex);  // before the costmap goes out (tests read both)
    totals.scans_integrated += selected.size();
    totals.tsdf_scans += tsdf_scans;
    totals.tsdf_shed_scans += shed[kTsdf];
    totals.scans_reintegrated += reintegrated;
    totals.rebuilds_completed += rebuilds_completed;
    totals.newest_stamp_ns = newest_stamp_ns;
  }

  if (mapper.rebuilding()) shed[kRebuild] = mapper.rebuild_remaining();  // for the next scans
  if (rebuilt) {
    const auto& cs = mapper.correction_stats();
    spdlog::info(
        "corrections: rebuilt window swapped in ({} scans re-integrated so far, {} TSDF "
        "blocks erased, {} scans rolled out)",
        cs.scans_reintegrated, cs.tsdf_blocks_erased, cs.scans_rolled_out);
  }

  // ---- costmap + 2D ESDF, once per tick (when something changed) ----
  const bool update = !selected.empty() || zones_changed || rebuilt;
  const auto t_costmap0 = Clock::now();
  if (update) {
    mapper.update_costmap(zones, newest_stamp_ns, *pool);
    have_costmap = true;
  }
  const auto t_costmap1 = Clock::now();
  stage_ms[kCostmap] = ms_between(t_costmap0, t_costmap1);

  // ---- publish the costmap and the ESDF slice: the planner and the safety filter do not wait
  // for the 3D band ----
  if (update) {
    const auto& layers = mapper.costmap();
    outputs->publish_costmap(layers.costmap, newest_stamp_ns, config.outputs.frame_id);
    if (!config.outputs.obstacle_grid_topic.empty()) {
      core::to_obstacle_grid(layers.costmap, obstacle_grid);
      outputs->publish_obstacle_grid(obstacle_grid, newest_stamp_ns, config.outputs.frame_id);
    }
    if (!config.outputs.esdf_slice_grid_topic.empty()) {
      core::to_distance_display(layers.obstacle_distance, layers.costmap.geometry(),
                                config.outputs.esdf_slice_grid_range_m, esdf_slice_grid);
      outputs->publish_esdf_slice_grid(esdf_slice_grid, newest_stamp_ns, config.outputs.frame_id);
    }
    outputs->publish_slice(layers.obstacle_distance, layers.costmap.geometry(), newest_stamp_ns,
                           config.outputs.frame_id);
  }
  const auto t_costmap_out = Clock::now();
  // Measured, never used to decide: newest integrated scan stamp -> costmap handed to DDS.
  double stamp_to_publish_ms = -1.0;
  if (update && !selected.empty()) {
    stamp_to_publish_ms = static_cast<double>(stamp_now() - newest_stamp_ns) / 1e6;
  }

  // ---- 3D ESDF band (esdf_band.enabled), from the costmap's ground, then its box out ----
  const bool band = update && config.mapping.esdf_band.enabled;
  if (band) mapper.update_esdf_band(zones, newest_stamp_ns, *pool);
  const auto t_band1 = Clock::now();
  stage_ms[kEsdfBand] = ms_between(t_costmap_out, t_band1);
  if (band) {
    const auto& p = config.mapping.esdf_band;
    outputs->publish_band(mapper.esdf_band(), mapper.vehicle_pose().translation().head<2>(),
                          p.publish_radius_m, newest_stamp_ns, config.outputs.frame_id);
  }
  const auto t_published = Clock::now();
  stage_ms[kPublish] = ms_between(t_costmap1, t_costmap_out) + ms_between(t_band1, t_published);

  // ---- report ----
  const double cycle_duration = ms_between(t_start, t_published);
  bool overrun = cycle_duration > config.budgets.cycle_ms;
  for (std::size_t i = 0; i < kStageCount; ++i) {
    auto& s = report.stages[i];
    s.duration_ms = stage_ms[i];
    s.overrun = stage_ms[i] > s.budget_ms;
    s.shed_items = shed[i];
    overrun = overrun || s.overrun;
  }
  report.stamp_ns = newest_stamp_ns;
  report.cycle_index = cycle_index;
  report.tick_ns = tick_ns;
  report.wake_jitter_ms = jitter_ms;
  report.skipped_ticks = skipped;
  report.cycle_duration_ms = cycle_duration;
  report.overrun = overrun;
  report.drops.resize(drops.entries().size());
  std::copy(drops.entries().begin(), drops.entries().end(), report.drops.begin());
  report.rejections.resize(rejections.entries().size());
  std::copy(rejections.entries().begin(), rejections.entries().end(), report.rejections.begin());
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const std::int64_t newest = scheduler.newest_stamp(static_cast<std::uint32_t>(i));
    auto& age = report.input_ages[i];
    age.age_ms = newest == 0 ? -1.0 : static_cast<double>(tick_ns - newest) / kNsPerMs;
    age.stale = newest == 0 || tick_ns - newest > ms_to_ns(config.sensors[i].max_age_ms);
  }
  {
    const auto newest = poses.newest_stamp();
    auto& age = report.input_ages.back();
    age.age_ms = newest ? static_cast<double>(tick_ns - *newest) / kNsPerMs : -1.0;
    age.stale = !newest || tick_ns - *newest > ms_to_ns(config.pose.max_age_ms);
  }
  report.points_in = points_in;
  report.points_used = points_used;
  report.map_memory_bytes = mapper.occupancy().memory_bytes();
  {
    // Before the report goes out, so whoever reads the report and then the totals agrees.
    std::lock_guard lock(totals_mutex);
    totals.ticks += 1;
    totals.skipped_ticks += skipped;
    totals.overruns += overrun ? 1 : 0;
    cycle_ms.add(cycle_duration);
    jitter_ms_window.add(jitter_ms);
    if (stamp_to_publish_ms >= 0.0) stamp_to_publish.add(stamp_to_publish_ms);
  }
  outputs->publish_report(report);

  if (cycle_index % config.outputs.diagnostic_array_every == 0) {
    fill_diagnostics(stage_ms, jitter_ms, overrun);
    outputs->publish_diagnostics(diag);
  }
  ++cycle_index;
}

void Executor::Impl::fill_diagnostics(const double* stage_ms, double jitter_ms, bool overrun) {
  diag.stamp_ns = tick_ns;
  const auto put = [&](std::size_t i, double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f", v);
    diag.values[i].second = buf;
  };
  const auto put_flag = [&](std::size_t i, bool v) {
    diag.values[i].second = v ? "true" : "false";
  };
  // The costmap carries the newest integrated scan's stamp: its age is the tick's distance to
  // it (CycleReport: tick_ns − stamp_ns).
  const double costmap_age_ms = have_costmap && newest_stamp_ns != 0
                                    ? static_cast<double>(tick_ns - newest_stamp_ns) / 1e6
                                    : -1.0;
  const bool costmap_stale =
      costmap_age_ms < 0.0 || costmap_age_ms > config.outputs.costmap_max_age_ms;
  put(0, report.cycle_duration_ms);
  put(1, jitter_ms);
  put(2, stage_ms[kIntegrate]);
  put(3, stage_ms[kCostmap]);
  put(4, static_cast<double>(totals.scans_integrated));
  put(5, static_cast<double>(drops.total_sum()));
  put(6, static_cast<double>(rejections.total_sum()));
  put(7, static_cast<double>(totals.skipped_ticks));
  put(8, stamp_to_publish.percentile(0.99));
  put(9, stage_ms[kTsdf]);
  put(10, stage_ms[kRebuild]);
  put(11, stage_ms[kEsdfBand]);
  put(12, costmap_age_ms);
  put_flag(13, costmap_stale);
  put(14, static_cast<double>(scheduler.pending()));
  put(15, static_cast<double>(poses.size()));
  put(16, static_cast<double>(totals.clock_steps));
  char message[kDiagMessageSize];
  std::size_t used = 0;
  // Appends `text` and, when `value_ms` >= 0, " (N ms)" (else `otherwise`, if given).
  const auto append = [&](const char* text, double value_ms = -1.0,
                          const char* otherwise = nullptr) {
    int n = 0;
    if (value_ms >= 0.0) {
      n = std::snprintf(message + used, sizeof message - used, "%s (%.0f ms)", text, value_ms);
    } else {
      n = std::snprintf(message + used, sizeof message - used, "%s%s", text,
                        otherwise != nullptr ? otherwise : "");
    }
    if (n > 0) used = std::min(sizeof message - 1, used + static_cast<std::size_t>(n));
  };
  message[0] = '\0';
  if (costmap_stale) append("costmap stale", costmap_age_ms, " (no costmap yet)");
  bool any_input_stale = false;
  for (std::size_t i = 0; i < report.input_ages.size(); ++i) {
    const auto& a = report.input_ages[i];
    put(kDiagFixed + 2 * i, a.age_ms);
    put_flag(kDiagFixed + 2 * i + 1, a.stale);
    if (!a.stale) continue;
    if (!any_input_stale) append(used > 0 ? "; input stale: " : "input stale: ");
    if (any_input_stale) append(", ");
    append(a.input.c_str(), a.age_ms, " (none yet)");
    any_input_stale = true;
  }
  if (overrun) append(used > 0 ? "; over budget" : "over budget");
  diag.level = costmap_stale ? 2 : (any_input_stale || overrun) ? 1 : 0;
  diag.message = used > 0 ? message : "ok";
}

void Executor::Impl::on_clock_step(std::int64_t step_ns, std::int64_t tick_time_ns) {
  tick_ns = tick_time_ns;
  const std::int64_t future = tick_time_ns + max_future_ns;
  const std::size_t scans_rejected = scheduler.on_clock_step(tick_time_ns, rejections);
  const std::size_t poses_dropped = poses.drop_after(future);
  drops.add("pose.clock_step", poses_dropped);
  if (poses_dropped > 0) {
    // Later live samples are predicted from the ones kept, not from the old clock's.
    core::StampedPose tail[2];
    jumps.reset(std::span<const core::StampedPose>(tail, poses.newest_two(tail)));
  }
  std::size_t corrections_dropped = 0;
  while (!pending_corrections.empty() && pending_corrections.back().stamp_ns > future) {
    pending_corrections.pop_back();  // sorted by stamp
    ++corrections_dropped;
  }
  rejections.add("correction.clock_step", corrections_dropped);
  if (newest_stamp_ns > future) newest_stamp_ns = 0;  // no age on the new clock until a scan
  {
    std::lock_guard lock(totals_mutex);
    ++totals.clock_steps;
    totals.last_clock_step_ns = step_ns;
  }
  // Rare (a clock set by hand, a first NTP or PTP fix), so one line each.
  spdlog::warn(
      "executor: the stamp clock (CLOCK_REALTIME) stepped {:+.3f} s against CLOCK_MONOTONIC; "
      "ticks now carry the new clock's time, the schedule is unchanged; old-clock data "
      "dropped: {} pending scan(s), {} pose(s), {} correction(s)",
      static_cast<double>(step_ns) / 1e9, scans_rejected, poses_dropped, corrections_dropped);
}

core::Result<std::unique_ptr<Executor>> Executor::create(const config::Config& cfg) {
  if (auto schedule = check_schedule(cfg.executor); !schedule) return schedule.error();
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) return participant.error();
  auto impl = std::make_unique<Impl>(cfg, std::move(participant).value());
  const auto& q = cfg.dds.qos;
  impl->sinks.reserve(cfg.sensors.size());
  for (std::uint32_t i = 0; i < cfg.sensors.size(); ++i) {
    const auto& s = cfg.sensors[i];
    auto input = transport::ScanInput::create(impl->participant, s.topic, s.frame_id, q.lidar,
                                              cfg.executor.queue_depth);
    if (!input) return input.error();
    impl->scans.push_back(std::move(input).value());
    impl->sinks.emplace_back(*impl, i);
    impl->T_B_S.push_back(s.T_base_sensor);
  }
  auto pose = transport::PoseInput::create(impl->participant, cfg.pose.topic,
                                           cfg.pose.type == config::PoseType::kOdometry
                                               ? transport::PoseMessage::kOdometry
                                               : transport::PoseMessage::kPoseWithCovarianceStamped,
                                           cfg.pose.frame_id, q.pose,
                                           std::max<std::size_t>(cfg.executor.queue_depth, 64));
  if (!pose) return pose.error();
  impl->pose_input = std::move(pose).value();
  if (cfg.mapping.corrections.enabled) {
    auto trajectory = transport::TrajectoryInput::create(
        impl->participant, cfg.pose.correction_topic, cfg.pose.frame_id, q.pose, 4);
    if (!trajectory) return trajectory.error();
    impl->trajectory_input = std::move(trajectory).value();
  }
  auto zones = transport::ZoneInput::create(impl->participant, cfg.outputs.virtual_obstacles_topic,
                                            q.virtual_obstacles);
  if (!zones) return zones.error();
  impl->zone_input = std::move(zones).value();
  transport::OutputTopics topics{
      cfg.outputs.costmap_topic,
      cfg.outputs.esdf_slice_topic,
      cfg.mapping.esdf_band.enabled ? cfg.outputs.esdf_band_topic : std::string(),
      cfg.outputs.cycle_report_topic,
      cfg.outputs.diagnostic_array_topic,
      cfg.outputs.obstacle_grid_topic,
      cfg.outputs.esdf_slice_grid_topic};
  transport::OutputQos oq{q.costmap,     q.esdf_slice, q.esdf_band, q.diagnostics,
                          q.diagnostics, q.costmap,    q.costmap};
  auto outputs = transport::MapOutputs::create(impl->participant, topics, oq);
  if (!outputs) return outputs.error();
  impl->outputs = std::move(outputs).value();
  impl->prepare_report();
  return std::unique_ptr<Executor>(new Executor(std::move(impl)));
}

Executor::Executor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Executor::~Executor() = default;

void Executor::prepare(const RunHooks& hooks) {
  Impl& d = *impl_;
  if (d.pool) return;
  if (hooks.on_thread_start) hooks.on_thread_start();
  if (d.periodic_save()) d.start_saver();  // before real_time_setup: not pinned, not SCHED_FIFO
  d.real_time_setup(hooks);
}

void Executor::run(const std::function<bool()>& stop_requested, const RunHooks& hooks) {
  Impl& d = *impl_;
  prepare(hooks);
  const bool periodic_save = d.periodic_save();
  const auto save_every = static_cast<std::uint64_t>(
      std::max(1.0, std::round(d.config.state.save_period_s * d.config.executor.rate_hz)));
  const std::int64_t period_ns = std::llround(1e9 / d.config.executor.rate_hz);
  // create() refused any other rate (a NaN period never comes due: no tick, no stop seen).
  TARMAC_ASSERT(period_ns >= std::llround(1e9 / config::kMaxRateHz) &&
                    period_ns <= std::llround(1e9 / config::kMinRateHz),
                "executor period outside [1 / kMaxRateHz, 1 / kMinRateHz]");
  warn_if_watchdog_too_short(period_ns);
  // Ticks sit on multiples of the period of the stamp clock (CLOCK_REALTIME); the sleep runs on
  // CLOCK_MONOTONIC, so a wall-clock step does not distort the schedule (each tick compares the
  // two clocks and follows a step of the stamp clock: clock_step_ns()).
  d.stamp_clock = hooks.stamp_clock_ns;
  const std::int64_t real_now = d.stamp_now();
  const std::int64_t mono_now = monotonic_ns();
  // Tick k sits at k·period + sensor phase + input delay: a LiDAR phase-locked to the grid (PTP)
  // waits exactly input_delay for its tick. Unsynchronised sensors wait 0..period more.
  const std::int64_t offset_ns =
      ms_to_ns(d.config.executor.sensor_phase_ms + d.config.executor.input_delay_ms) % period_ns;
  std::int64_t tick_real = ((real_now - offset_ns) / period_ns + 1) * period_ns + offset_ns;
  std::int64_t deadline = mono_now + (tick_real - real_now);
  const auto status_every = static_cast<std::uint64_t>(std::max(1.0, d.config.executor.rate_hz));
  char status[320];
  spdlog::info("executor: {} Hz, {} workers, input delay {} ms, pose wait {} ms",
               d.config.executor.rate_hz, d.config.executor.workers,
               d.config.executor.input_delay_ms, d.config.executor.pose_wait_ms);
  const std::int64_t wake_lead_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(ThreadPool::kWakeLead).count();
  while (!stop_requested()) {
    // Asleep until the tick, but never longer than kStopPollSlice without looking at the stop
    // predicate: a long period (rate_hz 0.1) must not delay a stop.
    if (!sleep_until_or_stopped(deadline - wake_lead_ns, stop_requested)) break;
    // The workers slept since the last tick: they are woken a little before this one, so the
    // first stage's first parallel_for does not run on this thread alone while they wake up
    // (tens of µs on the project's VMs).
    d.pool->wake();
    sleep_until_monotonic(deadline);
    const std::int64_t woke = monotonic_ns();
    const std::int64_t stamp_clock_offset = d.stamp_now() - woke;
    std::int64_t late = woke - deadline;
    std::uint32_t skipped = 0;
    if (late >= period_ns) {
      // Late by whole periods: those ticks are skipped (counted), never run in a burst.
      const std::int64_t n = late / period_ns;
      skipped = static_cast<std::uint32_t>(n);
      deadline += n * period_ns;
      tick_real += n * period_ns;
      late -= n * period_ns;
    }
    // A step of the stamp clock (a wall-clock jump) moves the tick times with it, in whole
    // periods; the deadlines stay on CLOCK_MONOTONIC, so the loop neither bursts nor stalls.
    const std::int64_t step = clock_step_ns(stamp_clock_offset - (tick_real - deadline), period_ns);
    tick_real += step;
    d.tick(tick_real, static_cast<double>(late) / 1e6, skipped, step);
    if (hooks.on_tick_end) hooks.on_tick_end(d.cycle_index - 1);
    if (periodic_save && d.cycle_index % save_every == 0) d.snapshot_tsdf();
    // The systemd watchdog is pinged here and nowhere else: after a tick completed, on the
    // thread that runs the ticks. Not from another thread and not from the sleep above, so a
    // loop that stops ticking (a stuck stage, a schedule that never comes due) stops the pings,
    // and systemd restarts the service after WatchdogSec.
    sd_notify(0, "WATCHDOG=1");
    if (d.cycle_index % status_every == 0) {
      std::memcpy(status, "STATUS=", 7);
      format_status(status + 7, sizeof status - 7);
      sd_notify(0, status);
    }
    deadline += period_ns;
    tick_real += period_ns;
  }
  if (hooks.on_loop_end) hooks.on_loop_end();
  if (periodic_save) d.stop_saver();  // an in-flight save completes before run() returns
  const auto t = totals();
  spdlog::info("executor: stopped after {} ticks ({} skipped, {} over budget), {} scans integrated",
               t.ticks, t.skipped_ticks, t.overruns, t.scans_integrated);
  // Every drop and rejection since start, for the operator reading the journal after a stop.
  std::string counted;
  for (const auto* counters : {&d.drops, &d.rejections}) {
    for (const auto& e : counters->entries()) {
      if (e.total > 0)
        counted += fmt::format("{}{} {}", counted.empty() ? "" : ", ", e.reason, e.total);
    }
  }
  spdlog::info("executor: dropped or rejected since start: {}", counted.empty() ? "none" : counted);
}

ExecutorTotals Executor::totals() const {
  std::lock_guard lock(impl_->totals_mutex);
  return impl_->totals;
}

std::string Executor::status_line() const {
  char buf[256];
  format_status(buf, sizeof buf);
  return buf;
}

void Executor::format_status(char* buf, std::size_t size) const {
  std::lock_guard lock(impl_->totals_mutex);
  const auto& d = *impl_;
  std::snprintf(buf, size,
                "stamp->publish p50 %.1f p99 %.1f ms; cycle p50 %.1f p99 %.1f ms (budget %.0f); "
                "jitter p99 %.2f ms; %llu scans, %llu skipped, %llu over budget",
                d.stamp_to_publish.percentile(0.5), d.stamp_to_publish.percentile(0.99),
                d.cycle_ms.percentile(0.5), d.cycle_ms.percentile(0.99), d.config.budgets.cycle_ms,
                d.jitter_ms_window.percentile(0.99),
                static_cast<unsigned long long>(d.totals.scans_integrated),
                static_cast<unsigned long long>(d.totals.skipped_ticks),
                static_cast<unsigned long long>(d.totals.overruns));
}

core::Status Executor::save_map() const {
  const auto& st = impl_->config.state;
  const std::filesystem::path dir = st.dir;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return core::Error{"state.io", st.dir + ": " + ec.message()};
  const auto& map = impl_->mapper.occupancy();
  std::vector<float> log_odds;
  map.export_log_odds(log_odds);
  const std::filesystem::path file = dir / st.map_file;
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return core::Error{"state.io", tmp.string() + ": cannot be written"};
    // A self-describing header line, then float32 log-odds in window order (x fastest).
    const auto dims = map.window_size();
    const auto& min = map.window_min();
    char header[256];
    const int n =
        std::snprintf(header, sizeof header,
                      "tarmac occupancy window v1 voxel_size_m %.6f min_vox %d %d %d dims %d %d %d "
                      "stamp_ns %lld float32-log-odds unknown=-1e9\n",
                      map.params().voxel_size_m, min.x(), min.y(), min.z(), dims.x(), dims.y(),
                      dims.z(), static_cast<long long>(impl_->newest_stamp_ns));
    out.write(header, n);
    out.write(reinterpret_cast<const char*>(log_odds.data()),
              static_cast<std::streamsize>(log_odds.size() * sizeof(float)));
    if (!out) return core::Error{"state.io", tmp.string() + ": write failed"};
  }
  std::filesystem::rename(tmp, file, ec);
  if (ec) return core::Error{"state.io", file.string() + ": " + ec.message()};
  return core::Ok{};
}

}  // namespace tarmac::daemon

namespace tarmac::daemon {

void Executor::Impl::start_saver() {
  saver = std::thread([this] { saver_loop(); });
}

void Executor::Impl::stop_saver() {
  {
    std::lock_guard lock(saver_mutex);
    saver_stop = true;
  }
  saver_wake.notify_one();
  saver.join();
}

void Executor::Impl::snapshot_tsdf() {
  if (saver_busy.load()) {
    std::lock_guard lock(totals_mutex);
    ++totals.tsdf_saves_skipped;
    spdlog::warn("state: periodic TSDF save skipped, the previous one is still being written");
    return;
  }
  const auto t0 = Clock::now();
  auto copy = std::make_unique<core::TsdfLayer>(mapper.tsdf().clone());
  core::StaticOccupancy static_copy = static_occupancy();
  const double copy_ms = ms_between(t0, Clock::now());
  saver_busy = true;
  {
    std::lock_guard lock(saver_mutex);
    saver_snapshot = std::move(copy);
    saver_static = std::move(static_copy);
    saver_info = tsdf_info();
  }
  saver_wake.notify_one();
  spdlog::debug("state: TSDF snapshot for the periodic save copied in {:.1f} ms", copy_ms);
}

void Executor::Impl::saver_loop() {
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 10);  // best effort: below the cycle
  std::unique_lock lock(saver_mutex);
  while (true) {
    saver_wake.wait(lock, [this] { return saver_stop || saver_snapshot != nullptr; });
    if (saver_snapshot == nullptr) return;  // stop requested, nothing pending
    std::unique_ptr<core::TsdfLayer> layer = std::move(saver_snapshot);
    const core::StaticOccupancy occupancy = std::move(saver_static);
    const core::TsdfMapInfo info = saver_info;
    lock.unlock();
    // Said before the write: after a crash, the log shows whether one was in flight (its
    // .tmp is left behind, the previous complete save stands).
    spdlog::info("state: periodic TSDF save to {} started ({} voxels, stamp {} ns)",
                 tsdf_path().string(), layer->voxel_count(), info.stamp_ns);
    const auto t0 = Clock::now();
    std::error_code ec;
    std::filesystem::create_directories(config.state.dir, ec);
    const core::Status saved = core::save_tsdf(tsdf_path(), *layer, info, &occupancy);
    const double ms = ms_between(t0, Clock::now());
    {
      std::lock_guard totals_lock(totals_mutex);
      ++(saved ? totals.tsdf_saves : totals.tsdf_save_failures);
    }
    if (saved) {
      spdlog::info("state: periodic TSDF save to {} ({} voxels, stamp {} ns) in {:.0f} ms",
                   tsdf_path().string(), layer->voxel_count(), info.stamp_ns, ms);
    } else {
      spdlog::error("state: periodic TSDF save failed: {} [{}]", saved.error().message,
                    saved.error().code);
    }
    layer.reset();
    saver_busy = false;
    lock.lock();
  }
}

core::Status Executor::save_tsdf() const {
  const Impl& d = *impl_;
  std::error_code ec;
  std::filesystem::create_directories(d.config.state.dir, ec);
  if (ec) return core::Error{"state.io", d.config.state.dir + ": " + ec.message()};
  const core::StaticOccupancy occupancy = d.static_occupancy();
  return core::save_tsdf(d.tsdf_path(), d.mapper.tsdf(), d.tsdf_info(), &occupancy);
}

const core::TsdfLayer& Executor::tsdf() const {
  return impl_->mapper.tsdf();
}

TsdfLoadResult Executor::load_tsdf() {
  Impl& d = *impl_;
  TsdfLoadResult result;
  if (!d.config.mapping.tsdf.enabled || !d.config.state.load_on_start) return result;
  const std::filesystem::path file = d.tsdf_path();
  std::error_code ec;
  // A save cut short (a crash, kill -9, power loss) leaves its .tmp; the file itself is only
  // ever replaced whole (rename), so it is the last complete save.
  const std::filesystem::path partial = file.string() + ".tmp";
  if (std::filesystem::exists(partial, ec)) {
    std::filesystem::remove(partial, ec);
    spdlog::warn(
        "state: {} is a save cut short (crash or kill); removed, the last complete "
        "save is {}",
        partial.string(), file.string());
  }
  if (!std::filesystem::exists(file, ec)) {
    result.kind = TsdfLoadResult::Kind::kAbsent;
    spdlog::info("state: no saved TSDF at {}; starting with an empty TSDF", file.string());
    return result;
  }
  const auto& t = d.config.mapping.tsdf;
  core::Status checked = core::Ok{};
  core::Result<core::LoadedTsdf> loaded = core::Error{"tsdf_io.open", "not read"};
  try {
    loaded = core::load_tsdf(file);
    checked = loaded ? core::check_tsdf_matches(loaded.value().info, d.config.outputs.frame_id,
                                                t.voxel_size_m, t.truncation_m)
                     : core::Status(loaded.error());
    if (checked) {
      checked = core::check_static_occupancy_matches(
          loaded.value().occupancy, static_cast<float>(d.config.mapping.occupancy.voxel_size_m));
      if (!checked) {
        checked = core::Error{checked.error().code, file.string() + ": " + checked.error().message};
      }
    }
  } catch (const std::exception& e) {
    checked = core::Error{"tsdf_io.corrupt", file.string() + ": " + e.what()};
  }
  if (!checked) {
    result.kind = TsdfLoadResult::Kind::kRefused;
    result.error = checked.error().code + ": " + checked.error().message;
    // Kept aside for inspection, and so the save on exit does not overwrite the evidence.
    const std::filesystem::path aside = file.string() + ".refused";
    std::filesystem::rename(file, aside, ec);
    spdlog::error("state: saved TSDF {} refused ({}); starting with an empty TSDF ({})",
                  file.string(), result.error,
                  ec ? "could not be moved aside: " + ec.message() : "moved to " + aside.string());
    return result;
  }
  auto& map = loaded.value();
  if (map.info.config_hash != d.hash) {
    spdlog::warn(
        "state: saved TSDF was built with config {} (now {}); frame, voxel size and "
        "truncation match, so it is used",
        map.info.config_hash, d.hash);
  }
  result.kind = TsdfLoadResult::Kind::kLoaded;
  result.voxels = map.layer.voxel_count();
  result.static_voxels = map.occupancy.voxels.size();
  d.loaded_stamp_ns = map.info.stamp_ns;
  d.mapper.tsdf() = std::move(map.layer);
  d.mapper.occupancy().import_static(map.occupancy.voxels);
  spdlog::info(
      "state: TSDF loaded from {}: {} voxels in {} blocks, static occupancy {} voxels (saved at "
      "stamp {} ns)",
      file.string(), result.voxels, d.mapper.tsdf().block_count(), result.static_voxels,
      map.info.stamp_ns);
  return result;
}

}  // namespace tarmac::daemon
