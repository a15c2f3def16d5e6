#include "tarmac/daemon/cycle.hpp"

#include <chrono>

#include "tarmac/daemon/clock.hpp"

namespace tarmac::daemon {

namespace {
using Clock = std::chrono::steady_clock;
}  // namespace

Cycle::Cycle(core::Mapper& mapper, core::TaskRunner& runner, Quotas quotas)
    : mapper_(mapper), runner_(runner), quotas_(quotas) {}

void Cycle::begin() {
  tick_ = Tick{};
}

const Cycle::ScanResult& Cycle::scan(const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                                     const Eigen::Isometry3d& T_B_S,
                                     const core::ScanMotion* motion) {
  ScanResult& r = last_;
  r = ScanResult{};
  const auto t0 = Clock::now();
  r.filtered = mapper_.ingest(cloud, T_W_B, T_B_S, runner_, motion);
  r.ingest_ms = ms_between(t0, Clock::now());
  // Each stage's time includes the residency step before it, and the last stage's the step
  // that closes the scan: the paging a stage causes is counted against its budget.
  double* last_ms = &r.integrate_ms;
  integrate_occupancy(r);
  if (mapper_.params().tsdf.enabled) {
    if (integrate_tsdf(r)) last_ms = &r.tsdf_ms;
  }
  if (mapper_.rebuilding()) {
    rebuild_step(r);
    last_ms = &r.rebuild_ms;
  }
  const auto t_end = Clock::now();
  residency_step(ScanStage::kEnd, {}, r.rebuild.completed);
  *last_ms += ms_between(t_end, Clock::now());
  add_to_tick(r);
  return r;
}

void Cycle::residency_step(ScanStage next, std::span<const Eigen::Vector3d> at_W,
                           bool rebuild_completed) {
  if (pager_ == nullptr) return;
  ResidencyStep step;
  step.next = next;
  step.at_W = at_W;
  step.rebuilding = mapper_.rebuilding();
  step.rebuild_completed = rebuild_completed;
  pager_->step(mapper_.tsdf(), step);
}

void Cycle::integrate_occupancy(ScanResult& r) {
  const auto t0 = Clock::now();
  const Eigen::Vector3d base_W = r.filtered.T_W_B.translation();
  residency_step(ScanStage::kOccupancy, {&base_W, 1});
  r.occupancy = mapper_.integrate(r.filtered, runner_);
  r.integrate_ms = ms_between(t0, Clock::now());
}

bool Cycle::integrate_tsdf(ScanResult& r) {
  // Shed first (DESIGN.md §3), by the points quota only: the same scans skip the TSDF
  // whatever the machine's speed.
  const std::uint64_t n = r.filtered.points_W.size();
  if (tick_.tsdf_points + n > quotas_.tsdf_points_per_cycle) {
    r.tsdf_shed = true;
    ++tick_.tsdf_shed;
    return false;
  }
  const auto t0 = Clock::now();
  tick_.tsdf_points += n;
  residency_step(ScanStage::kTsdf, {&r.filtered.sensor_W, 1});
  r.tsdf = &mapper_.integrate_tsdf(r.filtered, runner_);
  ++tick_.tsdf_scans;
  r.tsdf_ms = ms_between(t0, Clock::now());
  return true;
}

// A rebuild after a pose correction steps once per scan (a points quota of retained scans),
// so its progress is a function of the scan sequence, not of how scans fall into ticks.
void Cycle::rebuild_step(ScanResult& r) {
  const auto t0 = Clock::now();
  if (pager_ != nullptr) mapper_.rebuild_sensors(rebuild_sensors_);
  residency_step(ScanStage::kRebuild, rebuild_sensors_);
  r.rebuild = mapper_.rebuild_step(runner_);
  r.rebuild_ms = ms_between(t0, Clock::now());
  tick_.scans_reintegrated += r.rebuild.scans;
  tick_.rebuilds_completed += r.rebuild.completed ? 1 : 0;
}

void Cycle::add_to_tick(const ScanResult& r) {
  ++tick_.scans;
  tick_.points_in += r.filtered.counts.input;
  tick_.points_used += r.filtered.counts.kept;
  tick_.columns_changed += r.occupancy.changed.count();
  tick_.ingest_ms += r.ingest_ms;
  tick_.integrate_ms += r.integrate_ms;
  tick_.tsdf_ms += r.tsdf_ms;
  tick_.rebuild_ms += r.rebuild_ms;
}

void Cycle::share_with_fleet(const core::BevPeers* peers) {
  if (!fleet_) mapper_.track_fleet_observations();
  fleet_ = true;
  peers_ = peers;
}

const core::CostmapLayers& Cycle::update_costmap(const Eigen::Isometry3d& T_W_B,
                                                 std::span<const core::VirtualZone> zones,
                                                 std::int64_t stamp_ns) {
  const auto t0 = Clock::now();
  const core::CostmapLayers& layers =
      fleet_ ? mapper_.update_costmap(T_W_B, zones, stamp_ns, runner_, peers_, fleet_counts_)
             : mapper_.update_costmap(T_W_B, zones, stamp_ns, runner_);
  tick_.costmap_ms += ms_between(t0, Clock::now());
  return layers;
}

bool Cycle::update_esdf_band(const Eigen::Isometry3d& T_W_B,
                             std::span<const core::VirtualZone> zones, std::int64_t stamp_ns) {
  if (!mapper_.params().esdf_band.enabled) return false;
  const auto t0 = Clock::now();
  mapper_.update_esdf_band(T_W_B, zones, stamp_ns, runner_);
  tick_.esdf_band_ms += ms_between(t0, Clock::now());
  return true;
}

}  // namespace tarmac::daemon
