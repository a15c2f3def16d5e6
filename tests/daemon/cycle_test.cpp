// daemon::Cycle: the stages in order, the TSDF points quota per tick.

#include "tarmac/daemon/cycle.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "tarmac/core/mapper.hpp"

namespace tarmac::daemon {
namespace {

/// A ring wall 6 m round the sensor (1.8 m up) and the ground inside it.
core::PointCloud ring_scan(std::int64_t stamp_ns, int n) {
  core::PointCloud cloud;
  cloud.stamp_ns = stamp_ns;
  for (int i = 0; i < n; ++i) {
    const float a = 2.0f * static_cast<float>(M_PI) * static_cast<float>(i) / static_cast<float>(n);
    const float z = -1.7f + 3.0f * static_cast<float>(i % 7) / 7.0f;
    cloud.points_S.emplace_back(6.0f * std::cos(a), 6.0f * std::sin(a), z);
    if (i % 2 == 0) cloud.points_S.emplace_back(3.0f * std::cos(a), 3.0f * std::sin(a), -1.8f);
  }
  return cloud;
}

Eigen::Isometry3d base_at(double x) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation().x() = x;
  return T;
}

Eigen::Isometry3d sensor_on_base() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation().z() = 1.8;
  return T;
}

TEST(Cycle, TsdfQuota_ShedsTheScanThatWouldPassItAndRestartsEachTick) {
  core::MapperParams params;
  core::Mapper mapper(params);
  core::SerialRunner runner;
  const core::PointCloud a = ring_scan(1'000'000'000, 600), b = ring_scan(1'100'000'000, 600);
  // Room for one scan's filtered points and a half.
  const std::uint64_t per_scan = mapper.ingest(a, base_at(0), sensor_on_base()).points_W.size();
  ASSERT_GT(per_scan, 500u);
  core::Mapper fresh(params);
  Cycle cycle(fresh, runner, Cycle::Quotas{per_scan + per_scan / 2});

  cycle.begin();
  const Cycle::ScanResult& first = cycle.scan(a, base_at(0), sensor_on_base());
  ASSERT_NE(first.tsdf, nullptr);
  EXPECT_FALSE(first.tsdf_shed);
  EXPECT_GT(first.tsdf->voxel_updates, 0u);
  const Cycle::ScanResult& second = cycle.scan(b, base_at(0.1), sensor_on_base());
  EXPECT_EQ(second.tsdf, nullptr);
  EXPECT_TRUE(second.tsdf_shed);
  EXPECT_GT(second.occupancy.voxel_visits, 0u);  // the occupancy still takes the scan
  // The tick sums what each scan changed.
  const std::size_t second_changed = second.occupancy.changed.count();
  EXPECT_GT(second_changed, 0u);
  EXPECT_GT(cycle.tick().columns_changed, second_changed);
  EXPECT_EQ(cycle.tick().scans, 2u);
  EXPECT_EQ(cycle.tick().tsdf_scans, 1u);
  EXPECT_EQ(cycle.tick().tsdf_shed, 1u);
  EXPECT_EQ(cycle.tick().tsdf_points, per_scan);
  EXPECT_EQ(cycle.tick().points_in, a.size() + b.size());

  cycle.begin();  // a new tick: a new quota
  EXPECT_EQ(cycle.tick().scans, 0u);
  EXPECT_EQ(cycle.tick().columns_changed, 0u);
  const Cycle::ScanResult& third = cycle.scan(b, base_at(0.1), sensor_on_base());
  EXPECT_NE(third.tsdf, nullptr);
  EXPECT_EQ(cycle.tick().tsdf_shed, 0u);
}

// The cycle is the mapper's stages in DESIGN.md §3's order, nothing else: the same maps as the
// stages called by hand, and each stage timed.
TEST(Cycle, SameMapsAsTheStagesCalledInOrder) {
  core::MapperParams params;
  core::Mapper by_hand(params), cycled(params);
  core::SerialRunner runner;
  Cycle cycle(cycled, runner, {});
  for (int k = 0; k < 3; ++k) {
    const core::PointCloud cloud = ring_scan(1'000'000'000 + k * 100'000'000, 500 + 50 * k);
    const Eigen::Isometry3d T_W_B = base_at(0.2 * k);
    const core::FilteredScan scan = by_hand.ingest(cloud, T_W_B, sensor_on_base(), runner);
    by_hand.integrate(scan, runner);
    by_hand.integrate_tsdf(scan, runner);
    by_hand.update_costmap(by_hand.vehicle_pose(), {}, cloud.stamp_ns, runner);
    by_hand.update_esdf_band(by_hand.vehicle_pose(), {}, cloud.stamp_ns, runner);

    cycle.begin();
    const Cycle::ScanResult& r = cycle.scan(cloud, T_W_B, sensor_on_base());
    EXPECT_EQ(r.filtered.points_W.size(), scan.points_W.size());
    cycle.update_costmap(cycle.mapper().vehicle_pose(), {}, cloud.stamp_ns);
    EXPECT_EQ(cycle.update_esdf_band(cycle.mapper().vehicle_pose(), {}, cloud.stamp_ns),
              params.esdf_band.enabled);
    EXPECT_GT(cycle.tick().ingest_ms + cycle.tick().integrate_ms, 0.0);
    EXPECT_GT(cycle.tick().costmap_ms, 0.0);
  }
  EXPECT_EQ(by_hand.tsdf().digest(), cycled.tsdf().digest());
  EXPECT_EQ(by_hand.costmap().costmap.cells(), cycled.costmap().costmap.cells());
  EXPECT_GT(cycled.tsdf().block_count(), 0u);
}

}  // namespace
}  // namespace tarmac::daemon
