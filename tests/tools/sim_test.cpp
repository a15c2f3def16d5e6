// tarmac_sim: exact ray/primitive ranges, the airside scene layout, the moving tug, and the
// KITTI sequence writer (determinism, sensor frame, poses) checked against Scene::raycast.

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../support/sim_poses.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace {

using namespace tarmac::sim;
using V = Eigen::Vector3d;

constexpr double kExact = 1e-9;  // m: analytic answers in double precision

double deg(double d) {
  return d * std::numbers::pi / 180.0;
}

double range_or_nan(const Primitive& p, const V& origin_W, const V& dir_W) {
  const auto r = intersect(p, origin_W, dir_W.normalized());
  return r ? *r : std::nan("");
}

// ---- ray vs primitive ----

TEST(Intersect, Box_HitsNearFace) {
  const Box box{V(1, -1, -1), V(3, 1, 1)};
  EXPECT_NEAR(range_or_nan(box, V(0, 0, 0), V(1, 0, 0)), 1.0, kExact);
  EXPECT_NEAR(range_or_nan(box, V(5, 0.5, 0.5), V(-1, 0, 0)), 2.0, kExact);
  EXPECT_NEAR(range_or_nan(box, V(2, 0, 10), V(0, 0, -1)), 9.0, kExact);
}

TEST(Intersect, Box_DiagonalRayHitsEdge) {
  const Box box{V(1, 1, -1), V(2, 2, 1)};
  EXPECT_NEAR(range_or_nan(box, V(0, 0, 0), V(1, 1, 0)), std::sqrt(2.0), kExact);
  // Through the top face at an angle: z = 1 reached after 1/sin(30°) = 2 m.
  const Box wide{V(-10, -10, -5), V(10, 10, 1)};
  EXPECT_NEAR(range_or_nan(wide, V(0, 0, 0), V(std::cos(deg(30)), 0, std::sin(deg(30)))), 2.0,
              kExact);
}

TEST(Intersect, Box_FromInsideHitsExitFace) {
  const Box box{V(1, -1, -1), V(3, 1, 1)};
  EXPECT_NEAR(range_or_nan(box, V(2, 0, 0), V(1, 0, 0)), 1.0, kExact);
  EXPECT_NEAR(range_or_nan(box, V(2.5, 0, 0.25), V(0, 0, -1)), 1.25, kExact);
}

TEST(Intersect, Box_MissesWhenOffsetOrBehind) {
  const Box box{V(1, -1, -1), V(3, 1, 1)};
  EXPECT_FALSE(intersect(box, V(0, 0, 0), V(0, 1, 0)));
  EXPECT_FALSE(intersect(box, V(0, 0, 0), V(-1, 0, 0)));   // behind the origin
  EXPECT_FALSE(intersect(box, V(0, 1.5, 0), V(1, 0, 0)));  // parallel, outside the y slab
  EXPECT_FALSE(intersect(box, V(0, 0, 0), V(1, 0, 1.5).normalized()));  // passes over it
}

TEST(Intersect, CylinderAlongY_SideCapsAndOffset) {
  // Axis along y through (x, z) = (0, 3), y in [-5, 5], r = 2 (a fuselage-like cylinder).
  const Cylinder cyl{Axis::kY, V(0, -5, 3), 10.0, 2.0};
  EXPECT_NEAR(range_or_nan(cyl, V(-10, 0, 3), V(1, 0, 0)), 8.0, kExact);
  EXPECT_NEAR(range_or_nan(cyl, V(-10, 0, 4), V(1, 0, 0)), 10.0 - std::sqrt(3.0), kExact);
  EXPECT_NEAR(range_or_nan(cyl, V(0, 0, 0), V(0, 0, 1)), 1.0, kExact);        // bottom at z = 1
  EXPECT_NEAR(range_or_nan(cyl, V(0.5, -10, 3.5), V(0, 1, 0)), 5.0, kExact);  // cap y = -5
  EXPECT_NEAR(range_or_nan(cyl, V(0, 0, 3), V(0, 1, 0)), 5.0, kExact);        // from inside: cap
  EXPECT_FALSE(intersect(cyl, V(-10, 0, 5.5), V(1, 0, 0)));                   // above
  EXPECT_FALSE(intersect(cyl, V(-10, 6, 3), V(1, 0, 0)));                     // beyond the cap
  EXPECT_FALSE(intersect(cyl, V(2.5, -10, 3), V(0, 1, 0)));                   // parallel, outside
}

TEST(Intersect, VerticalCylinder_SideAndTopCap) {
  const Cylinder gear{Axis::kZ, V(5, 0, 0), 3.0, 0.3};
  EXPECT_NEAR(range_or_nan(gear, V(0, 0, 1), V(1, 0, 0)), 4.7, kExact);
  EXPECT_NEAR(range_or_nan(gear, V(5, 0, 10), V(0, 0, -1)), 7.0, kExact);
  // Off-centre chord: |y| = 0.18 meets the circle at x = 5 − 0.24.
  EXPECT_NEAR(range_or_nan(gear, V(0, 0.18, 2), V(1, 0, 0)), 4.76, kExact);
  EXPECT_FALSE(intersect(gear, V(0, 0, 3.5), V(1, 0, 0)));
  EXPECT_FALSE(intersect(gear, V(0, 0.31, 1), V(1, 0, 0)));
}

TEST(Intersect, CylinderAlongX_Side) {
  const Cylinder engine{Axis::kX, V(23, 5, 2.2), 5.0, 1.0};
  EXPECT_NEAR(range_or_nan(engine, V(25, 0, 2.2), V(0, 1, 0)), 4.0, kExact);
  EXPECT_NEAR(range_or_nan(engine, V(20, 5, 2.2), V(1, 0, 0)), 3.0, kExact);  // front cap
  EXPECT_NEAR(range_or_nan(engine, V(25, 5, 0), V(0, 0, 1)), 1.2, kExact);
}

TEST(Intersect, Cone_SideApexBaseAndInside) {
  const Cone cone{V(0, 0, 0), 0.2, 0.5};  // radius 0.2 − 0.4·z
  EXPECT_NEAR(range_or_nan(cone, V(-1, 0, 0.25), V(1, 0, 0)), 0.9, kExact);
  EXPECT_NEAR(range_or_nan(cone, V(-1, 0, 0.1), V(1, 0, 0)), 0.84, kExact);
  EXPECT_NEAR(range_or_nan(cone, V(0, -1, 0.4), V(0, 1, 0)), 0.96, kExact);
  EXPECT_NEAR(range_or_nan(cone, V(0, 0, 2), V(0, 0, -1)), 1.5, kExact);  // apex
  // A steep ray (steeper than the cone's side) 5 cm off the axis meets the side at z = 0.375.
  EXPECT_NEAR(range_or_nan(cone, V(0.05, 0, 2), V(0, 0, -1)), 1.625, kExact);
  EXPECT_NEAR(range_or_nan(cone, V(0.1, 0, -1), V(0, 0, 1)), 1.0, kExact);  // base from below
  EXPECT_NEAR(range_or_nan(cone, V(0, 0, 0.1), V(1, 0, 0)), 0.16, kExact);  // from inside
  EXPECT_FALSE(intersect(cone, V(-1, 0.3, 0.1), V(1, 0, 0)));
  EXPECT_FALSE(intersect(cone, V(-1, 0, 0.6), V(1, 0, 0)));  // above the apex
  EXPECT_FALSE(intersect(cone, V(0.25, 0, 2), V(0, 0, -1)));
}

TEST(Intersect, Cone_SlantedRayMatchesClosedForm) {
  // Ray from (-1, 0, 0) rising at slope 0.1: z = 0.1·(x + 1); the side −x = 0.2 − 0.4·z gives
  // −0.96·x = 0.16, x = −1/6, after (5/6)·sqrt(1 + 0.1²) m.
  const Cone cone{V(0, 0, 0), 0.2, 0.5};
  const V dir = V(1, 0, 0.1).normalized();
  const double expected = (5.0 / 6.0) * std::sqrt(1.0 + 0.01);
  EXPECT_NEAR(range_or_nan(cone, V(-1, 0, 0), dir), expected, kExact);
}

TEST(Intersect, Plane_DownwardRangeIsHeightOverSine) {
  const Plane ground{V::UnitZ(), 0.0};
  for (const double elevation_deg : {-1.0, -7.5, -22.5, -45.0, -90.0}) {
    const double e = deg(elevation_deg);
    const V dir(std::cos(e), 0.0, std::sin(e));
    EXPECT_NEAR(range_or_nan(ground, V(3, 4, 2), dir), 2.0 / std::sin(-e), kExact);
  }
  EXPECT_FALSE(intersect(ground, V(0, 0, 2), V(1, 0, 0)));
  EXPECT_FALSE(intersect(ground, V(0, 0, 2), V(0, 0, 1)));
  EXPECT_NEAR(range_or_nan(ground, V(0, 0, -1), V(0, 0, 1)), 1.0, kExact);
}

TEST(Contains, EachPrimitive_InsideAndOutside) {
  EXPECT_TRUE(contains(Plane{V::UnitZ(), 0.0}, V(0, 0, -0.01)));
  EXPECT_FALSE(contains(Plane{V::UnitZ(), 0.0}, V(0, 0, 0)));
  EXPECT_TRUE(contains(Box{V(0, 0, 0), V(1, 1, 1)}, V(1, 0.5, 0)));
  EXPECT_FALSE(contains(Box{V(0, 0, 0), V(1, 1, 1)}, V(1.01, 0.5, 0)));
  EXPECT_TRUE(contains(Cylinder{Axis::kY, V(0, -5, 3), 10.0, 2.0}, V(1.9, 4.9, 3)));
  EXPECT_FALSE(contains(Cylinder{Axis::kY, V(0, -5, 3), 10.0, 2.0}, V(1.5, 0, 4.5)));
  EXPECT_TRUE(contains(Cone{V(0, 0, 0), 0.2, 0.5}, V(0.09, 0, 0.25)));
  EXPECT_FALSE(contains(Cone{V(0, 0, 0), 0.2, 0.5}, V(0.11, 0, 0.25)));
}

// ---- the airside scene ----

class Airside : public ::testing::Test {
 protected:
  const Scene scene_ = Scene::airside_default();

  int id(const char* name) const {
    const Object* object = scene_.find(name);
    EXPECT_NE(object, nullptr) << name;
    return object ? object->id : -1;
  }
};

TEST_F(Airside, Objects_HaveUniqueIdsAndOnlyTheTugMoves) {
  const auto& objects = scene_.objects();
  ASSERT_EQ(objects.size(), 16u);
  for (std::size_t i = 0; i < objects.size(); ++i) {
    EXPECT_EQ(objects[i].id, static_cast<int>(i));
    EXPECT_EQ(objects[i].dynamic(), objects[i].name == "tug") << objects[i].name;
  }
  EXPECT_EQ(objects[0].kind, "ground");
}

TEST_F(Airside, DownwardBeamOverOpenGround_RangeIsHeightOverSine) {
  for (const double elevation_deg : {-3.0, -10.0, -22.5}) {
    const double e = deg(elevation_deg);
    const V dir(0.0, -std::cos(e), std::sin(e));  // towards −y, open apron
    const auto hit = scene_.raycast(V(5, -20, 2), dir, 100.0, 0.0);
    ASSERT_TRUE(hit);
    EXPECT_EQ(hit->object_id, id("ground"));
    EXPECT_NEAR(hit->range_m, 2.0 / std::sin(-e), kExact);
    EXPECT_NEAR(hit->point_W.z(), 0.0, kExact);
  }
}

TEST_F(Airside, RaycastBeyondMaxRange_ReturnsNothing) {
  const double e = deg(-1.0);  // ground at 2 / sin(1°) = 114.6 m
  EXPECT_FALSE(scene_.raycast(V(5, -20, 2), V(0, -std::cos(e), std::sin(e)), 100.0, 0.0));
  EXPECT_TRUE(scene_.raycast(V(5, -20, 2), V(0, -std::cos(e), std::sin(e)), 120.0, 0.0));
  EXPECT_FALSE(scene_.raycast(V(0, 0, 2), V(0, 0, 1), 100.0, 0.0));  // open sky
}

TEST_F(Airside, WingOverhangsPath_VerticalRayHitsWingBottom) {
  const auto hit = scene_.raycast(V(30, 0, 0.1), V(0, 0, 1), 100.0, 0.0);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object_id, id("wing_right"));
  EXPECT_NEAR(hit->point_W.z(), 4.0, kExact);
  EXPECT_NEAR(hit->range_m, 3.9, kExact);
}

TEST_F(Airside, DrivePath_ClearBelowThreeAndAHalfMetresAboveTheCones) {
  // Along the whole path (tug parked), nothing overhead is lower than 3.5 m.
  for (double x = 0.0; x <= 60.0; x += 0.25) {
    for (const double y : {-1.0, 0.0, 1.0}) {
      const auto hit = scene_.raycast(V(x, y, 0.6), V(0, 0, 1), 100.0, 100.0);
      if (hit) {
        EXPECT_GE(hit->point_W.z(), 3.5) << "x " << x << " y " << y;
      }
    }
  }
}

TEST_F(Airside, DrivePath_OnlyConeAndDebrisIntersectTheCorridor) {
  // Static objects whose bounds meet the corridor |y| <= 1.2, z in [0, 3.5], x in [0, 60].
  std::vector<std::string> blocking;
  for (const Object& object : scene_.objects()) {
    if (object.kind == "ground" || object.dynamic()) continue;
    const Aabb b = scene_.bounds_at(object.id, 0.0);
    if (b.max_W.x() >= 0.0 && b.min_W.x() <= 60.0 && b.max_W.y() >= -1.2 && b.min_W.y() <= 1.2 &&
        b.max_W.z() >= 0.0 && b.min_W.z() <= 3.5) {
      blocking.push_back(object.name);
    }
  }
  EXPECT_EQ(blocking, (std::vector<std::string>{"cone_path", "debris"}));
}

TEST_F(Airside, HorizontalRayAlongPath_HitsConeThenDebris) {
  const V along(1, 0, 0);
  // Cone at (40, 0): radius at z = 0.05 is 0.2 · (1 − 0.05 / 0.5) = 0.18.
  auto hit = scene_.raycast(V(0, 0, 0.05), along, 100.0, 20.0);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object_id, id("cone_path"));
  EXPECT_NEAR(hit->range_m, 39.82, kExact);
  // Half a metre to the left the cone is missed and the debris face x = 46.9 is hit.
  hit = scene_.raycast(V(0, 0.5, 0.05), along, 100.0, 20.0);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object_id, id("debris"));
  EXPECT_NEAR(hit->range_m, 46.9, kExact);
  // Above the debris (0.1 m) and the cone (0.5 m) nothing is in the way.
  EXPECT_FALSE(scene_.raycast(V(0, 0.5, 0.6), along, 100.0, 20.0));
  // While the tug crosses (t = 2 s, centre y = 0) it is hit first, at its face x = 14.2.
  hit = scene_.raycast(V(0, 0, 0.05), along, 100.0, 2.0);
  ASSERT_TRUE(hit);
  EXPECT_EQ(hit->object_id, id("tug"));
  EXPECT_NEAR(hit->range_m, 14.2, kExact);
}

TEST_F(Airside, Tug_OccupiesPathOnlyWhileCrossing) {
  const V on_path(15, 0, 0.5);
  // Centre y = −4 + 2·t, half length 1.5 m: covers y = 0 for t in [1.25, 2.75] s.
  EXPECT_FALSE(scene_.occupied(on_path, 0.0));
  EXPECT_FALSE(scene_.occupied(on_path, 1.2));
  EXPECT_TRUE(scene_.occupied(on_path, 1.3));
  EXPECT_TRUE(scene_.occupied(on_path, 2.0));
  EXPECT_TRUE(scene_.occupied(on_path, 2.7));
  EXPECT_FALSE(scene_.occupied(on_path, 2.8));
  EXPECT_FALSE(scene_.occupied(on_path, 5.0));
  EXPECT_FALSE(scene_.occupied(on_path, 100.0));
  EXPECT_TRUE(scene_.occupied(V(15, -4, 0.5), 0.0));   // start
  EXPECT_TRUE(scene_.occupied(V(15, 8, 0.5), 100.0));  // parked after 6 s
  EXPECT_FALSE(scene_.occupied(V(15, 0, 1.6), 2.0));   // above its roof
}

TEST_F(Airside, Tug_BoundsFollowTheMotion) {
  const int tug = id("tug");
  const Aabb at2 = scene_.bounds_at(tug, 2.0);
  EXPECT_TRUE(at2.min_W.isApprox(V(14.2, -1.5, 0.0), 1e-12));
  EXPECT_TRUE(at2.max_W.isApprox(V(15.8, 1.5, 1.5), 1e-12));
  const Aabb parked = scene_.bounds_at(tug, 50.0);
  EXPECT_NEAR(parked.min_W.y(), 6.5, kExact);
  EXPECT_NEAR(parked.max_W.y(), 9.5, kExact);
}

TEST_F(Airside, Tug_NeverWithinTwoMetresOfTheVehicle) {
  // The default drive (3 m/s along y = 0): the vehicle footprint |dx| <= 2, |y| <= 1 stays clear.
  const DrivePath path;
  for (double t_s = 0.0; t_s <= path.duration_s(); t_s += 0.05) {
    const double x = path.T_W_base(t_s).translation().x();
    const Aabb b = scene_.bounds_at(id("tug"), t_s);
    const bool overlap = b.max_W.x() >= x - 2.0 && b.min_W.x() <= x + 2.0 && b.max_W.y() >= -1.0 &&
                         b.min_W.y() <= 1.0;
    EXPECT_FALSE(overlap) << "t " << t_s;
  }
}

TEST_F(Airside, Occupied_GroundFuselageAndFreeSpace) {
  EXPECT_TRUE(scene_.occupied(V(0, 0, -0.01), 0.0));
  EXPECT_FALSE(scene_.occupied(V(0, 0, 0.0), 0.0));
  EXPECT_FALSE(scene_.occupied(V(30, 0, 2.0), 0.0));  // under the wing
  EXPECT_TRUE(scene_.occupied(V(30, 12, 3.0), 0.0));  // fuselage axis
  EXPECT_TRUE(scene_.occupied(V(30, 0, 4.2), 0.0));   // inside the wing
  EXPECT_TRUE(scene_.occupied(V(40, 0, 0.2), 0.0));   // inside the path cone
}

TEST_F(Airside, Json_ListsEveryObjectAndTheTugMotion) {
  const std::string json = scene_.to_json();
  for (const Object& object : scene_.objects()) {
    EXPECT_NE(json.find("\"name\": \"" + object.name + "\""), std::string::npos) << object.name;
  }
  EXPECT_NE(json.find("\"motion\": {\"velocity_mps\": [0, 2, 0], \"start_s\": 0, \"stop_s\": 6}"),
            std::string::npos);
  EXPECT_NE(json.find("\"T_world_scene\": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]"),
            std::string::npos);
}

// ---- LiDAR and sequence ----

TEST(GaussianNoise, SameSeedSameStream_UnitMoments) {
  GaussianNoise a(42), b(42), c(43);
  double sum = 0.0, sum_sq = 0.0;
  bool differs = false;
  constexpr int kN = 200000;
  for (int i = 0; i < kN; ++i) {
    const double x = a.sample();
    EXPECT_EQ(x, b.sample());
    differs |= x != c.sample();
    sum += x;
    sum_sq += x * x;
  }
  EXPECT_TRUE(differs);
  EXPECT_NEAR(sum / kN, 0.0, 0.01);
  EXPECT_NEAR(sum_sq / kN, 1.0, 0.015);
}

TEST(Lidar, LowestBeamBackwardsOverOpenGround_RangeIsHeightOverSine) {
  const Scene scene = Scene::airside_default();
  const Lidar lidar(LidarParams{});
  const DrivePath path;
  std::vector<LidarReturn> returns;
  lidar.scan(scene, path.T_W_S(0.0), 0.0, nullptr, returns);
  const LidarReturn* backwards = nullptr;  // beam 0 (−22.5°), azimuth 180° (step 512)
  for (const LidarReturn& r : returns) {
    if (r.beam == 0 && r.azimuth_step == 512) backwards = &r;
  }
  ASSERT_NE(backwards, nullptr);
  EXPECT_EQ(backwards->object_id, 0);
  EXPECT_EQ(backwards->intensity, kGroundIntensity);
  EXPECT_NEAR(backwards->range_m, 2.0 / std::sin(deg(22.5)), kExact);
  EXPECT_NEAR(backwards->point_S.z(), -2.0, kExact);
  EXPECT_NEAR(backwards->point_S.x(), -2.0 / std::tan(deg(22.5)), 1e-9);
  // Upward beams into open sky give no point.
  EXPECT_LT(returns.size(), 32u * 1024u);
  EXPECT_GE(returns.size(), 15u * 1024u);  // the 15 lowest beams all reach the ground
}

TEST(Lidar, Directions_AreUnitWithEvenElevations) {
  const Lidar lidar(LidarParams{});
  for (int b = 0; b < 32; ++b) {
    const V& d = lidar.direction_S(b, 0);
    EXPECT_NEAR(d.norm(), 1.0, 1e-15);
    EXPECT_NEAR(std::asin(d.z()), deg(-22.5 + 45.0 * b / 31.0), 1e-12);
  }
  EXPECT_NEAR(lidar.direction_S(0, 256).x(), 0.0, 1e-15);  // 90° azimuth: +y
  EXPECT_GT(lidar.direction_S(0, 256).y(), 0.0);
}

TEST(SequenceParams, DefaultScans_DriveTheWholePath) {
  SequenceParams params;
  EXPECT_EQ(params.scan_count(), 201);  // 60 m at 3 m/s and 10 Hz, both ends included
  params.rate_hz = 0.5;
  EXPECT_EQ(params.scan_count(), 11);
  params.scans = 3;
  EXPECT_EQ(params.scan_count(), 3);
  params.lidar.beams = 0;
  EXPECT_FALSE(params.validate().empty());
}

std::string read_bytes(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A fresh directory under the temp dir, removed on destruction.
struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& tag) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path = std::filesystem::temp_directory_path() / ("tarmac_sim_" + std::string(info->name()) +
                                                     "_" + tag + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

struct ScanPointsS {
  std::vector<V> points_S;
  std::vector<float> intensity;
};

ScanPointsS read_scan(const std::filesystem::path& file) {
  const std::string bytes = read_bytes(file);
  EXPECT_EQ(bytes.size() % 16, 0u);
  ScanPointsS scan;
  for (std::size_t i = 0; i + 16 <= bytes.size(); i += 16) {
    float xyzi[4];
    std::memcpy(xyzi, bytes.data() + i, 16);  // the test machine is little-endian (x86-64)
    scan.points_S.emplace_back(xyzi[0], xyzi[1], xyzi[2]);
    scan.intensity.push_back(xyzi[3]);
  }
  return scan;
}

using tarmac::test::read_sim_poses;

TEST(WriteSequence, SameArguments_ByteIdenticalOutput) {
  SequenceParams params;
  params.lidar.azimuth_steps = 256;
  params.lidar.range_noise_m = 0.03;
  params.seed = 7;
  params.scans = 6;
  params.tilt_deg = 3.0;
  const Scene scene = Scene::airside_default();
  TempDir a("a"), b("b"), c("c");
  ASSERT_TRUE(write_sequence(scene, params, a.path).ok());
  ASSERT_TRUE(write_sequence(scene, params, b.path).ok());
  params.seed = 8;
  ASSERT_TRUE(write_sequence(scene, params, c.path).ok());
  for (const char* name :
       {"poses.txt", "times.txt", "scene.json", "README.txt", "dynamic_boxes.txt"}) {
    EXPECT_EQ(read_bytes(a.path / name), read_bytes(b.path / name)) << name;
  }
  for (int i = 0; i < 6; ++i) {
    const std::string scan = "scans/00000" + std::to_string(i) + ".bin";
    const std::string bytes = read_bytes(a.path / scan);
    EXPECT_GT(bytes.size(), 16u * 1000u);
    EXPECT_EQ(bytes, read_bytes(b.path / scan)) << scan;
    EXPECT_NE(bytes, read_bytes(c.path / scan)) << scan << ": the seed changes the noise";
  }
}

TEST(WriteSequence, RewriteWithFewerScans_RemovesStaleScans) {
  SequenceParams params;
  params.lidar.azimuth_steps = 16;
  params.scans = 4;
  TempDir dir("out");
  const Scene scene = Scene::airside_default();
  ASSERT_TRUE(write_sequence(scene, params, dir.path).ok());
  params.scans = 2;
  const SequenceResult result = write_sequence(scene, params, dir.path);
  ASSERT_TRUE(result.ok()) << result.error;
  EXPECT_EQ(result.summary.scans, 2);
  int files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir.path / "scans"))
    ++files;
  EXPECT_EQ(files, 2);
  EXPECT_EQ(read_sim_poses(dir.path / "poses.txt").size(), 2u);
}

/// Every point of every scan, moved into the scene frame with its pose, lies on the scene
/// surface that a ray from the sensor towards it meets first (noise off).
void expect_points_on_scene_surfaces(double tilt_deg) {
  SequenceParams params;
  params.rate_hz = 0.5;  // 11 scans, one every 6 m; the tug crosses the path in scan 1
  params.tilt_deg = tilt_deg;
  const Scene scene = Scene::airside_default();
  TempDir dir("tilt" + std::to_string(static_cast<int>(tilt_deg)));
  const SequenceResult result = write_sequence(scene, params, dir.path);
  ASSERT_TRUE(result.ok()) << result.error;
  ASSERT_EQ(result.summary.scans, 11);

  const auto poses = read_sim_poses(dir.path / "poses.txt");
  ASSERT_EQ(poses.size(), 11u);
  std::ifstream times(dir.path / "times.txt");
  const Eigen::Isometry3d T_W_O = params.T_O_W().inverse();
  std::size_t checked = 0, tug_points = 0;
  for (int i = 0; i < 11; ++i) {
    double stamp_s = -1.0;
    times >> stamp_s;
    EXPECT_EQ(stamp_s, 2.0 * i);
    // Poses round-trip exactly: shortest decimal representation.
    const Eigen::Isometry3d T_O_S_expected = params.T_O_W() * params.path.T_W_S(stamp_s);
    EXPECT_TRUE(poses[i].matrix() == T_O_S_expected.matrix()) << "scan " << i;
    if (tilt_deg != 0.0) {
      // Not gravity-aligned: the sensor's z axis is tilted in the poses' world frame.
      EXPECT_NEAR(poses[i].linear().col(2).z(), std::cos(deg(tilt_deg)), 1e-12);
    }

    char name[32];
    std::snprintf(name, sizeof(name), "scans/%06d.bin", i);
    const ScanPointsS scan = read_scan(dir.path / name);
    ASSERT_GT(scan.points_S.size(), 15u * 1024u) << name;
    const Eigen::Isometry3d T_W_S = T_W_O * poses[i];
    const V origin_W = T_W_S.translation();
    for (std::size_t k = 0; k < scan.points_S.size(); ++k) {
      const V p_W = T_W_S * scan.points_S[k];
      const double measured_m = (p_W - origin_W).norm();
      const auto hit = scene.raycast(origin_W, p_W - origin_W, 100.0, stamp_s);
      ASSERT_TRUE(hit) << name << " point " << k;
      ASSERT_NEAR(hit->range_m, measured_m, 1e-4) << name << " point " << k;
      ASSERT_EQ(scan.intensity[k], hit->object_id == 0 ? kGroundIntensity : kObjectIntensity);
      tug_points += scene.objects()[static_cast<std::size_t>(hit->object_id)].name == "tug";
      ++checked;
    }
  }
  EXPECT_GT(checked, 11u * 15u * 1024u);
  EXPECT_GT(tug_points, 100u);  // the moving tug is seen
}

TEST(WriteSequence, PointsInSensorFrame_LieOnSceneSurfaces) {
  expect_points_on_scene_surfaces(0.0);
}

TEST(WriteSequence, TiltedWorld_PointsStillLieOnSceneSurfaces) {
  expect_points_on_scene_surfaces(7.0);
}

}  // namespace
