#include "tarmac/core/costmap_builder.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

#include "tarmac/core/esdf_band.hpp"

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
/// plus whatever `extra` adds. No beam goes into the sky here, so the envelope above the sensor
/// is never observed: these tests take FreeRule::kAnyVoxel (params()); the whole-envelope rule
/// has its own tests (FreeRule.*).
class Envelope : public ::testing::Test {
 protected:
  static CostmapParams params() {
    CostmapParams cp;
    cp.free_rule = FreeRule::kAnyVoxel;
    return cp;
  }

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

  /// The obstacle_rule bits of the cell at (x, y).
  std::uint8_t rule_at(double x, double y) const {
    const auto cell = layers_.costmap.geometry().cell_of(x, y);
    EXPECT_TRUE(cell.has_value());
    return layers_.obstacle_rule[static_cast<std::size_t>(cell->y()) * layers_.costmap.width() +
                                 static_cast<std::size_t>(cell->x())];
  }

  void build(const CostmapParams& cp = params(), std::span<const VirtualZone> zones = {},
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
  EXPECT_NE(rule_at(-6.0, 3.0) & obstacle_rule::kVoxel, 0) << "the cone's voxels block";
  EXPECT_EQ(rule_at(6.0, 0.0), 0) << "under the wing";
  EXPECT_EQ(rule_at(-6.0, 3.7), 0) << "inscribed, not an obstacle";
}

TEST_F(Envelope, Peers_FillWhatThisVehicleDidNotSee_InflatedLikeItsOwn_OwnNewerCellsKept) {
  constexpr std::int64_t kS = 1'000'000'000;
  const std::int64_t t_own = 100 * kS;
  map_.track_column_observations(0, 30);
  map_.set_observation_stamp(t_own);
  scan({});  // the apron within 12 m: free, observed at t_own
  // A peer's cells on the same lattice: occupied and free beyond this vehicle's 12 m, occupied
  // where this vehicle saw free later than the peer, and occupied where the peer saw it later.
  const GridGeometry2D g{-16.0, -16.0, 0.2, 160, 160};
  std::vector<BevState> state(g.cell_count(), BevState::kUnknown);
  std::vector<std::int64_t> seen(g.cell_count(), 0);
  const auto put = [&](double x, double y, BevState s, std::int64_t t) {
    const auto c = g.cell_of(x, y);
    state[c->y() * 160 + c->x()] = s;
    seen[c->y() * 160 + c->x()] = t;
  };
  put(14.1, 0.1, BevState::kOccupied, t_own);
  put(14.1, 0.7, BevState::kFree, t_own);
  put(14.1, 5.1, BevState::kFree, t_own);
  put(6.1, 6.1, BevState::kOccupied, t_own - kS);
  put(-6.1, -6.1, BevState::kOccupied, t_own + kS);
  BevEncoder peer("tug-b", 0.2);
  BevPeers peers("tug-a", 0.2, 10 * kS);
  ASSERT_TRUE(peers.apply(peer.encode({g, state, seen}, t_own + kS, true, 10 * kS), t_own + kS));
  std::vector<std::int64_t> own;
  map_.export_column_observed(own);
  CostmapPeers fleet{&peers, own, t_own + kS, {}};
  SerialRunner runner;
  build_costmap(map_, params(), Eigen::Isometry3d::Identity(), {}, 0, layers_, runner, &fleet);
  EXPECT_EQ(cost_at(14.1, 0.1), kCostLethal) << "a peer's obstacle where this vehicle saw nothing";
  EXPECT_EQ(cost_at(14.1, 0.7), kCostInscribed) << "inflated like one's own (free, 0.6 m away)";
  EXPECT_EQ(cost_at(14.1, 1.3), kCostUnknown) << "unknown to everyone";
  EXPECT_EQ(cost_at(14.1, 5.1), kCostFree);
  EXPECT_EQ(cost_at(6.1, 6.1), kCostFree) << "this vehicle's newer observation is kept";
  EXPECT_EQ(cost_at(-6.1, -6.1), kCostLethal) << "the peer's newer observation wins";
  EXPECT_EQ(rule_at(14.1, 0.1), obstacle_rule::kPeer);
  EXPECT_EQ(rule_at(-6.1, -6.1), obstacle_rule::kPeer);
  EXPECT_EQ(rule_at(6.1, 6.1), 0);
  EXPECT_EQ(fleet.counts.cells, 4u);
  EXPECT_EQ(fleet.counts.occupied, 2u);
  EXPECT_EQ(fleet.counts.cells_by_peer.at("tug-b"), 4u);
  build();  // no peers
  EXPECT_EQ(cost_at(14.1, 0.1), kCostUnknown);
  EXPECT_EQ(cost_at(-6.1, -6.1), kCostFree);
}

TEST_F(Envelope, LowStructureInsideEnvelopeBlocks) {
  std::vector<Eigen::Vector3f> extra;
  box(extra, {4.0f, -1.0f, 2.0f}, {5.0f, 1.0f, 2.2f});  // a beam at 2 m: below 2.8 m
  scan(extra);
  build();
  EXPECT_EQ(cost_at(4.5, 0.0), kCostLethal);
}

TEST_F(Envelope, LowObjectBlocks_WhateverTheFreeRuleSaysOfTheEnvelopeAbove) {
  // 10 cm debris: found from its returns' heights inside the ground voxel. The envelope above the
  // sensor is never observed here (no sky beams), so the whole-envelope rule leaves the open
  // apron unknown; the debris still reads lethal, not unknown.
  std::vector<Eigen::Vector3f> extra;
  box(extra, {2.95f, -4.05f, 0.15f}, {3.05f, -3.95f, 0.15f});
  scan(extra);
  CostmapParams cp;
  cp.free_rule = FreeRule::kWholeEnvelope;
  build(cp);
  EXPECT_EQ(cost_at(3.0, -4.0), kCostLethal);
  EXPECT_EQ(cost_at(-6.0, 6.0), kCostUnknown);
  build(params());
  EXPECT_EQ(cost_at(3.0, -4.0), kCostLethal);
  EXPECT_EQ(cost_at(-6.0, 6.0), kCostFree);
  EXPECT_NE(rule_at(3.0, -4.0) & obstacle_rule::kRise, 0) << "its voxel's latest returns rise";
  EXPECT_EQ(rule_at(3.0, -4.0) & (obstacle_rule::kVoxel | obstacle_rule::kDrop), 0);
}

TEST_F(Envelope, ALoneRisingReturnIsALethalLowObjectUntilItLapses) {
  // One return rising 10 cm over the 5 cm apron: a candidate, lethal (lethal_returns 1). Then
  // scans that return only far from it (nothing sees its spot): it lapses after
  // candidate_scans (10) scans without a second rising return.
  scan({Eigen::Vector3f(3.013f, -3.983f, 0.15f)}, 1);
  build();
  EXPECT_EQ(cost_at(3.0, -4.0), kCostLethal);
  EXPECT_NE(rule_at(3.0, -4.0) & obstacle_rule::kLowObject, 0) << "one return makes it lethal";
  std::vector<Eigen::Vector3f> far;
  for (float x = -10.0f; x <= -8.0f; x += 0.1f) {
    for (float y = -1.0f; y <= 1.0f; y += 0.1f) far.emplace_back(x + 0.013f, y + 0.017f, 0.05f);
  }
  SerialRunner runner;
  for (int i = 0; i < 9; ++i) map_.integrate(Eigen::Vector3d(0.05, 0.05, 2.0), far, {}, runner);
  build();
  EXPECT_NE(rule_at(3.0, -4.0) & obstacle_rule::kLowObject, 0) << "nine scans: still waiting";
  map_.integrate(Eigen::Vector3d(0.05, 0.05, 2.0), far, {}, runner);
  build();
  EXPECT_EQ(rule_at(3.0, -4.0) & obstacle_rule::kLowObject, 0) << "ten scans without a second";
  EXPECT_TRUE(map_.low_objects().all().empty());
}

TEST_F(Envelope, DebrisStaysLethalUntilRaysGoPastWhereItStood) {
  // 10 cm debris (returns 10 cm over the 5 cm apron) seen in one scan, then scans whose only
  // return on it lies low on its face, with the apron behind it in its shadow: the voxel's
  // latest heights are the face's (2 cm), its empty top read free by the rays over it; the
  // object keeps its evidence (LowObjects). Then the apron seen whole, rays landing behind its
  // spot under where its top was: it is gone.
  std::vector<Eigen::Vector3f> debris;
  box(debris, {2.95f, -4.05f, 0.15f}, {3.05f, -3.95f, 0.15f});
  scan(debris, 1);
  build();
  ASSERT_EQ(cost_at(3.0, -4.0), kCostLethal);
  const Eigen::Vector2f spot(3.0f, -4.0f);
  std::vector<Eigen::Vector3f> shadowed;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      const Eigen::Vector2f q(x + 0.013f, y + 0.017f);
      // The shadow: behind the spot, within 15 degrees of its bearing, up to 1 m beyond it.
      const bool behind = q.norm() > spot.norm() - 0.05f && q.norm() < spot.norm() + 1.0f &&
                          q.normalized().dot(spot.normalized()) > std::cos(0.26f);
      if (!behind) shadowed.emplace_back(q.x(), q.y(), 0.05f);
    }
  }
  shadowed.emplace_back(2.95f, -3.99f, 0.07f);  // low on its face
  SerialRunner runner;
  for (int i = 0; i < 10; ++i) {
    map_.integrate(Eigen::Vector3d(0.05, 0.05, 2.0), shadowed, {}, runner);
  }
  // Its returns' centre lies on the corner of four cells: one of them is lethal.
  const auto lethal_round = [&] {
    int n = 0;
    for (const double x : {2.9, 3.1}) {
      for (const double y : {-4.1, -3.9}) n += cost_at(x, y) == kCostLethal ? 1 : 0;
    }
    return n;
  };
  build();
  EXPECT_GE(lethal_round(), 1) << "nothing went past it";
  // The cell of the face's return: its voxel's latest heights (2 cm) no longer rise, and the
  // kept object alone holds it. Its neighbours, which nothing returned from since, still rise.
  EXPECT_EQ(rule_at(2.95, -3.99), obstacle_rule::kLowObject);
  for (const double x : {2.9, 3.1}) {
    for (const double y : {-4.1, -3.9}) {
      if (cost_at(x, y) != kCostLethal) continue;
      EXPECT_NE(rule_at(x, y) & (obstacle_rule::kRise | obstacle_rule::kLowObject), 0);
      EXPECT_EQ(rule_at(x, y) & (obstacle_rule::kVoxel | obstacle_rule::kDrop), 0);
    }
  }
  // The 3D band agrees with the slice: the lethal cell's column holds an occupied voxel, though
  // the voxel's own heights (the face's 2 cm) no longer rise.
  EsdfBandParams bp;
  bp.enabled = true;
  EsdfBand band;
  build_esdf_band(map_, layers_, params(), bp, Eigen::Isometry3d::Identity(), {}, 0, band, runner);
  const GridGeometry2D& g = layers_.costmap.geometry();
  int lethal_columns = 0, in_band = 0;
  for (const double x : {2.9, 3.1}) {
    for (const double y : {-4.1, -3.9}) {
      if (cost_at(x, y) != kCostLethal) continue;
      ++lethal_columns;
      const auto cell = g.cell_of(x, y);
      const std::size_t plane = g.cell_count();
      for (int lz = 0; lz < band.field.dims.z(); ++lz) {
        const std::size_t i =
            lz * plane + static_cast<std::size_t>(cell->y()) * g.width + cell->x();
        if (band.states[i] == CellState::kOccupied) {
          ++in_band;
          break;
        }
      }
    }
  }
  EXPECT_GE(lethal_columns, 1);
  EXPECT_EQ(in_band, lethal_columns) << "every lethal cell of the debris is in the band";
  // The apron whole, with the beams through where it stood, 2 to 6 cm over the apron, landing
  // on it behind the spot.
  ASSERT_EQ(map_.low_objects().all().size(), 1u);
  const Eigen::Vector2f c = map_.low_objects().all()[0].xy_W;
  const Eigen::Vector3f origin(0.05f, 0.05f, 2.0f);
  std::vector<Eigen::Vector3f> past;
  for (const float h : {0.07f, 0.09f, 0.11f}) {
    const Eigen::Vector3f over(c.x(), c.y(), h);
    past.push_back(origin + (origin.z() - 0.05f) / (origin.z() - h) * (over - origin));
  }
  scan(past, 1);
  build();
  EXPECT_GE(lethal_round(), 1) << "one scan of rays past it is not enough";
  scan(past, 1);
  build();
  EXPECT_EQ(lethal_round(), 0) << "two scans of rays past where it stood";
  EXPECT_EQ(cost_at(3.0, -4.0), kCostFree);
  EXPECT_TRUE(map_.low_objects().all().empty());
}

// Windows of more than 64 layers classify columns layer by layer, the others with per-column
// bit sets (costmap/columns.cpp): on the same scene, all of it well inside both windows, the two
// give the same ground, classes and costs, under both free rules.
TEST(ColumnClasses, TallWindowLayerByLayerEqualsTheBitSets) {
  for (const FreeRule rule : {FreeRule::kAnyVoxel, FreeRule::kWholeEnvelope}) {
    std::vector<CostmapLayers> layers;
    for (const int nz : {40, 70}) {
      OccupancyParams p = test::apron_window_params();
      p.window_z_vox = nz;
      OccupancyMap map(p);
      map.recenter(Eigen::Vector3d::Zero());
      std::vector<Eigen::Vector3f> extra;
      test::add_box(extra, {4.0f, -3.0f, 4.0f}, {8.0f, 3.0f, 4.4f});         // wing, 4 m up
      test::add_box(extra, {-6.1f, 2.9f, 0.05f}, {-5.9f, 3.1f, 0.55f});      // cone
      test::add_box(extra, {2.95f, -4.05f, 0.15f}, {3.05f, -3.95f, 0.15f});  // debris
      test::add_box(extra, {4.0f, -1.0f, 2.0f}, {5.0f, 1.0f, 2.2f});         // beam at 2 m
      test::scan_apron(map, extra, 3);
      CostmapParams cp;
      cp.free_rule = rule;
      SerialRunner runner;
      layers.emplace_back();
      build_costmap(map, cp, Eigen::Isometry3d::Identity(), {}, 0, layers.back(), runner);
    }
    EXPECT_EQ(layers[0].ground_z_m.cells(), layers[1].ground_z_m.cells());
    EXPECT_EQ(layers[0].column_class.cells(), layers[1].column_class.cells());
    EXPECT_EQ(layers[0].costmap.cells(), layers[1].costmap.cells());
    EXPECT_EQ(layers[0].obstacle_rule, layers[1].obstacle_rule);
    EXPECT_GT(
        std::count(layers[1].costmap.cells().begin(), layers[1].costmap.cells().end(), kCostLethal),
        0);
  }
}

TEST_F(Envelope, UnknownPolicyAndVirtualZones) {
  scan({});
  CostmapParams cp = params();
  build(cp);
  EXPECT_EQ(cost_at(14.5, 14.5), kCostUnknown);  // beyond the observed 12 m square
  cp.unknown_cost = UnknownCost::kLethal;
  build(cp);
  EXPECT_EQ(cost_at(14.5, 14.5), kCostLethal);

  VirtualZone spill{"spill-1", {{2, 2}, {4, 2}, {4, 4}, {2, 4}}, -1.0, 1.0, 5'000, false};
  VirtualZone restricted{
      "stand-7", {{-15.9, -15.9}, {-2, -15.9}, {-2, -2}, {-15.9, -2}}, -5.0, 5.0, 0, true};
  const std::vector<VirtualZone> zones{spill, restricted};
  build(params(), zones, 1'000);
  EXPECT_EQ(cost_at(3.0, 3.0), kCostLethal);
  EXPECT_EQ(cost_at(-5.0, -5.0), kCostFree) << "observed free stays drivable in a restricted zone";
  EXPECT_EQ(cost_at(-14.5, -14.5), kCostLethal) << "unknown inside a restricted zone is lethal";
  build(params(), zones, 6'000);  // the spill zone expired at 5 µs
  EXPECT_EQ(cost_at(3.0, 3.0), kCostFree);

  // Vertices far outside the int range of cell indices: clamped, every cell inside lethal.
  const std::vector<VirtualZone> huge{
      {"huge", {{-1e30, -1e30}, {1e30, -1e30}, {1e30, -9.0}, {-1e30, -9.0}}}};
  build(params(), huge, 0);
  EXPECT_EQ(cost_at(-15.9, -15.9), kCostLethal);
  EXPECT_EQ(cost_at(15.9, -9.1), kCostLethal);
  EXPECT_EQ(cost_at(0.1, 5.0), kCostFree);
}

/// The free-space rule on an apron seen as a spinning LiDAR 2 m up sees it: ground returns out to
/// 30 m (rays to far ground observe the layers just below the sensor near it) and beams without
/// return into the sky, aimed at every voxel above the sensor within 4 m and up to 3.5 m. An
/// overhang 2.2–2.6 m up over [1.5, 2.5] x [-2.5, -1.5] that no return came from (a black
/// underside) stops the sky beams that would cross it: its voxels stay unknown.
class FreeRuleApron : public ::testing::Test {
 protected:
  FreeRuleApron() : map_(test::apron_window_params()) {
    map_.recenter(Eigen::Vector3d::Zero());
    const Eigen::Vector3f origin(0.05f, 0.05f, 2.0f);
    std::vector<Eigen::Vector3f> ground;
    for (int a = 0; a < 720; ++a) {
      const float az = static_cast<float>(a) * 0.5f * std::numbers::pi_v<float> / 180.0f;
      for (float r = 0.5f; r <= 30.0f; r += 0.2f)
        ground.emplace_back(r * std::cos(az) + 0.05f, r * std::sin(az) + 0.05f, 0.05f);
    }
    const Eigen::AlignedBox3f overhang(Eigen::Vector3f(1.5f, -2.5f, 2.2f),
                                       Eigen::Vector3f(2.5f, -1.5f, 2.6f));
    std::vector<Eigen::Vector3f> sky;
    for (float x = -4.1f; x <= 4.1f; x += 0.2f) {
      for (float y = -4.1f; y <= 4.1f; y += 0.2f) {
        for (float z = 2.1f; z <= 3.5f; z += 0.2f) {
          const Eigen::Vector3f d = (Eigen::Vector3f(x, y, z) - origin).normalized();
          if (!crosses(overhang, origin, d)) sky.push_back(d);
        }
      }
    }
    SerialRunner runner;
    for (int i = 0; i < 3; ++i) map_.integrate(origin.cast<double>(), ground, sky, runner);
  }

  /// The ray origin + t·d, t in [0, 30 m], meets the box.
  static bool crosses(const Eigen::AlignedBox3f& box, const Eigen::Vector3f& o,
                      const Eigen::Vector3f& d) {
    float t0 = 0.0f;
    float t1 = 30.0f;
    for (int a = 0; a < 3; ++a) {
      if (d[a] == 0.0f) {
        if (o[a] < box.min()[a] || o[a] > box.max()[a]) return false;
        continue;
      }
      float ta = (box.min()[a] - o[a]) / d[a];
      float tb = (box.max()[a] - o[a]) / d[a];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    return t0 <= t1;
  }

  std::int8_t cost_at(FreeRule rule, double x, double y) {
    CostmapParams cp;
    cp.free_rule = rule;
    SerialRunner runner;
    build_costmap(map_, cp, Eigen::Isometry3d::Identity(), {}, 0, layers_, runner);
    const auto cell = layers_.costmap.geometry().cell_of(x, y);
    EXPECT_TRUE(cell.has_value());
    return layers_.costmap.at(static_cast<std::uint32_t>(cell->x()),
                              static_cast<std::uint32_t>(cell->y()));
  }

  OccupancyMap map_;
  CostmapLayers layers_;
};

TEST_F(FreeRuleApron, WholeEnvelopeObserved_Free) {
  EXPECT_EQ(cost_at(FreeRule::kWholeEnvelope, 2.5, 1.5), kCostFree);
  EXPECT_EQ(cost_at(FreeRule::kWholeEnvelope, -3.0, -1.0), kCostFree);
}

TEST_F(FreeRuleApron, UnseenOverhangInTheEnvelope_UnknownNotFree) {
  // Rays under the overhang observed its column's lower voxels: free by the any-voxel rule,
  // which is the failure the whole-envelope rule exists for.
  EXPECT_EQ(cost_at(FreeRule::kAnyVoxel, 2.0, -2.0), kCostFree);
  EXPECT_EQ(cost_at(FreeRule::kWholeEnvelope, 2.0, -2.0), kCostUnknown);
}

TEST_F(FreeRuleApron, EnvelopeAboveTheSensorNeverObserved_Unknown) {
  // Beyond 4 m no sky beam was aimed: the envelope's top layers there are unknown.
  EXPECT_EQ(cost_at(FreeRule::kWholeEnvelope, 9.0, 0.0), kCostUnknown);
  EXPECT_EQ(cost_at(FreeRule::kAnyVoxel, 9.0, 0.0), kCostFree);
}

/// Nav2's StaticLayer reading of one OccupancyGrid value (nav2_costmap_2d, StaticLayer::
/// interpretValue), with the parameters a user sets: the model docs/ros2.md's table is checked
/// against. `inscribed_param`: Nav2 releases with `inscribed_obstacle_cost_value` (default 99)
/// map that value to 253; older ones (Humble) have no such parameter (pass -1).
int nav2_static_layer(std::int8_t value, bool track_unknown_space, bool trinary_costmap,
                      int inscribed_param = 99) {
  const auto v = static_cast<unsigned char>(value);  // Nav2 reads the int8 as unsigned char
  constexpr int kLethalThreshold = 100, kUnknownCostValue = 255;
  if (v == kUnknownCostValue) return track_unknown_space ? 255 : 0;
  if (inscribed_param >= 0 && v == inscribed_param) return 253;
  if (v >= kLethalThreshold) return 254;
  if (trinary_costmap) return 0;
  return static_cast<unsigned char>(static_cast<double>(v) / kLethalThreshold * 254);
}

/// The costmap of `points` seen three times from a sensor 2 m up at the origin (the apron's
/// window), under the any-voxel rule (nothing above the sensor is seen here).
CostmapLayers terrain_costmap(const std::vector<Eigen::Vector3f>& points) {
  OccupancyMap map(test::apron_window_params());
  map.recenter(Eigen::Vector3d::Zero());
  SerialRunner runner;
  for (int i = 0; i < 3; ++i) map.integrate(Eigen::Vector3d(0.05, 0.05, 2.0), points, {}, runner);
  CostmapParams cp;
  cp.free_rule = FreeRule::kAnyVoxel;
  CostmapLayers layers;
  build_costmap(map, cp, Eigen::Isometry3d::Identity(), {}, 0, layers, runner);
  return layers;
}

std::size_t lethal_cells(const CostmapLayers& layers) {
  std::size_t lethal = 0;
  for (std::uint32_t y = 0; y < layers.costmap.height(); ++y) {
    for (std::uint32_t x = 0; x < layers.costmap.width(); ++x) {
      lethal += layers.costmap.at(x, y) == kCostLethal ? 1 : 0;
    }
  }
  return lethal;
}

TEST(Terrain, GradesBothWaysAreGround_ObjectOnTheGradeBlocks) {
  // The vehicle on a flat 4 m wide strip at the origin; beyond x = 2 the ground climbs at 15 %
  // (1.5 m above the wheels' plane at x = 12), beyond x = −2 it falls at 15 %: both leave any
  // cone of slope round the vehicle's plane. A 0.5 m cone stands on the climb at (8, 3). The
  // sensor is 2 m up at the origin.
  const auto height = [](float x) {
    return x > 2.0f ? 0.15f * (x - 2.0f) : (x < -2.0f ? -0.15f * (-2.0f - x) : 0.0f);
  };
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      points.emplace_back(x + 0.013f, y + 0.017f, height(x + 0.013f) + 0.05f);
    }
  }
  test::add_box(points, {7.9f, 2.9f, height(7.9f) + 0.05f}, {8.1f, 3.1f, height(8.1f) + 0.55f});
  const CostmapLayers layers = terrain_costmap(points);
  const auto cost_at = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return layers.costmap.at(static_cast<std::uint32_t>(cell->x()),
                             static_cast<std::uint32_t>(cell->y()));
  };
  EXPECT_EQ(cost_at(8.0, 3.0), kCostLethal) << "the cone on the grade blocks";
  std::size_t ground = 0, lethal = 0;
  std::string first;
  for (double x = -11.0; x <= 11.0; x += 0.2) {
    for (double y = -11.0; y <= 11.0; y += 0.2) {
      if (std::hypot(x - 8.0, y - 3.0) < 1.5) continue;  // the cone and its inflation
      ++ground;
      if (cost_at(x, y) == kCostLethal) {
        ++lethal;
        if (first.empty()) first = std::to_string(x) + ", " + std::to_string(y);
      }
    }
  }
  EXPECT_EQ(lethal, 0u) << "of " << ground << " ground cells; the first at " << first;
  const auto ground_z = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return layers.ground_z_m.at(static_cast<std::uint32_t>(cell->x()),
                                static_cast<std::uint32_t>(cell->y()));
  };
  EXPECT_NEAR(ground_z(10.0, -5.0), 1.3, 0.2) << "the ground follows the climb";
  EXPECT_NEAR(ground_z(-10.0, 5.0), -1.1, 0.2) << "and the fall";
  EXPECT_NEAR(ground_z(0.5, 0.5), 0.1, 1e-6);
}

TEST(Terrain, TheGroundSpreadsAcrossTheEmptyCellsBetweenFarRings) {
  // A 15 % climb beyond x = 2 seen only in rings 3 m apart beyond x = 4 (far from a sensor the
  // beams' rings leave empty ground cells between them): the spread crosses the gaps, and the
  // rings on the climb are ground, not a row of walls.
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    const float fx = x + 0.013f;
    if (fx > 4.0f && std::fmod(fx, 3.0f) > 0.6f) continue;  // the gaps between rings
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      points.emplace_back(fx, y + 0.017f, (fx > 2.0f ? 0.15f * (fx - 2.0f) : 0.0f) + 0.05f);
    }
  }
  const CostmapLayers layers = terrain_costmap(points);
  EXPECT_EQ(lethal_cells(layers), 0u);
}

TEST(Terrain, ARampGoingDownSeenInRingsFarApartIsGround) {
  // A 12 % ramp down beyond x = 2 seen only in rings 7 m apart, as a far sensor's rings fall on
  // a surface falling away: 6 empty cells between the rings at x = 4 and 11, the second 0.84 m
  // lower. The spread crosses them at the ramp's grade; else the far ring would lie more than
  // max_ground_step_m under the ground carried from the near one and read as a drop.
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    const float fx = x + 0.013f;
    if (fx > 3.0f && std::fmod(fx + 3.0f, 7.0f) > 0.6f) continue;  // rings at 4, 11
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      points.emplace_back(fx, y + 0.017f, (fx > 2.0f ? -0.12f * (fx - 2.0f) : 0.0f) + 0.05f);
    }
  }
  const CostmapLayers layers = terrain_costmap(points);
  EXPECT_EQ(lethal_cells(layers), 0u);
}

TEST(Terrain, AStepAboveMaxGroundStepIsNoGround_ItsTopBlocks) {
  // A loading dock 1.2 m high (a solid block from x = 5 to 11), its top seen: the climb onto it
  // is a step of 1.2 m, more than max_ground_step_m (0.5), so its top is not ground and blocks.
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      const bool dock = x >= 5.0f && x <= 11.0f && y >= -3.0f && y <= 3.0f;
      points.emplace_back(x + 0.013f, y + 0.017f, dock ? 1.25f : 0.05f);
    }
  }
  const CostmapLayers layers = terrain_costmap(points);
  const auto cell = layers.costmap.geometry().cell_of(8.0, 0.0);
  EXPECT_EQ(layers.costmap.at(static_cast<std::uint32_t>(cell->x()),
                              static_cast<std::uint32_t>(cell->y())),
            kCostLethal);
  EXPECT_LT(layers.ground_z_m.at(static_cast<std::uint32_t>(cell->x()),
                                 static_cast<std::uint32_t>(cell->y())),
            0.7)
      << "the dock's top is not its ground";
}

TEST(Terrain, ADropBeyondMaxGroundStepIsAHazard_TheGroundBeforeItIsNot) {
  // The vehicle on a dock: beyond x = 5 the ground falls away 1.2 m to the road below (no slope
  // joins them), and a pit 1 m deep, 2 m square, lies at (−6, 0). Only what the sensor (2 m up
  // at the origin) sees is returned: the road from x = 8 on (the dock's edge hides the rest), the
  // pit's far wall. The rays into both pass more than max_ground_step_m (0.5) below the ground:
  // a vehicle that drove on would fall, and those cells read lethal; the dock's top is ground.
  const auto height = [](float x, float y) {
    if (x > 5.0f) return -1.2f;
    return std::abs(x + 6.0f) < 1.0f && std::abs(y) < 1.0f ? -1.0f : 0.0f;
  };
  const Eigen::Vector3f sensor(0.05f, 0.05f, 2.0f);
  const auto visible = [&](const Eigen::Vector3f& p) {
    const int steps = static_cast<int>((p - sensor).head<2>().norm() / 0.05f);
    for (int k = 1; k < steps; ++k) {
      const Eigen::Vector3f q = sensor + (p - sensor) * (static_cast<float>(k) / steps);
      if (q.z() < height(q.x(), q.y()) - 1e-3f) return false;
    }
    return true;
  };
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      const Eigen::Vector3f p(x + 0.013f, y + 0.017f, 0.0f);
      const Eigen::Vector3f ground(p.x(), p.y(), height(p.x(), p.y()) + 0.05f);
      if (visible(ground)) points.push_back(ground);
    }
  }
  for (float y = -1.0f; y <= 1.0f; y += 0.1f) {  // the pit's far wall faces the sensor
    for (float z = -0.95f; z <= 0.0f; z += 0.1f) {
      const Eigen::Vector3f wall(-6.98f, y + 0.017f, z);
      if (visible(wall)) points.push_back(wall);
    }
  }
  const CostmapLayers layers = terrain_costmap(points);
  const auto cost_at = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return layers.costmap.at(static_cast<std::uint32_t>(cell->x()),
                             static_cast<std::uint32_t>(cell->y()));
  };
  const auto rule_at = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return layers.obstacle_rule[static_cast<std::size_t>(cell->y()) * layers.costmap.width() +
                                static_cast<std::size_t>(cell->x())];
  };
  for (const double y : {-8.0, -3.0, 0.0, 4.0, 8.0}) {
    EXPECT_EQ(cost_at(6.9, y), kCostLethal) << "over the road below the edge, y = " << y;
    EXPECT_EQ(rule_at(6.9, y), obstacle_rule::kDrop) << "y = " << y;
    EXPECT_EQ(cost_at(9.0, y), kCostLethal) << "the road below, y = " << y;
    EXPECT_NE(cost_at(4.5, y), kCostLethal) << "the dock's top before its edge, y = " << y;
  }
  EXPECT_EQ(cost_at(-6.7, 0.0), kCostLethal) << "the pit";
  EXPECT_EQ(rule_at(-6.7, 0.0), obstacle_rule::kDrop);
  EXPECT_NE(cost_at(-6.0, 3.0), kCostLethal) << "the ground beside it";
}

TEST(Terrain, AStrayReturnBelowTheFloorLiftsNothingIntoAnObstacle) {
  // A glossy floor returns the odd point well below itself (a reflection, a mixed pixel): the
  // floor round it must not rise above that point into a ring of low objects. Real floors did
  // this (balm_hall: a few strays a scan, 5–30 cm under the floor); a 10 cm box still blocks.
  std::vector<Eigen::Vector3f> points;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f) {
      points.emplace_back(x + 0.013f, y + 0.017f, 0.05f);
    }
  }
  points.emplace_back(4.01f, 0.01f, -0.2f);
  points.emplace_back(-3.01f, 5.01f, -0.15f);
  test::add_box(points, {6.9f, -3.1f, 0.05f}, {7.1f, -2.9f, 0.15f});
  const CostmapLayers layers = terrain_costmap(points);
  const auto cost_at = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return layers.costmap.at(static_cast<std::uint32_t>(cell->x()),
                             static_cast<std::uint32_t>(cell->y()));
  };
  EXPECT_EQ(cost_at(7.0, -3.0), kCostLethal) << "the box";
  for (double dx = -0.4; dx <= 0.41; dx += 0.2) {
    for (double dy = -0.4; dy <= 0.41; dy += 0.2) {
      EXPECT_NE(cost_at(4.0 + dx, dy), kCostLethal) << dx << ", " << dy;
      EXPECT_NE(cost_at(-3.0 + dx, 5.0 + dy), kCostLethal) << dx << ", " << dy;
    }
  }
}

TEST(Terrain, AGlossyFloorsMirrorImagesMakeNeitherADropNorALowerGround) {
  // A glossy floor (balm_hall's) reflects part of the beams that reach it: the sensor reports
  // the object the reflected beam hit along the beam's own direction, below the floor, and the
  // beam "passes" through the floor to it. Here returns 1.1 m apart in a 3 x 2 m patch have
  // such an image 2 m further on, down to 0.7 m under the floor: more than max_ground_step_m
  // (0.5), as deep as a pit (balm_hall's lie up to 3 m under its floor). The floor returned there
  // in every scan and holds the vehicle: not a drop, and its ground is the floor, not the images'
  // depth. (Terrain.ADropBeyondMaxGroundStep... keeps the pit and the dock edge, which return
  // nothing at the floor's height, as drops.)
  const Eigen::Vector3f sensor(0.05f, 0.05f, 2.0f);
  const auto in_patch = [](const Eigen::Vector3f& p) {
    return p.x() > 3.0f && p.x() < 6.0f && p.y() > -4.0f && p.y() < -2.0f;
  };
  std::vector<Eigen::Vector3f> points;
  std::size_t images = 0;
  for (int ix = -120; ix <= 120; ++ix) {
    for (int iy = -120; iy <= 120; ++iy) {
      const Eigen::Vector3f p(0.1f * ix + 0.013f, 0.1f * iy + 0.017f, 0.05f);
      points.push_back(p);
      if (in_patch(p) && ix % 11 == 0 && iy % 11 == 0) {
        points.push_back(p + 2.0f * (p - sensor).normalized());
        ++images;
      }
    }
  }
  ASSERT_GE(images, 4u);
  const CostmapLayers layers = terrain_costmap(points);
  const auto cell_of = [&](double x, double y) {
    const auto cell = layers.costmap.geometry().cell_of(x, y);
    return std::pair{static_cast<std::uint32_t>(cell->x()), static_cast<std::uint32_t>(cell->y())};
  };
  std::size_t lethal = 0, low = 0, cells = 0;
  for (double x = 3.1; x < 7.5; x += 0.2) {  // the patch and where its images' rays go
    for (double y = -5.1; y < -2.05; y += 0.2) {
      const auto [cx, cy] = cell_of(x, y);
      ++cells;
      lethal += layers.costmap.at(cx, cy) == kCostLethal ? 1 : 0;
      low += layers.ground_z_m.at(cx, cy) < -0.1f ? 1 : 0;
    }
  }
  EXPECT_EQ(lethal, 0u) << "of " << cells << " cells";
  EXPECT_EQ(low, 0u) << "of " << cells << " cells have a ground under the floor";
}

TEST(DistanceDisplay, ShadesDistanceLinearly_UnknownStaysUnknown) {
  DistanceField field;
  field.dims = {6, 1, 1};
  field.cell_size_m = 0.5;
  const float inf = std::numeric_limits<float>::infinity();
  field.distance_m = {0.0f, 2.5f, 5.0f, 7.0f, inf, std::numeric_limits<float>::quiet_NaN()};
  GridGeometry2D geometry;
  geometry.width = 6;
  geometry.height = 1;
  geometry.resolution_m = 0.5;
  Costmap grid;
  to_distance_display(field, geometry, 5.0, grid);
  ASSERT_EQ(grid.cells().size(), 6u);
  const std::vector<std::int8_t> want{100, 50, 0, 0, 0, -1};
  EXPECT_EQ(grid.cells(), want);
}

TEST(Nav2Translation, TableOfTheReadme) {
  // The values docs/ros2.md's "Nav2" table states, with the settings it gives.
  EXPECT_EQ(nav2_static_layer(kCostLethal, true, false), 254);
  EXPECT_EQ(nav2_static_layer(kCostInscribed, true, false), 253);
  EXPECT_EQ(nav2_static_layer(kCostInscribed, true, false, -1), 251);  // Humble: scaled
  EXPECT_EQ(nav2_static_layer(kCostUnknown, true, false), 255);
  EXPECT_EQ(nav2_static_layer(kCostFree, true, false), 0);
  EXPECT_EQ(nav2_static_layer(50, true, false), 127);
  for (int v = 1; v <= 98; ++v) {
    const int cost = nav2_static_layer(static_cast<std::int8_t>(v), true, false);
    EXPECT_GE(cost, 1) << v;
    EXPECT_LE(cost, 252) << v << ": an inflated cost must stay below Nav2's inscribed 253";
  }
  // Nav2's defaults are the danger the README and docs/ros2.md warn of: inflation and unknown
  // read free.
  EXPECT_EQ(nav2_static_layer(50, false, true), 0);
  EXPECT_EQ(nav2_static_layer(kCostUnknown, false, true), 0);
}

TEST_F(Envelope, Nav2ReadsEveryClassOfCellRight_CostmapAndObstacleGrid) {
  std::vector<Eigen::Vector3f> extra;
  box(extra, {-6.1f, 2.9f, 0.05f}, {-5.9f, 3.1f, 0.55f});  // cone, 0.5 m
  scan(extra);
  const std::vector<VirtualZone> zones{
      {"spill", {{2, 2}, {4, 2}, {4, 4}, {2, 4}}, -1.0, 1.0, 0, false},
      {"stand", {{-15.9, -15.9}, {-2, -15.9}, {-2, -2}, {-15.9, -2}}, -5.0, 5.0, 0, true}};
  build(params(), zones, 0);
  Costmap grid;
  to_obstacle_grid(layers_.costmap, grid);
  ASSERT_EQ(grid.width(), layers_.costmap.width());
  ASSERT_EQ(grid.height(), layers_.costmap.height());
  EXPECT_EQ(grid.geometry().origin_x_m, layers_.costmap.geometry().origin_x_m);

  const auto nav2 = [](std::int8_t v) { return nav2_static_layer(v, true, false); };
  const auto grid_at = [&](double x, double y) {
    const auto cell = grid.geometry().cell_of(x, y);
    return grid.at(static_cast<std::uint32_t>(cell->x()), static_cast<std::uint32_t>(cell->y()));
  };
  struct Case {
    const char* what;
    double x, y;
    int costmap_nav2, grid_nav2;
  };
  const Case cases[] = {
      {"obstacle (cone)", -6.0, 3.0, 254, 254},
      {"inscribed, 0.7 m from the cone", -6.0, 3.7, 253, 0},
      {"no-go zone", 3.0, 3.0, 254, 254},
      {"unknown, beyond the observed square", 14.5, 14.5, 255, 255},
      {"unknown inside a restricted zone", -14.5, -14.5, 254, 254},
      {"observed free inside a restricted zone", -5.0, -5.0, 0, 0},
      {"free, far from everything", 9.0, -9.0, 0, 0},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(nav2(cost_at(c.x, c.y)), c.costmap_nav2) << c.what;
    EXPECT_EQ(nav2(grid_at(c.x, c.y)), c.grid_nav2) << c.what;
  }
  // An inflated cell (1..98) reads as an inflated cost in Nav2 (1..252), and free in the grid.
  bool inflated_seen = false;
  const auto& cells = layers_.costmap.cells();
  for (std::size_t i = 0; i < cells.size(); ++i) {
    const std::int8_t v = cells[i];
    const std::int8_t g = grid.cells()[i];
    if (v >= 1 && v <= 98) {
      inflated_seen = true;
      EXPECT_GE(nav2(v), 1);
      EXPECT_LE(nav2(v), 252);
    }
    // The grid has lethal/free/unknown only, and exactly where the costmap is lethal/unknown.
    EXPECT_TRUE(g == kCostLethal || g == kCostFree || g == kCostUnknown) << int{g};
    EXPECT_EQ(g == kCostLethal, v == kCostLethal) << i;
    EXPECT_EQ(g == kCostUnknown, v == kCostUnknown) << i;
  }
  EXPECT_TRUE(inflated_seen);
}

}  // namespace
}  // namespace tarmac::core
