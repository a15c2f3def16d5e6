// The costmap through the Mapper on tarmac-sim's terrain scenes: the ground the simulator's rings
// give at range, as the vehicle approaches it.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <gtest/gtest.h>

#include "../support/sim_drive.hpp"
#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/mapper.hpp"

namespace tarmac {
namespace {

TEST(TerrainMapping, ARampFallingAwaySeenByFarRingsIsNoDrop) {
  // The parking scene: the apron, then from x = 30 a ramp going down 9 % to the lower road at
  // x = 55, between walls at y = ±5.3. Driving along y = −1 towards it, a ring lands on the
  // ramp's far part only where its own rays, landing a little further in the scans before,
  // passed a few centimetres over it: those misses emptied the voxels that hold the ramp, and
  // the ring's one return does not fill them again. The ramp is drivable ground all the same
  // (the road beyond it is reached by it), in every scan, within 30 m of the vehicle. A window of
  // more than 64 layers (found layer by layer, not from per-column bit sets) gives the same.
  core::Mapper mapper(test::without_tsdf());
  core::MapperParams tall_params = test::without_tsdf();
  tall_params.occupancy.window_z_vox = 70;
  core::Mapper tall(tall_params);
  std::size_t checked = 0, lethal = 0;
  std::string first;
  test::simulate(
      "parking", 0.0, 12.0,
      [&](int i, const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
          const Eigen::Isometry3d& T_B_S) {
        test::map_scan(mapper, cloud, T_W_B, T_B_S);
        test::map_scan(tall, cloud, T_W_B, T_B_S);
        const core::CostmapLayers& layers = mapper.costmap();
        ASSERT_EQ(layers.costmap.cells(), tall.costmap().costmap.cells()) << "scan " << i;
        ASSERT_EQ(layers.obstacle_rule, tall.costmap().obstacle_rule) << "scan " << i;
        const double vx = T_W_B.translation().x();
        // The ramp's middle: clear of its walls, its curb (y = −4.3 .. −4.0) and the
        // cone at (42, 2.5).
        for (double x = 30.5; x < std::min(vx + 30.0, 55.0); x += 0.2) {
          for (double y = -3.5; y <= 3.5; y += 0.2) {
            if (std::hypot(x - 42.0, y - 2.5) < 1.5) continue;
            const auto cell = layers.costmap.geometry().cell_of(x, y);
            ASSERT_TRUE(cell.has_value());
            const auto cx = static_cast<std::uint32_t>(cell->x());
            const auto cy = static_cast<std::uint32_t>(cell->y());
            ++checked;
            if (layers.costmap.at(cx, cy) != core::kCostLethal) continue;
            if (lethal++ == 0) {
              first =
                  "scan " + std::to_string(i) + " at (" + std::to_string(x) + ", " +
                  std::to_string(y) + "), rule " +
                  std::to_string(
                      layers.obstacle_rule[static_cast<std::size_t>(cy) * layers.costmap.width() +
                                           cx]);
            }
          }
        }
      });
  EXPECT_GT(checked, 10000u);
  EXPECT_EQ(lethal, 0u) << "of " << checked << " ramp cell-cycles; the first: " << first;
}

TEST(TerrainMapping, TheOrderOfACloudsPointsChangesNoCostmap) {
  // The parking scene's ramp, walls and lower level, each cloud as sent and reversed: the
  // ground a sparse column's rise is taken from is the ground remembered round it, which the
  // dense columns of the same scan write; in any order of the points, the same.
  core::Mapper as_sent(test::without_tsdf()), reversed(test::without_tsdf());
  core::PointCloud backwards;
  int compared = 0;
  test::simulate("parking", 40.0, 49.0,
                 [&](int i, const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                     const Eigen::Isometry3d& T_B_S) {
                   test::reverse_points(cloud, backwards);
                   test::map_scan(as_sent, cloud, T_W_B, T_B_S);
                   test::map_scan(reversed, backwards, T_W_B, T_B_S);
                   ASSERT_EQ(as_sent.costmap().costmap.cells(), reversed.costmap().costmap.cells())
                       << "scan " << i;
                   ASSERT_EQ(as_sent.costmap().obstacle_rule, reversed.costmap().obstacle_rule)
                       << "scan " << i;
                   ++compared;
                 });
  EXPECT_GT(compared, 25);
}

}  // namespace
}  // namespace tarmac
