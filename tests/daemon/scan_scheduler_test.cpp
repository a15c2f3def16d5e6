// ScanScheduler: selection by stamp and sensor, never by arrival; pose waits and drops;
// stamp rejections; deterministic quotas.

#include "tarmac/daemon/scan_scheduler.hpp"

#include <gtest/gtest.h>

namespace tarmac::daemon {
namespace {

constexpr std::int64_t kMs = 1'000'000;

SchedulerParams params(std::size_t sensors = 2) {
  SchedulerParams p;
  p.input_delay_ns = 20 * kMs;
  p.pose_wait_ns = 100 * kMs;
  p.max_future_ns = 200 * kMs;
  p.max_age_ns.assign(sensors, 5000 * kMs);
  p.points_per_cycle = 1000;
  p.points_per_scan = 1000;
  p.max_pending = 8;
  return p;
}

struct Harness {
  explicit Harness(const SchedulerParams& p) : scheduler(p) {}
  void add(std::uint32_t sensor, std::int64_t stamp_ns, std::int64_t tick_ns, int points = 10,
           int no_returns = 0) {
    core::PointCloud& c = scheduler.slot(drops);
    c.clear();
    c.stamp_ns = stamp_ns;
    for (int i = 0; i < points; ++i) c.points_S.emplace_back(static_cast<float>(i), 0.f, 0.f);
    for (int i = 0; i < no_returns; ++i) c.no_return_S.emplace_back(0.f, 0.f, 1.f);
    scheduler.commit(sensor, tick_ns, rejections);
  }
  std::vector<std::pair<std::int64_t, std::uint32_t>> select(std::int64_t tick_ns) {
    std::vector<ScanScheduler::Selected> out;
    last_stats = scheduler.select(tick_ns, poses, out, drops);
    std::vector<std::pair<std::int64_t, std::uint32_t>> got;
    for (const auto& s : out) {
      got.emplace_back(scheduler.cloud(s.slot).stamp_ns, s.sensor);
      scheduler.release(s.slot);
    }
    return got;
  }
  void pose_at(std::int64_t stamp_ns) {
    transport::PoseSample s;
    s.stamp_ns = stamp_ns;
    poses.insert(s);
  }
  ScanScheduler scheduler;
  PoseBuffer poses{64, 10000 * kMs};
  ReasonCounters drops, rejections;
  ScanScheduler::TickStats last_stats;
};

TEST(ScanScheduler, Select_OrdersByStampThenSensorWhateverTheArrivalOrder) {
  Harness h(params());
  const std::int64_t t = 1000 * kMs;
  h.pose_at(0);
  h.pose_at(t);
  h.add(1, 500 * kMs, t);
  h.add(0, 600 * kMs, t);
  h.add(0, 500 * kMs, t);
  h.add(1, 400 * kMs, t);
  const auto got = h.select(t);
  const std::vector<std::pair<std::int64_t, std::uint32_t>> want = {
      {400 * kMs, 1}, {500 * kMs, 0}, {500 * kMs, 1}, {600 * kMs, 0}};
  EXPECT_EQ(got, want);
}

TEST(ScanScheduler, Select_TakesOnlyScansOlderThanTheInputDelay) {
  Harness h(params());
  h.pose_at(0);
  h.pose_at(2000 * kMs);
  h.add(0, 985 * kMs, 1000 * kMs);
  EXPECT_TRUE(h.select(1000 * kMs).empty());  // 15 ms old < 20 ms input delay
  EXPECT_EQ(h.select(1005 * kMs).size(), 1u);
}

TEST(ScanScheduler, Select_ScanWithoutPoseWaitsThenIsDroppedAndCounted) {
  Harness h(params());
  h.pose_at(0);
  h.pose_at(400 * kMs);
  h.add(0, 500 * kMs, 600 * kMs);
  h.add(0, 550 * kMs, 600 * kMs);
  EXPECT_TRUE(h.select(600 * kMs).empty());  // no pose at/after 500 ms yet: wait
  EXPECT_EQ(h.drops.total("scan.pose_timeout"), 0u);
  EXPECT_TRUE(h.select(619 * kMs).empty());  // eligible at 520 ms, within its 100 ms wait
  EXPECT_EQ(h.drops.total("scan.pose_timeout"), 0u);
  EXPECT_TRUE(h.select(620 * kMs).empty());  // the 500 ms scan is dropped, the 550 ms one waits
  EXPECT_EQ(h.drops.total("scan.pose_timeout"), 1u);
  h.pose_at(700 * kMs);
  const auto got = h.select(730 * kMs);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].first, 550 * kMs);
}

TEST(ScanScheduler, Deskew_WaitsForThePoseAtTheLastPointAndCarriesBothEnds) {
  SchedulerParams p = params(1);
  p.deskew = {true};
  Harness h(p);
  h.pose_at(0);
  h.pose_at(500 * kMs);
  // A 100 ms sweep stamped at its start: points from 0 to +100 ms.
  const auto add_sweep = [&](std::int64_t stamp_ns, float span_s) {
    core::PointCloud& c = h.scheduler.slot(h.drops);
    c.clear();
    c.stamp_ns = stamp_ns;
    for (int i = 0; i <= 10; ++i) {
      c.points_S.emplace_back(1.f, 0.f, 0.f);
      c.time_offset_s.push_back(span_s * static_cast<float>(i) / 10.f);
    }
    h.scheduler.commit(0, stamp_ns, h.rejections);
  };
  add_sweep(450 * kMs, 0.1f);  // its last point, at 550 ms, is after the newest pose
  std::vector<ScanScheduler::Selected> out;
  h.scheduler.select(560 * kMs, h.poses, out, h.drops);  // within its pose wait
  EXPECT_TRUE(out.empty()) << "selected before the pose at its last point arrived";
  transport::PoseSample later;
  later.stamp_ns = 600 * kMs;
  later.T_W_B.translation() = Eigen::Vector3d(6.0, 0.0, 0.0);  // 10 m/s from 0 at 0 ms
  h.poses.insert(later);
  h.scheduler.select(561 * kMs, h.poses, out, h.drops);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].deskew);
  EXPECT_FLOAT_EQ(static_cast<float>(out[0].motion.t0_s), 0.0f);
  EXPECT_FLOAT_EQ(static_cast<float>(out[0].motion.t1_s), 0.1f);
  // Poses interpolated at 450 ms (stamp = first point) and 550 ms (last point).
  EXPECT_NEAR(out[0].T_W_B.translation().x(), 0.0, 1e-12);  // 0..500 ms are both at the origin
  EXPECT_NEAR(out[0].motion.T_W_B_0.translation().x(), 0.0, 1e-12);
  EXPECT_NEAR(out[0].motion.T_W_B_1.translation().x(), 3.0, 1e-6);
  h.scheduler.release(out[0].slot);

  // Times that span seconds are not sweep offsets: integrated without deskew, counted.
  add_sweep(560 * kMs, 5.0f);
  h.scheduler.select(590 * kMs, h.poses, out, h.drops);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_FALSE(out[0].deskew);
  EXPECT_EQ(h.drops.total("scan.deskew_span"), 1u);
}

TEST(ScanScheduler, Commit_RejectsFutureStaleAndLateStamps) {
  Harness h(params());
  const std::int64_t t = 10'000 * kMs;
  h.add(0, t + 201 * kMs, t);
  h.add(0, t - 5001 * kMs, t);
  EXPECT_EQ(h.rejections.total("scan.future"), 1u);
  EXPECT_EQ(h.rejections.total("scan.stale"), 1u);
  h.pose_at(t - 400 * kMs);
  h.add(1, t - 100 * kMs, t);
  h.pose_at(t);
  ASSERT_EQ(h.select(t).size(), 1u);
  h.add(0, t - 100 * kMs, t);  // same stamp, lower sensor id: its place is taken already
  h.add(1, t - 150 * kMs, t);  // older than what was integrated
  EXPECT_EQ(h.rejections.total("scan.late"), 2u);
  EXPECT_EQ(h.scheduler.pending(), 0u);
}

TEST(ScanScheduler, Quota_DefersWhatDoesNotFitAndDecimatesBigScans) {
  auto p = params(1);
  p.points_per_cycle = 100;
  p.points_per_scan = 40;
  Harness h(p);
  const std::int64_t t = 1000 * kMs;
  h.pose_at(0);
  h.pose_at(t);
  for (int i = 0; i < 4; ++i) h.add(0, (100 + i) * kMs, t, 35);
  h.add(0, 200 * kMs, t, 81);  // decimated to every 3rd point: 27
  auto got = h.select(t);
  EXPECT_EQ(got.size(), 2u);  // 35 + 35 fits, a third would not
  EXPECT_EQ(h.last_stats.deferred_scans, 3u);
  got = h.select(t + 100 * kMs);
  ASSERT_EQ(got.size(), 3u);  // 35 + 35 + 27
  EXPECT_EQ(got[2].first, 200 * kMs);
  EXPECT_EQ(h.last_stats.decimated_points, 81u - 27u);
  EXPECT_EQ(h.last_stats.deferred_scans, 0u);
}

TEST(ScanScheduler, Quota_CountsBeamsWithoutReturnAsRays) {
  auto p = params(1);
  p.points_per_cycle = 100;
  p.points_per_scan = 50;
  Harness h(p);
  const std::int64_t t = 1000 * kMs;
  h.pose_at(0);
  h.pose_at(t);
  // 51 returns + 50 beams without return: stride 3 would keep 17 + 17 = 34 (≤ 50), stride 2
  // 26 + 25 = 51 (> 50), so 3; both halves decimated alike.
  h.add(0, 100 * kMs, t, 51, 50);
  h.add(0, 101 * kMs, t, 20, 20);  // 40 rays: fits beside the first (34 + 40 <= 100)
  h.add(0, 102 * kMs, t, 20, 20);  // would make 114: waits
  std::vector<ScanScheduler::Selected> out;
  const auto stats = h.scheduler.select(t, h.poses, out, h.drops);
  ASSERT_EQ(out.size(), 2u);
  const core::PointCloud& first = h.scheduler.cloud(out[0].slot);
  EXPECT_EQ(first.size(), 17u);
  EXPECT_EQ(first.no_return_S.size(), 17u);
  EXPECT_EQ(stats.decimated_points, (51u - 17u) + (50u - 17u));
  EXPECT_EQ(stats.deferred_scans, 1u);
}

TEST(ScanScheduler, Slots_ShedTheOldestWhenFull) {
  auto p = params(1);
  p.max_pending = 2;
  Harness h(p);
  const std::int64_t t = 1000 * kMs;
  h.add(0, 900 * kMs, t);
  h.add(0, 910 * kMs, t);
  h.add(0, 920 * kMs, t);
  h.add(0, 930 * kMs, t);  // every slot pending: the oldest is shed for it
  EXPECT_EQ(h.drops.total("scan.shed_pending_full"), 1u);
  h.pose_at(0);
  h.pose_at(2000 * kMs);
  const auto got = h.select(t + 100 * kMs);
  ASSERT_EQ(got.size(), 3u);
  EXPECT_EQ(got[0].first, 910 * kMs);
}

}  // namespace
}  // namespace tarmac::daemon
