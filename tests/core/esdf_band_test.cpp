#include "tarmac/core/esdf_band.hpp"

#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "../support/apron_scene.hpp"
#include "tarmac/daemon/thread_pool.hpp"

namespace tarmac::core {
namespace {

/// The apron of support/apron_scene.hpp (vehicle base at the origin, sensor 2 m up) with the
/// scene's objects.
class Band : public ::testing::Test {
 protected:
  Band() : map_(test::apron_window_params()) { map_.recenter(Eigen::Vector3d::Zero()); }

  /// The scene: a wing 3.0–3.2 m up (above vehicle height 2.5 + clearance 0.3: the costmap
  /// ignores it), a 1.5 m pole, a 10 cm debris object.
  void scan_scene() {
    std::vector<Eigen::Vector3f> points;
    test::add_box(points, {4.0f, -3.0f, 3.0f}, {8.0f, 3.0f, 3.15f});        // wing
    test::add_box(points, {-5.1f, -0.1f, 0.05f}, {-4.9f, 0.1f, 1.5f});      // pole
    test::add_box(points, {2.95f, -4.05f, 0.15f}, {3.05f, -3.95f, 0.15f});  // debris, 10 cm up
    test::scan_apron(map_, points);
  }

  /// The apron has no beam into the sky (its envelope above the sensor is never observed): the
  /// costmap's slice takes the any-voxel free rule.
  static CostmapParams costmap_params() {
    CostmapParams cp;
    cp.free_rule = FreeRule::kAnyVoxel;
    return cp;
  }

  void build(TaskRunner& runner, std::span<const VirtualZone> zones = {}, EsdfBand* out = nullptr) {
    build_costmap(map_, costmap_params(), Eigen::Isometry3d::Identity(), zones, 0, layers_, runner);
    build_esdf_band(map_, layers_, costmap_params(), band_params_, Eigen::Isometry3d::Identity(),
                    zones, 0, out != nullptr ? *out : band_, runner);
  }

  /// Band cell of a world point.
  std::size_t cell(double x, double y, double z) const {
    const Eigen::Vector3i d = band_.field.dims;
    const double v = 0.2;
    const int ix = static_cast<int>(std::floor(x / v)) - band_.min.x();
    const int iy = static_cast<int>(std::floor(y / v)) - band_.min.y();
    const int iz = static_cast<int>(std::floor(z / v)) - band_.min.z();
    EXPECT_TRUE(ix >= 0 && ix < d.x() && iy >= 0 && iy < d.y() && iz >= 0 && iz < d.z());
    return (static_cast<std::size_t>(iz) * d.y() + iy) * d.x() + ix;
  }
  float distance(double x, double y, double z) const {
    return band_.field.distance_m[cell(x, y, z)];
  }
  float slice_distance(double x, double y) const {
    const auto c = layers_.costmap.geometry().cell_of(x, y);
    return layers_.obstacle_distance
        .distance_m[static_cast<std::size_t>(c->y()) * layers_.obstacle_distance.dims.x() + c->x()];
  }

  EsdfBandParams band_params_{true, 0.2, 3.4, UnknownPolicy::kReportUnknown};
  OccupancyMap map_;
  CostmapLayers layers_;
  EsdfBand band_;
};

TEST_F(Band, LayersAroundTheBaseClippedToTheWindow) {
  int z0 = 0, z1 = 0;
  // 3.6 m of band at 0.2 m: 19 layers (one more than 18, for a base between voxel boundaries).
  EXPECT_EQ(esdf_band_max_layers(band_params_, 0.2), 19);
  // Window bottom at −3 m = layer −15: the base at 0 starts at −0.2 m = window layer 14.
  esdf_band_layers(map_, band_params_, 0.0, z0, z1);
  EXPECT_EQ(z0, 14);
  EXPECT_EQ(z1, 33);
  esdf_band_layers(map_, band_params_, 0.1, z0, z1);  // [−0.1, 3.5) needs all 19
  EXPECT_EQ(z0, 14);
  EXPECT_EQ(z1, 33);
  esdf_band_layers(map_, band_params_, 4.0, z0, z1);  // top clipped to the window's 40 layers
  EXPECT_EQ(z0, 34);
  EXPECT_EQ(z1, 40);
  esdf_band_layers(map_, band_params_, 20.0, z0, z1);  // entirely above: empty
  EXPECT_EQ(z0, z1);
}

TEST_F(Band, OverhangIsAnObstacleIn3D_GroundIsNot_DebrisIs) {
  scan_scene();
  SerialRunner runner;
  build(runner);
  ASSERT_EQ(band_.field.dims, Eigen::Vector3i(160, 160, 19));
  // Under the wing just above the roof: 2D says far (the wing is above the envelope), 3D says
  // the wing's voxel [3.0, 3.2) is 0.4 m above the voxel [2.6, 2.8).
  EXPECT_GT(slice_distance(6.1, 0.1), 3.0f);
  EXPECT_NEAR(distance(6.1, 0.1, 2.7), 0.4f, 1e-6f);
  EXPECT_EQ(distance(6.1, 0.1, 3.1), 0.0f);
  EXPECT_EQ(band_.field.gradient_z[cell(6.1, 0.1, 2.7)], -1.0f) << "pointing away from the wing";
  // The ground is not an obstacle: its voxel, far from everything, is as far as the pole (the
  // nearest obstacle), not 0.
  EXPECT_GT(distance(-9.9, -9.9, 0.1), 5.0f);
  // The pole, and the debris in the ground layer (sub-voxel rise rule).
  EXPECT_EQ(distance(-5.0, 0.0, 1.0), 0.0f);
  EXPECT_EQ(distance(3.0, -4.0, 0.1), 0.0f);
  EXPECT_NEAR(distance(3.3, -4.0, 0.1), 0.2f, 1e-6f);  // next voxel along x: one voxel away
  // Unknown (beyond the observed 12 m square, above the sensor's view) reports NaN.
  EXPECT_TRUE(std::isnan(distance(15.1, 15.1, 0.1)));
  EXPECT_GE(esdf_band_obstacles(band_), 3u);
}

TEST_F(Band, DistancesEqualBruteForceOverTheBandsObstacles) {
  scan_scene();
  SerialRunner runner;
  build(runner);
  const Eigen::Vector3i d = band_.field.dims;
  std::vector<Eigen::Vector3i> sites;
  for (int z = 0; z < d.z(); ++z)
    for (int y = 0; y < d.y(); ++y)
      for (int x = 0; x < d.x(); ++x)
        if (band_.states[(static_cast<std::size_t>(z) * d.y() + y) * d.x() + x] ==
            CellState::kOccupied)
          sites.emplace_back(x, y, z);
  ASSERT_FALSE(sites.empty());
  // Every 7th voxel (a prime stride covers all rows and layers).
  for (std::size_t i = 0; i < band_.states.size(); i += 7) {
    const int x = static_cast<int>(i % d.x()), y = static_cast<int>((i / d.x()) % d.y()),
              z = static_cast<int>(i / (static_cast<std::size_t>(d.x()) * d.y()));
    long best = std::numeric_limits<long>::max();
    for (const auto& s : sites) {
      const long dx = x - s.x(), dy = y - s.y(), dz = z - s.z();
      best = std::min(best, dx * dx + dy * dy + dz * dz);
    }
    const float expected = static_cast<float>(std::sqrt(static_cast<double>(best)) * 0.2);
    if (band_.states[i] == CellState::kUnknown) {
      EXPECT_TRUE(std::isnan(band_.field.distance_m[i]));
    } else {
      ASSERT_EQ(band_.field.distance_m[i], expected) << "voxel " << x << "," << y << "," << z;
    }
  }
}

TEST_F(Band, VirtualZonesBurnInWithinTheirHeightRange) {
  scan_scene();
  const std::vector<VirtualZone> zones{
      {"spill", {{-3, 2}, {-2, 2}, {-2, 3}, {-3, 3}}, -1.0, 0.9, 0, false},
      {"stand", {{10, 10}, {15.8, 10}, {15.8, 15.8}, {10, 15.8}}, -5.0, 5.0, 0, true}};
  SerialRunner runner;
  build(runner, zones);
  EXPECT_EQ(distance(-2.5, 2.5, 0.5), 0.0f);  // inside the no-go zone's z range
  // Voxel [1.2, 1.4): the zone's top voxel is [0.8, 1.0), two voxels below.
  EXPECT_NEAR(distance(-2.5, 2.5, 1.3), 0.4f, 1e-6f);
  // Restricted: unknown inside is an obstacle, observed (the ground voxel) stays free.
  EXPECT_EQ(distance(15.1, 15.1, 0.1), 0.0f);
  EXPECT_GT(distance(11.1, 11.1, 0.1), 0.0f);
}

TEST_F(Band, ZonesOverAllHeightsAndFarVertices) {
  scan_scene();
  // The default z range (±1e9 m) and ±inf, vertices 1e30 m away: clamped, never cast out of
  // range; every band voxel inside is an obstacle.
  VirtualZone all_heights{"all", {{-8, 6}, {-6, 6}, {-6, 8}, {-8, 8}}};
  VirtualZone everything{"huge",
                         {{-1e30, -1e30}, {1e30, -1e30}, {1e30, -9.0}, {-1e30, -9.0}},
                         -std::numeric_limits<double>::infinity(),
                         std::numeric_limits<double>::infinity()};
  const std::vector<VirtualZone> zones{all_heights, everything};
  SerialRunner runner;
  build(runner, zones);
  EXPECT_EQ(distance(-7.0, 7.0, -0.1), 0.0f);
  EXPECT_EQ(distance(-7.0, 7.0, 3.3), 0.0f);
  EXPECT_EQ(distance(-15.9, -15.9, 1.1), 0.0f);
  EXPECT_EQ(distance(15.9, -9.1, 3.3), 0.0f);
  EXPECT_NEAR(distance(0.1, -8.9, 0.1), 0.2f, 1e-6f) << "one voxel north of the huge zone";
}

TEST_F(Band, SameBitsOnOneAndTwoThreads) {
  scan_scene();
  SerialRunner serial;
  daemon::ThreadPool pool(2);
  EsdfBand a, b;
  build(serial, {}, &a);
  build(pool, {}, &b);
  ASSERT_EQ(a.field.distance_m.size(), b.field.distance_m.size());
  EXPECT_EQ(0, std::memcmp(a.field.distance_m.data(), b.field.distance_m.data(),
                           a.field.distance_m.size() * sizeof(float)));
  EXPECT_EQ(a.field.gradient_x, b.field.gradient_x);
  EXPECT_EQ(a.field.gradient_y, b.field.gradient_y);
  EXPECT_EQ(a.field.gradient_z, b.field.gradient_z);
  EXPECT_EQ(a.states, b.states);
}

}  // namespace
}  // namespace tarmac::core
