// tarmac_sim's terrain: rays against boxes with a sloped top, the terrain scenes' ground at its
// analytic height, the drive's poses on that ground (pitched and rolled with it), the height
// drift written into the poses only, and the scans of a pitched sensor lying on the scene.

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "../support/sim_poses.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/sim/scene_catalog.hpp"

namespace {

using namespace tarmac::sim;
using V = Eigen::Vector3d;
using V2 = Eigen::Vector2d;

constexpr double kExact = 1e-9;  // m: analytic answers in double precision

// ---- ray vs box with a sloped top ----

/// A 10 m square rising 10 % along x and falling 2 % along y, its top 1 m up at (0, 0).
const SlopedBox kSloped{V2(0, 0), V2(10, 10), -5.0, 1.0, V2(0.1, -0.02)};

TEST(Intersect, SlopedBox_VerticalRayHitsTheTopAtItsHeight) {
  for (const V2& xy : {V2(0.5, 0.5), V2(5, 2), V2(9.9, 9.9), V2(3.3, 7.7)}) {
    const auto range = intersect(kSloped, V(xy.x(), xy.y(), 10.0), V(0, 0, -1));
    ASSERT_TRUE(range) << xy.transpose();
    EXPECT_NEAR(*range, 10.0 - (1.0 + 0.1 * xy.x() - 0.02 * xy.y()), kExact);
  }
  EXPECT_FALSE(intersect(kSloped, V(10.5, 5, 10), V(0, 0, -1))) << "beside the footprint";
}

TEST(Intersect, SlopedBox_SlantedRaysLandOnTheTopPlane) {
  const V origin(-20, 3, 6);
  for (const V& target : {V(2, 1, 0), V(6, 8, 0), V(9, 4, 0)}) {
    const V2 xy = target.head<2>();
    const V on_top(xy.x(), xy.y(), kSloped.top_at(xy));
    const V dir = (on_top - origin).normalized();
    const auto range = intersect(kSloped, origin, dir);
    ASSERT_TRUE(range);
    EXPECT_NEAR(*range, (on_top - origin).norm(), 1e-9);
    const V hit = origin + *range * dir;
    EXPECT_NEAR(hit.z(), kSloped.top_at(hit.head<2>()), 1e-12);
  }
}

TEST(Intersect, SlopedBox_SideFaceBottomInsideAndParallel) {
  // Level with the low side's middle, a ray along +x meets the face x = 0.
  EXPECT_NEAR(*intersect(kSloped, V(-3, 5, 0.5), V(1, 0, 0)), 3.0, kExact);
  // From below, the bottom face.
  EXPECT_NEAR(*intersect(kSloped, V(5, 5, -8), V(0, 0, 1)), 3.0, kExact);
  // From inside, the top face on the way out.
  EXPECT_NEAR(*intersect(kSloped, V(5, 0, 0), V(0, 0, 1)), 1.5, kExact);
  // Parallel to the top plane, just above it: no crossing; just below it: the far side.
  const V along = V(1, 0, 0.1).normalized();
  EXPECT_FALSE(intersect(kSloped, V(0, 5, 0.9 + 1e-6), along));
  EXPECT_NEAR(*intersect(kSloped, V(-1, 5, 0.8 - 1e-6), along), std::hypot(1.0, 0.1), 1e-9);
}

TEST(Contains, SlopedBox_UnderTheTopAboveTheBottomOverTheFootprint) {
  EXPECT_TRUE(contains(kSloped, V(5, 5, 1.4 - 1e-9)));  // top at 1.4 here
  EXPECT_FALSE(contains(kSloped, V(5, 5, 1.4 + 1e-9)));
  EXPECT_FALSE(contains(kSloped, V(5, 5, -5.1)));
  EXPECT_FALSE(contains(kSloped, V(10.1, 5, 0)));
  const Aabb b = bounds(kSloped);
  EXPECT_EQ(b.min_W, V(0, 0, -5));
  EXPECT_NEAR(b.max_W.z(), 2.0, kExact);  // the corner (10, 0)
  const Primitive moved = translated(kSloped, V(1, 2, 3));
  EXPECT_TRUE(contains(moved, V(6, 7, 4.4 - 1e-9)));
  EXPECT_FALSE(contains(moved, V(6, 7, 4.4 + 1e-9)));
}

// ---- the terrain scenes' ground ----

/// The ground's height under a vertical ray from 20 m up, and that what it hit is ground.
double ground_hit_z(const Scene& scene, const V2& xy) {
  const auto hit = scene.raycast(V(xy.x(), xy.y(), 20.0), V(0, 0, -1), 100.0, 0.0);
  EXPECT_TRUE(hit) << xy.transpose();
  if (!hit) return std::nan("");
  EXPECT_EQ(scene.objects()[static_cast<std::size_t>(hit->object_id)].kind, "ground")
      << xy.transpose();
  return hit->point_W.z();
}

TEST(TerrainScene, Ramp_RaysHitTheProfileAtItsAnalyticHeight) {
  const Scene scene = Scene::apron_ramp(0.10, 25.0);
  const auto profile = [](double x) { return std::clamp(0.1 * (x - 20.0), 0.0, 2.5); };
  for (const double x : {-90.0, 5.0, 19.9, 20.0, 27.5, 33.3, 44.9, 45.0, 60.0, 200.0}) {
    for (const double y : {-40.0, 0.0, 12.3}) {
      EXPECT_NEAR(ground_hit_z(scene, {x, y}), profile(x), kExact) << x << ", " << y;
      EXPECT_NEAR(*scene.terrain().height_m({x, y}), profile(x), kExact);
    }
  }
  // The sensor on the apron sees a point of the ramp where the ramp is.
  const V sensor(0, 0, 2), on_ramp(30, 1, 1.0);
  const auto hit = scene.raycast(sensor, on_ramp - sensor, 100.0, 0.0);
  ASSERT_TRUE(hit);
  EXPECT_NEAR(hit->range_m, (on_ramp - sensor).norm(), 1e-9);
}

TEST(TerrainScene, Crown_CrossSectionFallsTwoPercentEachSideThenTheShoulders) {
  const Scene scene = Scene::crowned_road();
  const std::vector<std::pair<double, double>> section = {
      {-20.0, -0.12}, {-8.0, -0.12}, {-6.5, -0.06}, {-5.0, 0.0},  {-2.5, 0.05},
      {0.0, 0.1},     {2.5, 0.05},   {5.0, 0.0},    {6.5, -0.06}, {30.0, -0.12}};
  for (const auto& [y, z] : section) {
    for (const double x : {-10.0, 42.0}) {
      EXPECT_NEAR(ground_hit_z(scene, {x, y}), z, kExact) << x << ", " << y;
    }
  }
}

TEST(TerrainScene, Parking_LowerLevelUnderTheDeckAndTheRampBetween) {
  const Scene scene = Scene::parking_levels();
  EXPECT_NEAR(ground_hit_z(scene, {10.0, -1.0}), 0.0, kExact);
  EXPECT_NEAR(ground_hit_z(scene, {42.5, -1.0}), -1.125, kExact);  // 12.5 m down at 9 %
  EXPECT_NEAR(ground_hit_z(scene, {70.0, 0.0}), -2.25, kExact);
  EXPECT_NEAR(ground_hit_z(scene, {95.0, 15.0}), -2.25, kExact);  // the bays
  EXPECT_NEAR(ground_hit_z(scene, {60.0, 20.0}), 0.0, kExact);    // the apron beside the cut
  EXPECT_NEAR(ground_hit_z(scene, {200.0, 0.0}), 0.0, kExact);    // beyond the road's end
  // Under the deck, 3.6 m of headroom above the road.
  const auto up = scene.raycast(V(115, 0, -2.0), V(0, 0, 1), 100.0, 0.0);
  ASSERT_TRUE(up);
  EXPECT_EQ(scene.objects()[static_cast<std::size_t>(up->object_id)].name, "deck");
  EXPECT_NEAR(up->point_W.z() - (-2.25), 3.6, kExact);
  // The curb stands 15 cm on the ramp's surface.
  const auto curb = scene.raycast(V(40, -4.15, 5), V(0, 0, -1), 100.0, 0.0);
  ASSERT_TRUE(curb);
  EXPECT_EQ(scene.objects()[static_cast<std::size_t>(curb->object_id)].kind, "curb");
  EXPECT_NEAR(curb->point_W.z() - *scene.terrain().height_m({40, -4.15}), 0.15, kExact);
}

// ---- the drive on the terrain ----

/// Pitch (nose up positive) and roll (left side up positive) of a base frame, rad.
double pitch_of(const Eigen::Isometry3d& T) {
  const V x = T.linear().col(0);
  return std::atan2(x.z(), x.head<2>().norm());
}
double roll_of(const Eigen::Isometry3d& T) {
  const V y = T.linear().col(1);
  return std::asin(y.z());
}

TEST(TerrainDrive, Ramp10_BaseOnTheSurfacePitchedByTheGrade) {
  const auto drive = scene_drive("ramp10", std::nullopt, 2.0);
  ASSERT_TRUE(drive);
  const DrivePath& path = drive->path;
  ASSERT_FALSE(path.terrain.flat());
  // x = 3 t: on the apron, on the ramp (both axles on it), on the upper level.
  for (const auto& [x, z, pitch] :
       std::vector<std::tuple<double, double, double>>{{10.0, 0.0, 0.0},
                                                       {25.0, 0.5, std::atan(0.1)},
                                                       {32.5, 1.25, std::atan(0.1)},
                                                       {60.0, 2.5, 0.0}}) {
    const Eigen::Isometry3d T = path.T_W_base(x / 3.0);
    EXPECT_NEAR(T.translation().x(), x, 1e-12);
    EXPECT_NEAR(T.translation().z(), z, 1e-12) << x;
    EXPECT_NEAR(pitch_of(T), pitch, 1e-12) << x;
    EXPECT_NEAR(roll_of(T), 0.0, 1e-12) << x;
    EXPECT_NEAR((T.linear().transpose() * T.linear() - Eigen::Matrix3d::Identity()).norm(), 0.0,
                1e-12);
    // The sensor is 2 m up the pitched base's z axis.
    const Eigen::Isometry3d T_W_S = path.T_W_S(x / 3.0);
    EXPECT_NEAR((T_W_S.translation() - (T * V(0, 0, 2))).norm(), 0.0, 1e-12);
  }
  // Over the foot of the ramp the axles even the kink out: the pitch rises in between.
  const double at_foot = pitch_of(path.T_W_base(20.0 / 3.0));
  EXPECT_GT(at_foot, 0.01);
  EXPECT_LT(at_foot, std::atan(0.1) - 0.01);
}

TEST(TerrainDrive, Crown_RightLaneRolledByTheCrossFall) {
  const auto drive = scene_drive("crown", std::nullopt, 2.0);
  ASSERT_TRUE(drive);
  const Eigen::Isometry3d T = drive->path.T_W_base(10.0);
  EXPECT_NEAR(T.translation().y(), -2.5, 1e-12);
  EXPECT_NEAR(T.translation().z(), 0.05, 1e-12);  // 0.1 at the crown, 2.5 m down at 2 %
  EXPECT_NEAR(pitch_of(T), 0.0, 1e-12);
  EXPECT_NEAR(roll_of(T), std::atan(0.02), 1e-12);  // its left side up, towards the crown
}

TEST(TerrainDrive, Parking_DownTheRampAndUnderTheDeck) {
  const auto drive = scene_drive("parking", 4.0, 1.9);
  ASSERT_TRUE(drive);
  EXPECT_EQ(drive->path.speed_mps, 4.0);
  EXPECT_EQ(drive->path.sensor_height_m, 1.9);
  const Eigen::Isometry3d on_ramp = drive->path.T_W_base(42.5 / 4.0);
  EXPECT_NEAR(on_ramp.translation().z(), -1.125, 1e-12);
  EXPECT_NEAR(pitch_of(on_ramp), -std::atan(0.09), 1e-12);  // nose down
  const Eigen::Isometry3d end = drive->path.T_W_base(1000.0);
  EXPECT_NEAR(end.translation().x(), 120.0, 1e-12);
  EXPECT_NEAR(end.translation().z(), -2.25, 1e-12);
}

TEST(TerrainDrive, FlatScenes_LevelOnTheGroundPlane) {
  for (const char* name : {"airside", "terminal", "aircraft"}) {
    const auto drive = scene_drive(name, std::nullopt, 2.0);
    ASSERT_TRUE(drive) << name;
    EXPECT_TRUE(drive->path.terrain.flat()) << name;
    const Eigen::Isometry3d T = drive->path.T_W_base(3.0);
    EXPECT_EQ(T.translation().z(), 0.0) << name;
    EXPECT_EQ(T.linear().col(2), V::UnitZ()) << name;
  }
  EXPECT_FALSE(scene_drive("moon", std::nullopt, 2.0));
}

// ---- the written sequence ----

std::string read_bytes(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

using tarmac::test::read_sim_poses;

/// A fresh directory under the temp dir, removed on destruction.
struct TempDir {
  std::filesystem::path path;
  explicit TempDir(const std::string& tag) {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path = std::filesystem::temp_directory_path() / ("tarmac_terrain_" + std::string(info->name()) +
                                                     "_" + tag + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

/// A short, sparse sequence of the scene `name`: `scans` scans spread over the whole drive.
SequenceParams sparse_params(const SceneDrive& drive, int scans) {
  SequenceParams params;
  params.path = drive.path;
  params.lidar.beams = 8;
  params.lidar.azimuth_steps = 256;
  params.scans = scans;
  params.rate_hz = (scans - 1) / drive.path.duration_s();
  return params;
}

class DriftZ : public ::testing::TestWithParam<const char*> {};

TEST_P(DriftZ, ShiftsTheWrittenPosesOnly_ToMAtTheEnd) {
  const auto drive = scene_drive(GetParam(), std::nullopt, 2.0);
  ASSERT_TRUE(drive);
  SequenceParams params = sparse_params(*drive, 5);
  TempDir true_dir("true"), drifted_dir("drifted");
  ASSERT_TRUE(write_sequence(drive->scene, params, true_dir.path).ok());
  params.drift_z_m = 0.5;
  const SequenceResult result = write_sequence(drive->scene, params, drifted_dir.path);
  ASSERT_TRUE(result.ok()) << result.error;
  for (const char* name : {"scans/000000.bin", "scans/000004.bin", "organised/000002.bin",
                           "obstacle_columns.txt", "scene.json", "times.txt"}) {
    EXPECT_EQ(read_bytes(true_dir.path / name), read_bytes(drifted_dir.path / name)) << name;
  }
  const auto truth = read_sim_poses(true_dir.path / "poses.txt");
  const auto written = read_sim_poses(drifted_dir.path / "poses.txt");
  ASSERT_EQ(truth.size(), 5u);
  ASSERT_EQ(written.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    const V shift = written[i].translation() - truth[i].translation();
    EXPECT_NEAR(shift.x(), 0.0, 1e-12) << i;
    EXPECT_NEAR(shift.y(), 0.0, 1e-12) << i;
    EXPECT_NEAR(shift.z(), 0.5 * i / 4.0, 1e-12) << i;
    EXPECT_TRUE(written[i].linear() == truth[i].linear()) << i;
  }
  EXPECT_NE(read_bytes(true_dir.path / "README.txt"), read_bytes(drifted_dir.path / "README.txt"));
  // The ground truth of terrain, the curbs' of the scene with curbs; the flat scenes have none.
  EXPECT_EQ(std::filesystem::exists(true_dir.path / "ground_cells.txt"),
            !drive->path.terrain.flat());
  EXPECT_EQ(read_bytes(true_dir.path / "ground_cells.txt"),
            read_bytes(drifted_dir.path / "ground_cells.txt"));
  EXPECT_EQ(std::filesystem::exists(true_dir.path / "curb_columns.txt"),
            std::string(GetParam()) == "parking");
}

INSTANTIATE_TEST_SUITE_P(EveryKindOfScene, DriftZ,
                         ::testing::Values("airside", "aircraft", "ramp10", "parking"));

TEST(WriteSequence, PathNotOnTheScenesTerrain_Refused) {
  const auto drive = scene_drive("ramp5", std::nullopt, 2.0);
  ASSERT_TRUE(drive);
  SequenceParams params = sparse_params(*drive, 2);
  params.path.terrain = Terrain{};  // the plane z = 0: under the upper level
  TempDir dir("out");
  const SequenceResult result = write_sequence(drive->scene, params, dir.path);
  EXPECT_FALSE(result.ok());
  EXPECT_NE(result.error.find("terrain"), std::string::npos) << result.error;
}

/// Every point of every scan, moved into the scene frame with its (pitched, rolled) pose, lies
/// on the scene surface that a ray from the sensor towards it meets first.
TEST(WriteSequence, TerrainScenes_PointsInSensorFrameLieOnSceneSurfaces) {
  for (const char* name : {"ramp10", "crown", "parking"}) {
    const auto drive = scene_drive(name, std::nullopt, 2.0);
    ASSERT_TRUE(drive) << name;
    // Eight scans: none at a round x, where a beam across the drive would run along a face.
    const SequenceParams params = sparse_params(*drive, 8);
    TempDir dir(name);
    const SequenceResult result = write_sequence(drive->scene, params, dir.path);
    ASSERT_TRUE(result.ok()) << result.error;
    const auto poses = read_sim_poses(dir.path / "poses.txt");
    ASSERT_EQ(poses.size(), 8u);
    std::size_t checked = 0;
    for (int i = 0; i < 8; ++i) {
      EXPECT_TRUE(poses[i].matrix() == params.path.T_W_S(params.stamp_s(i)).matrix()) << i;
      char file[32];
      std::snprintf(file, sizeof(file), "scans/%06d.bin", i);
      const std::string bytes = read_bytes(dir.path / file);
      ASSERT_GT(bytes.size(), 16u * 500u) << name << " " << file;
      const V origin_W = poses[i].translation();
      for (std::size_t k = 0; k + 16 <= bytes.size(); k += 16) {
        float xyz[3];
        std::memcpy(xyz, bytes.data() + k, 12);  // the test machine is little-endian (x86-64)
        const V p_W = poses[i] * V(xyz[0], xyz[1], xyz[2]);
        const auto hit = drive->scene.raycast(origin_W, p_W - origin_W, 100.0, params.stamp_s(i));
        ASSERT_TRUE(hit) << name << " " << file << " point " << k / 16;
        ASSERT_NEAR(hit->range_m, (p_W - origin_W).norm(), 1e-4)
            << name << " " << file << " point " << k / 16;
        ++checked;
      }
    }
    EXPECT_GT(checked, 8u * 500u) << name;
  }
}

}  // namespace
