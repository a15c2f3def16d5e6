// The dynamic-clearing figures on a hand-made history: a 1 × 1 m object over one costmap cell,
// then gone; the cell blocks for two more scans, then reads free.

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/tools/clearing.hpp"

namespace tarmac::tools {
namespace {

using core::ColumnClass;

/// A 10 × 10 grid of 1 m cells at the origin, every cell `c`.
core::Grid2D<std::uint8_t> grid_of(ColumnClass c) {
  core::GridGeometry2D g;
  g.resolution_m = 1.0;
  g.width = 10;
  g.height = 10;
  return core::Grid2D<std::uint8_t>(g, static_cast<std::uint8_t>(c));
}

/// Scans 0 and 1 the object covers cell (5, 5) (box 5.2..5.8 m), scans 2..3 it is gone and the
/// cell still blocks, at scan 4 it reads free; the sensor stays at `sensor_xy`.
ClearingReport run(const Eigen::Vector2d& sensor_xy, double blind_radius_m) {
  DynamicTruth truth;
  for (int scan = 0; scan < 2; ++scan) {
    truth.boxes.push_back({scan, 7, {5.2, 5.2, 0.0}, {5.8, 5.8, 1.5}});
  }
  ClearingTracker tracker(truth);
  const auto all_free = grid_of(ColumnClass::kFree);
  auto with_object = grid_of(ColumnClass::kFree);
  with_object.at(5, 5) = static_cast<std::uint8_t>(ColumnClass::kObstacle);
  for (int scan = 0; scan < 5; ++scan) {
    tracker.observe(scan, 0.1 * scan, scan < 4 ? with_object : all_free, sensor_xy, blind_radius_m);
  }
  return tracker.report();
}

TEST(ClearingTracker, TimeToClear_FromTheLastScanUnderTheObject) {
  const ClearingReport r = run({0.0, 0.0}, 0.0);
  EXPECT_EQ(r.path_cells, 1u);
  EXPECT_EQ(r.measured, 1u);
  EXPECT_EQ(r.cleared, 1u);
  EXPECT_EQ(r.ghost_cells, 0u);
  EXPECT_NEAR(r.p50_s, 0.3, 1e-9);  // under it at 0.1 s, free at 0.4 s
  EXPECT_EQ(r.blind_at_leave, 0u);
  EXPECT_NEAR(r.in_view_max_s, 0.3, 1e-9);
}

TEST(ClearingTracker, CellLeftInsideTheBlindZone_IsCountedApart) {
  // The cell centre (5.5, 5.5) is 2.1 m from the sensor at (4, 4): inside a 3 m blind radius,
  // outside a 2 m one.
  const ClearingReport blind = run({4.0, 4.0}, 3.0);
  EXPECT_EQ(blind.cleared, 1u);
  EXPECT_EQ(blind.blind_at_leave, 1u);
  EXPECT_NEAR(blind.p50_s, 0.3, 1e-9);
  EXPECT_EQ(blind.in_view_max_s, 0.0);  // no cell left in view
  const ClearingReport seen = run({4.0, 4.0}, 2.0);
  EXPECT_EQ(seen.blind_at_leave, 0u);
  EXPECT_NEAR(seen.in_view_p50_s, 0.3, 1e-9);
}

TEST(ClearingTracker, BlindRadius_IsTheNearestGroundReturn) {
  const std::vector<Eigen::Vector3f> points = {
      {3.0f, 4.0f, 0.05f},   // ground, 5 m away
      {1.0f, 1.0f, 1.0f},    // an object 1.4 m away: not ground
      {0.0f, -6.0f, -0.1f},  // ground, 6 m away
  };
  EXPECT_NEAR(blind_radius_from_ground({0.0, 0.0, 2.0}, points, 0.0), 5.0, 1e-6);
  EXPECT_TRUE(std::isinf(blind_radius_from_ground({0.0, 0.0, 2.0}, points, 10.0)));
}

}  // namespace
}  // namespace tarmac::tools
