// Faults injected into tarmacd's executor over loopback DDS (issue 19 item 5): a LiDAR that
// stops, a pose stream that stops and comes back, the wall clock stepping an hour either way, and
// four times the input the quotas allow. Each test has its own DDS domain and runs under the
// packet capture (nothing off loopback).

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "diagnostic_msgsPubSubTypes.h"
#include "executor_harness.hpp"
#include "loopback_only.hpp"
#include "tarmac/daemon/clock.hpp"
#include "tarmac/replay/replayer.hpp"
#include "test_env.hpp"

namespace tarmac::daemon {
namespace {

using namespace std::chrono_literals;
using test::kTimeScale;
using test::peer;
using test::ReportReader;
using test::RunningExecutor;
using test::sequence;
using test::test_config;
using test::total_of;
using test::wait_for_report;
using DiagReader = transport::Reader<diagnostic_msgs::msg::dds_::DiagnosticArray_PubSubType>;

/// One DiagnosticArray as the tests read it: the executor's status, its values by key.
struct Diag {
  int level = -1;
  std::string message;
  std::vector<std::pair<std::string, std::string>> values;
  [[nodiscard]] std::string value(const std::string& key) const {
    for (const auto& [k, v] : values) {
      if (k == key) return v;
    }
    ADD_FAILURE() << "no DiagnosticArray value " << key;
    return "";
  }
  [[nodiscard]] double number(const std::string& key) const {
    return std::strtod(value(key).c_str(), nullptr);
  }
};

/// Everything received so far on `reader`, appended to `out`.
void take_diags(DiagReader& reader, std::vector<Diag>& out) {
  std::vector<transport::DiagnosticArrayMsg> batch;
  reader.take_all(batch);
  for (const auto& m : batch) {
    if (m.status().empty()) continue;
    Diag d;
    d.level = m.status()[0].level();
    d.message = m.status()[0].message();
    for (const auto& kv : m.status()[0].values()) d.values.emplace_back(kv.key(), kv.value());
    out.push_back(std::move(d));
  }
}

/// Every CycleReport received so far, appended to `out`.
void take_reports(ReportReader& reader, std::vector<transport::CycleReport>& out) {
  std::vector<transport::CycleReportMsg> batch;
  reader.take_all(batch);
  for (const auto& m : batch) out.push_back(transport::from_cycle_report(m));
}

const transport::InputAgeReport* age_of(const transport::CycleReport& r, const std::string& input) {
  for (const auto& a : r.input_ages) {
    if (a.input == input) return &a;
  }
  return nullptr;
}

/// The CycleReports of a run that lasted `elapsed` (measured by the test, around the
/// executor's whole life), checked for a schedule that kept its pace: consecutive reports (by
/// cycle index) are one period apart on the stamp clock, times the ticks skipped in between,
/// plus `step_ns` exactly once when the stamp clock stepped; and the ticks run and skipped
/// together never outnumber the periods that really went by. A loaded machine may skip ticks
/// (counted, never burst); a schedule that followed a stepped wall clock would count an hour of
/// them (36000) in a run of seconds, whatever the machine.
void expect_steady_schedule(const std::vector<transport::CycleReport>& reports,
                            std::int64_t period_ns, std::int64_t step_ns,
                            std::chrono::steady_clock::duration elapsed) {
  ASSERT_GT(reports.size(), 10u);
  int steps_seen = 0;
  std::uint64_t skipped = 0;
  for (std::size_t i = 1; i < reports.size(); ++i) {
    const auto& a = reports[i - 1];
    const auto& b = reports[i];
    skipped += b.skipped_ticks;
    if (b.cycle_index != a.cycle_index + 1) continue;  // a report lost in between
    const std::int64_t expected = period_ns * (1 + static_cast<std::int64_t>(b.skipped_ticks));
    const std::int64_t diff = b.tick_ns - a.tick_ns;
    if (step_ns != 0 && diff == expected + step_ns) {
      ++steps_seen;
      continue;
    }
    EXPECT_EQ(diff, expected) << "cycle " << b.cycle_index;
  }
  if (step_ns != 0) {
    EXPECT_EQ(steps_seen, 1);
  }
  const auto periods = static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(elapsed).count() / period_ns);
  EXPECT_LE(reports.back().cycle_index - reports.front().cycle_index + skipped, periods + 1)
      << skipped << " ticks skipped";
  std::printf("schedule: %zu reports, %llu ticks skipped, %llu periods elapsed\n", reports.size(),
              static_cast<unsigned long long>(skipped), static_cast<unsigned long long>(periods));
}

class Faults : public test::LoopbackOnly {
 protected:
  Faults() { expect_loopback_traffic_ = true; }
};

// ---- a: one of two LiDARs stops ----

TEST_F(Faults, OneOfTwoLidarsStops_TheOtherKeepsMapping_ReportAndDiagnosticsNameTheStaleOne) {
  auto cfg = test_config(test::kDomainFaultLidarStops, 2);
  // Front's replay is paced by what the executor integrated (below): its scans may reach it
  // late behind a rebuild (each loop jumps the pose 6 m back) and must still count. Rear must
  // go stale, after a second: long enough that its six scans, sent on schedule at the start,
  // are fresh when they arrive on any machine that is not stalled for a second.
  test::take_late_input(cfg);
  cfg.executor.queue_depth = 16;  // front's pace leaves at most 4 + rear's 6 scans in flight
  constexpr double kRearMaxAgeMs = 1000.0 * kTimeScale;
  config::SensorConfig rear;
  rear.id = "rear";
  rear.topic = "rt/tarmac/lidar/rear/points";
  rear.frame_id = "lidar_rear";
  rear.max_age_ms = kRearMaxAgeMs;
  cfg.sensors.push_back(rear);
  cfg.outputs.diagnostic_array_every = 1;
  RunningExecutor executor(cfg);
  auto participant = peer(test::kDomainFaultLidarStops);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  auto diags = DiagReader::create(participant, cfg.outputs.diagnostic_array_topic,
                                  cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(diags.ok());

  // The two participants have found each other (a report arrived) before the replays' clock
  // starts: on a loaded machine discovery can take longer than the 2 s lead below, and rear's
  // six scans would then be sent after their stamps had gone stale.
  const auto first =
      wait_for_report(*reports.value(), [](const transport::CycleReport&) { return true; });
  ASSERT_GT(first.tick_ns, 0) << "no CycleReport from the executor";
  // Both LiDARs on the same stamps (a shared start): front for 3 s with the poses, rear for
  // its first 6 scans (0.3 s) only (times kTimeScale, as every duration below).
  const std::int64_t start = clock_now_ns(CLOCK_REALTIME) + 2'000'000'000LL * kTimeScale;
  tools::ReplayOptions front;
  front.lidar_qos = cfg.dds.qos.lidar;
  front.rate_scale = 2.0 / kTimeScale;
  front.loops = 3;
  front.start_ns = start;
  tools::ReplayOptions rear_options = front;
  rear_options.lidar_topic = rear.topic;
  rear_options.frame_id = rear.frame_id;
  rear_options.publish_poses = false;
  rear_options.loops = 1;
  rear_options.max_scans = 6;
  // Front's scan k waits until the executor has integrated k − 3 scans in all (rear's count
  // too, so a rear scan lost on a stalled machine cannot hold front back).
  front.pace = test::paced_by(executor.get(), 4);
  core::Result<tools::ReplayStats> front_stats = core::Error{"", ""};
  core::Result<tools::ReplayStats> rear_stats = core::Error{"", ""};
  std::thread front_thread([&] { front_stats = tools::replay(participant, sequence(), front); });
  std::thread rear_thread(
      [&] { rear_stats = tools::replay(participant, sequence(), rear_options); });
  // While front goes on: rear stale with its age, front fresh.
  const auto stale = wait_for_report(*reports.value(), [](const transport::CycleReport& r) {
    const auto* f = age_of(r, "front");
    const auto* b = age_of(r, "rear");
    return f != nullptr && b != nullptr && b->stale && b->age_ms > 1.2 * kRearMaxAgeMs &&
           !f->stale && f->age_ms >= 0.0;
  });
  front_thread.join();
  rear_thread.join();
  ASSERT_TRUE(front_stats.ok()) << front_stats.error().message;
  ASSERT_TRUE(rear_stats.ok()) << rear_stats.error().message;
  const auto* rear_age = age_of(stale, "rear");
  ASSERT_NE(rear_age, nullptr);
  ASSERT_TRUE(rear_age->stale) << "no report with rear stale and front fresh";
  // Its age is the distance from the tick to its last scan.
  EXPECT_NEAR(rear_age->age_ms,
              static_cast<double>(stale.tick_ns - rear_stats.value().last_stamp_ns) / 1e6, 1e-3);
  // Front kept mapping after rear went stale: scans stamped past rear's last + its max age
  // were integrated.
  EXPECT_GT(stale.stamp_ns, rear_stats.value().last_stamp_ns + std::llround(kRearMaxAgeMs * 1e6));

  // The DiagnosticArray says the same: WARN, rear named with its age, front fresh.
  std::vector<Diag> seen;
  take_diags(*diags.value(), seen);
  const auto warn = std::find_if(seen.begin(), seen.end(), [](const Diag& d) {
    return d.level == 1 && d.value("input.rear.stale") == "true" &&
           d.value("input.front.stale") == "false" && d.number("input.rear.age_ms") > kRearMaxAgeMs;
  });
  ASSERT_NE(warn, seen.end()) << "no DiagnosticArray with rear stale and front fresh";
  EXPECT_NE(warn->message.find("input stale: rear ("), std::string::npos) << warn->message;
  EXPECT_EQ(warn->message.find("front"), std::string::npos) << warn->message;
  EXPECT_EQ(warn->value("costmap_stale"), "false");
  EXPECT_GE(warn->number("input.front.age_ms"), 0.0);

  // The last scans may still be in the input delay and the pose wait on a loaded machine; and a
  // loaded machine may reject a rear scan as stale, or shed one when the pending queue is full
  // (rear's six arrive at once beside front's): every scan is integrated or counted, never lost
  // without a count.
  const auto rejected_scans = [](const transport::CycleReport& r) {
    std::uint64_t n = 0;
    for (const auto* reasons : {&r.rejections, &r.drops}) {
      for (const auto& reason : *reasons) {
        if (reason.reason.rfind("scan.", 0) == 0) n += reason.total;
      }
    }
    return n;
  };
  transport::CycleReport last;
  test::eventually([&] {
    last = wait_for_report(*reports.value(), [](const transport::CycleReport&) { return true; });
    return executor.get().totals().scans_integrated + rejected_scans(last) >= 66;
  });
  std::string rejections;
  for (const auto& reason : last.rejections) {
    if (reason.total > 0) rejections += " " + reason.reason + "=" + std::to_string(reason.total);
  }
  rejections += "; drops:";
  for (const auto& reason : last.drops) {
    if (reason.total > 0) rejections += " " + reason.reason + "=" + std::to_string(reason.total);
  }
  EXPECT_EQ(executor.get().totals().scans_integrated + rejected_scans(last), 60u + 6u)
      << "every scan of both LiDARs integrated or counted; rejections:" << rejections;
  EXPECT_GE(executor.get().totals().scans_integrated, 60u)
      << "front's scans all integrated; rejections:" << rejections;
}

// ---- b: the pose stream stops, then comes back ----

TEST_F(Faults, PoseStreamStops_ScansDroppedCostmapStaleInDiagnostics_MappingResumesWithPoses) {
  auto cfg = test_config(test::kDomainFaultPoseStops, 2);
  cfg.outputs.diagnostic_array_every = 1;
  cfg.outputs.costmap_max_age_ms = 400.0 * kTimeScale;
  cfg.pose.max_age_ms = 300.0 * kTimeScale;
  RunningExecutor executor(cfg);
  auto participant = peer(test::kDomainFaultPoseStops);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  auto diags = DiagReader::create(participant, cfg.outputs.diagnostic_array_topic,
                                  cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(diags.ok());
  // 40 scans at 20 Hz; the localiser is silent for scans 10..25 (0.8 s; all times kTimeScale).
  constexpr std::size_t kGapFirst = 10, kGap = 16, kTotal = 40;
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.loops = 2;
  options.pose_gap_first = kGapFirst;
  options.pose_gap_count = kGap;
  core::Result<tools::ReplayStats> stats = core::Error{"", ""};
  std::atomic<bool> done{false};
  std::thread replay([&] {
    stats = tools::replay(participant, sequence(), options);
    done = true;
  });
  std::vector<Diag> seen;
  std::vector<transport::CycleReport> seen_reports;
  while (!done) {
    diags.value()->wait_for_sample(50ms);
    take_diags(*diags.value(), seen);
    take_reports(*reports.value(), seen_reports);
  }
  replay.join();
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  const auto last = wait_for_report(*reports.value(), [&](const transport::CycleReport& r) {
    return r.stamp_ns == stats.value().last_stamp_ns;
  });
  take_diags(*diags.value(), seen);

  // Every scan of the gap dropped with a counted reason: its pose never came (pose_timeout),
  // or the poses around it came further apart than pose.max_gap_ms (pose_gap).
  const std::uint64_t timeout = total_of(last.drops, "scan.pose_timeout");
  EXPECT_GE(timeout, 1u);
  EXPECT_EQ(timeout + total_of(last.drops, "scan.pose_gap"), kGap);
  // Mapping resumed with the poses: the last scan is in the costmap, all others integrated.
  EXPECT_EQ(last.stamp_ns, stats.value().last_stamp_ns) << "mapping did not resume";
  EXPECT_EQ(executor.get().totals().scans_integrated, kTotal - kGap);

  // During the gap the CycleReport's costmap age (tick − newest scan) grew past the limit,
  // and the DiagnosticArray said so: ERROR, costmap_stale, the pose input stale.
  EXPECT_TRUE(std::any_of(seen_reports.begin(), seen_reports.end(), [](const auto& r) {
    return r.stamp_ns != 0 && r.tick_ns - r.stamp_ns > 400'000'000LL * kTimeScale;
  }));
  const auto error = std::find_if(seen.begin(), seen.end(), [](const Diag& d) {
    return d.level == 2 && d.value("costmap_stale") == "true" &&
           d.number("costmap_age_ms") > 400.0 * kTimeScale;
  });
  ASSERT_NE(error, seen.end()) << "no DiagnosticArray with the costmap stale";
  EXPECT_NE(error->message.find("costmap stale ("), std::string::npos) << error->message;
  EXPECT_EQ(error->value("input.pose.stale"), "true");
  EXPECT_NE(error->message.find("pose ("), std::string::npos) << error->message;
  // ... and cleared once poses were back.
  const auto after = std::find_if(error, seen.end(), [](const Diag& d) {
    return d.value("costmap_stale") == "false" && d.value("input.pose.stale") == "false";
  });
  ASSERT_NE(after, seen.end()) << "costmap never fresh again after the gap";
  EXPECT_EQ(after->level, 0) << after->message;
  EXPECT_EQ(after->message, "ok");
}

// ---- b2: a sensor whose clock leads the vehicle's, within the future tolerance ----

TEST_F(Faults, SensorClockAheadWithinTolerance_ScansIntegrated_ItsAgeIsZeroNeverNegative) {
  auto cfg = test_config(test::kDomainFaultSensorAhead, 2);
  RunningExecutor executor(cfg);
  auto participant = peer(test::kDomainFaultSensorAhead);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  // Stamps 150 ms ahead of the tick clock (the tolerance is 200 ms): each scan is taken,
  // and each is still "in the future" at the ticks that follow its arrival.
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.max_scans = 10;
  options.clock_offset_ns = 150'000'000LL * kTimeScale;
  ASSERT_TRUE(tools::replay(participant, sequence(), options).ok());
  test::eventually([&] { return executor.get().totals().scans_integrated >= 10; });
  EXPECT_EQ(executor.get().totals().scans_integrated, 10u);
  std::vector<transport::CycleReport> seen;
  take_reports(*reports.value(), seen);
  std::size_t received = 0, at_zero = 0;
  for (const auto& r : seen) {
    const auto* front = age_of(r, "front");
    ASSERT_NE(front, nullptr);
    if (front->age_ms == -1.0) continue;  // none yet
    ++received;
    EXPECT_GE(front->age_ms, 0.0) << "cycle " << r.cycle_index;
    at_zero += front->age_ms == 0.0 ? 1 : 0;
  }
  EXPECT_GT(received, 0u) << "no report after the first scan";
  EXPECT_GT(at_zero, 0u) << "no tick saw a scan stamped after it";
}

// ---- c: the wall clock steps ±1 h ----

/// The executor's stamp clock is CLOCK_REALTIME + an offset the test steps by `step_ns` (the
/// machine's clock cannot be set in a test; RunHooks::stamp_clock_ns is the seam). Before the
/// step 6 scans are integrated; after it, 4 scans (with poses) stamped by the old clock must be
/// rejected with counted reasons, then 6 scans stamped by the new clock integrated; the ticks
/// keep one period apart throughout (the step appears once, in whole periods).
void check_clock_step(std::uint32_t domain, std::int64_t step_ns) {
  auto cfg = test_config(domain, 2);
  std::atomic<std::int64_t> offset{0};
  RunHooks hooks;
  hooks.stamp_clock_ns = [&offset] { return clock_now_ns(CLOCK_REALTIME) + offset.load(); };
  const auto t_start = std::chrono::steady_clock::now();
  RunningExecutor executor(cfg, hooks);
  auto participant = peer(domain);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  std::vector<transport::CycleReport> seen;
  const auto wait_integrated = [&](std::uint64_t n) {
    test::eventually([&] {
      take_reports(*reports.value(), seen);
      return executor.get().totals().scans_integrated >= n;
    });
    return executor.get().totals().scans_integrated;
  };
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.max_scans = 6;
  ASSERT_TRUE(tools::replay(participant, sequence(), options).ok());
  ASSERT_EQ(wait_integrated(6), 6u);

  offset = step_ns;  // the wall clock steps
  tools::ReplayOptions old_clock = options;
  old_clock.max_scans = 4;  // a sensor and a localiser still on the old clock
  ASSERT_TRUE(tools::replay(participant, sequence(), old_clock).ok());
  tools::ReplayOptions new_clock = options;
  new_clock.clock_offset_ns = step_ns;
  auto after = tools::replay(participant, sequence(), new_clock);
  ASSERT_TRUE(after.ok()) << after.error().message;
  EXPECT_EQ(wait_integrated(12), 12u) << "scans stamped by the new clock not integrated";
  const auto last = wait_for_report(*reports.value(), [&](const transport::CycleReport& r) {
    seen.push_back(r);
    return r.stamp_ns == after.value().last_stamp_ns;
  });
  EXPECT_EQ(last.stamp_ns, after.value().last_stamp_ns) << "costmap not on the new clock";
  // Enough reports to judge the schedule by: the first ones may go out before this reader has
  // matched (discovery is slow under a sanitizer), so the loop ticks on until there are 11.
  const auto distinct = [&seen] {
    std::set<std::uint64_t> cycles;
    for (const auto& r : seen) cycles.insert(r.cycle_index);
    return cycles.size();
  };
  test::eventually([&] {
    take_reports(*reports.value(), seen);
    return distinct() > 10;
  });
  executor.stop();
  const auto elapsed = std::chrono::steady_clock::now() - t_start;
  take_reports(*reports.value(), seen);
  std::sort(seen.begin(), seen.end(),
            [](const auto& a, const auto& b) { return a.cycle_index < b.cycle_index; });
  seen.erase(
      std::unique(seen.begin(), seen.end(),
                  [](const auto& a, const auto& b) { return a.cycle_index == b.cycle_index; }),
      seen.end());

  const auto t = executor.get().totals();
  EXPECT_EQ(t.clock_steps, 1u);
  EXPECT_EQ(t.last_clock_step_ns, step_ns);
  EXPECT_EQ(t.scans_integrated, 12u);
  if (step_ns > 0) {
    // Old-clock scans are an hour old on the new clock; their poses are harmless history.
    EXPECT_EQ(total_of(last.rejections, "scan.stale"), 4u);
    EXPECT_EQ(total_of(last.rejections, "scan.future"), 0u);
  } else {
    // Old-clock scans and poses are an hour in the future; the poses of before the step,
    // which would refuse every new pose as out of order, were dropped at the step.
    EXPECT_EQ(total_of(last.rejections, "scan.future"), 4u);
    EXPECT_EQ(total_of(last.rejections, "pose.future"), 4u);
    EXPECT_GE(total_of(last.drops, "pose.clock_step"), 6u);
    EXPECT_EQ(total_of(last.rejections, "scan.stale"), 0u);
  }
  EXPECT_EQ(total_of(last.rejections, "scan.late"), 0u);
  // No burst, no stall: never more ticks, run or skipped, than periods went by (monotonic).
  expect_steady_schedule(seen, std::llround(1e9 / cfg.executor.rate_hz), step_ns, elapsed);
}

TEST_F(Faults, WallClockStepsOneHourAhead_TicksKeepPace_OldStampsStale_NewStampsIntegrated) {
  check_clock_step(test::kDomainFaultClockAhead, 3'600'000'000'000);
}

TEST_F(Faults, WallClockStepsOneHourBack_TicksKeepPace_OldStampsFuture_NewStampsIntegrated) {
  check_clock_step(test::kDomainFaultClockBack, -3'600'000'000'000);
}

// ---- d: four times the input the quotas allow ----

TEST_F(Faults, FourTimesTheQuota_RateHolds_SheddingCounted_EveryScanAccountedFor) {
  const auto& seq = sequence();
  std::uint64_t scan_points = 0, scan_returns = 0;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  for (std::size_t k = 0; k < seq.scans.size(); ++k) {
    ASSERT_TRUE(tools::read_sequence_scan(seq, k, cloud, scratch).ok());
    // The quotas count rays: returns and beams without return.
    scan_points = std::max<std::uint64_t>(scan_points, cloud.size() + cloud.no_return_S.size());
    scan_returns = std::max<std::uint64_t>(scan_returns, cloud.size());
  }
  auto cfg = test_config(test::kDomainFaultOverload, 2);
  // Scans come at 80 Hz into a 10 Hz cycle (8 per tick; both slowed by kTimeScale); the quotas
  // take 2 per tick, each decimated to half its rays, and the TSDF (which counts returns only)
  // of about one of them.
  cfg.quotas.points_per_scan = scan_points / 2;
  cfg.quotas.points_per_cycle = scan_points;
  cfg.quotas.tsdf_points_per_cycle = scan_returns / 4;
  // Each of the ten loops starts the trajectory 6 m back: a pose jump, which would make every
  // loop a rebuild. Rebuilding under overload is a load of its own (its quota is
  // corrections.rebuild_points_per_cycle); this test is about the input quotas alone.
  cfg.mapping.corrections.enabled = false;
  const auto t_start = std::chrono::steady_clock::now();
  RunningExecutor executor(cfg);
  auto participant = peer(test::kDomainFaultOverload);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 8.0 / kTimeScale;
  options.loops = 10;  // 200 scans in 2.5 s
  core::Result<tools::ReplayStats> stats = core::Error{"", ""};
  std::atomic<bool> done{false};
  std::thread replay([&] {
    stats = tools::replay(participant, seq, options);
    done = true;
  });
  std::vector<transport::CycleReport> seen;
  while (!done) {
    reports.value()->wait_for_sample(50ms);
    take_reports(*reports.value(), seen);
  }
  replay.join();
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  // Every scan sent is integrated or dropped with a reason (reliable DDS: none lost on the way).
  const auto dropped_in = [](const transport::CycleReport& r) {
    std::uint64_t dropped = 0;
    for (const char* reason :
         {"scan.shed_pending_full", "queue.scan_overflow", "scan.pose_timeout", "scan.pose_gap",
          "scan.pose_before_buffer", "transport.scan_lost.front"}) {
      dropped += total_of(r.drops, reason);
    }
    for (const auto& e : r.rejections) {
      if (e.reason.rfind("scan.", 0) == 0 || e.reason.rfind("pointcloud.", 0) == 0) {
        dropped += e.total;
      }
    }
    return dropped;
  };
  // The backlog drains at the quota's pace once the input stops, however slowly the machine
  // lets it: wait until every scan is accounted for.
  test::eventually([&] {
    take_reports(*reports.value(), seen);
    return !seen.empty() && executor.get().totals().scans_integrated + dropped_in(seen.back()) >=
                                stats.value().scans;
  });
  executor.stop();
  const auto elapsed = std::chrono::steady_clock::now() - t_start;
  take_reports(*reports.value(), seen);
  ASSERT_FALSE(seen.empty());
  std::sort(seen.begin(), seen.end(),
            [](const auto& a, const auto& b) { return a.cycle_index < b.cycle_index; });
  const auto& last = seen.back();
  const auto t = executor.get().totals();

  // Shedding is counted at every quota: scans shed from a full pending pool, scans deferred
  // to the next tick, points decimated, TSDF stages shed.
  EXPECT_GT(total_of(last.drops, "scan.shed_pending_full"), 0u);
  EXPECT_GT(total_of(last.drops, "scan.tsdf_shed_quota"), 0u);
  std::uint64_t deferred = 0, decimated = 0, max_points_in = 0, full_ticks = 0;
  for (const auto& r : seen) {
    for (const auto& s : r.stages) {
      if (s.name == "drain") {
        deferred += s.shed_items;
        full_ticks += s.shed_items > 0 ? 1 : 0;
      }
      if (s.name == "ingest") decimated += s.shed_items;
    }
    max_points_in = std::max(max_points_in, r.points_in);
  }
  EXPECT_GT(deferred, 0u);
  EXPECT_GT(decimated, 0u);
  EXPECT_LE(max_points_in, cfg.quotas.points_per_cycle) << "a tick took more than its quota";
  EXPECT_EQ(t.scans_integrated + dropped_in(last), stats.value().scans);
  // A tick that deferred scans took its whole quota: two decimated scans (each half a scan's
  // rays, the cycle quota one scan's). Reports lost on the way only lower the count.
  EXPECT_GE(t.scans_integrated, 2 * full_ticks);

  // The rate held: one period between ticks, never a burst.
  expect_steady_schedule(seen, std::llround(1e9 / cfg.executor.rate_hz), 0, elapsed);
}

}  // namespace
}  // namespace tarmac::daemon
