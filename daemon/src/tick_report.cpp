#include "tick_report.hpp"

#include <cstdio>

namespace tarmac::daemon {

namespace {

constexpr const char* kStageNames[kStageCount] = {"drain",   "ingest",  "integrate", "tsdf",
                                                  "rebuild", "costmap", "esdf_band", "publish"};

}  // namespace

TickReport::TickReport(const config::Config& config, const std::string& config_hash)
    : costmap_max_age_ms_(config.outputs.costmap_max_age_ms), fleet_(config.fleet.enabled) {
  report_.frame_id = config.outputs.frame_id;
  report_.config_hash = config_hash;
  report_.cycle_budget_ms = config.budgets.cycle_ms;
  report_.stages.resize(kStageCount);
  const double budgets[kStageCount] = {config.budgets.drain_ms,     config.budgets.ingest_ms,
                                       config.budgets.integrate_ms, config.budgets.tsdf_ms,
                                       config.budgets.rebuild_ms,   config.budgets.costmap_ms,
                                       config.budgets.esdf_band_ms, config.budgets.publish_ms};
  for (std::size_t i = 0; i < kStageCount; ++i) {
    report_.stages[i].name = kStageNames[i];
    report_.stages[i].budget_ms = budgets[i];
  }
  report_.input_ages.resize(config.sensors.size() + 1);
  for (std::size_t i = 0; i < config.sensors.size(); ++i) {
    report_.input_ages[i].input = config.sensors[i].id;
  }
  report_.input_ages.back().input = "pose";
  report_.drops.reserve(32 + 2 * config.sensors.size());
  report_.rejections.reserve(32);

  // The DiagnosticArray's keys are set here once; each tick only rewrites the values and the
  // message in place (capacity reserved here, so publishing them does not allocate).
  diag_.name = "tarmacd: executor";
  diag_.hardware_id = config.dds.participant.name;
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
  diag_.values.resize(kDiagFixed + 2 * report_.input_ages.size());
  for (std::size_t i = 0; i < kDiagFixed; ++i) diag_.values[i].first = kKeys[i];
  for (std::size_t i = 0; i < report_.input_ages.size(); ++i) {
    const std::string prefix = "input." + report_.input_ages[i].input;
    diag_.values[kDiagFixed + 2 * i].first = prefix + ".age_ms";
    diag_.values[kDiagFixed + 2 * i + 1].first = prefix + ".stale";
  }
  if (config.mapping.tsdf.enabled && config.mapping.tsdf.resident_limit_mb > 0) {
    for (const char* key : {"tsdf_resident_mib", "tsdf_tiles_stored", "tsdf_tile_loads_late_total",
                            "tsdf_tile_errors_total"}) {
      diag_.values.emplace_back(key, std::string());
      ++paging_keys_;
    }
  }
  if (fleet_) diag_.values.emplace_back("fleet.newest_age_ms", std::string());
  for (auto& v : diag_.values) v.second.reserve(32);
  diag_.message.reserve(kDiagMessageSize);
}

void TickReport::declare_reasons(ReasonCounters& drops, ReasonCounters& rejections) {
  for (const char* r :
       {"queue.scan_overflow", "queue.pose_overflow", "scan.shed_pending_full", "scan.pose_timeout",
        "scan.pose_before_buffer", "scan.pose_gap", "points.non_finite", "points.too_close",
        "points.ego_vehicle", "points.isolated", "points.no_return_refused", "scan.tsdf_shed_quota",
        "scan.deskew_span", "scan.layout_undecided", "scan.time_unrelated", "pose.clock_step",
        "transport.pose_lost"}) {
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
                        "pointcloud.driver_mismatch",
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
}

bool TickReport::set_stages(const double* stage_ms, const std::uint64_t* shed, double cycle_ms) {
  bool overrun = cycle_ms > report_.cycle_budget_ms;
  for (std::size_t i = 0; i < kStageCount; ++i) {
    auto& s = report_.stages[i];
    s.duration_ms = stage_ms[i];
    s.overrun = stage_ms[i] > s.budget_ms;
    s.shed_items = shed[i];
    overrun = overrun || s.overrun;
  }
  report_.cycle_duration_ms = cycle_ms;
  report_.overrun = overrun;
  return overrun;
}

const transport::DiagnosticReport& TickReport::diagnostics(const DiagnosticFacts& f) {
  const std::int64_t tick_ns = report_.tick_ns;
  diag_.stamp_ns = tick_ns;
  const auto put = [&](std::size_t i, double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f", v);
    diag_.values[i].second = buf;
  };
  const auto put_flag = [&](std::size_t i, bool v) {
    diag_.values[i].second = v ? "true" : "false";
  };
  // The costmap carries the newest integrated scan's stamp: its age is the tick's distance to
  // it (CycleReport: tick_ns − stamp_ns).
  const double costmap_age_ms = f.have_costmap && f.newest_stamp_ns != 0
                                    ? static_cast<double>(tick_ns - f.newest_stamp_ns) / 1e6
                                    : -1.0;
  const bool costmap_stale = costmap_age_ms < 0.0 || costmap_age_ms > costmap_max_age_ms_;
  put(0, report_.cycle_duration_ms);
  put(1, f.jitter_ms);
  put(2, f.stage_ms[kIntegrate]);
  put(3, f.stage_ms[kCostmap]);
  put(4, static_cast<double>(f.scans_integrated));
  put(5, static_cast<double>(f.drops));
  put(6, static_cast<double>(f.rejections));
  put(7, static_cast<double>(f.skipped_ticks));
  put(8, f.stamp_to_publish_p99_ms);
  put(9, f.stage_ms[kTsdf]);
  put(10, f.stage_ms[kRebuild]);
  put(11, f.stage_ms[kEsdfBand]);
  put(12, costmap_age_ms);
  put_flag(13, costmap_stale);
  put(14, static_cast<double>(f.pending_scans));
  put(15, static_cast<double>(f.pose_samples));
  put(16, static_cast<double>(f.clock_steps));
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
  for (std::size_t i = 0; i < report_.input_ages.size(); ++i) {
    const auto& a = report_.input_ages[i];
    put(kDiagFixed + 2 * i, a.age_ms);
    put_flag(kDiagFixed + 2 * i + 1, a.stale);
    if (!a.stale) continue;
    if (!any_input_stale) append(used > 0 ? "; input stale: " : "input stale: ");
    if (any_input_stale) append(", ");
    append(a.input.c_str(), a.age_ms, " (none yet)");
    any_input_stale = true;
  }
  if (paging_keys_ > 0 && f.paging != nullptr) {
    const std::size_t b = paging_base();
    put(b, static_cast<double>(f.paging->resident_bytes) / (1024.0 * 1024.0));
    put(b + 1, static_cast<double>(f.paging->stored_tiles));
    put(b + 2, static_cast<double>(f.paging->loads_late));
    const std::uint64_t errors = f.paging->write_errors + f.paging->load_errors;
    put(b + 3, static_cast<double>(errors));
    // A failed write stops eviction (memory then grows past the limit): worth a warning.
    if (f.paging->write_errors > 0)
      append(used > 0 ? "; tsdf tile writes failing" : "tsdf tile writes failing");
  }
  if (fleet_) put_fleet();
  if (f.overrun) append(used > 0 ? "; over budget" : "over budget");
  const bool paging_failing = f.paging != nullptr && f.paging->write_errors > 0;
  diag_.level = costmap_stale ? 2 : (any_input_stale || f.overrun || paging_failing) ? 1 : 0;
  diag_.message = used > 0 ? message : "ok";
  return diag_;
}

void TickReport::put_fleet() {
  // After the fixed keys and the inputs' pairs: the newest peer cell's age, then each peer's
  // cells and summary age (a pair added the first time a peer is heard of).
  const std::size_t base = paging_base() + paging_keys_ + 1;
  const auto put = [&](std::size_t i, double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3f", v);
    diag_.values[i].second = buf;
  };
  put(base - 1, report_.fleet_newest_age_ms);
  const auto& peers = report_.fleet_peers;
  if (diag_.values.size() < base + 2 * peers.size()) diag_.values.resize(base + 2 * peers.size());
  diag_peers_.resize(std::max(diag_peers_.size(), peers.size()));
  for (std::size_t i = 0; i < peers.size(); ++i) {
    if (diag_peers_[i] !=
        peers[i].vehicle_id) {  // peers are in id order: a new one shifts the rest
      diag_peers_[i] = peers[i].vehicle_id;
      diag_.values[base + 2 * i].first = "fleet." + peers[i].vehicle_id + ".cells";
      diag_.values[base + 2 * i + 1].first = "fleet." + peers[i].vehicle_id + ".age_ms";
    }
    put(base + 2 * i, static_cast<double>(peers[i].cells));
    put(base + 2 * i + 1, peers[i].age_ms);
  }
}

}  // namespace tarmac::daemon
