#pragma once
// What the in-process executor tests share (executor_test.cpp, fault_injection_test.cpp): a small
// simulated sequence, a test config, the executor on its own thread, a peer participant and the
// CycleReport reader. Every DDS test passes its own domain (test_env.hpp).

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::test {

using ReportReader = transport::Reader<tarmac_msgs::msg::dds_::CycleReport_PubSubType>;

inline constexpr int kScans = 20;

/// A small sequence (kScans scans of 16 beams at 10 Hz) generated once for the whole binary.
inline const tools::KittiSequence& sequence() {
  static const tools::KittiSequence seq = [] {
    const auto dir = std::filesystem::temp_directory_path() /
                     ("tarmac-executor-test-" + std::to_string(::getpid()));
    sim::SequenceParams p;
    p.scans = kScans;
    p.lidar.beams = 16;
    p.lidar.azimuth_steps = 512;
    const auto written = sim::write_sequence(sim::Scene::airside_default(), p, dir);
    EXPECT_TRUE(written.ok()) << written.error;
    auto opened = tools::open_kitti(dir);
    EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
    return std::move(opened).value();
  }();
  return seq;
}

/// `c` in slow motion by kTimeScale (test_env.hpp): the executor's rate divided; its waits, the
/// input ages, the stage budgets and the pose-jump prediction gap multiplied. Replays then run
/// at their rate divided by kTimeScale too, so every tick sees the same scans as in the normal
/// build. Sensors added later need their max_age_ms scaled by the test.
inline void scale_time(config::Config& c) {
  const double s = kTimeScale;
  c.executor.rate_hz /= s;
  c.executor.input_delay_ms *= s;
  c.executor.pose_wait_ms *= s;
  c.executor.max_future_ms *= s;
  c.pose.max_gap_ms *= s;
  c.pose.max_age_ms *= s;
  for (auto& sensor : c.sensors) sensor.max_age_ms *= s;
  auto& b = c.budgets;
  for (double* ms : {&b.drain_ms, &b.ingest_ms, &b.integrate_ms, &b.tsdf_ms, &b.rebuild_ms,
                     &b.costmap_ms, &b.esdf_band_ms, &b.publish_ms, &b.cycle_ms}) {
    *ms *= s;
  }
  c.outputs.costmap_max_age_ms *= s;
  c.mapping.corrections.max_prediction_gap_s *= s;
}

inline config::Config test_config(std::uint32_t domain, std::uint32_t workers) {
  config::Config c;
  c.dds.participant.domain_id = domain;
  c.dds.participant.name = "tarmacd-test";
  // Reliable scans: a lost sample would change the map, and this test is about determinism.
  c.dds.qos.lidar = {transport::Reliability::kReliable, transport::Durability::kVolatile, 8};
  c.executor.workers = workers;
  c.executor.realtime_priority = 0;
  c.executor.lock_memory = false;
  c.executor.input_delay_ms = 40.0;
  c.executor.pose_wait_ms = 200.0;
  c.mapping.occupancy.window_x_vox = 200;  // 40 x 40 x 6 m keeps the test fast
  c.mapping.occupancy.window_y_vox = 200;
  c.mapping.occupancy.window_z_vox = 30;
  c.state.save_on_exit = false;
  scale_time(c);
  return c;
}

/// The executor on its own thread, stopped and joined on destruction.
class RunningExecutor {
 public:
  explicit RunningExecutor(const config::Config& cfg, const daemon::RunHooks& hooks = {}) {
    auto created = daemon::Executor::create(cfg);
    EXPECT_TRUE(created.ok()) << (created.ok() ? "" : created.error().message);
    executor_ = std::move(created).value();
    thread_ =
        std::thread([this, hooks] { executor_->run([this] { return stop_.load(); }, hooks); });
  }
  ~RunningExecutor() { stop(); }
  RunningExecutor(const RunningExecutor&) = delete;
  RunningExecutor& operator=(const RunningExecutor&) = delete;
  /// Stops and joins the executor (then its map may be read).
  void stop() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  daemon::Executor& get() { return *executor_; }

 private:
  std::unique_ptr<daemon::Executor> executor_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

/// `c` made to take input at the pace the test feeds it rather than at the clock's: a replay
/// paced by paced_by() may fall behind its schedule on a loaded machine, and its scans and
/// poses then arrive late, their stamps unchanged. Scans are not judged stale for a minute and
/// wait up to 10 s for their pose, so the maps depend on the samples alone (the determinism
/// contract), never on how busy the machine was. Not for tests about staleness or pose waits.
inline void take_late_input(config::Config& c) {
  for (auto& sensor : c.sensors) sensor.max_age_ms = 60'000.0 * kTimeScale;
  c.executor.pose_wait_ms = 10'000.0 * kTimeScale;
}

/// A tools::ReplayOptions::pace that holds scan k back until `executor` has integrated
/// `needed(k)` scans in all (its total, whatever the sensor), and gives up after a minute
/// (× kTimeScale) without progress.
inline std::function<bool(std::size_t, std::int64_t)> paced_by(
    const daemon::Executor& executor, std::function<std::uint64_t(std::size_t)> needed) {
  return [&executor, needed = std::move(needed)](std::size_t k, std::int64_t) {
    const std::uint64_t want = needed(k);
    std::uint64_t last = executor.totals().scans_integrated;
    auto deadline = std::chrono::steady_clock::now() + kTimeScale * std::chrono::seconds(60);
    while (last < want) {
      if (std::chrono::steady_clock::now() > deadline) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      const std::uint64_t now = executor.totals().scans_integrated;
      if (now != last) {  // progress: the minute starts again
        last = now;
        deadline = std::chrono::steady_clock::now() + kTimeScale * std::chrono::seconds(60);
      }
    }
    return true;
  };
}

/// The same for one sensor's replay: at most `ahead` scans beyond what `executor` has
/// integrated since `integrated_before` (its total when the replay starts). With `ahead` below
/// the executor's queue depth (8) no scan is ever shed from a full queue, however the machine
/// stalls.
inline std::function<bool(std::size_t, std::int64_t)> paced_by(
    const daemon::Executor& executor, std::size_t ahead = 4, std::uint64_t integrated_before = 0) {
  return paced_by(executor, [ahead, integrated_before](std::size_t k) -> std::uint64_t {
    return k < ahead ? integrated_before : integrated_before + (k - ahead) + 1;
  });
}

inline transport::Participant peer(std::uint32_t domain) {
  transport::ParticipantConfig pc;
  pc.domain_id = domain;
  pc.name = "executor-test-peer";
  auto p = transport::Participant::create(pc);
  EXPECT_TRUE(p.ok());
  return std::move(p).value();
}

/// Collects CycleReports until `done(report)` or the timeout; returns the last one.
inline transport::CycleReport wait_for_report(
    ReportReader& reader, const std::function<bool(const transport::CycleReport&)>& done,
    std::chrono::seconds timeout = kTimeScale * std::chrono::seconds(15)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::vector<transport::CycleReportMsg> batch;
  transport::CycleReport last;
  while (std::chrono::steady_clock::now() < deadline) {
    reader.wait_for_sample(std::chrono::milliseconds(100));
    batch.clear();
    reader.take_all(batch);
    for (const auto& m : batch) {
      last = transport::from_cycle_report(m);
      if (done(last)) return last;
    }
  }
  return last;
}

/// The total since start of `reason` in a report's drops or rejections (0 when absent).
inline std::uint64_t total_of(const std::vector<transport::ReasonReport>& list,
                              const std::string& reason) {
  for (const auto& e : list) {
    if (e.reason == reason) return e.total;
  }
  return 0;
}

}  // namespace tarmac::test
