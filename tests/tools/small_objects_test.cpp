/// @file The score per small object (tools/small_objects.hpp) and the truth tarmac-sim writes
/// for it (small_objects.txt).

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <unistd.h>

#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/sim/scene_catalog.hpp"
#include "tarmac/tools/small_objects.hpp"

namespace tarmac::tools {
namespace {

struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& name)
      : path(std::filesystem::temp_directory_path() /
             ("tarmac_small_objects_" + name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

/// A 20 × 20 costmap of 0.2 m cells, its corner at the origin, all free.
core::Grid2D<std::int8_t> free_costmap() {
  core::GridGeometry2D g;
  g.resolution_m = 0.2;
  g.width = 20;
  g.height = 20;
  return core::Grid2D<std::int8_t>(g, 0);
}

TEST(SmallObjects, ScoredFromTheFirstScanWithTwoReturns_WithinTheRadius) {
  SmallObject o;
  o.name = "debris_10cm";
  o.kind = "debris";
  o.min_W = {2.01, 2.01, 0.0};  // cell (10, 10)
  o.max_W = {2.09, 2.09, 0.1};
  o.returns = {{3, 1}, {5, 2}, {6, 4}};
  o.first_two = 5;
  SmallObjectTracker tracker({o});
  auto map = free_costmap();
  map.at(10, 10) = 100;
  tracker.observe(map, 4, {2.05, 7.05});  // before its first scan with two returns: not counted
  map.at(10, 10) = 0;
  tracker.observe(map, 5, {2.05, 7.05});  // 5 m off, read free
  map.at(11, 9) = 100;                    // next to its cell
  tracker.observe(map, 6, {2.05, 7.05});
  tracker.observe(map, 7, {2.05, 32.05});  // lethal, 30 m off: beyond the radius
  map.at(11, 9) = 0;
  map.at(12, 10) = 100;  // two cells off: not it
  tracker.observe(map, 8, {2.05, 7.05});
  const SmallObject& s = tracker.objects().front();
  EXPECT_NEAR(s.first_two_range_m, 5.0, 1e-9);
  EXPECT_EQ(s.first_lethal, 6);
  EXPECT_NEAR(s.first_lethal_range_m, 5.0, 1e-9);
  EXPECT_EQ(s.cycles_near, 3);  // scans 5, 6 and 8
  EXPECT_EQ(s.cycles_lethal, 1);
  const std::string summary = small_objects_summary(tracker, 0.08);
  EXPECT_NE(summary.find("lethal in 33.3 % of them"), std::string::npos) << summary;
  // Lower than costmap.min_obstacle_height_m: listed, not scored.
  EXPECT_NE(small_objects_summary(tracker, 0.15).find("not scored"), std::string::npos);
}

TEST(SmallObjects, ReadRefusesABadLine_AnUnknownObject_AMissingFile) {
  TempDir dir("read");
  const auto write = [&](const std::string& text) {
    std::ofstream(dir.path / "small_objects.txt") << text;
    return read_small_objects(dir.path / "small_objects.txt");
  };
  const std::string object = "object 3 cone_a cone 1 2 0 1.4 2.4 0.5\n";
  const auto good = write("# comment\n" + object + "returns 0 3 1\nreturns 2 3 5\n");
  ASSERT_TRUE(good.ok()) << good.error().message;
  ASSERT_EQ(good.value().size(), 1u);
  EXPECT_EQ(good.value()[0].name, "cone_a");
  EXPECT_EQ(good.value()[0].first_two, 2);
  EXPECT_NEAR(good.value()[0].height_m(), 0.5, 1e-12);
  EXPECT_EQ(write(object + "returns 0 4 1\n").error().code, "objects.parse");  // no object 4
  EXPECT_EQ(write(object + "returns 0 3\n").error().code, "objects.parse");
  EXPECT_EQ(write(object + object).error().code, "objects.parse");  // the same id twice
  EXPECT_EQ(write("object 3 cone_a cone 1 2\n").error().code, "objects.parse");
  EXPECT_EQ(read_small_objects(dir.path / "none.txt").error().code, "objects.open");
}

TEST(SmallObjects, TheSimWritesEachSmallObjectWithItsBoxAndReturns_AnEmptyApronNone) {
  auto drive = sim::scene_drive("debris", std::nullopt, 2.0);
  ASSERT_TRUE(drive.has_value());
  sim::SequenceParams params;
  params.path = drive->path;
  params.path.start_W = {20.0, 0.0};  // the first row of debris 5 m ahead
  params.lidar.beams = 64;
  params.scans = 2;
  TempDir dir("sim");
  const sim::SequenceResult written = sim::write_sequence(drive->scene, params, dir.path);
  ASSERT_TRUE(written.ok()) << written.error;
  const auto read = read_small_objects(dir.path / "small_objects.txt");
  ASSERT_TRUE(read.ok()) << read.error().message;
  const std::vector<SmallObject>& objects = read.value();
  ASSERT_EQ(objects.size(), 13u);  // 11 cubes and the two landing gear legs
  const auto find = [&](const std::string& name) -> const SmallObject* {
    for (const SmallObject& o : objects) {
      if (o.name == name) return &o;
    }
    return nullptr;
  };
  const SmallObject* near = find("debris_20cm_25");
  ASSERT_NE(near, nullptr);
  EXPECT_EQ(near->kind, "debris");
  EXPECT_NEAR(near->min_W.x(), 24.9, 1e-9);
  EXPECT_NEAR(near->max_W.y(), 3.1, 1e-9);
  EXPECT_NEAR(near->height_m(), 0.2, 1e-9);
  EXPECT_EQ(near->first_two, 0) << "5 m ahead, 20 cm high: returns from the first scan";
  ASSERT_NE(find("debris_10cm_25"), nullptr);
  EXPECT_GE(find("debris_10cm_25")->returns.at(0), 2);
  ASSERT_NE(find("gear_front"), nullptr);
  EXPECT_EQ(find("gear_front")->kind, "landing_gear");

  auto apron = sim::scene_drive("apron", std::nullopt, 2.0);
  ASSERT_TRUE(apron.has_value());
  params.path = apron->path;
  ASSERT_TRUE(sim::write_sequence(apron->scene, params, dir.path).ok());
  EXPECT_FALSE(std::filesystem::exists(dir.path / "small_objects.txt"))
      << "none in an empty scene, and none left from the run before";
}

}  // namespace
}  // namespace tarmac::tools
