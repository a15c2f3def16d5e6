#include "tarmac/core/tsdf_changes.hpp"

#include <cmath>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

/// A horizontal fan of rays from the origin onto vertical walls x = f(y), with space carving,
/// integrated `scans` times.
template <typename WallX>
TsdfLayer walls(WallX wall_x, int scans) {
  TsdfParams p;
  p.space_carving = true;
  TsdfIntegrator integrator(p);
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.01, 0.02, 0.03);
  std::vector<Eigen::Vector3f> pts;
  for (int a = -400; a <= 400; ++a) {
    for (int e = -20; e <= 20; ++e) {
      const double az = 20.0 * M_PI / 180.0 * a / 400.0, el = 5.0 * M_PI / 180.0 * e / 20.0;
      const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                              std::sin(el));
      // Which wall the ray meets depends on the side (y sign) it travels to.
      const double x = wall_x(d.y());
      pts.push_back((o + (x - o.x()) / d.x() * d).cast<float>());
    }
  }
  SerialRunner runner;
  for (int s = 0; s < scans; ++s) integrator.integrate(o, pts, layer, runner);
  return layer;
}

float cell_at(const ChangeMap& m, double x, double y) {
  const auto c = m.geometry.cell_of(x, y);
  EXPECT_TRUE(c.has_value());
  return m.change[static_cast<std::size_t>(c->y()) * m.geometry.width + c->x()];
}

// Prior: one wall at x = 10.02. Now: for y < 0 the wall moved back to x = 12.02 (removed at
// 10), for y > 0 a new wall stands at x = 8.02 in front of it.
TEST(TsdfChanges, MovedWalls_NewAndRemovedWithConfidence) {
  const TsdfLayer prior = walls([](double) { return 10.02; }, 4);
  const TsdfLayer now = walls([](double dy) { return dy < 0 ? 12.02 : 8.02; }, 4);
  ChangeParams params;
  params.confident_weight = 4.0f;
  ChangeMap map;
  ASSERT_TRUE(detect_changes(prior, now, params, map).ok());
  EXPECT_GT(map.new_voxels, 0u);
  EXPECT_GT(map.removed_voxels, 0u);
  EXPECT_FLOAT_EQ(cell_at(map, 10.05, -1.55), -1.0f);  // removed, full confidence
  EXPECT_FLOAT_EQ(cell_at(map, 8.05, 1.55), 1.0f);     // new
  EXPECT_EQ(cell_at(map, 5.05, -1.05), 0.0f);          // free in both: unchanged
  EXPECT_EQ(cell_at(map, 5.05, 1.05), 0.0f);
  EXPECT_TRUE(std::isnan(cell_at(map, 11.05, 1.55)));  // occluded now: unknown
  // Unchanged maps: nothing new, nothing removed.
  ChangeMap same;
  ASSERT_TRUE(detect_changes(prior, prior, params, same).ok());
  EXPECT_GT(same.compared_voxels, 10000u);
  EXPECT_EQ(same.new_voxels, 0u);
  EXPECT_EQ(same.removed_voxels, 0u);
}

TEST(TsdfChanges, Confidence_FollowsTheWeakerMap) {
  const TsdfLayer prior = walls([](double) { return 10.02; }, 2);
  const TsdfLayer now = walls([](double dy) { return dy < 0 ? 12.02 : 8.02; }, 8);
  ChangeParams params;
  params.confident_weight = 8.0f;
  ChangeMap map;
  ASSERT_TRUE(detect_changes(prior, now, params, map).ok());
  EXPECT_FLOAT_EQ(cell_at(map, 10.05, -1.55), -0.25f);  // min(2, 8) / 8
  TsdfLayer other(0.2f, 0.6f);
  EXPECT_EQ(detect_changes(prior, other, params, map).error().code, "tsdf_changes.mismatch");
}

}  // namespace
}  // namespace tarmac::core
