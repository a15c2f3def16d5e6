// The mapping pipeline on real data: ../shared/data/mulran_kaist03 (car-mounted Ouster OS1-64,
// 21 keyframes along a straight campus road lined with trees and parked vehicles; the car drives
// from x = 0 to x = −23.6 m along y ≈ 0, world frame = first LiDAR frame, z up).

#include <gtest/gtest.h>

#include "tarmac/core/mapper.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/tools/kitti.hpp"
#include "test_env.hpp"

namespace tarmac {
namespace {

struct RunResult {
  core::CostmapLayers layers;
  std::vector<Eigen::Vector3d> path_W;
  std::vector<float> log_odds;
};

RunResult run(const std::filesystem::path& dir, std::size_t threads) {
  auto seq = tools::open_kitti(dir);
  EXPECT_TRUE(seq.ok()) << (seq.ok() ? "" : seq.error().message);
  core::MapperParams params;
  // MulRan's scans are unorganised (no beams without return): the envelope above the roof is
  // observed only where something above returned, so the road is judged by the any-voxel rule.
  params.costmap.free_rule = core::FreeRule::kAnyVoxel;
  core::Mapper mapper(params);
  daemon::ThreadPool pool(threads);
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = 1.9;  // roof-mounted
  RunResult result;
  core::PointCloud cloud;
  for (std::size_t k = 0; k < seq.value().scans.size(); ++k) {
    EXPECT_TRUE(tools::read_kitti_scan(seq.value().scans[k], cloud).ok());
    const Eigen::Isometry3d T_W_B = seq.value().T_W_S[k] * T_B_S.inverse();
    const auto scan = mapper.ingest(cloud, T_W_B, T_B_S);
    mapper.integrate(scan, pool);
    mapper.update_costmap(mapper.vehicle_pose(), {}, 0, pool);
    result.path_W.push_back(T_W_B.translation());
  }
  const auto& l = mapper.costmap();
  result.layers.costmap = l.costmap.clone();
  result.layers.column_class = l.column_class.clone();
  mapper.occupancy().export_log_odds(result.log_odds);
  return result;
}

double lethal_fraction(const core::Costmap& costmap, double x0, double x1, double y0, double y1) {
  std::size_t lethal = 0, total = 0;
  for (double x = x0; x < x1; x += 0.2) {
    for (double y = y0; y < y1; y += 0.2) {
      const auto c = costmap.geometry().cell_of(x, y);
      if (!c) continue;
      ++total;
      lethal += costmap.at(c->x(), c->y()) == core::kCostLethal ? 1 : 0;
    }
  }
  return total > 0 ? static_cast<double>(lethal) / static_cast<double>(total) : 0.0;
}

TEST(MulranKaist03, RoadIsFreeRoadsideIsOccupied_SameForOneAndTwoThreads) {
  const auto dir = test::data_dir() / "mulran_kaist03";
  TARMAC_REQUIRE_OR_SKIP(std::filesystem::exists(dir / "poses.txt"),
                         "data not found: " + dir.string() + " (set TARMAC_DATA_DIR)");
  const auto one = run(dir, 1);
  const auto& costmap = one.layers.costmap;
  // Where the car drove, the costmap is not lethal and not unknown.
  for (const auto& p : one.path_W) {
    const auto c = costmap.geometry().cell_of(p.x(), p.y());
    ASSERT_TRUE(c.has_value());
    const int cost = costmap.at(c->x(), c->y());
    EXPECT_TRUE(cost >= 0 && cost < core::kCostInscribed) << "at " << p.transpose() << ": " << cost;
  }
  // The lane the car drove (its 1.8 m width plus 0.5 m each side) is free over the whole run;
  // the tree and parked-vehicle rows 5–10 m to either side are not.
  const double road = lethal_fraction(costmap, -23.0, 0.0, -1.4, 1.4);
  const double left = lethal_fraction(costmap, -23.0, 0.0, 5.0, 10.0);
  const double right = lethal_fraction(costmap, -23.0, 0.0, -10.0, -5.0);
  std::printf("lethal fraction: road %.4f, left side %.3f, right side %.3f\n", road, left, right);
  EXPECT_EQ(road, 0.0);
  EXPECT_GT(left, 0.05);
  EXPECT_GT(right, 0.05);

  const auto two = run(dir, 2);
  EXPECT_EQ(one.log_odds, two.log_odds);
  EXPECT_EQ(one.layers.costmap.cells(), two.layers.costmap.cells());
}

}  // namespace
}  // namespace tarmac
