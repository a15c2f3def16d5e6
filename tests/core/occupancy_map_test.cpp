#include "tarmac/core/occupancy_map.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <tuple>

#include <gtest/gtest.h>

#include "tarmac/daemon/thread_pool.hpp"

#include "../support/apron_scene.hpp"
#include "occupancy_test_util.hpp"

namespace tarmac::core {
namespace {

using namespace occupancy_test;  // NOLINT(google-build-using-namespace): the tests' own helpers

/// Returns every 0.1 m over x in [2, 4], y in [y0, y1), at height z.
void add_patch(std::vector<Eigen::Vector3f>& points, float y0, float y1, float z) {
  for (float x = 2.0f; x <= 4.0f; x += 0.1f) {
    for (float y = y0; y < y1; y += 0.1f) points.emplace_back(x + 0.013f, y + 0.017f, z);
  }
}

/// The confirmed low objects whose centre lies south of y_max.
std::size_t confirmed_low_objects(const OccupancyMap& map, float y_max = 100.0f) {
  const LowObjects& objects = map.low_objects();
  return static_cast<std::size_t>(std::count_if(
      objects.all().begin(), objects.all().end(),
      [&](const LowObject& o) { return objects.confirmed(o) && o.xy_W.y() < y_max; }));
}

TEST(OccupancyMap, LowObjects_TheFloorFoundAtTheirTopRemovesThem_AKerbsTopAloneDoesNot) {
  const Eigen::Vector3d origin(0.05, 0.05, 2.0);
  SerialRunner runner;
  // A floor at 5 cm that one scan also returned twice under itself (a glossy floor's mirror
  // images, 4 cm apart in depth: the scan's ground round them lies 10 cm low, and is not
  // remembered). The floor round them rises 10 cm: low objects. The next two scans return
  // from the floor alone, where their tops are: they are gone.
  {
    OccupancyMap map(test::apron_window_params());
    map.recenter(Eigen::Vector3d::Zero());
    std::vector<Eigen::Vector3f> floor;
    add_patch(floor, -5.0f, -3.0f, 0.05f);
    std::vector<Eigen::Vector3f> mirrored = floor;
    mirrored.emplace_back(3.013f, -3.983f, -0.05f);
    mirrored.emplace_back(3.113f, -3.983f, -0.09f);
    map.integrate(origin, mirrored, {}, runner);
    ASSERT_GT(confirmed_low_objects(map), 0u);
    map.integrate(origin, floor, {}, runner);
    EXPECT_GT(confirmed_low_objects(map), 0u) << "one scan is not enough (clear_scans 2)";
    map.integrate(origin, floor, {}, runner);
    EXPECT_EQ(confirmed_low_objects(map), 0u) << "two scans found the floor at their tops";
  }
  // A 15 cm kerb at y = -4 seen with its road, then from where its road is not returned: the
  // kerb's top lies on those scans' ground, but the road is remembered beside its edge, and
  // the objects there stay. (Those further up the top rose only because the road lay within
  // ground_radius_m of them; scans of the top alone overwrite the memory under them.)
  {
    OccupancyMap map(test::apron_window_params());
    map.recenter(Eigen::Vector3d::Zero());
    std::vector<Eigen::Vector3f> kerb, top_only;
    add_patch(kerb, -5.0f, -4.0f, 0.05f);
    add_patch(kerb, -4.0f, -3.0f, 0.20f);
    add_patch(top_only, -4.0f, -3.0f, 0.20f);
    map.integrate(origin, kerb, {}, runner);
    const std::size_t edge = confirmed_low_objects(map, -3.8f);
    ASSERT_GT(edge, 0u);
    for (int i = 0; i < 5; ++i) map.integrate(origin, top_only, {}, runner);
    EXPECT_EQ(confirmed_low_objects(map, -3.8f), edge) << "the kerb's road is remembered";
  }
}

TEST(OccupancyMap, LogOddsArithmeticAndClamping) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  const Scan scan{Eigen::Vector3d(0.1, 0.1, 0.1), {Eigen::Vector3f(3.1f, 0.1f, 0.1f)}, {}};
  const VoxelIndex hit = map.voxel_of(Eigen::Vector3d(3.1, 0.1, 0.1));
  const VoxelIndex free = map.voxel_of(Eigen::Vector3d(1.5, 0.1, 0.1));
  EXPECT_EQ(map.log_odds(hit), OccupancyMap::kUnknown);
  float expected = 0.0f;
  for (int i = 0; i < 10; ++i) {
    integrate(map, scan);
    expected = std::min(expected + std::log(0.7f / 0.3f), std::log(0.85f / 0.15f));
    EXPECT_FLOAT_EQ(map.log_odds(hit), expected) << i;
  }
  EXPECT_FLOAT_EQ(map.log_odds(hit), map.max_log_odds());
  EXPECT_FLOAT_EQ(map.log_odds(free), map.min_log_odds());  // 0.4 clamps at 0.12 after 5 misses
  EXPECT_NEAR(probability_of(map.min_log_odds()), 0.12f, 1e-6);
}

TEST(OccupancyMap, OncePerScan_OccupiedWinsOverFree) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  // Two returns along one line: the far ray passes through the near return's voxel, and two
  // returns in one voxel: still a single hit update.
  const Scan scan{Eigen::Vector3d(0.1, 0.1, 0.1),
                  {Eigen::Vector3f(2.1f, 0.1f, 0.1f), Eigen::Vector3f(2.15f, 0.12f, 0.1f),
                   Eigen::Vector3f(4.1f, 0.1f, 0.1f)},
                  {}};
  const auto stats = integrate(map, scan);
  EXPECT_EQ(stats.hit_updates, 2u);
  EXPECT_FLOAT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(2.1, 0.1, 0.1))), map.hit_log_odds());
  EXPECT_FLOAT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(1.1, 0.1, 0.1))), map.miss_log_odds());
}

TEST(OccupancyMap, NoReturnAndBeyondMaxRange_ClearUpToClearingRange) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  const Eigen::Vector3d origin(0.1, 0.1, 0.1);
  // A beam with no return along +y, a return at 9 m (beyond max range 8) along +x.
  const Scan scan{origin, {Eigen::Vector3f(9.1f, 0.1f, 0.1f)}, {Eigen::Vector3f(0.0f, 1.0f, 0.0f)}};
  const auto stats = integrate(map, scan);
  EXPECT_EQ(stats.hit_updates, 0u);
  EXPECT_FLOAT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(0.1, 4.9, 0.1))), map.miss_log_odds());
  EXPECT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(0.1, 5.3, 0.1))), OccupancyMap::kUnknown);
  EXPECT_FLOAT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(4.9, 0.1, 0.1))), map.miss_log_odds());
  EXPECT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(5.3, 0.1, 0.1))), OccupancyMap::kUnknown);
  EXPECT_EQ(map.log_odds(map.voxel_of(Eigen::Vector3d(9.1, 0.1, 0.1))), OccupancyMap::kUnknown);
}

TEST(OccupancyMap, NonFinitePointsAreSkipped) {
  OccupancyMap map(small_params());
  const Scan scan{Eigen::Vector3d(0.1, 0.1, 0.1),
                  {Eigen::Vector3f(std::nanf(""), 1.0f, 0.0f), Eigen::Vector3f(INFINITY, 0, 0)},
                  {Eigen::Vector3f(std::nanf(""), 0, 0), Eigen::Vector3f::Zero()}};
  const auto stats = integrate(map, scan);
  EXPECT_EQ(stats.hit_updates + stats.miss_updates, 0u);
}

TEST(OccupancyMap, ZeroOrNonFiniteUpAxisIsTakenAsZ) {
  // Thousands of returns in the 16 columns of a tiny window, with an up axis that is NaN,
  // infinite or zero: the map must equal one integrated with +z (a NaN height once made every
  // return book its column again, past the list's end).
  OccupancyParams p;
  p.window_x_vox = p.window_y_vox = p.window_z_vox = 4;
  p.window_below_m = 0.4;
  ASSERT_TRUE(p.validate().ok());
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-0.35f, 0.35f);
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 5000; ++i) points.emplace_back(u(rng), u(rng), u(rng));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  SerialRunner serial;
  OccupancyMap reference(p);
  for (int k = 0; k < 3; ++k) reference.integrate(Eigen::Vector3d::Zero(), points, {}, serial);
  std::vector<float> want, got;
  reference.export_log_odds(want);
  for (const Eigen::Vector3d& up :
       {Eigen::Vector3d(0, 0, nan), Eigen::Vector3d(inf, 0, 1), Eigen::Vector3d(0, 0, 0)}) {
    OccupancyMap map(p);
    for (int k = 0; k < 3; ++k) map.integrate(Eigen::Vector3d::Zero(), points, {}, serial, up);
    map.export_log_odds(got);
    EXPECT_EQ(std::memcmp(got.data(), want.data(), want.size() * sizeof(float)), 0);
    for (int z = 0; z < 4; ++z) {
      const std::uint8_t* a = map.ring_layer_rise_cm(z);
      const std::uint8_t* b = reference.ring_layer_rise_cm(z);
      EXPECT_TRUE(std::equal(a, a + 16, b)) << z;
    }
  }
}

TEST(OccupancyMap, Scrolling_KeepsContentAndForgetsWhatLeft) {
  const auto params = small_params();
  OccupancyMap map(params);
  map.recenter(Eigen::Vector3d::Zero());
  const Eigen::Vector3d origin(0.1, 0.1, 0.1);
  integrate(
      map,
      Scan{origin, {Eigen::Vector3f(6.1f, 3.1f, 0.5f), Eigen::Vector3f(-7.9f, -2.9f, 0.3f)}, {}});
  std::vector<float> before;
  map.export_log_odds(before);
  const VoxelIndex near_hit = map.voxel_of(Eigen::Vector3d(6.1, 3.1, 0.5));
  const VoxelIndex far_hit = map.voxel_of(Eigen::Vector3d(-7.9, -2.9, 0.3));
  const VoxelIndex min_before = map.window_min();

  // Move 3.1 m in +x, 1.3 m in +y, 0.45 m up: the window scrolls by (15, 6, 2) voxels.
  map.recenter(Eigen::Vector3d(3.1, 1.3, 0.45));
  const VoxelIndex shift = map.window_min() - min_before;
  EXPECT_EQ(shift, VoxelIndex(15, 6, 2));
  EXPECT_FLOAT_EQ(map.log_odds(near_hit), map.hit_log_odds());
  EXPECT_FALSE(map.in_window(far_hit));  // x = -40 left the window (new min x = -35)
  // Every voxel still in the window holds exactly what it held before.
  const Eigen::Vector3i dims = map.window_size();
  for (int z = 0; z < dims.z(); ++z)
    for (int y = 0; y < dims.y(); ++y)
      for (int x = 0; x < dims.x(); ++x) {
        const VoxelIndex g = min_before + VoxelIndex(x, y, z);
        if (!map.in_window(g)) continue;
        ASSERT_EQ(map.log_odds(g),
                  before[(static_cast<std::size_t>(z) * dims.y() + y) * dims.x() + x]);
      }
  // Coming back: what left is unknown, not resurrected from the ring.
  map.recenter(Eigen::Vector3d::Zero());
  EXPECT_EQ(map.log_odds(far_hit), OccupancyMap::kUnknown);
  EXPECT_FLOAT_EQ(map.log_odds(near_hit), map.hit_log_odds());
}

TEST(OccupancyMap, Scrolling_RandomMovesKeepWhatStaysAndEnterUnknown) {
  // Shifts of 1 to 30 voxels either way on each axis, so that the slabs cleared at once span
  // the ring's end too: after every move, each voxel still in the window holds what it held,
  // and each voxel that entered reads unknown (no static layer here). The window's layer is not a
  // multiple of 64 voxels, so the slot ranges the clearing splits into (on 3 threads) cut rows.
  auto params = small_params();
  params.static_promote_scans = 0;
  params.window_x_vox = 101;
  daemon::ThreadPool pool(3);
  for (const bool parallel : {false, true}) {
    OccupancyMap map(params);
    std::mt19937_64 rng(21);
    std::uniform_int_distribution<int> step(-30, 30);
    std::uniform_real_distribution<float> spread(-7.0f, 7.0f);
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    map.recenter(position);
    const Eigen::Vector3i dims = map.window_size();
    std::uint64_t entered_checked = 0;
    for (int move = 0; move < 60; ++move) {
      Scan scan{position + Eigen::Vector3d(0.01, 0.01, 0.01), {}, {}};
      for (int i = 0; i < 300; ++i) {
        scan.points.push_back(position.cast<float>() +
                              Eigen::Vector3f(spread(rng), spread(rng), spread(rng) / 4.0f));
      }
      integrate(map, scan);
      const VoxelIndex min_before = map.window_min();
      std::vector<float> before;
      map.export_log_odds(before);
      position += Eigen::Vector3d(step(rng), step(rng), step(rng) / 6) * params.voxel_size_m;
      if (parallel) {
        map.recenter(position, pool);
      } else {
        map.recenter(position);
      }
      for (int z = 0; z < dims.z(); ++z) {
        for (int y = 0; y < dims.y(); ++y) {
          for (int x = 0; x < dims.x(); ++x) {
            const VoxelIndex g = map.window_min() + VoxelIndex(x, y, z);
            const VoxelIndex old = g - min_before;
            const bool stayed = (old.array() >= 0).all() && (old.array() < dims.array()).all();
            const float want =
                stayed
                    ? before[(static_cast<std::size_t>(old.z()) * dims.y() + old.y()) * dims.x() +
                             old.x()]
                    : OccupancyMap::kUnknown;
            entered_checked += stayed ? 0 : 1;
            ASSERT_EQ(map.log_odds(g), want) << "move " << move << " voxel " << g.transpose();
          }
        }
      }
    }
    EXPECT_GT(entered_checked, 100000u);
  }
}

// A target voxel 3 m along x; a "present" scan returns from it, an "absent" scan's ray passes
// through it to a return 1 m behind.
struct Target {
  Eigen::Vector3d origin{0.1, 0.1, 0.1};
  Eigen::Vector3f at{3.1f, 0.1f, 0.1f};
  Eigen::Vector3f behind{4.1f, 0.1f, 0.1f};
  Scan present() const { return Scan{origin, {at}, {}}; }
  Scan absent() const { return Scan{origin, {behind}, {}}; }
};

TEST(OccupancyMap, DynamicLayer_ClearsInFiveMissesFromTheClamp) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex v = map.voxel_of(t.at.cast<double>());
  for (int i = 0; i < 10; ++i) integrate(map, t.present());  // < promotion: dynamic only
  ASSERT_FLOAT_EQ(map.log_odds(v), map.max_log_odds());
  EXPECT_FALSE(map.is_static(v));
  // logit(0.85) = 1.735, logit(0.4) = -0.405: 4 misses leave 0.113, the 5th reads free.
  for (int i = 1; i <= 5; ++i) {
    integrate(map, t.absent());
    EXPECT_EQ(map.log_odds(v) > 0.0f, i < 5) << i;
  }
}

// The apply pass skips voxels it knows to sit at the lower clamp (a miss changes nothing there).
// Every other write of a voxel's log-odds must end that: a hit, the window scrolling it out and
// back (per-voxel and whole-row clears), a reset and a static layer import. Each step below
// fails if the skip outlives that write (the miss would be lost).
TEST(OccupancyMap, LowerClampSkip_EndsWithEveryOtherWriteOfTheVoxel) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex v = map.voxel_of(t.at.cast<double>());  // free while t.behind is returned
  const float l_min = map.min_log_odds(), l_hit = map.hit_log_odds(), l_miss = map.miss_log_odds();
  const auto to_clamp = [&] {
    for (int i = 0; i < 6; ++i) integrate(map, t.absent());
    ASSERT_EQ(map.log_odds(v), l_min);
  };
  to_clamp();
  integrate(map, t.present());
  ASSERT_EQ(map.log_odds(v), l_min + l_hit);
  integrate(map, t.absent());
  EXPECT_EQ(map.log_odds(v), std::max(l_min + l_hit + l_miss, l_min)) << "after a hit";
  // Out along x (one voxel per row cleared) and back: unknown, then one miss.
  to_clamp();
  map.recenter(Eigen::Vector3d(15.0, 0.0, 0.0));
  ASSERT_FALSE(map.in_window(v));
  map.recenter(Eigen::Vector3d::Zero());
  ASSERT_EQ(map.log_odds(v), OccupancyMap::kUnknown);
  integrate(map, t.absent());
  EXPECT_EQ(map.log_odds(v), l_miss) << "after scrolling along x";
  // Out along y (whole rows cleared) and back.
  to_clamp();
  map.recenter(Eigen::Vector3d(0.0, 12.0, 0.0));
  ASSERT_FALSE(map.in_window(v));
  map.recenter(Eigen::Vector3d::Zero());
  integrate(map, t.absent());
  EXPECT_EQ(map.log_odds(v), l_miss) << "after scrolling along y";
  // Out of the window at once (the whole window cleared) and back.
  to_clamp();
  map.recenter(Eigen::Vector3d(100.0, 0.0, 0.0));
  map.recenter(Eigen::Vector3d::Zero());
  integrate(map, t.absent());
  EXPECT_EQ(map.log_odds(v), l_miss) << "after leaving the window";
  to_clamp();
  map.reset();
  integrate(map, t.absent());
  EXPECT_EQ(map.log_odds(v), l_miss) << "after a reset";
  // Imported as static: the layer's misses count again, and ten of them demote it.
  to_clamp();
  const std::vector<VoxelIndex> layer{v};
  map.import_static(layer);
  ASSERT_TRUE(map.is_static(v));
  ASSERT_EQ(map.log_odds(v), l_hit);
  std::uint64_t demotions = 0;
  for (int i = 0; i < 10; ++i) demotions += integrate(map, t.absent()).demotions;
  EXPECT_EQ(demotions, 1u) << "after a static import";
  EXPECT_FALSE(map.is_static(v));
}

TEST(OccupancyMap, StaticLayer_PromotedAfterConsecutiveHitsAndOnlyStrongFreeEvidenceRemovesIt) {
  OccupancyParams p = small_params();
  p.static_promote_scans = 20;
  p.static_demote_scans = 10;
  OccupancyMap map(p);
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex v = map.voxel_of(t.at.cast<double>());
  // A miss that leaves it occupied does not break the run; 19 hits are not enough.
  for (int i = 0; i < 10; ++i) integrate(map, t.present());
  integrate(map, t.absent());
  for (int i = 0; i < 8; ++i) integrate(map, t.present());
  EXPECT_FALSE(map.is_static(v));
  EXPECT_EQ(integrate(map, t.present()).promotions, 0u);  // hit 19
  EXPECT_EQ(integrate(map, t.present()).promotions, 1u);  // hit 20
  EXPECT_TRUE(map.is_static(v));
  EXPECT_EQ(map.static_count(), 1u);
  // Nine free observations, a return, nine more: never cleared, never below one hit's log-odds.
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 9; ++i) {
      integrate(map, t.absent());
      ASSERT_TRUE(map.is_static(v));
      ASSERT_GE(map.log_odds(v), map.hit_log_odds());
    }
    if (round == 0) integrate(map, t.present());
  }
  // The tenth consecutive free observation removes it, and it reads free at once.
  // The same scan is the 20th consecutive hit of the voxel behind it: that one becomes static.
  const VoxelIndex behind = map.voxel_of(t.behind.cast<double>());
  EXPECT_FALSE(map.is_static(behind));
  const auto stats = integrate(map, t.absent());
  EXPECT_EQ(stats.demotions, 1u);
  EXPECT_EQ(stats.promotions, 1u);
  EXPECT_FALSE(map.is_static(v));
  EXPECT_TRUE(map.is_static(behind));
  EXPECT_EQ(map.static_count(), 1u);
  EXPECT_LE(map.log_odds(v), 0.0f);
}

TEST(OccupancyMap, StaticLayer_ARunBrokenByReadingFreeStartsAgain) {
  OccupancyMap map(small_params());  // 20 / 10
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex v = map.voxel_of(t.at.cast<double>());
  for (int i = 0; i < 15; ++i) integrate(map, t.present());  // a tug's face: 15 scans
  for (int i = 0; i < 5; ++i) integrate(map, t.absent());    // reads free
  ASSERT_LE(map.log_odds(v), 0.0f);
  // 1.735 − 5·0.405 = −0.29: the first hit brings it to +0.56, so it starts the new run.
  for (int i = 0; i < 19; ++i) integrate(map, t.present());
  EXPECT_FALSE(map.is_static(v));
  integrate(map, t.present());
  EXPECT_TRUE(map.is_static(v));
}

TEST(OccupancyMap, StaticLayer_SurvivesScrollingAwayAndBackAndImportExport) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex v = map.voxel_of(t.at.cast<double>());
  for (int i = 0; i < 20; ++i) integrate(map, t.present());
  ASSERT_TRUE(map.is_static(v));
  map.recenter(Eigen::Vector3d(40.0, 0.0, 0.0));  // the window (20 m wide) leaves it
  ASSERT_FALSE(map.in_window(v));
  EXPECT_TRUE(map.is_static(v));
  map.recenter(Eigen::Vector3d::Zero());  // back: it reads occupied without a new scan
  EXPECT_FLOAT_EQ(map.log_odds(v), map.hit_log_odds());
  EXPECT_EQ(map.log_odds(v + VoxelIndex(1, 0, 0)), OccupancyMap::kUnknown);  // unknown stays
  std::vector<VoxelIndex> out;
  map.export_static(out);
  ASSERT_EQ(out, std::vector<VoxelIndex>{v});
  // A fresh map given that layer: static inside the window at its first placement.
  OccupancyMap fresh(small_params());
  const std::vector<VoxelIndex> layer{v, VoxelIndex(-500, 7, -3)};
  fresh.import_static(layer);
  fresh.recenter(Eigen::Vector3d::Zero());
  EXPECT_FLOAT_EQ(fresh.log_odds(v), fresh.hit_log_odds());
  EXPECT_TRUE(fresh.is_static(VoxelIndex(-500, 7, -3)));
  EXPECT_EQ(fresh.static_count(), 2u);
  fresh.export_static(out);
  EXPECT_EQ(out, (std::vector<VoxelIndex>{VoxelIndex(-500, 7, -3), v}));
}

TEST(OccupancyMap, StaticLayer_ZeroPromotionDisablesIt) {
  OccupancyParams p = small_params();
  p.static_promote_scans = 0;
  OccupancyMap map(p);
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  for (int i = 0; i < 50; ++i) integrate(map, t.present());
  EXPECT_EQ(map.static_count(), 0u);
  p.static_promote_scans = 128;
  EXPECT_FALSE(p.validate().ok());
  p.static_promote_scans = 20;
  p.static_demote_scans = 0;
  EXPECT_FALSE(p.validate().ok());
}

// Ranges are bounded: a walk's voxel indices are 32-bit. Beyond 2^31 voxels of range the walks
// would wrap (the lanes' conversions saturate instead), so such a config is refused.
/// An underside: a plate's bottom at z = 1.65 (in the voxel [1.6, 1.8) of column x 3.0..3.2),
/// seen from a sensor 1 m up below it, with free space observed under it and nothing above.
struct Underside {
  Eigen::Vector3d origin{0.0, 0.0, 1.0};
  Scan seen() const {  // returns on the plate, and a ray to a wall beyond passing under it
    Scan s{origin, {}, {}};
    for (int i = 0; i < 4; ++i) s.points.emplace_back(3.02f + 0.05f * i, 0.05f, 1.65f);
    s.points.emplace_back(6.0f, 0.05f, 2.0f);  // at x 3.0..3.2 it is at 1.50..1.53 m
    return s;
  }
  Scan grazing() const {  // under the plate's surface, through the voxel's empty bottom
    return Scan{origin, {{6.0f, 0.05f, 2.2f}}, {}};  // 1.60..1.64 m at x 3.0..3.2
  }
  Scan through() const {  // through the voxel above its lowest return: where the plate was
    return Scan{origin, {{6.0f, 0.05f, 2.4f}}, {}};  // 1.70..1.75 m at x 3.0..3.2
  }
};

TEST(OccupancyMap, Underside_RaysGrazingUnderItsLowestReturnDoNotClearIt) {
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d(0.0, 0.0, 0.0));
  const Underside u;
  integrate(map, u.seen());
  const VoxelIndex plate = map.voxel_of({3.1, 0.05, 1.65});
  ASSERT_GT(map.log_odds(plate), 0.0f);
  ASSERT_LT(map.log_odds(plate - VoxelIndex::UnitZ()), 0.0f);                    // free below
  ASSERT_EQ(map.log_odds(plate + VoxelIndex::UnitZ()), OccupancyMap::kUnknown);  // none above
  for (int i = 0; i < 20; ++i) integrate(map, u.grazing());
  EXPECT_GT(map.log_odds(plate), 0.0f) << "grazing rays eroded the underside";
  // A ray through where its returns were shows it gone: five misses from the clamp.
  for (int i = 0; i < 5; ++i) integrate(map, u.through());
  EXPECT_LE(map.log_odds(plate), 0.0f);
}

TEST(OccupancyMap, TopSurface_ClearedByAnyRayThroughIt) {
  // The same plate seen from above (free space above it, nothing below): a tug's roof. Any ray
  // through its voxel is a miss, as before, so a vehicle that drove away clears as fast.
  OccupancyMap map(small_params());
  map.recenter(Eigen::Vector3d(0.0, 0.0, 0.0));
  const Eigen::Vector3d origin(0.0, 0.0, 1.9);
  Scan seen{origin, {}, {}};
  for (int i = 0; i < 4; ++i) seen.points.emplace_back(3.02f + 0.05f * i, 0.05f, 1.45f);
  integrate(map, seen);
  const VoxelIndex roof = map.voxel_of({3.1, 0.05, 1.45});
  ASSERT_GT(map.log_odds(roof), 0.0f);
  // Rays over the roof's returns (1.56..1.58 m at x 3.0..3.2) to something beyond.
  const Scan over{origin, {{10.0f, 0.05f, 0.833f}}, {}};
  for (int i = 0; i < 5; ++i) integrate(map, over);
  EXPECT_LE(map.log_odds(roof), 0.0f);
}

TEST(OccupancyMap, LeavingTheWindow_OccupiedWithReturnsInTwoScansIsKept_OneIsNot) {
  OccupancyMap map(small_params());  // 20 m window
  map.recenter(Eigen::Vector3d::Zero());
  const Target t;
  const VoxelIndex twice = map.voxel_of(t.at.cast<double>());
  for (int i = 0; i < 2; ++i) integrate(map, t.present());
  const Eigen::Vector3f once_at(-3.05f, 2.05f, 0.55f);
  integrate(map, Scan{Eigen::Vector3d::Zero(), {once_at}, {}});
  const VoxelIndex once = map.voxel_of(once_at.cast<double>());
  ASSERT_GT(map.log_odds(once), 0.0f);
  EXPECT_FALSE(map.is_static(twice));
  map.recenter(Eigen::Vector3d(30.0, 0.0, 0.0));  // both leave (scrolled slabs)
  EXPECT_TRUE(map.is_static(twice));
  EXPECT_FALSE(map.is_static(once));
  map.recenter(Eigen::Vector3d::Zero());
  EXPECT_GT(map.log_odds(twice), 0.0f);
  EXPECT_EQ(map.log_odds(once), OccupancyMap::kUnknown);
  // A jump farther than the window (the whole window cleared at once) keeps the same way.
  const Eigen::Vector3f far_at(1.05f, -2.05f, 0.35f);
  for (int i = 0; i < 2; ++i) integrate(map, Scan{Eigen::Vector3d::Zero(), {far_at}, {}});
  map.recenter(Eigen::Vector3d(500.0, 0.0, 0.0));
  EXPECT_TRUE(map.is_static(map.voxel_of(far_at.cast<double>())));
}

TEST(OccupancyMap, Params_RangesAreBounded) {
  OccupancyParams p = small_params();
  p.max_range_m = 1000.0;
  p.clearing_range_m = 1000.0;
  EXPECT_TRUE(p.validate().ok());
  p.max_range_m = 1e8;
  EXPECT_FALSE(p.validate().ok());
  p.max_range_m = 50.0;
  p.clearing_range_m = 1e8;
  EXPECT_FALSE(p.validate().ok());
  p.clearing_range_m = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(p.validate().ok());
}

/// Calls `fn` with every voxel of the window that reads occupied, but the one holding `origin`.
template <typename Fn>
void for_each_occupied(const OccupancyMap& map, const Eigen::Vector3d& origin, Fn&& fn) {
  const VoxelIndex own = map.voxel_of(origin);
  const Eigen::Vector3i dims = map.window_size();
  for (int z = 0; z < dims.z(); ++z)
    for (int y = 0; y < dims.y(); ++y)
      for (int x = 0; x < dims.x(); ++x) {
        const VoxelIndex q = map.window_min() + VoxelIndex(x, y, z);
        if (q != own && map.log_odds(q) > 0.0f) fn(q);
      }
}

/// Brute force over the window: how far along `dir` from `origin` the ray enters the first
/// occupied voxel past the origin's (the slab test on each), or infinity within `max_t`.
double first_occupied_brute_force(const OccupancyMap& map, const Eigen::Vector3d& origin,
                                  const Eigen::Vector3d& dir, double max_t) {
  const double v = map.params().voxel_size_m;
  double best = std::numeric_limits<double>::infinity();
  for_each_occupied(map, origin, [&](const VoxelIndex& q) {
    double enter = -std::numeric_limits<double>::infinity();
    double leave = std::numeric_limits<double>::infinity();
    for (int a = 0; a < 3; ++a) {
      const double lo = q[a] * v, hi = (q[a] + 1) * v;
      if (dir[a] == 0.0) {
        if (origin[a] < lo || origin[a] >= hi) enter = leave = 0.0;  // never inside
        continue;
      }
      const double t0 = (lo - origin[a]) / dir[a], t1 = (hi - origin[a]) / dir[a];
      enter = std::max(enter, std::min(t0, t1));
      leave = std::min(leave, std::max(t0, t1));
    }
    if (enter < leave && enter >= 0.0 && enter < max_t) best = std::min(best, enter);
  });
  return best;
}

/// A window that is not a multiple of the brick (8 voxels) in any axis, rays to 12 m.
OccupancyParams odd_window_params() {
  auto params = small_params();
  params.window_x_vox = 101;
  params.window_y_vox = 94;
  params.window_z_vox = 21;
  params.max_range_m = 12.0;
  return params;
}

/// Ground 1.5 m below the scan's origin, and free space everywhere round it (misses clear what
/// left).
void add_ground_and_free_space(Scan& scan, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 300; ++i) {
    scan.points.push_back(
        (scan.origin + Eigen::Vector3d(6.0 * u(rng), 6.0 * u(rng), -1.5)).cast<float>());
  }
  for (int i = 0; i < 400; ++i) {
    scan.clearing.push_back(Eigen::Vector3f(u(rng), u(rng), 0.3 * u(rng)).normalized());
  }
}

TEST(OccupancyMap, FirstOccupied_SameAsBruteForce_WhileObjectsComeGoAndTheWindowMoves) {
  // The walk crosses empty bricks of 8³ voxels many at a time; whatever the flags hold (set by
  // hits, by the static layer coming back, stale after misses cleared a brick), it must find
  // the voxel a brute force over every occupied voxel finds. A window that is not a multiple of
  // the brick in any axis, scrolled across the ring's end; boxes that appear, move and vanish;
  // rays from near the sensor in every direction, most of them near the horizontal.
  auto params = odd_window_params();
  params.static_promote_scans = 3;
  OccupancyMap map(params);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Vector3d position(0.05, 0.05, 0.05);
  std::vector<Eigen::Vector3d> boxes;
  for (int i = 0; i < 6; ++i) boxes.emplace_back(8.0 * u(rng), 8.0 * u(rng), u(rng));
  std::size_t found = 0, checked = 0;
  for (int scan_no = 0; scan_no < 40; ++scan_no) {
    Scan scan{position, {}, {}};
    for (std::size_t b = 0; b < boxes.size(); ++b) {
      if ((scan_no + static_cast<int>(b)) % 7 == 0) continue;  // now and then a box is gone
      for (int i = 0; i < 60; ++i) {
        scan.points.push_back(
            (position + boxes[b] + Eigen::Vector3d(0.5 * u(rng), 0.5 * u(rng), 0.4 * u(rng)))
                .cast<float>());
      }
    }
    add_ground_and_free_space(scan, rng);
    map.recenter(position);
    integrate(map, scan);
    for (int r = 0; r < 60; ++r) {
      const Eigen::Vector3d from = position + Eigen::Vector3d(u(rng), u(rng), 0.3 * u(rng));
      Eigen::Vector3d dir(u(rng), u(rng), (r % 3 == 0 ? 1.0 : 0.2) * u(rng));
      if (r == 0) dir = Eigen::Vector3d(1.0, 0.0, 0.0);  // along an axis: no crossing on two
      dir.normalize();
      const double max_t = 2.0 + 10.0 * (u(rng) + 1.0);
      const double want = first_occupied_brute_force(map, from, dir, max_t);
      const double got = map.first_occupied(from, dir, max_t);
      ++checked;
      if (std::isinf(want)) {
        EXPECT_TRUE(std::isinf(got)) << "scan " << scan_no << " ray " << r << " got " << got;
      } else {
        ++found;
        EXPECT_NEAR(got, want, 1e-9) << "scan " << scan_no << " ray " << r;
      }
    }
    // Boxes drift and the vehicle moves, by up to 12 voxels: the window scrolls round its ring.
    for (auto& b : boxes) b += Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng), 0.0);  // round it
    position += Eigen::Vector3d(2.4 * u(rng), 2.4 * u(rng), 0.2 * u(rng));
  }
  EXPECT_GT(found, checked / 4) << "too few rays met anything to test the walk";
  EXPECT_LT(found, checked * 9 / 10) << "too few rays crossed empty space";
}

TEST(OccupancyMap, SkyHorizon_ClearsOnlyRaysTheBruteForceFindsNothingOn) {
  // The sky horizon lets a scan's beams without return skip their walk. It must never clear a
  // ray that meets an occupied voxel, for any max_t: checked against the brute force over the
  // whole window with the window scrolled across the ring's end in all three axes (bricks cut
  // in two at the seam), boxes above and below the sensor at every azimuth, rays from level to
  // straight up.
  OccupancyMap map(odd_window_params());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Vector3d position(0.05, 0.05, 0.05);
  std::size_t cleared = 0, free_rays = 0, blocked = 0, checked = 0, aimed = 0;
  for (int scan_no = 0; scan_no < 30; ++scan_no) {
    Scan scan{position, {}, {}};
    for (int b = 0; b < 8; ++b) {  // small boxes from 1 m below the sensor to 1.5 m above it,
      // out to the window's edges (where the bricks cut by the ring's seam lie)
      const Eigen::Vector3d c =
          position + Eigen::Vector3d(9.8 * u(rng), 9.2 * u(rng), 0.25 + 1.25 * u(rng));
      for (int i = 0; i < 40; ++i) {
        scan.points.push_back(
            (c + Eigen::Vector3d(0.3 * u(rng), 0.3 * u(rng), 0.2 * u(rng))).cast<float>());
      }
    }
    add_ground_and_free_space(scan, rng);
    map.recenter(position);
    integrate(map, scan);
    SkyHorizon sky;
    map.sky_horizon(position, sky);
    // A ray aimed at the centre of any occupied voxel meets it: never cleared. Every voxel of
    // the window, so the bricks the ring's seam cuts in two are checked whatever the scan.
    for_each_occupied(map, position, [&](const VoxelIndex& q) {
      const Eigen::Vector3d at = (q.cast<double>() + Eigen::Vector3d::Constant(0.5)) * 0.2;
      ++aimed;
      EXPECT_FALSE(sky.clears((at - position).normalized()))
          << "scan " << scan_no << " voxel " << q.transpose();
    });
    for (int r = 0; r < 80; ++r) {
      Eigen::Vector3d dir(u(rng), u(rng), 0.0);
      if (r % 4 != 0) dir.z() = (r % 4 == 1 ? 0.05 : 0.6) * (u(rng) + 1.0);  // r % 4 == 0: level
      if (r == 1) dir = Eigen::Vector3d(0.0, 0.0, 1.0);
      dir.normalize();
      const double want = first_occupied_brute_force(map, position, dir, 100.0);
      ++checked;
      if (std::isinf(want)) {
        ++free_rays;
        if (sky.clears(dir)) ++cleared;
      } else {
        ++blocked;
        EXPECT_FALSE(sky.clears(dir))
            << "scan " << scan_no << " ray " << r << " meets a voxel at " << want << " m";
      }
    }
    position += Eigen::Vector3d(2.4 * u(rng), 2.4 * u(rng), 0.4 * u(rng));
  }
  // Enough of each kind for the checks above to mean something (how much the horizon clears
  // where it should is the next test's).
  EXPECT_GT(blocked, checked / 10) << "too few rays met anything to test the horizon";
  EXPECT_GT(cleared, checked / 20) << "too few cleared rays checked (of " << free_rays << " free)";
  EXPECT_GT(aimed, 1000u);
}

TEST(OccupancyMap, SkyHorizon_ClearsEveryRayAboveTheObjectsRound) {
  // Objects 5 to 8 m away all round, their tops at most 1 m over the sensor: the horizon is
  // drawn from bricks (1.6 m wide at 0.2 m) with their highest occupied voxel, and a voxel's
  // margin each way, so every ray rising faster than (1 + 0.2 + 0.2) / (5 − 1.6 − 0.2) must be
  // cleared, whatever its azimuth; a level ray towards an object must not be.
  auto params = small_params();
  params.max_range_m = 12.0;
  OccupancyMap map(params);
  const Eigen::Vector3d origin(0.3, -0.1, 0.1);
  Scan scan{origin, {}, {}};
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 3000; ++i) {
    const double az = 2.0 * M_PI * u(rng), r = 5.0 + 3.0 * u(rng);
    scan.points.push_back(
        (origin + Eigen::Vector3d(r * std::cos(az), r * std::sin(az), -1.0 + 1.95 * u(rng)))
            .cast<float>());
  }
  map.recenter(origin);
  integrate(map, scan);
  SkyHorizon sky;
  map.sky_horizon(origin, sky);
  const double steep = 1.4 / 3.2;
  int level_blocked = 0;
  for (int k = 0; k < 720; ++k) {
    const double az = 2.0 * M_PI * k / 720.0;
    const Eigen::Vector3d across(std::cos(az), std::sin(az), 0.0);
    EXPECT_TRUE(sky.clears((across + Eigen::Vector3d(0, 0, steep * 1.001)).normalized()))
        << "azimuth " << az;
    if (!sky.clears(across)) ++level_blocked;
  }
  EXPECT_EQ(level_blocked, 720) << "objects stand all round at the sensor's height";
}

TEST(OccupancyMap, SkyHorizon_BoxOverTheSensor_ClearsNothing) {
  // A box overhead (a wing over the vehicle): every rising ray may meet it; none is cleared,
  // not even the ones that miss it (the horizon cannot tell them apart).
  OccupancyMap map(small_params());
  const Eigen::Vector3d origin(0.1, 0.1, 0.1);
  Scan scan{origin, {}, {}};
  for (int i = 0; i < 50; ++i) {
    scan.points.emplace_back(0.1f + 0.01f * static_cast<float>(i % 7), 0.1f, 1.5f);
  }
  map.recenter(origin);
  integrate(map, scan);
  SkyHorizon sky;
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(0.0, 0.0, 1.0))) << "not drawn yet: clears nothing";
  map.sky_horizon(origin, sky);
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(0.0, 0.0, 1.0)));
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(1.0, 0.0, 1.0).normalized()));
  // Without it, the same rays are cleared: the same SkyHorizon redrawn keeps nothing of before.
  OccupancyMap empty(small_params());
  empty.recenter(origin);
  empty.sky_horizon(origin, sky);
  EXPECT_TRUE(sky.clears(Eigen::Vector3d(1.0, 0.0, 1.0).normalized()));
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(1.0, 0.0, -0.1).normalized()))
      << "a descending ray is never cleared";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(nan, 0.0, 1.0)));
  EXPECT_FALSE(sky.clears(Eigen::Vector3d(1.0, 0.0, nan)));
}

TEST(OccupancyMap, Deterministic_ForOneTwoAndFourThreads) {
  auto params = small_params();
  params.window_x_vox = 200;
  params.window_y_vox = 200;
  params.max_range_m = 18.0;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<float> u(-19.0f, 19.0f);
  std::vector<Scan> scans;
  for (int s = 0; s < 5; ++s) {
    Scan scan{Eigen::Vector3d(0.3 * s, 0.1 * s, 0.2), {}, {}};
    for (int i = 0; i < 20000; ++i) scan.points.emplace_back(u(rng), u(rng), u(rng) / 10.0f);
    for (int i = 0; i < 500; ++i)
      scan.clearing.push_back(Eigen::Vector3f(u(rng), u(rng), 0.1f).normalized());
    scans.push_back(std::move(scan));
  }
  std::vector<std::vector<float>> results;
  for (const std::size_t threads : {1u, 2u, 4u}) {
    daemon::ThreadPool pool(threads);
    OccupancyMap map(params);
    for (const auto& scan : scans) {
      map.recenter(scan.origin);
      map.integrate(scan.origin, scan.points, scan.clearing, pool);
    }
    results.emplace_back();
    map.export_log_odds(results.back());
  }
  EXPECT_EQ(0, std::memcmp(results[0].data(), results[1].data(), results[0].size() * 4));
  EXPECT_EQ(0, std::memcmp(results[0].data(), results[2].data(), results[0].size() * 4));
}

TEST(OccupancyMap, ColumnObservations_InTheBandOnly_StampedPerScan_MoveWithTheWindow) {
  // Window 100 x 100 x 20 at 0.2 m from z = −2 m (sensor at z = 0): band = layers 0..12, i.e.
  // z in [−2, 0.6) m. One ray along +x at z = 0.1 to x = 6 m, one climbing to (0, 3, 1.9) m: it
  // leaves the band at y ≈ 0.8 m.
  const std::int64_t t1 = 1'000'000'000, t2 = 2'000'000'000;
  OccupancyMap tracked(small_params()), plain(small_params());
  tracked.track_column_observations(0, 12);
  const Scan scan{Eigen::Vector3d(0.1, 0.1, 0.1), {{6.1f, 0.1f, 0.1f}, {0.1f, 3.1f, 1.9f}}, {}};
  tracked.set_observation_stamp(t1);
  integrate(tracked, scan);
  integrate(plain, scan);
  std::vector<float> a, b;
  tracked.export_log_odds(a);
  plain.export_log_odds(b);
  EXPECT_EQ(a, b) << "tracking changed the map";
  std::vector<std::int64_t> seen;
  tracked.export_column_observed(seen);
  const VoxelIndex lo = tracked.window_min();
  const int nx = tracked.window_size().x();
  const auto at = [&](double x, double y) {
    const int ix = static_cast<int>(std::floor(x / 0.2)) - lo.x();
    const int iy = static_cast<int>(std::floor(y / 0.2)) - lo.y();
    return seen[static_cast<std::size_t>(iy * nx + ix)];
  };
  EXPECT_EQ(at(0.1, 0.1), t1);  // the sensor's column
  EXPECT_EQ(at(3.1, 0.1), t1);  // passed in the band
  EXPECT_EQ(at(6.1, 0.1), t1);  // the return
  EXPECT_EQ(at(0.1, 0.5), t1);  // the climbing ray still in the band (z ≈ 0.35 m)
  EXPECT_EQ(at(0.1, 2.5), 0);   // ... passed above it (z ≈ 1.6 m)
  EXPECT_EQ(at(0.1, 3.1), 0);   // its return at 1.9 m: above the band
  EXPECT_EQ(at(-3.0, -3.0), 0);
  // A second scan stamps what it observes, the rest keeps its time.
  tracked.set_observation_stamp(t2);
  integrate(tracked, Scan{Eigen::Vector3d(0.1, 0.1, 0.1), {{0.1f, -2.9f, 0.1f}}, {}});
  tracked.export_column_observed(seen);
  EXPECT_EQ(at(0.1, -2.9), t2);
  EXPECT_EQ(at(3.1, 0.1), t1);
  // The window moves 5 m along +x: the columns stay with the world, those entering are unseen.
  SerialRunner runner;
  tracked.recenter(Eigen::Vector3d(5.1, 0.1, 0.1), runner);
  tracked.export_column_observed(seen);
  const VoxelIndex moved = tracked.window_min();
  ASSERT_EQ(moved.x(), lo.x() + 25);
  const auto at2 = [&](double x, double y) {
    const int ix = static_cast<int>(std::floor(x / 0.2)) - moved.x();
    const int iy = static_cast<int>(std::floor(y / 0.2)) - moved.y();
    return seen[static_cast<std::size_t>(iy * nx + ix)];
  };
  EXPECT_EQ(at2(3.1, 0.1), t1);
  EXPECT_EQ(at2(6.1, 0.1), t1);
  EXPECT_EQ(at2(14.9, 0.1), 0);  // entered now, where ring slots held columns that left
  std::int64_t newest = 0;
  for (std::size_t k = static_cast<std::size_t>(nx - 25); k < seen.size();
       k += static_cast<std::size_t>(nx)) {
    for (int j = 0; j < 25; ++j) newest = std::max(newest, seen[k + static_cast<std::size_t>(j)]);
  }
  EXPECT_EQ(newest, 0) << "a column that entered kept a stamp of the one that left its slots";
}

}  // namespace
}  // namespace tarmac::core
