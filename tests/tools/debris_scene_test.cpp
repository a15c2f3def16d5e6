// The debris report (core::extract_debris through the Mapper) on the simulator's scenes: nothing on
// the empty apron, and the 10 and 20 cm cubes of `--scene debris` reported with ids that hold
// from scan to scan, the 5 cm one (under min_obstacle_height_m) not.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "../support/sim_drive.hpp"
#include "tarmac/core/mapper.hpp"

namespace tarmac {
namespace {

using test::map_scan;
using test::simulate;
using test::without_tsdf;

/// Drives `name` from x = start_x to x = stop_x, calling `each` with the debris after every scan.
void drive(const char* name, double start_x, double stop_x,
           const std::function<void(int, const std::vector<core::Debris>&)>& each) {
  core::Mapper mapper(without_tsdf());
  simulate(name, start_x, stop_x,
           [&](int i, const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
               const Eigen::Isometry3d& T_B_S) {
             map_scan(mapper, cloud, T_W_B, T_B_S);
             each(i, mapper.debris());
           });
}

TEST(DebrisScene, EmptyApron_NoDebrisInAnyScan) {
  int scans = 0;
  drive("apron", 5.0, 20.0, [&](int i, const std::vector<core::Debris>& debris) {
    ++scans;
    EXPECT_TRUE(debris.empty()) << "scan " << i << ": " << debris.size() << " pieces, the first at "
                                << debris.front().xy_W.transpose();
  });
  EXPECT_GT(scans, 40);
}

TEST(DebrisScene, CubesAreReportedWithIdsThatHold_TheFiveCentimetreOneNot) {
  // The first row at x = 25: 10 cm at y = 0.6, 5 cm at y = −1.5, 20 cm at y = 3.0.
  const auto near = [](const core::Debris& d, double x, double y) {
    return (d.xy_W - Eigen::Vector2d(x, y)).norm() < 0.3;
  };
  // Every cube of 10 and 20 cm in the scene (small_objects.txt).
  const std::vector<Eigen::Vector2d> cubes = {{25.0, 0.6}, {25.0, 3.0},  {45.0, -0.8}, {45.0, 1.5},
                                              {65.0, 2.0}, {65.0, -3.0}, {88.0, -1.0}, {89.0, 2.3}};
  const auto a_cube = [&](const core::Debris& d) {
    return std::any_of(cubes.begin(), cubes.end(),
                       [&](const Eigen::Vector2d& c) { return near(d, c.x(), c.y()); });
  };
  std::map<std::uint32_t, int> first_scan;  // id -> scan it first appeared
  std::optional<std::uint32_t> id_10cm, id_20cm;
  std::vector<core::Debris> last;
  drive("debris", 5.0, 22.0, [&](int i, const std::vector<core::Debris>& debris) {
    for (const core::Debris& d : debris) {
      first_scan.try_emplace(d.id, i);
      EXPECT_TRUE(a_cube(d)) << "scan " << i << ": debris at " << d.xy_W.transpose();
      EXPECT_LE(d.height_m, 0.3);
      // One id per cube: once named, a cube keeps its id.
      if (near(d, 25.0, 0.6)) {
        if (!id_10cm) id_10cm = d.id;
        EXPECT_EQ(d.id, *id_10cm) << "scan " << i;
      }
      if (near(d, 25.0, 3.0)) {
        if (!id_20cm) id_20cm = d.id;
        EXPECT_EQ(d.id, *id_20cm) << "scan " << i;
      }
    }
    last = debris;
  });
  ASSERT_TRUE(id_10cm.has_value()) << "the 10 cm cube never reported";
  ASSERT_TRUE(id_20cm.has_value()) << "the 20 cm cube never reported";
  EXPECT_NE(*id_10cm, *id_20cm);
  ASSERT_GE(last.size(), 2u);
  for (const core::Debris& d : last) {
    EXPECT_LT(d.first_seen_ns, d.last_confirmed_ns);
    EXPECT_GE(d.returns, 2u);
    EXPECT_NEAR(d.ground_z_m, 0.0, 0.05);
    EXPECT_LE(d.footprint_m, 0.5);
  }
}

TEST(DebrisScene, TheOrderOfACloudsPointsChangesNoCostmap) {
  // A driver lays a sweep out in rows by beam, by firing, or as a list of its returns: the same
  // returns in another order must give the same costmap. The occupancy updates each voxel once
  // per scan; the low objects (the debris at x = 25, 5–17 m ahead here) take the rising returns
  // in an order of their own.
  core::Mapper as_sent(without_tsdf()), reversed(without_tsdf());
  core::PointCloud backwards;
  std::size_t confirmed = 0;
  simulate("debris", 8.0, 20.0,
           [&](int i, const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
               const Eigen::Isometry3d& T_B_S) {
             test::reverse_points(cloud, backwards);
             map_scan(as_sent, cloud, T_W_B, T_B_S);
             map_scan(reversed, backwards, T_W_B, T_B_S);
             const core::CostmapLayers &a = as_sent.costmap(), &b = reversed.costmap();
             ASSERT_EQ(a.costmap.cells(), b.costmap.cells()) << "scan " << i;
             ASSERT_EQ(a.obstacle_rule, b.obstacle_rule) << "scan " << i;
             const auto objects_a = as_sent.occupancy().low_objects().all();
             const auto objects_b = reversed.occupancy().low_objects().all();
             ASSERT_EQ(objects_a.size(), objects_b.size()) << "scan " << i;
             for (std::size_t k = 0; k < objects_a.size(); ++k) {
               EXPECT_EQ(objects_a[k].id, objects_b[k].id);
               EXPECT_EQ(objects_a[k].xy_W, objects_b[k].xy_W) << "scan " << i << ", object " << k;
               EXPECT_EQ(objects_a[k].returns, objects_b[k].returns);
             }
             confirmed = static_cast<std::size_t>(
                 std::count_if(objects_a.begin(), objects_a.end(), [&](const core::LowObject& o) {
                   return as_sent.occupancy().low_objects().confirmed(o);
                 }));
           });
  EXPECT_GT(confirmed, 0u) << "the low objects took part";
}

}  // namespace
}  // namespace tarmac
