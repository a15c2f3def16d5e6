// extract_debris: the confirmed low objects that are small, low, on the ground and apart from
// other obstacles, on hand-built objects and costmap columns.

#include "tarmac/core/debris.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

constexpr double kVoxel = 0.2;
constexpr int kN = 100;  // a 20 m window from (0, 0), ground at z = 0
constexpr std::int64_t kScanNs = 100'000'000;

/// Low objects made by scans of rising returns (two per spot confirm it; nothing sees through).
class World {
 public:
  World() : objects_(params(), kN, kN, kVoxel) {
    objects_.place(0, 0);
    const GridGeometry2D g{0.0, 0.0, kVoxel, kN, kN};
    layers_.column_class = Grid2D<std::uint8_t>(g, static_cast<std::uint8_t>(ColumnClass::kFree));
    layers_.ground_z_m = Grid2D<float>(g, 0.0f);
  }

  static LowObjectParams params() {
    LowObjectParams p;
    EXPECT_TRUE(p.validate().ok());
    return p;
  }

  /// Queues `returns` rising returns at (x, y), `rise_cm` above the ground, for the next scan.
  void object(float x, float y, int rise_cm, int returns = 2) {
    for (int i = 0; i < returns; ++i) {
      points_.emplace_back(x, y, static_cast<float>(rise_cm) * 0.01f);
      const int cx = static_cast<int>(std::floor(x / kVoxel));
      const int cy = static_cast<int>(std::floor(y / kVoxel));
      voxel_.push_back(0);
      column_.push_back(static_cast<std::uint32_t>(cy * kN + cx));
      rise_.push_back(static_cast<std::uint8_t>(rise_cm));
    }
  }

  /// Integrates the queued returns as one scan and marks the lethal objects' columns as
  /// the costmap does (mark_low_objects).
  void scan() {
    LowObjects::Scan s;
    s.origin_W = Eigen::Vector3f(1.0f, 1.0f, 2.0f);
    s.points_W = points_;
    s.voxel = voxel_;
    s.column = column_;
    s.rise_cm = rise_;
    s.number = ++scans_;
    s.stamp_ns = static_cast<std::int64_t>(scans_) * kScanNs;
    objects_.update(s);
    points_.clear();
    voxel_.clear();
    column_.clear();
    rise_.clear();
    for (const LowObject& o : objects_.all()) {
      if (objects_.lethal(o)) obstacle(o.xy_W.x(), o.xy_W.y());
    }
  }

  /// An obstacle column from the voxels at (x, y).
  void obstacle(double x, double y) {
    const auto c = layers_.column_class.geometry().cell_of(x, y);
    ASSERT_TRUE(c.has_value());
    layers_.column_class.at(c->x(), c->y()) = static_cast<std::uint8_t>(ColumnClass::kObstacle);
  }
  void ground(double x, double y, float z) {
    const auto c = layers_.ground_z_m.geometry().cell_of(x, y);
    ASSERT_TRUE(c.has_value());
    layers_.ground_z_m.at(c->x(), c->y()) = z;
  }

  /// The rules below one scan decides: listed from the scan that confirmed it (min_scans 1).
  /// The scan count has its own test, with the defaults.
  static DebrisParams at_once() {
    DebrisParams p;
    p.min_scans = 1;
    return p;
  }

  std::vector<Debris> debris(const DebrisParams& p = at_once()) {
    std::vector<Debris> out;
    extract_debris(objects_, layers_, p, scratch_, out);
    return out;
  }

  const LowObjects& objects() const { return objects_; }

 private:
  LowObjects objects_;
  CostmapLayers layers_;
  DebrisScratch scratch_;
  std::vector<Eigen::Vector3f> points_;
  std::vector<std::uint32_t> voxel_, column_;
  std::vector<std::uint8_t> rise_;
  std::uint32_t scans_ = 0;
};

TEST(Debris, EmptyApron_NoDebris) {
  World w;
  w.scan();
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, LoneCube_IsDebrisWithItsEvidence) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.scan();
  w.object(10.1f, 10.1f, 12, 1);
  w.scan();
  const auto d = w.debris();
  ASSERT_EQ(d.size(), 1u);
  EXPECT_EQ(d[0].id, w.objects().all()[0].id);
  EXPECT_NEAR(d[0].xy_W.x(), 10.1, 1e-5);
  EXPECT_NEAR(d[0].xy_W.y(), 10.1, 1e-5);
  EXPECT_NEAR(d[0].height_m, 0.12, 1e-6);
  EXPECT_NEAR(d[0].ground_z_m, 0.0, 1e-6);
  EXPECT_NEAR(d[0].footprint_m, kVoxel, 1e-9);
  EXPECT_EQ(d[0].first_seen_ns, kScanNs);
  EXPECT_EQ(d[0].last_confirmed_ns, 2 * kScanNs);
  EXPECT_EQ(d[0].returns, 3u);
  EXPECT_EQ(d[0].scans, 2u);
  EXPECT_EQ(d[0].objects, 1u);
}

TEST(Debris, ConfirmedInOneScan_IsListedOnceASecondScanSeesItRise) {
  World w;
  w.object(10.1f, 10.1f, 10);  // two rising returns: lethal from this scan
  w.scan();
  ASSERT_EQ(w.objects().all().size(), 1u);
  EXPECT_TRUE(w.objects().confirmed(w.objects().all()[0]));
  EXPECT_TRUE(w.debris(DebrisParams{}).empty()) << "one scan: lethal, not yet listed";
  w.scan();  // a scan with no return on it changes nothing
  EXPECT_TRUE(w.debris(DebrisParams{}).empty());
  w.object(10.1f, 10.1f, 9, 1);
  w.scan();
  const auto d = w.debris(DebrisParams{});
  ASSERT_EQ(d.size(), 1u);
  EXPECT_EQ(d[0].scans, 2u);
  EXPECT_EQ(d[0].returns, 3u);
  DebrisParams three;
  three.min_scans = 3;
  EXPECT_TRUE(w.debris(three).empty());
}

TEST(Debris, Candidate_IsNotDebris) {
  World w;
  w.object(10.1f, 10.1f, 10, 1);  // one return: lethal, not confirmed
  w.scan();
  EXPECT_TRUE(w.objects().lethal(w.objects().all()[0]));
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, KerbAlongThreeMetres_IsNotDebris) {
  World w;
  for (int i = 0; i < 15; ++i) w.object(7.1f + 0.2f * static_cast<float>(i), 10.1f, 15);
  w.scan();
  ASSERT_EQ(w.objects().all().size(), 15u);
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, ObjectBesideAnObstacleColumn_IsNotDebris) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.scan();
  w.obstacle(10.5, 10.1);  // a cone's column 0.4 m away, not touching
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, ObjectAtAWallFoot_IsNotDebris) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.scan();
  for (int i = 0; i < 20; ++i) w.obstacle(10.3, 8.1 + 0.2 * i);  // touching, 4 m long
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, ObstacleBeyondTheClearance_LeavesItDebris) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.scan();
  w.obstacle(10.7, 10.1);  // 0.6 m away
  EXPECT_EQ(w.debris().size(), 1u);
  DebrisParams wide = World::at_once();
  wide.clearance_m = 0.6;
  EXPECT_TRUE(w.debris(wide).empty());
}

TEST(Debris, TallerThanTheLimit_IsNotDebris) {
  World w;
  w.object(10.1f, 10.1f, 35);
  w.scan();
  EXPECT_TRUE(w.debris().empty());
  DebrisParams tall = World::at_once();
  tall.max_height_m = 0.4;
  EXPECT_EQ(w.debris(tall).size(), 1u);
}

TEST(Debris, OffItsColumnsGround_IsNotDebris) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.scan();
  w.ground(10.1, 10.1, 0.5f);  // its base lies 0.5 m under the column's ground (a roof's)
  EXPECT_TRUE(w.debris().empty());
}

TEST(Debris, ObjectsWithinTheLink_AreOnePiece) {
  World w;
  w.object(10.1f, 10.1f, 10);
  w.object(10.35f, 10.1f, 20, 3);  // 0.25 m apart, the next column
  w.scan();
  const auto d = w.debris();
  ASSERT_EQ(d.size(), 1u);
  EXPECT_EQ(d[0].objects, 2u);
  EXPECT_EQ(d[0].returns, 5u);
  EXPECT_NEAR(d[0].height_m, 0.2, 1e-6);
  EXPECT_NEAR(d[0].footprint_m, 2 * kVoxel, 1e-9);
  EXPECT_NEAR(d[0].xy_W.x(), (2 * 10.1 + 3 * 10.35) / 5, 1e-5);
}

TEST(Debris, Ids_AreTheSmallestObjectIdsAndStableAcrossCalls) {
  World w;
  w.object(5.1f, 5.1f, 10);
  w.object(15.1f, 15.1f, 10);
  w.scan();
  const auto first = w.debris();
  ASSERT_EQ(first.size(), 2u);
  EXPECT_LT(first[0].id, first[1].id);
  // A later object joins the second piece; one more appears apart.
  w.object(15.35f, 15.1f, 10);
  w.object(2.1f, 2.1f, 10);
  w.scan();
  const auto second = w.debris();
  ASSERT_EQ(second.size(), 3u);
  EXPECT_EQ(second[0].id, first[0].id);
  EXPECT_EQ(second[1].id, first[1].id);
  EXPECT_EQ(second[1].objects, 2u);
  EXPECT_GT(second[2].id, first[1].id);
  EXPECT_NEAR(second[2].xy_W.x(), 2.1, 1e-5);
  const auto again = w.debris();
  ASSERT_EQ(again.size(), second.size());
  for (std::size_t i = 0; i < again.size(); ++i) EXPECT_EQ(again[i].id, second[i].id);
}

TEST(Debris, Params_RefuseOutOfRange) {
  DebrisParams p;
  EXPECT_TRUE(p.validate().ok());
  p.max_height_m = 0.0;
  EXPECT_FALSE(p.validate().ok());
  p = DebrisParams{};
  p.max_footprint_m = std::nan("");
  EXPECT_FALSE(p.validate().ok());
  p = DebrisParams{};
  p.clearance_m = -0.1;
  EXPECT_FALSE(p.validate().ok());
  p = DebrisParams{};
  p.min_scans = 0;
  EXPECT_FALSE(p.validate().ok());
  p.min_scans = 1001;
  EXPECT_FALSE(p.validate().ok());
}

}  // namespace
}  // namespace tarmac::core
