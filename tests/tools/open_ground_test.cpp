/// @file The open-ground figure for real data (tools/open_ground.hpp): which cells the returns
/// show as open flat ground, what the costmap read there, and which of them lie away from
/// steps and low returns.

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/grid2d.hpp"
#include "tarmac/tools/lethal_causes.hpp"
#include "tarmac/tools/open_ground.hpp"

namespace tarmac::tools {
namespace {

/// Four returns in each 0.2 m cell of x, y in [−6, 6): the road at z = 0 up to y = 1.9, the
/// pavement a 0.15 m kerb higher from y = 2; a 1 m wall at x ≥ 5, y < −4 (0.3 m or taller:
/// the ground within 1 m of it is not open).
std::vector<Eigen::Vector3f> kerbside() {
  std::vector<Eigen::Vector3f> points;
  for (int ix = -30; ix < 30; ++ix) {
    for (int iy = -30; iy < 30; ++iy) {
      for (const float d : {0.05f, 0.15f}) {
        for (const float e : {0.05f, 0.15f}) {
          const float x = 0.2f * ix + d, y = 0.2f * iy + e;
          points.emplace_back(x, y, y >= 2.0f ? 0.15f : 0.0f);
          if (ix >= 25 && iy < -20) points.emplace_back(x, y, 1.0f);
        }
      }
    }
  }
  return points;
}

core::Grid2D<std::int8_t> costmap(std::int8_t fill) {
  core::GridGeometry2D g;
  g.origin_x_m = -6.0;
  g.origin_y_m = -6.0;
  g.resolution_m = 0.2;
  g.width = 60;
  g.height = 60;
  return core::Grid2D<std::int8_t>(g, fill);
}

TEST(OpenGround, CountsTheFlatGround_AKerbIsFlatButNotAwayFromSteps) {
  OpenGroundTracker tracker(0.2, 2.8);
  tracker.add(kerbside());
  core::Grid2D<std::int8_t> grid = costmap(0);
  // Lethal along the kerb's top edge, inscribed 1 m either side of it, as the costmap reads a
  // kerb (min_obstacle_height_m 0.08).
  for (std::uint32_t x = 0; x < 60; ++x) {
    for (std::uint32_t y = 35; y < 46; ++y) grid.at(x, y) = y == 40 ? 100 : 99;
  }
  const OpenGroundCycle& c = tracker.observe(grid, 7);
  EXPECT_EQ(c.scan, 7);
  // Open: all cells with returns (the window's edge cells have fewer neighbours, not fewer
  // returns), but none within 1 m of the wall, nor the wall's own.
  EXPECT_GT(c.cells, 2800u);
  EXPECT_LT(c.cells, 3600u - 50u);
  EXPECT_EQ(c.lethal, 60u) << "the kerb's 15 cm are open flat ground by the measure";
  EXPECT_EQ(c.inscribed, 600u);
  EXPECT_EQ(c.lethal + c.inscribed + c.free, c.cells);
  // Away from the step: every cell more than 1 m (5 rows) from the two rows the step marks
  // (39 and 40, either side of the kerb's face), so none of the kerb's band.
  EXPECT_EQ(c.away, c.cells - 60u * 12u);
  EXPECT_EQ(c.away_lethal, 0u);
  EXPECT_EQ(c.away_inscribed, 0u);
}

TEST(OpenGround, ALethalCellNoReturnExplainsIsCountedAwayFromSteps) {
  OpenGroundTracker tracker(0.2, 2.8);
  tracker.add(kerbside());
  core::Grid2D<std::int8_t> grid = costmap(0);
  grid.at(10, 10) = 100;  // (−3.9, −3.9): road, no step, no low return within 1 m
  const OpenGroundCycle& c = tracker.observe(grid, 0);
  EXPECT_EQ(c.lethal, 1u);
  EXPECT_EQ(c.away_lethal, 1u);
}

TEST(OpenGround, ALowReturnTakesItsNeighbourhoodOutOfTheAwayCount) {
  std::vector<Eigen::Vector3f> points = kerbside();
  points.emplace_back(-3.9f, -3.9f, 0.1f);  // one return 10 cm up in the road's cell (10, 10)
  OpenGroundTracker tracker(0.2, 2.8);
  tracker.add(points);
  core::Grid2D<std::int8_t> grid = costmap(0);
  grid.at(10, 10) = 100;
  const OpenGroundCycle& c = tracker.observe(grid, 0);
  EXPECT_EQ(c.lethal, 1u) << "10 cm is under the measure's 0.25 m: open flat ground";
  EXPECT_EQ(c.away_lethal, 0u);
}

TEST(OpenGround, GivenTheCostmapsRules_CountsEachLethalCellUnderItsFirstRule) {
  namespace rule = core::obstacle_rule;
  OpenGroundTracker tracker(0.2, 2.8);
  tracker.add(kerbside());
  core::Grid2D<std::int8_t> grid = costmap(0);
  std::vector<std::uint8_t> classes(60 * 60, static_cast<std::uint8_t>(core::ColumnClass::kFree));
  std::vector<std::uint8_t> rules(60 * 60, 0);
  const auto lethal = [&](std::uint32_t x, std::uint32_t y, std::uint8_t bits,
                          core::ColumnClass cls) {
    grid.at(x, y) = 100;
    classes[y * 60 + x] = static_cast<std::uint8_t>(cls);
    rules[y * 60 + x] = bits;
  };
  // The kerb's face: 40 cells by the rise rule (one with a kept low object too), 20 by a voxel.
  for (std::uint32_t x = 0; x < 60; ++x) {
    lethal(x, 40, x < 40 ? rule::kRise : rule::kVoxel, core::ColumnClass::kObstacle);
  }
  rules[40 * 60 + 3] |= rule::kLowObject;
  // Away from the kerb: a kept low object, a virtual zone over a voxel, an unknown cell that the
  // unknown policy costs lethal.
  lethal(10, 10, rule::kLowObject, core::ColumnClass::kObstacle);
  lethal(12, 10, rule::kVoxel, core::ColumnClass::kVirtual);
  lethal(14, 10, 0, core::ColumnClass::kUnknown);
  const OpenGroundCycle& c = tracker.observe(grid, 0, LethalCauseView{classes, rules});
  const auto n = [](const LethalCauseCounts& counts, LethalCause cause) {
    return counts.cells[static_cast<std::size_t>(cause)];
  };
  EXPECT_EQ(c.lethal, 63u);
  EXPECT_EQ(c.lethal_by_cause.total(), 63u);
  EXPECT_EQ(n(c.lethal_by_cause, LethalCause::kRise), 40u);
  EXPECT_EQ(n(c.lethal_by_cause, LethalCause::kVoxel), 20u);
  EXPECT_EQ(n(c.lethal_by_cause, LethalCause::kLowObject), 1u);
  EXPECT_EQ(n(c.lethal_by_cause, LethalCause::kZone), 1u);
  EXPECT_EQ(n(c.lethal_by_cause, LethalCause::kOther), 1u);
  EXPECT_EQ(c.away_lethal_by_cause.total(), 3u);
  EXPECT_EQ(n(c.away_lethal_by_cause, LethalCause::kLowObject), 1u);
  EXPECT_NE(open_ground_summary(tracker).find("its lethal cells by rule: voxel 31.7 %, rise "
                                              "63.5 %, low_object 1.6 %, zone 1.6 %, other 1.6 % "
                                              "(away from steps and low returns: low_object "
                                              "33.3 %, zone 33.3 %, other 33.3 %)"),
            std::string::npos)
      << open_ground_summary(tracker);
  // obstacle_rule.png: each lethal cell in its rule's colour (rows north up), the rest grey.
  const std::vector<std::uint8_t> rgb = render_lethal_causes(grid, LethalCauseView{classes, rules});
  const auto pixel = [&](std::uint32_t x, std::uint32_t y) {
    const std::uint8_t* p = &rgb[((59 - y) * 60 + x) * 3];
    return std::vector<std::uint8_t>{p[0], p[1], p[2]};
  };
  const auto colour = [](LethalCause cause) {
    const std::uint8_t* c = kLethalCauseColour[static_cast<std::size_t>(cause)];
    return std::vector<std::uint8_t>{c[0], c[1], c[2]};
  };
  EXPECT_EQ(pixel(3, 40), colour(LethalCause::kRise)) << "rise and a kept object: the rise first";
  EXPECT_EQ(pixel(50, 40), colour(LethalCause::kVoxel));
  EXPECT_EQ(pixel(10, 10), colour(LethalCause::kLowObject));
  EXPECT_EQ(pixel(12, 10), colour(LethalCause::kZone));
  EXPECT_EQ(pixel(14, 10), colour(LethalCause::kOther));
  EXPECT_EQ(pixel(20, 20), (std::vector<std::uint8_t>{230, 230, 230}));
  // Without the rules (a costmap received over DDS), nothing is counted or printed.
  OpenGroundTracker plain(0.2, 2.8);
  plain.add(kerbside());
  EXPECT_EQ(plain.observe(grid, 0).lethal_by_cause.total(), 0u);
  EXPECT_EQ(open_ground_summary(plain).find("by rule"), std::string::npos);
}

}  // namespace
}  // namespace tarmac::tools
