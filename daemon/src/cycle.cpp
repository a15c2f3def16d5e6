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
  const core::FilteredScan& filtered = r.filtered;
  const auto t1 = Clock::now();
  if (pager_ != nullptr) pager_->before_occupancy(mapper_.tsdf(), filtered.T_W_B.translation());
  r.occupancy = mapper_.integrate(filtered, runner_);
  if (pager_ != nullptr) pager_->after_occupancy();
  const auto t2 = Clock::now();
  r.ingest_ms = ms_between(t0, t1);
  r.integrate_ms = ms_between(t1, t2);
  if (mapper_.params().tsdf.enabled) {
    // Shed first (DESIGN.md §3), by the points quota only: the same scans skip the TSDF
    // whatever the machine's speed.
    const std::uint64_t n = filtered.points_W.size();
    if (tick_.tsdf_points + n <= quotas_.tsdf_points_per_cycle) {
      tick_.tsdf_points += n;
      if (pager_ != nullptr) pager_->before_scan(mapper_.tsdf(), filtered.sensor_W);
      r.tsdf = &mapper_.integrate_tsdf(filtered, runner_);
      if (pager_ != nullptr) {
        pager_->after_scan(mapper_.tsdf(), filtered.sensor_W, mapper_.rebuilding());
      }
      ++tick_.tsdf_scans;
      r.tsdf_ms = ms_between(t2, Clock::now());
    } else {
      r.tsdf_shed = true;
      ++tick_.tsdf_shed;
    }
  }
  // A rebuild after a pose correction steps once per scan (a points quota of retained scans),
  // so its progress is a function of the scan sequence, not of how scans fall into ticks.
  if (mapper_.rebuilding()) {
    const auto t3 = Clock::now();
    if (pager_ != nullptr) {
      mapper_.rebuild_sensors(rebuild_sensors_);
      pager_->before_rebuild(mapper_.tsdf(), rebuild_sensors_);
    }
    r.rebuild = mapper_.rebuild_step(runner_);
    // The window and static layer re-derived from the retained scans are the map now.
    if (r.rebuild.completed && pager_ != nullptr) pager_->occupancy_replaced();
    r.rebuild_ms = ms_between(t3, Clock::now());
    tick_.scans_reintegrated += r.rebuild.scans;
    tick_.rebuilds_completed += r.rebuild.completed ? 1 : 0;
  }
  ++tick_.scans;
  tick_.points_in += filtered.counts.input;
  tick_.points_used += filtered.counts.kept;
  tick_.ingest_ms += r.ingest_ms;
  tick_.integrate_ms += r.integrate_ms;
  tick_.tsdf_ms += r.tsdf_ms;
  tick_.rebuild_ms += r.rebuild_ms;
  return r;
}

void Cycle::share_with_fleet(const core::BevPeers* peers) {
  if (!fleet_) mapper_.track_fleet_observations();
  fleet_ = true;
  peers_ = peers;
}

const core::CostmapLayers& Cycle::update_costmap(std::span<const core::VirtualZone> zones,
                                                 std::int64_t stamp_ns) {
  const auto t0 = Clock::now();
  const core::CostmapLayers& layers =
      fleet_ ? mapper_.update_costmap(zones, stamp_ns, runner_, peers_, fleet_counts_)
             : mapper_.update_costmap(zones, stamp_ns, runner_);
  tick_.costmap_ms += ms_between(t0, Clock::now());
  return layers;
}

bool Cycle::update_esdf_band(std::span<const core::VirtualZone> zones, std::int64_t stamp_ns) {
  if (!mapper_.params().esdf_band.enabled) return false;
  const auto t0 = Clock::now();
  mapper_.update_esdf_band(zones, stamp_ns, runner_);
  tick_.esdf_band_ms += ms_between(t0, Clock::now());
  return true;
}

}  // namespace tarmac::daemon
