// The costmap's safety figures: the scorer on hand-made costmaps (obstacle columns and drivable
// ground), the stamped scorer's choice of scan for a costmap that arrives stamped (tarmacd's over
// DDS), and the simulator's truth of which columns a costmap must show lethal on the
// parked-aircraft scene and of which cells are ground on the parking levels.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

#include <gtest/gtest.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/sim/scene_catalog.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/stamped_safety.hpp"

namespace tarmac::tools {
namespace {

/// A 20 × 20 costmap of 0.2 m cells with its corner at the lattice point (−10, −10) (−2 m), all
/// `fill`.
core::Costmap costmap_of(std::int8_t fill) {
  core::GridGeometry2D g;
  g.resolution_m = 0.2;
  g.origin_x_m = -2.0;
  g.origin_y_m = -2.0;
  g.width = 20;
  g.height = 20;
  return core::Costmap(g, fill);
}

TEST(Safety, ScoresLethalNearFreeInflatedUnknownAndFalseLethal) {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 0;    // seen at scan 0: cell (10, 10)
  truth.first_seen[ObstacleTruth::key(3, 0)] = 0;    // cell (13, 10)
  truth.first_seen[ObstacleTruth::key(6, 0)] = 0;    // cell (16, 10)
  truth.first_seen[ObstacleTruth::key(-5, 0)] = 0;   // cell (5, 10)
  truth.first_seen[ObstacleTruth::key(0, 5)] = 5;    // seen only from scan 5
  truth.first_seen[ObstacleTruth::key(0, -5)] = -1;  // never seen
  auto map = costmap_of(core::kCostFree);
  map.at(11, 10) = core::kCostLethal;  // one cell from column (0, 0): counts for it
  map.at(13, 10) = 50;                 // inflated only
  map.at(16, 10) = core::kCostUnknown;
  // column (-5, 0) reads free: the unsafe case
  map.at(2, 2) = core::kCostLethal;  // far from every column: false lethal
  const SafetyCycle c = score_costmap(map, truth, 1, {0.0, 0.0}, 20.0);
  EXPECT_EQ(c.visible, 4u);
  EXPECT_EQ(c.lethal_near, 1u);
  EXPECT_EQ(c.read_inflated, 1u);
  EXPECT_EQ(c.read_unknown, 1u);
  EXPECT_EQ(c.read_free, 1u);
  EXPECT_EQ(c.lethal_cells, 2u);
  EXPECT_EQ(c.false_lethal, 1u);
  EXPECT_DOUBLE_EQ(c.share_lethal(), 0.25);
  EXPECT_EQ(c.false_lethal_by_cause.total(), 0u) << "no rules given";
  // Given the costmap's rules: the false lethal cell counted under the one that made it.
  std::vector<std::uint8_t> classes(400, static_cast<std::uint8_t>(core::ColumnClass::kFree));
  std::vector<std::uint8_t> rules(400, 0);
  classes[2 * 20 + 2] = classes[10 * 20 + 11] =
      static_cast<std::uint8_t>(core::ColumnClass::kObstacle);
  rules[2 * 20 + 2] = core::obstacle_rule::kDrop;
  rules[10 * 20 + 11] = core::obstacle_rule::kVoxel;
  const SafetyCycle why = score_costmap(map, truth, 1, {0.0, 0.0}, 20.0, {}, {classes, rules});
  EXPECT_EQ(why.false_lethal_by_cause.total(), 1u);
  EXPECT_EQ(why.false_lethal_by_cause.cells[static_cast<std::size_t>(LethalCause::kDrop)], 1u);
  // Out of the radius: nothing counted.
  const SafetyCycle far = score_costmap(map, truth, 1, {100.0, 0.0}, 20.0);
  EXPECT_EQ(far.visible, 0u);
  EXPECT_EQ(far.lethal_cells, 0u);
  // From scan 5 the column (0, 5) is visible too.
  EXPECT_EQ(score_costmap(map, truth, 5, {0.0, 0.0}, 20.0).visible, 5u);
}

TEST(Safety, TrackerReportsTheWorstCycle) {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 0;
  SafetyTracker tracker(truth);
  auto good = costmap_of(core::kCostFree);
  good.at(10, 10) = core::kCostLethal;
  const auto bad = costmap_of(core::kCostFree);
  tracker.observe(good, 0, {0.0, 0.0});
  tracker.observe(bad, 1, {0.0, 0.0});
  tracker.observe(good, 2, {0.0, 0.0});
  const SafetyReport r = tracker.report();
  EXPECT_EQ(r.cycles, 3u);
  EXPECT_DOUBLE_EQ(r.worst_share, 0.0);
  EXPECT_EQ(r.worst_scan, 1);
  EXPECT_NEAR(r.mean_share, 2.0 / 3.0, 1e-12);
  EXPECT_EQ(r.read_free, 1u);
}

TEST(Safety, SimulatorTruthOfTheAircraftStand_BellyGearEnginesAreColumns_NotTheWing) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("tarmac_safety_truth_" + std::to_string(::getpid()));
  sim::SequenceParams p;
  p.path = sim::DrivePath::loop({-30.0, -22.0}, {30.0, 22.0}, 10.0, 20.0);
  p.scans = 3;
  p.lidar.beams = 8;
  p.lidar.azimuth_steps = 256;
  const auto written = sim::write_sequence(sim::Scene::aircraft_stand(), p, dir);
  ASSERT_TRUE(written.ok()) << written.error;
  auto truth = read_obstacle_truth(dir / "obstacle_columns.txt");
  ASSERT_TRUE(truth.ok()) << truth.error().message;
  const auto column = [&](double x, double y) {
    return truth.value().is_column(static_cast<std::int64_t>(std::floor(x / 0.2)),
                                   static_cast<std::int64_t>(std::floor(y / 0.2)));
  };
  EXPECT_TRUE(column(0.1, 0.1)) << "the belly (1.5 m) is inside the 2.8 m envelope";
  EXPECT_TRUE(column(14.0, 0.0)) << "nose gear";
  EXPECT_FALSE(column(0.0, 10.0)) << "the wing (3.3 m) is above the envelope";
  EXPECT_TRUE(column(-2.0, -6.0)) << "engine (bottom 1.2 m)";
  EXPECT_TRUE(column(20.05, 0.05)) << "cone";
  EXPECT_FALSE(column(19.0, 0.0)) << "past the fuselage's end";
  EXPECT_FALSE(column(8.0, 1.9)) << "beside the fuselage";
  EXPECT_FALSE(column(25.0, 10.0)) << "open apron";
  std::filesystem::remove_all(dir);
}

/// A ground truth of every cell of costmap_of()'s square but those of column ix = 5 (a step).
GroundTruth ground_but_a_step() {
  GroundTruth ground;
  for (std::int64_t iy = -10; iy < 10; ++iy) {
    for (std::int64_t ix = -10; ix < 10; ++ix) {
      if (ix != 5) ground.z_m[ObstacleTruth::key(ix, iy)] = 0.1f * static_cast<float>(ix);
    }
  }
  return ground;
}

TEST(Safety, GroundReadLethalIsFalse_TheCurbAndWhatIsNextToItAreNot) {
  ObstacleTruth truth;
  for (std::int64_t ix = -10; ix < 10; ++ix) {
    truth.first_seen[ObstacleTruth::key(ix, -5)] = 0;  // a curb along y = -1 m: cells (*, 5)
    truth.curb_first_seen[ObstacleTruth::key(ix, -5)] = ix < 0 ? 0 : 1;  // its right half later
  }
  truth.ground = ground_but_a_step();
  auto map = costmap_of(core::kCostFree);
  for (std::uint32_t cx = 0; cx < 20; ++cx) map.at(cx, 5) = core::kCostLethal;  // the curb
  map.at(3, 6) = core::kCostLethal;    // next to the curb: within one cell of it
  map.at(12, 15) = core::kCostLethal;  // open ground: false
  map.at(2, 12) = 99;                  // inscribed is not lethal
  map.at(15, 12) = core::kCostLethal;  // the step (ix = 5): not ground, not counted
  const SafetyCycle c = score_costmap(map, truth, 0, {0.0, 0.0}, 20.0);
  // 20 x 20 cells, less the step's column (20) and the curb's rows 4..6 on the 19 other columns.
  EXPECT_EQ(c.ground_cells, 400u - 20u - 3u * 19u);
  EXPECT_EQ(c.ground_lethal, 1u);
  EXPECT_DOUBLE_EQ(c.share_ground_lethal(), 1.0 / 323.0);
  // The curb is seen and lethal.
  EXPECT_EQ(c.visible, 20u);
  EXPECT_EQ(c.lethal_near, 20u);
  EXPECT_EQ(c.curb_visible, 10u);
  EXPECT_EQ(c.curb_lethal_near, 10u);
  // The ground figure reaches 30 m, the obstacle figures 20 m.
  const SafetyCycle far = score_costmap(map, truth, 0, {25.0, 0.0}, 20.0);
  EXPECT_EQ(far.lethal_cells, 0u);
  EXPECT_EQ(far.visible, 0u);
  EXPECT_EQ(far.ground_cells, c.ground_cells);
  EXPECT_EQ(far.ground_lethal, 1u);
  EXPECT_EQ(score_costmap(map, truth, 0, {35.0, 0.0}, 20.0).ground_cells, 0u);
  // Driven over: the curb's cells and their neighbours free.
  for (std::uint32_t cy = 4; cy <= 6; ++cy) {
    for (std::uint32_t cx = 0; cx < 20; ++cx) map.at(cx, cy) = core::kCostFree;
  }
  map.at(19, 5) = core::kCostLethal;
  const SafetyCycle missed = score_costmap(map, truth, 1, {0.0, 0.0}, 20.0);
  EXPECT_EQ(missed.curb_visible, 20u);
  EXPECT_EQ(missed.curb_lethal_near, 2u);  // (18, 5) and (19, 5)
  EXPECT_EQ(missed.read_free, 18u);
  EXPECT_DOUBLE_EQ(missed.share_curb_lethal(), 0.1);
}

TEST(Safety, GroundFigure_WithoutGroundTruthEveryCellIsGround_MovingBoxesLeftOut) {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 0;  // cell (10, 10)
  auto map = costmap_of(core::kCostFree);
  map.at(2, 2) = core::kCostLethal;
  map.at(17, 17) = core::kCostLethal;  // under the moving box
  DynamicBox tug;
  tug.min_W = Eigen::Vector3d(1.2, 1.2, 0.0);
  tug.max_W = Eigen::Vector3d(1.8, 1.8, 1.5);
  const DynamicBox moving[] = {tug};
  const SafetyCycle c = score_costmap(map, truth, 0, {0.0, 0.0}, 20.0, moving);
  // Every cell but the nine round the column and the 5 x 5 within a cell of the tug's box.
  EXPECT_EQ(c.ground_cells, 400u - 9u - 25u);
  EXPECT_EQ(c.ground_lethal, 1u);
  EXPECT_EQ(c.false_lethal, 1u);
  EXPECT_EQ(c.open_cells, 400u - 9u);
}

TEST(Safety, TrackerReportsTheWorstGroundCycle_InTheLineAndTheJson) {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 0;
  SafetyTracker tracker(truth);
  auto clean = costmap_of(core::kCostFree);
  clean.at(10, 10) = core::kCostLethal;
  auto bad = costmap_of(core::kCostFree);
  bad.at(10, 10) = core::kCostLethal;
  for (std::uint32_t cx = 0; cx < 4; ++cx) bad.at(cx, 0) = core::kCostLethal;
  tracker.observe(clean, 0, {0.0, 0.0});
  tracker.observe(bad, 1, {0.0, 0.0});
  const SafetyReport r = tracker.report();
  EXPECT_EQ(r.ground_cells, 2u * 391u);
  EXPECT_EQ(r.ground_lethal, 4u);
  EXPECT_EQ(r.worst_ground_scan, 1);
  EXPECT_DOUBLE_EQ(r.worst_ground_lethal, 4.0 / 391.0);
  EXPECT_DOUBLE_EQ(r.mean_ground_lethal, 2.0 / 391.0);
  const std::string line = safety_summary(r);
  EXPECT_NE(line.find("ground within 30 m read lethal worst 1.02 % (scan 1), mean 0.51 % (4 of "
                      "782 ground cell-cycles)"),
            std::string::npos)
      << line;
  EXPECT_EQ(line.find("curb"), std::string::npos) << "no curbs in this truth";
  const auto j = safety_json(tracker);
  EXPECT_EQ(j["ground_lethal"], 4u);
  ASSERT_EQ(j["cycle_fields"].size(), 14u);
  EXPECT_EQ(j["cycle_fields"][8], "ground_cells");
  EXPECT_EQ(j["per_cycle"][1][9], 4u);
}

TEST(Safety, ReachableGround_AWallCutsOffTheLevelBeyondIt_AStepUpDoesToo) {
  // 20 x 20 cells at 0.2 m round the vehicle at (0, 0): a wall (obstacle columns) along x = 1 m,
  // the ground beyond it 2.25 m higher (an upper level whose way round lies outside the
  // window), and a step of 0.3 m at y = 1 m on the vehicle's side (no wall: the step stops it).
  ObstacleTruth truth;
  GroundTruth ground;
  for (std::int64_t iy = -10; iy < 10; ++iy) {
    truth.first_seen[ObstacleTruth::key(5, iy)] = 0;  // the wall: cells (15, *)
    for (std::int64_t ix = -10; ix < 10; ++ix) {
      if (ix == 5) continue;
      ground.z_m[ObstacleTruth::key(ix, iy)] = ix > 5 ? 2.25f : (iy >= 5 ? 0.3f : 0.0f);
    }
  }
  truth.ground = std::move(ground);
  auto map = costmap_of(core::kCostFree);
  map.at(18, 3) = core::kCostLethal;  // beyond the wall
  map.at(2, 17) = core::kCostLethal;  // on the step's top
  map.at(3, 3) = core::kCostLethal;   // on the vehicle's level
  const SafetyCycle c = score_costmap(map, truth, 0, {0.0, 0.0}, 20.0);
  EXPECT_EQ(c.ground_lethal, 3u);
  EXPECT_EQ(c.reach_lethal, 1u);
  // The vehicle's level: x < 14 (the wall's neighbours left out as near a column), y < 15.
  EXPECT_EQ(c.reach_cells, 14u * 15u);
  EXPECT_DOUBLE_EQ(c.share_reach_lethal(), 1.0 / 210.0);
}

TEST(Safety, TrackerReportsTheCurbsWhenTheTruthHasThem) {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 0;
  truth.curb_first_seen[ObstacleTruth::key(0, 0)] = 0;
  SafetyTracker tracker(truth);
  auto lethal = costmap_of(core::kCostFree);
  lethal.at(10, 10) = core::kCostLethal;
  tracker.observe(lethal, 0, {0.0, 0.0});
  tracker.observe(costmap_of(core::kCostFree), 1, {0.0, 0.0});  // driven over
  const SafetyReport r = tracker.report();
  EXPECT_TRUE(r.curbs);
  EXPECT_DOUBLE_EQ(r.worst_curb_share, 0.0);
  EXPECT_EQ(r.worst_curb_scan, 1);
  EXPECT_DOUBLE_EQ(r.mean_curb_share, 0.5);
  const std::string line = safety_summary(r);
  EXPECT_NE(line.find("; curb columns lethal within one cell worst 0.0 % (scan 1), mean 50.0 %"),
            std::string::npos)
      << line;
  const auto j = safety_json(tracker);
  EXPECT_EQ(j["per_cycle"][0][10], 1u);  // curb_visible
  EXPECT_EQ(j["per_cycle"][0][11], 1u);  // curb_lethal_near
  EXPECT_EQ(j["per_cycle"][1][11], 0u);
}

TEST(Safety, SimulatorTruthOfTheParkingLevels_CurbIsAColumn_TheDeckIsNot_GroundFollowsTheRamp) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("tarmac_safety_parking_" + std::to_string(::getpid()));
  const auto drive = sim::scene_drive("parking", std::nullopt, 2.0);
  ASSERT_TRUE(drive);
  sim::SequenceParams p;
  p.path = drive->path;
  p.scans = 3;
  p.rate_hz = 2.0 / p.path.duration_s();  // the start, the middle and the end of the drive
  p.lidar.beams = 8;
  p.lidar.azimuth_steps = 256;
  const auto written = sim::write_sequence(drive->scene, p, dir);
  ASSERT_TRUE(written.ok()) << written.error;
  auto read = read_dataset_truth(dir);
  ASSERT_TRUE(read.ok()) << read.error().message;
  const ObstacleTruth& truth = read.value();
  ASSERT_TRUE(truth.ground);
  const auto cell = [](double v) { return static_cast<std::int64_t>(std::floor(v / 0.2)); };
  const auto column = [&](double x, double y) { return truth.is_column(cell(x), cell(y)); };
  const auto ground_z = [&](double x, double y) -> double {
    const auto it = truth.ground->z_m.find(ObstacleTruth::key(cell(x), cell(y)));
    return it == truth.ground->z_m.end() ? std::nan("") : it->second;
  };
  EXPECT_TRUE(column(40.1, -4.1)) << "the curb on the ramp, 15 cm above it";
  EXPECT_TRUE(column(100.1, -4.1)) << "the curb on the lower road";
  const auto curb = [&](double x, double y) {
    return truth.curb_first_seen.count(ObstacleTruth::key(cell(x), cell(y))) != 0;
  };
  EXPECT_TRUE(curb(40.1, -4.1));
  EXPECT_TRUE(curb(100.1, -4.1));
  EXPECT_FALSE(curb(60.1, -5.1)) << "the wall is no curb";
  EXPECT_FALSE(curb(48.0, -3.2)) << "nor the cone beside it";
  EXPECT_FALSE(column(40.1, -3.7)) << "beside the curb";
  EXPECT_TRUE(column(48.0, -3.2)) << "a 30 cm cone 1.6 m below the apron, on the ramp";
  EXPECT_TRUE(column(60.1, -5.1)) << "the wall";
  EXPECT_FALSE(column(115.1, 0.1)) << "under the deck, 3.6 m up";
  EXPECT_NEAR(ground_z(115.1, 0.1), -2.25, 1e-6) << "the road under the deck";
  EXPECT_NEAR(ground_z(42.5, -1.0), -1.125, 1e-3) << "the ramp, 12.5 m down at 9 %";
  EXPECT_NEAR(ground_z(40.1, -3.7), -0.9 - 0.09 * 0.1, 1e-3) << "the ramp beside the curb";
  EXPECT_NEAR(ground_z(10.1, 30.1), 0.0, 1e-6) << "the apron";
  EXPECT_TRUE(std::isnan(ground_z(60.1, 5.3))) << "the cut's edge: a step, no ground";
  EXPECT_TRUE(std::isnan(ground_z(-100.0, 0.0))) << "farther from the drive than the margin";
  std::filesystem::remove_all(dir);
}

/// One column at (0, 0), first seen at scan 1, so a cycle's `visible` tells which scan it was
/// scored against; the vehicle stays at the origin for 4 scans.
StampedSafetyScorer stamped_scorer() {
  ObstacleTruth truth;
  truth.first_seen[ObstacleTruth::key(0, 0)] = 1;
  return StampedSafetyScorer(truth, std::vector<Eigen::Vector2d>(4, Eigen::Vector2d::Zero()), {});
}

TEST(StampedSafety, CostmapIsScoredAsTheLatestScanAtOrBeforeItsStamp) {
  StampedSafetyScorer scorer = stamped_scorer();
  ASSERT_TRUE(scorer.add_scan_stamp(1000).ok());
  ASSERT_TRUE(scorer.add_scan_stamp(2000).ok());
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 500).ok());   // before scan 0
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 1000).ok());  // scan 0
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 1500).ok());  // between: scan 0
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 2000).ok());  // scan 1
  ASSERT_EQ(scorer.costmaps(), 3u);
  const auto& cycles = scorer.tracker().cycles();
  EXPECT_EQ(cycles[0].scan, 0);
  EXPECT_EQ(cycles[0].visible, 0u);
  EXPECT_EQ(cycles[1].scan, 0);
  EXPECT_EQ(cycles[2].scan, 1);
  EXPECT_EQ(cycles[2].visible, 1u);
  EXPECT_EQ(cycles[2].read_free, 1u);
  EXPECT_EQ(scorer.before_first_scan(), 1u);
  EXPECT_EQ(scorer.stamp_not_a_scan(), 1u);
  EXPECT_EQ(scorer.scans_with_costmap(), 2u);
}

TEST(StampedSafety, CostmapAheadOfThePosesWaitsForItsScan) {
  StampedSafetyScorer scorer = stamped_scorer();
  ASSERT_TRUE(scorer.add_scan_stamp(1000).ok());
  // Costmaps of scans 1 and 2 arrive before those scans' stamps: not scored against scan 0.
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 2000).ok());
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 3000).ok());
  EXPECT_EQ(scorer.costmaps(), 0u);
  ASSERT_TRUE(scorer.add_scan_stamp(2000).ok());
  ASSERT_EQ(scorer.costmaps(), 1u);
  EXPECT_EQ(scorer.tracker().cycles()[0].scan, 1);
  ASSERT_TRUE(scorer.add_scan_stamp(3000).ok());
  ASSERT_EQ(scorer.costmaps(), 2u);
  EXPECT_EQ(scorer.tracker().cycles()[1].scan, 2);
  // At the end, a costmap newer than every scan is scored as the last scan.
  ASSERT_TRUE(scorer.add_costmap(costmap_of(core::kCostFree), 3500).ok());
  EXPECT_EQ(scorer.costmaps(), 2u);
  scorer.finish();
  ASSERT_EQ(scorer.costmaps(), 3u);
  EXPECT_EQ(scorer.tracker().cycles()[2].scan, 2);
  EXPECT_EQ(scorer.stamp_not_a_scan(), 1u);
}

TEST(StampedSafety, RefusesStampsOutOfOrderExtraScansAndAnotherResolution) {
  StampedSafetyScorer scorer = stamped_scorer();
  ASSERT_TRUE(scorer.add_scan_stamp(1000).ok());
  const auto same = scorer.add_scan_stamp(1000);
  ASSERT_FALSE(same.ok());
  EXPECT_EQ(same.error().code, "safety.stamp_order");
  for (std::int64_t t : {2000, 3000, 4000}) ASSERT_TRUE(scorer.add_scan_stamp(t).ok());
  const auto fifth = scorer.add_scan_stamp(5000);
  ASSERT_FALSE(fifth.ok());
  EXPECT_EQ(fifth.error().code, "safety.too_many_scans");
  core::GridGeometry2D g = costmap_of(0).geometry();
  g.resolution_m = 0.1;
  const auto finer = scorer.add_costmap(core::Costmap(g, core::kCostFree), 1000);
  ASSERT_FALSE(finer.ok());
  EXPECT_EQ(finer.error().code, "safety.resolution");
  // float32 resolution as nav_msgs/OccupancyGrid carries it: accepted.
  g.resolution_m = static_cast<double>(0.2f);
  EXPECT_TRUE(scorer.add_costmap(core::Costmap(g, core::kCostFree), 1000).ok());
}

}  // namespace
}  // namespace tarmac::tools
