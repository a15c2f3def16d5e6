// The executor (executor.hpp): its state (Impl), the tick (inputs, one daemon::Cycle, drops,
// publishing, the report), clock steps, and the run loop with its timing and between-tick work.
// Just over 600 lines because Impl's members are declared here beside the tick that uses them;
// the window file and TSDF loading are in map_store.cpp, the tick's inputs, schedule and report
// in tick_*.cpp, pose corrections in pose_corrections.cpp.

#include "tarmac/daemon/executor.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <utility>

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>
#include <tbb/parallel_for.h>

#include "fleet_share.hpp"
#include "map_store.hpp"
#include "pose_corrections.hpp"
#include "tarmac/core/assert.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/daemon/clock.hpp"
#include "tarmac/daemon/cycle.hpp"
#include "tarmac/daemon/pose_buffer.hpp"
#include "tarmac/daemon/realtime.hpp"
#include "tarmac/daemon/reason_counters.hpp"
#include "tarmac/daemon/scan_scheduler.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/transport/inputs.hpp"
#include "tarmac/transport/outputs.hpp"
#include "tick_inputs.hpp"
#include "tick_report.hpp"
#include "tick_schedule.hpp"

namespace tarmac::daemon {

namespace {

using Clock = std::chrono::steady_clock;
constexpr std::int64_t kNsPerMs = 1'000'000;

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
    void count(std::string_view reason) override { owner_.drops.add(reason); }

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
          owner_.corrections.on_pose(sample);
          if (owner_.fleet) owner_.fleet->note_pose(sample.position_std_m);
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
      owner_.corrections.queue_trajectory(stamp_ns, poses, owner_.newest_stamp_ns);
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
        corrections(cfg.mapping.corrections, poses, mapper),
        store(cfg, hash),
        pose_sink(*this),
        trajectory_sink(*this),
        reports(cfg, hash),
        max_future_ns(ms_to_ns(cfg.executor.max_future_ms)) {
    mapper.reserve_scans(cfg.quotas.reserve_points_per_scan);
    TickReport::declare_reasons(drops, rejections);
    selected.reserve(cfg.quotas.max_pending_scans + 1);
    sinks.reserve(cfg.sensors.size());
    for (std::uint32_t i = 0; i < cfg.sensors.size(); ++i) {
      sinks.emplace_back(*this, i);
      T_B_S.push_back(cfg.sensors[i].T_base_sensor);
    }
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

  /// Between ticks: rebuilds some of the TSDF spare blocks and nodes the last scans took (at most
  /// a 16th of tsdf.reserve_blocks' worth a tick, a few ms), so a growing map's new blocks cost
  /// integrate neither allocation nor page faults. On this thread, not a helper: a helper at a
  /// lower priority would hold its malloc arena's lock while preempted, and a tick freeing one of
  /// its blocks (a rebuild erasing blocks) would wait for it.
  void top_up_tsdf_spares() {
    const std::size_t per_tick = std::max<std::size_t>(64, config.mapping.tsdf.reserve_blocks / 16);
    const auto t0 = Clock::now();
    const std::size_t built = mapper.top_up_tsdf_spares(per_tick);
    if (built == 0) return;
    spares_built += built;
    spares_max_ms = std::max(spares_max_ms, ms_between(t0, Clock::now()));
  }

  /// One tick at `tick_time_ns` (stamp clock); `clock_step_ns` != 0: the stamp clock stepped by
  /// that much since the last tick (on_clock_step() runs first).
  void tick(std::int64_t tick_time_ns, double jitter_ms, std::uint32_t skipped,
            std::int64_t clock_step_ns);
  /// A tick's stage times and shed items, as the CycleReport carries them.
  struct StageFigures {
    double ms[kStageCount] = {};
    std::uint64_t shed[kStageCount] = {};
  };
  /// What the drain found changed besides the scans it selected (into `selected`).
  struct Drained {
    bool zones_changed = false, fleet_changed = false;
  };
  /// What went out this tick, for the report.
  struct Published {
    double stamp_to_publish_ms = -1.0;  ///< newest integrated scan stamp -> costmap handed out
    std::chrono::steady_clock::time_point done;
  };
  /// drain: the queues into the scheduler's slots, the pose buffer, the zones and the peers;
  /// then the scans due at this tick selected by stamp.
  Drained drain_inputs(StageFigures& f);
  /// The mapping stages, scan by scan in (stamp, sensor) order, and the corrections due; the
  /// totals updated.
  const Cycle::Tick& map_selected(StageFigures& f);
  /// The costmap and the 2D ESDF when `update`, published, then the 3D band.
  Published update_outputs(bool update, const Cycle::Tick& done, StageFigures& f);
  /// The CycleReport (and every diagnostic_array_every ticks the DiagnosticArray) of this tick.
  void report_tick(std::chrono::steady_clock::time_point start, const Published& out,
                   const Cycle::Tick& done, const StageFigures& f, double jitter_ms,
                   std::uint32_t skipped);
  /// The stamp clock stepped by `step_ns` (a whole number of periods) and ticks now sit at
  /// `tick_time_ns` on it: what was stamped by the old clock beyond the new tick + max_future
  /// (after a backward step) is forgotten — pending scans judged again ("scan.future" /
  /// "scan.stale"), poses ("pose.clock_step"), queued corrections ("correction.clock_step"),
  /// the scan order and the costmap's stamp — so scans stamped by the new clock are taken.
  void on_clock_step(std::int64_t step_ns, std::int64_t tick_time_ns);
  /// The report's input ages at this tick: each sensor's newest scan, then the pose stream.
  void fill_input_ages(transport::CycleReport& report) const;
  [[nodiscard]] double age_at_tick_ms(std::int64_t stamp_ns) const;
  /// The DiagnosticArray from this tick's facts (every outputs.diagnostic_array_every ticks).
  void publish_diagnostics(const double* stage_ms, double jitter_ms, bool overrun);
  /// The stamp clock (RunHooks::stamp_clock_ns, else CLOCK_REALTIME).
  [[nodiscard]] std::int64_t stamp_now() const {
    return stamp_clock ? stamp_clock() : realtime_ns();
  }

  config::Config config;
  transport::Participant participant;
  std::string hash;
  std::vector<SensorSink> sinks;
  std::unique_ptr<TickInputs> inputs;
  std::unique_ptr<transport::MapOutputs> outputs;
  std::unique_ptr<FleetShare> fleet;  // fleet.enabled: peers' summaries in, this vehicle's out
  std::vector<Eigen::Isometry3d> T_B_S;

  PoseBuffer poses;
  ScanScheduler scheduler;
  core::Mapper mapper;
  PoseCorrections corrections;
  MapStore store;
  std::vector<int> dds_threads;    // created by Fast DDS for this executor's participant
  std::uint64_t spares_built = 0;  // TSDF spare blocks rebuilt between ticks
  double spares_max_ms = 0.0;
  PoseSinkImpl pose_sink;
  TrajectorySinkImpl trajectory_sink;
  std::unique_ptr<ThreadPool> pool;
  std::unique_ptr<Cycle> cycle;  // the mapping stages, on `pool`
  std::vector<core::VirtualZone> zones;
  core::Costmap obstacle_grid;    // outputs.obstacle_grid_topic: the costmap without inflation
  core::Costmap esdf_slice_grid;  // outputs.esdf_slice_grid_topic: the 2D ESDF for display

  ReasonCounters drops, rejections;
  std::vector<ScanScheduler::Selected> selected;
  TickReport reports;
  std::int64_t tick_ns = 0;  // the current tick's time on the stamp clock
  std::int64_t newest_stamp_ns = 0;
  bool have_costmap = false;
  std::int64_t max_future_ns = 0;
  std::function<std::int64_t()> stamp_clock;  // RunHooks::stamp_clock_ns, set by run()

  mutable std::mutex totals_mutex;  // totals and windows are read by status_line() from main
  ExecutorTotals totals;
  RecentWindow cycle_ms, jitter_ms_window, stamp_to_publish;
  std::uint64_t cycle_index = 0;
};

void Executor::Impl::tick(std::int64_t tick_time_ns, double jitter_ms, std::uint32_t skipped,
                          std::int64_t clock_step_ns) {
  const auto t_start = Clock::now();
  tick_ns = tick_time_ns;
  drops.begin_tick();
  rejections.begin_tick();
  if (clock_step_ns != 0) on_clock_step(clock_step_ns, tick_time_ns);
  StageFigures f;
  const Drained in = drain_inputs(f);
  f.ms[kDrain] = ms_between(t_start, Clock::now());
  const Cycle::Tick& done = map_selected(f);
  const bool update =
      !selected.empty() || in.zones_changed || done.rebuilds_completed > 0 || in.fleet_changed;
  const Published out = update_outputs(update, done, f);
  report_tick(t_start, out, done, f, jitter_ms, skipped);
}

Executor::Impl::Drained Executor::Impl::drain_inputs(StageFigures& f) {
  Drained d;
  d.zones_changed = inputs->drain(zones, drops, rejections, cycle_index);
  // Peers' summaries change this vehicle's costmap only once it has one of its own.
  d.fleet_changed = fleet && fleet->take(tick_ns, drops, rejections) && have_costmap;
  const auto stats = scheduler.select(tick_ns, poses, selected, drops);
  f.shed[kDrain] = stats.deferred_scans;
  f.shed[kIngest] = stats.decimated_points;
  return d;
}

const Cycle::Tick& Executor::Impl::map_selected(StageFigures& f) {
  cycle->begin();
  corrections.apply_jumps();  // the drain found them; the map changes here
  for (const auto& sel : selected) {
    const core::PointCloud& cloud = scheduler.cloud(sel.slot);
    // A correction stamped before this scan applies before it (and after every earlier scan).
    if (corrections.pending()) corrections.apply_before(cloud.stamp_ns);
    const Cycle::ScanResult& r =
        cycle->scan(cloud, sel.T_W_B, T_B_S[sel.sensor], sel.deskew ? &sel.motion : nullptr);
    if (r.tsdf_shed) drops.add("scan.tsdf_shed_quota");
    drops.add("points.non_finite", r.filtered.counts.non_finite);
    drops.add("points.too_close", r.filtered.counts.too_close);
    drops.add("points.ego_vehicle", r.filtered.counts.ego_vehicle);
    drops.add("points.isolated", r.filtered.counts.isolated);
    drops.add("points.no_return_refused", r.filtered.counts.no_returns_refused);
    drops.add("scan.layout_undecided", r.filtered.counts.layout_undecided);
    newest_stamp_ns = std::max(newest_stamp_ns, cloud.stamp_ns);
    scheduler.release(sel.slot);
  }
  const Cycle::Tick& done = cycle->tick();
  f.ms[kIngest] = done.ingest_ms;
  f.ms[kIntegrate] = done.integrate_ms;
  f.ms[kTsdf] = done.tsdf_ms;
  f.ms[kRebuild] = done.rebuild_ms;
  f.shed[kTsdf] = done.tsdf_shed;

  // Corrections stamped up to the input horizon (no scan up to their stamp is still pending):
  // every scan before them is in, every later one is to come.
  if (corrections.pending()) {
    const std::int64_t horizon = std::min(tick_ns - ms_to_ns(config.executor.input_delay_ms),
                                          scheduler.oldest_pending_stamp() - 1);
    corrections.apply_before(horizon + 1);
  }
  {
    std::lock_guard lock(totals_mutex);  // before the costmap goes out (tests read both)
    totals.scans_integrated += done.scans;
    totals.tsdf_scans += done.tsdf_scans;
    totals.tsdf_shed_scans += done.tsdf_shed;
    totals.scans_reintegrated += done.scans_reintegrated;
    totals.rebuilds_completed += done.rebuilds_completed;
    totals.newest_stamp_ns = newest_stamp_ns;
  }
  if (mapper.rebuilding()) f.shed[kRebuild] = mapper.rebuild_remaining();  // for the next scans
  if (done.rebuilds_completed > 0) {
    const auto& cs = mapper.correction_stats();
    spdlog::info(
        "corrections: rebuilt window swapped in ({} scans re-integrated so far, {} TSDF "
        "blocks erased, {} scans rolled out)",
        cs.scans_reintegrated, cs.tsdf_blocks_erased, cs.scans_rolled_out);
  }
  return done;
}

Executor::Impl::Published Executor::Impl::update_outputs(bool update, const Cycle::Tick& done,
                                                         StageFigures& f) {
  // ---- costmap + 2D ESDF, once per tick (when something changed) ----
  if (update) {
    // Peers' observations age on the costmap's clock (its newest scan), not the tick's: the
    // same scans and summaries give the same costmap.
    if (fleet) fleet->expire(newest_stamp_ns);
    cycle->update_costmap(mapper.vehicle_pose(), zones, newest_stamp_ns);
    have_costmap = true;
  }
  f.ms[kCostmap] = done.costmap_ms;
  const auto t_costmap1 = Clock::now();

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
    if (!config.outputs.debris_topic.empty()) {
      outputs->publish_debris(mapper.debris(), newest_stamp_ns, config.outputs.frame_id);
    }
  }
  if (fleet && have_costmap) fleet->publish_if_due(tick_ns, mapper);
  const auto t_costmap_out = Clock::now();
  Published out;
  // Measured, never used to decide: newest integrated scan stamp -> costmap handed to DDS.
  if (update && !selected.empty()) {
    out.stamp_to_publish_ms = static_cast<double>(stamp_now() - newest_stamp_ns) / 1e6;
  }

  // ---- 3D ESDF band (esdf_band.enabled), from the costmap's ground, then its box out ----
  const bool band =
      update && cycle->update_esdf_band(mapper.vehicle_pose(), zones, newest_stamp_ns);
  const auto t_band1 = Clock::now();
  f.ms[kEsdfBand] = done.esdf_band_ms;
  if (band) {
    const auto& p = config.mapping.esdf_band;
    outputs->publish_band(mapper.esdf_band(), mapper.vehicle_pose().translation().head<2>(),
                          p.publish_radius_m, newest_stamp_ns, config.outputs.frame_id);
  }
  out.done = Clock::now();
  f.ms[kPublish] = ms_between(t_costmap1, t_costmap_out) + ms_between(t_band1, out.done);
  return out;
}

void Executor::Impl::report_tick(std::chrono::steady_clock::time_point start, const Published& out,
                                 const Cycle::Tick& done, const StageFigures& f, double jitter_ms,
                                 std::uint32_t skipped) {
  const double cycle_duration = ms_between(start, out.done);
  const bool overrun = reports.set_stages(f.ms, f.shed, cycle_duration);
  transport::CycleReport& report = reports.report();
  report.stamp_ns = newest_stamp_ns;
  report.cycle_index = cycle_index;
  report.tick_ns = tick_ns;
  report.wake_jitter_ms = jitter_ms;
  report.skipped_ticks = skipped;
  report.drops.resize(drops.entries().size());
  std::copy(drops.entries().begin(), drops.entries().end(), report.drops.begin());
  report.rejections.resize(rejections.entries().size());
  std::copy(rejections.entries().begin(), rejections.entries().end(), report.rejections.begin());
  fill_input_ages(report);
  report.points_in = done.points_in;
  report.points_used = done.points_used;
  report.map_memory_bytes = mapper.occupancy().memory_bytes();
  report.debris = static_cast<std::uint32_t>(mapper.debris().size());
  report.columns_changed = static_cast<std::uint32_t>(
      std::min<std::uint64_t>(done.columns_changed, std::numeric_limits<std::uint32_t>::max()));
  if (fleet) fleet->fill_report(tick_ns, cycle->fleet_counts(), report);
  {
    // Before the report goes out, so whoever reads the report and then the totals agrees.
    std::lock_guard lock(totals_mutex);
    if (fleet) {
      totals.fleet_messages_published = fleet->messages_published();
      totals.fleet_bytes_published = fleet->bytes_published();
    }
    totals.ticks += 1;
    totals.skipped_ticks += skipped;
    totals.overruns += overrun ? 1 : 0;
    cycle_ms.add(cycle_duration);
    jitter_ms_window.add(jitter_ms);
    if (out.stamp_to_publish_ms >= 0.0) stamp_to_publish.add(out.stamp_to_publish_ms);
  }
  outputs->publish_report(report);

  if (cycle_index % config.outputs.diagnostic_array_every == 0) {
    publish_diagnostics(f.ms, jitter_ms, overrun);
  }
  ++cycle_index;
}

// A sample stamped after the tick (accepted within the future tolerance, or drained while the
// tick ran late) is as fresh as can be: age 0. Negative ages stay reserved for "none yet".
double Executor::Impl::age_at_tick_ms(std::int64_t stamp_ns) const {
  return static_cast<double>(std::max<std::int64_t>(tick_ns - stamp_ns, 0)) / kNsPerMs;
}

void Executor::Impl::fill_input_ages(transport::CycleReport& report) const {
  for (std::size_t i = 0; i < config.sensors.size(); ++i) {
    const std::int64_t newest = scheduler.newest_stamp(static_cast<std::uint32_t>(i));
    auto& age = report.input_ages[i];
    age.age_ms = newest == 0 ? -1.0 : age_at_tick_ms(newest);
    age.stale = newest == 0 || tick_ns - newest > ms_to_ns(config.sensors[i].max_age_ms);
  }
  {
    const auto newest = poses.newest_stamp();
    auto& age = report.input_ages.back();
    age.age_ms = newest ? age_at_tick_ms(*newest) : -1.0;
    age.stale = !newest || tick_ns - *newest > ms_to_ns(config.pose.max_age_ms);
  }
}

void Executor::Impl::publish_diagnostics(const double* stage_ms, double jitter_ms, bool overrun) {
  DiagnosticFacts facts;
  facts.stage_ms = stage_ms;
  facts.jitter_ms = jitter_ms;
  facts.overrun = overrun;
  facts.have_costmap = have_costmap;
  facts.newest_stamp_ns = newest_stamp_ns;
  facts.scans_integrated = totals.scans_integrated;
  facts.drops = drops.total_sum();
  facts.rejections = rejections.total_sum();
  facts.skipped_ticks = totals.skipped_ticks;
  facts.stamp_to_publish_p99_ms = stamp_to_publish.percentile(0.99);
  facts.pending_scans = scheduler.pending();
  facts.pose_samples = poses.size();
  facts.clock_steps = totals.clock_steps;
  TsdfPagerStats paging;
  if (store.pager() != nullptr) {
    paging = store.pager()->stats();
    facts.paging = &paging;
  }
  outputs->publish_diagnostics(reports.diagnostics(facts));
}

void Executor::Impl::on_clock_step(std::int64_t step_ns, std::int64_t tick_time_ns) {
  tick_ns = tick_time_ns;
  const std::int64_t future = tick_time_ns + max_future_ns;
  const std::size_t scans_rejected = scheduler.on_clock_step(tick_time_ns, rejections);
  const std::size_t poses_dropped = poses.drop_after(future);
  drops.add("pose.clock_step", poses_dropped);
  // Later live samples are predicted from the ones kept, not from the old clock's.
  if (poses_dropped > 0) corrections.reset_prediction();
  const std::size_t corrections_dropped = corrections.drop_after(future);
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
  const std::vector<int> threads_before = thread_ids();
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) return participant.error();
  auto impl = std::make_unique<Impl>(cfg, std::move(participant).value());
  TickInputs::Sinks sinks{{}, &impl->pose_sink, &impl->trajectory_sink};
  for (auto& sink : impl->sinks) sinks.scans.push_back(&sink);
  auto inputs = TickInputs::create(impl->participant, cfg, std::move(sinks), impl->drops);
  if (!inputs) return inputs.error();
  impl->inputs = std::move(inputs).value();
  const auto& q = cfg.dds.qos;
  transport::OutputTopics topics{
      cfg.outputs.costmap_topic,
      cfg.outputs.esdf_slice_topic,
      cfg.mapping.esdf_band.enabled ? cfg.outputs.esdf_band_topic : std::string(),
      cfg.outputs.cycle_report_topic,
      cfg.outputs.diagnostic_array_topic,
      cfg.outputs.obstacle_grid_topic,
      cfg.outputs.esdf_slice_grid_topic,
      cfg.outputs.debris_topic};
  transport::OutputQos oq{q.costmap,     q.esdf_slice, q.esdf_band, q.diagnostics,
                          q.diagnostics, q.costmap,    q.costmap,   q.debris};
  auto outputs = transport::MapOutputs::create(impl->participant, topics, oq);
  if (!outputs) return outputs.error();
  impl->outputs = std::move(outputs).value();
  if (!cfg.outputs.debris_topic.empty()) {
    impl->outputs->reserve_debris(
        static_cast<std::size_t>(cfg.mapping.occupancy.low_objects.capacity));
  }
  if (cfg.fleet.enabled) {
    auto fleet = FleetShare::create(impl->participant, cfg, cfg.mapping.occupancy.voxel_size_m,
                                    impl->drops, impl->rejections);
    if (!fleet) return fleet.error();
    impl->fleet = std::move(fleet).value();
  }
  impl->dds_threads = threads_since(threads_before);
  return std::unique_ptr<Executor>(new Executor(std::move(impl)));
}

Executor::Executor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Executor::~Executor() = default;

void Executor::prepare(const RunHooks& hooks) {
  Impl& d = *impl_;
  if (d.pool) return;
  if (hooks.on_thread_start) hooks.on_thread_start();
  if (d.store.periodic()) d.store.start_saver();  // before real_time_setup: not pinned, not FIFO
  if (auto paged = d.store.open_pager(d.mapper); !paged) {
    // Mapping goes on with the whole TSDF in memory; the DiagnosticArray has no paging keys.
    spdlog::error("state: TSDF paging off, the TSDF is not bounded: {} [{}]", paged.error().message,
                  paged.error().code);
  }
  // OpenVDB deep-copies trees with TBB (the periodic save's copy, the pager's copies of tiles),
  // whose worker threads start at first use and inherit the starting thread's scheduling and
  // CPU set. Started here, before the real-time setup, they are ordinary threads, and no
  // thread is created mid-run (a soak saw one appear at the first periodic save).
  tbb::parallel_for(0, 1024, [](int) {});
  d.pool = real_time_setup(d.config.executor, hooks.on_thread_start);
  d.cycle = std::make_unique<Cycle>(d.mapper, *d.pool,
                                    Cycle::Quotas{d.config.quotas.tsdf_points_per_cycle});
  d.cycle->page_tsdf(d.store.pager());
  if (d.fleet) d.cycle->share_with_fleet(&d.fleet->peers());
  raise_dds_threads(d.config.executor, d.dds_threads);
}

void Executor::run(const std::function<bool()>& stop_requested, const RunHooks& hooks) {
  Impl& d = *impl_;
  prepare(hooks);
  const bool periodic_save = d.store.periodic();
  const std::uint64_t save_every = d.store.period_ticks(d.config.executor.rate_hz);
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
    if (periodic_save && d.cycle_index % save_every == 0)
      d.store.snapshot(d.mapper, d.newest_stamp_ns);
    d.top_up_tsdf_spares();
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
  if (periodic_save) d.store.stop_saver();  // an in-flight save completes before run() returns
  if (d.spares_built > 0) {
    spdlog::info(
        "executor: TSDF spares rebuilt between ticks: {} blocks' worth of blocks and nodes "
        "(at most {:.1f} ms a tick)",
        d.spares_built, d.spares_max_ms);
  }
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
  ExecutorTotals t;
  {
    std::lock_guard lock(impl_->totals_mutex);
    t = impl_->totals;
  }
  const auto corrections = impl_->corrections.counts();
  t.pose_jumps = corrections.pose_jumps;
  t.trajectory_corrections = corrections.trajectories;
  t.late_corrections = corrections.late;
  const auto saves = impl_->store.counts();
  t.tsdf_saves = saves.saves;
  t.tsdf_save_failures = saves.failures;
  t.tsdf_saves_skipped = saves.skipped;
  return t;
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
  return impl_->store.save_window(impl_->mapper.occupancy(), impl_->newest_stamp_ns);
}

core::Status Executor::save_tsdf() const {
  return impl_->store.save_tsdf(impl_->mapper, impl_->newest_stamp_ns);
}

TsdfLoadResult Executor::load_tsdf() {
  TsdfLoadResult result = impl_->store.load_tsdf(impl_->mapper);
  // The loaded layer replaced the one sized at construction: its block lookup tables again.
  if (result.kind == TsdfLoadResult::Kind::kLoaded) {
    impl_->mapper.reserve_scans(impl_->config.quotas.reserve_points_per_scan);
  }
  return result;
}

const core::TsdfLayer& Executor::tsdf() const {
  return impl_->mapper.tsdf();
}

const core::OccupancyMap& Executor::occupancy() const {
  return impl_->mapper.occupancy();
}

}  // namespace tarmac::daemon
