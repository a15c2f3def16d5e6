#include "tarmac/core/costmap_builder.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "../support/apron_scene.hpp"

namespace tarmac::core {
namespace {

TEST(Inflation, Nav2CostsAndOccupancyGridValues) {
  CostmapParams p;  // inscribed 1.0 m, inflation 3.0 m, scaling 3.0 /m
  EXPECT_EQ(nav2_cost(0.0, p), 254);
  EXPECT_EQ(nav2_cost(0.6, p), 253);
  EXPECT_EQ(nav2_cost(1.0, p), 253);
  EXPECT_EQ(nav2_cost(2.0, p), static_cast<std::uint8_t>(252.0 * std::exp(-3.0)));  // 12
  EXPECT_EQ(nav2_cost(3.01, p), 0);
  EXPECT_EQ(to_occupancy_value(254), 100);
  EXPECT_EQ(to_occupancy_value(253), 99);
  EXPECT_EQ(to_occupancy_value(0), 0);
  EXPECT_EQ(to_occupancy_value(1), 1);
  EXPECT_EQ(to_occupancy_value(12), 1 + 97 * 11 / 251);
  EXPECT_EQ(to_occupancy_value(252), 98);
}

TEST(Polygon, EvenOddContainment) {
  const std::vector<Eigen::Vector2d> square{{0, 0}, {2, 0}, {2, 2}, {0, 2}};
  EXPECT_TRUE(polygon_contains(square, {1, 1}));
  EXPECT_FALSE(polygon_contains(square, {2.5, 1}));
  const std::vector<Eigen::Vector2d> concave{{0, 0}, {4, 0}, {4, 4}, {2, 1}, {0, 4}};
  EXPECT_FALSE(polygon_contains(concave, {2, 3}));
  EXPECT_TRUE(polygon_contains(concave, {1, 1}));
}

/// A flat apron seen from a sensor 2 m up at the origin: ground points every 0.1 m within 12 m,
/// plus whatever `extra` adds.
class Envelope : public ::testing::Test {
 protected:
  Envelope() : map_(test::apron_window_params()) { map_.recenter(Eigen::Vector3d::Zero()); }

  void scan(const std::vector<Eigen::Vector3f>& extra, int times = 3) {
    test::scan_apron(map_, extra, times);
  }

  std::int8_t cost_at(double x, double y) const {
    const auto cell = layers_.costmap.geometry().cell_of(x, y);
    EXPECT_TRUE(cell.has_value());
    return layers_.costmap.at(static_cast<std::uint32_t>(cell->x()),
                              static_cast<std::uint32_t>(cell->y()));
  }

  void build(const CostmapParams& cp = {}, std::span<const VirtualZone> zones = {},
             std::int64_t stamp_ns = 0) {
    SerialRunner runner;
    build_costmap(map_, cp, Eigen::Isometry3d::Identity(), zones, stamp_ns, layers_, runner);
  }

  static void box(std::vector<Eigen::Vector3f>& pts, Eigen::Vector3f lo, Eigen::Vector3f hi) {
    test::add_box(pts, lo, hi);
  }

  OccupancyMap map_;
  CostmapLayers layers_;
};

TEST_F(Envelope, WingAboveVehicleDoesNotBlock_ConeOnGroundDoes) {
  std::vector<Eigen::Vector3f> extra;
  box(extra, {4.0f, -3.0f, 4.0f}, {8.0f, 3.0f, 4.4f});     // wing underside 4 m up
  box(extra, {-6.1f, 2.9f, 0.05f}, {-5.9f, 3.1f, 0.55f});  // cone, 0.5 m
  scan(extra);
  build();
  EXPECT_EQ(cost_at(6.0, 0.0), 0) << "the wing is above vehicle height + clearance";
  EXPECT_EQ(cost_at(-6.0, 3.0), kCostLethal) << "a 0.5 m cone blocks";
  EXPECT_EQ(cost_at(-6.0, 3.7), kCostInscribed);  // 0.7 m from the cone
  EXPECT_EQ(cost_at(9.0, -9.0), kCostFree);
  EXPECT_NEAR(layers_.ground_z_m.at(80, 80), 0.1, 1e-6);  // centre of the ground voxel [0, 0.2)
}

TEST_F(Envelope, LowStructureInsideEnvelopeBlocks) {
  std::vector<Eigen::Vector3f> extra;
  box(extra, {4.0f, -1.0f, 2.0f}, {5.0f, 1.0f, 2.2f});  // a beam at 2 m: below 2.8 m
  scan(extra);
  build();
  EXPECT_EQ(cost_at(4.5, 0.0), kCostLethal);
}

TEST_F(Envelope, UnknownPolicyAndVirtualZones) {
  scan({});
  CostmapParams cp;
  build(cp);
  EXPECT_EQ(cost_at(14.5, 14.5), kCostUnknown);  // beyond the observed 12 m square
  cp.unknown_cost = UnknownCost::kLethal;
  build(cp);
  EXPECT_EQ(cost_at(14.5, 14.5), kCostLethal);

  VirtualZone spill{"spill-1", {{2, 2}, {4, 2}, {4, 4}, {2, 4}}, -1.0, 1.0, 5'000, false};
  VirtualZone restricted{
      "stand-7", {{-15.9, -15.9}, {-2, -15.9}, {-2, -2}, {-15.9, -2}}, -5.0, 5.0, 0, true};
  const std::vector<VirtualZone> zones{spill, restricted};
  build(CostmapParams{}, zones, 1'000);
  EXPECT_EQ(cost_at(3.0, 3.0), kCostLethal);
  EXPECT_EQ(cost_at(-5.0, -5.0), kCostFree) << "observed free stays drivable in a restricted zone";
  EXPECT_EQ(cost_at(-14.5, -14.5), kCostLethal) << "unknown inside a restricted zone is lethal";
  build(CostmapParams{}, zones, 6'000);  // the spill zone expired at 5 µs
  EXPECT_EQ(cost_at(3.0, 3.0), kCostFree);

  // Vertices far outside the int range of cell indices: clamped, every cell inside lethal.
  const std::vector<VirtualZone> huge{
      {"huge", {{-1e30, -1e30}, {1e30, -1e30}, {1e30, -9.0}, {-1e30, -9.0}}}};
  build(CostmapParams{}, huge, 0);
  EXPECT_EQ(cost_at(-15.9, -15.9), kCostLethal);
  EXPECT_EQ(cost_at(15.9, -9.1), kCostLethal);
  EXPECT_EQ(cost_at(0.1, 5.0), kCostFree);
}

}  // namespace
}  // namespace tarmac::core
