/// @file The ray walks of OccupancyMap::integrate against the sampled reference traversal, and
/// the four- and eight-lane walks against the one-ray-at-a-time walk, bit for bit.

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

#include "occupancy_test_util.hpp"

namespace tarmac::core {
namespace {

using namespace occupancy_test;  // NOLINT(google-build-using-namespace): the tests' own helpers

TEST(OccupancyMap, Raycast_MatchesReferenceTraversal) {
  const auto params = small_params();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-6.0, 6.0);
  for (int trial = 0; trial < 200; ++trial) {
    OccupancyMap map(params);
    map.recenter(Eigen::Vector3d::Zero());
    const Eigen::Vector3d origin(0.3 * u(rng) / 6.0 + 0.05, 0.3 * u(rng) / 6.0 + 0.07, 0.013);
    Eigen::Vector3f end(static_cast<float>(u(rng)), static_cast<float>(u(rng)),
                        static_cast<float>(u(rng) / 4.0));
    if ((end.cast<double>() - origin).norm() > params.max_range_m) continue;
    integrate(map, Scan{origin, {end}, {}});
    auto expected = sampled_voxels(origin, end.cast<double>(), params.voxel_size_m);
    const VoxelIndex e = map.voxel_of(end.cast<double>());
    expected.erase({e.x(), e.y(), e.z()});
    // Every voxel the segment crosses is free; the end voxel is occupied; nothing else changed.
    const WindowScan window = scan_window(map, expected, nullptr);
    ASSERT_EQ(window.wrong, "") << "trial " << trial;
    ASSERT_EQ(window.free, expected.size()) << "trial " << trial;
    ASSERT_FLOAT_EQ(map.log_odds(e), map.hit_log_odds());
  }
}

// Many rays of one scan, in every direction (each face of the cube, along the axes, on the
// diagonals) and listed in random order, plus entries that must be skipped: the free voxels are
// exactly the union of their reference traversals, less the voxels any of them hit. The map
// walks the rays in its own order (by direction one at a time, in lanes of eight with AVX-512);
// a ray lost or walked twice on the way shows here.
TEST(OccupancyMap, Raycast_ManyRaysInEveryDirection_MarkTheUnionOfTheirTraversals) {
  const auto params = small_params();
  OccupancyMap map(params);
  map.recenter(Eigen::Vector3d::Zero());
  const Eigen::Vector3d origin(0.031, 0.057, 0.013);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> len(0.3, 4.0);
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < 400; ++i) dirs.emplace_back(g(rng), g(rng), g(rng));
  for (int a = 0; a < 3; ++a) {
    for (const double sign : {-1.0, 1.0}) dirs.push_back(sign * Eigen::Vector3d::Unit(a));
  }
  for (const double sx : {-1.0, 1.0}) {
    for (const double sy : {-1.0, 1.0}) dirs.emplace_back(sx, sy, 0.3 * sx * sy);
  }
  Scan scan{origin, {}, {}};
  VoxelSet expected_free, hits;
  for (const Eigen::Vector3d& d : dirs) {
    Eigen::Vector3d end = origin + d.normalized() * len(rng);
    end.z() = std::clamp(end.z(), -1.5, 1.5);
    const Eigen::Vector3f end_f = end.cast<float>();
    scan.points.push_back(end_f);
    auto crossed = sampled_voxels(origin, end_f.cast<double>(), params.voxel_size_m);
    const VoxelIndex e = map.voxel_of(end_f.cast<double>());
    crossed.erase({e.x(), e.y(), e.z()});
    expected_free.insert(crossed.begin(), crossed.end());
    hits.emplace(e.x(), e.y(), e.z());
  }
  for (const auto& h : hits) expected_free.erase(h);
  std::shuffle(scan.points.begin(), scan.points.end(), rng);
  // Skipped, wherever they sit in the list: not finite, and a return at the origin itself
  // (its own voxel is hit, nothing is crossed).
  scan.points.insert(scan.points.begin() + 17, Eigen::Vector3f(std::nanf(""), 1.0f, 0.0f));
  scan.points.insert(scan.points.begin() + 101, Eigen::Vector3f(0.0f, -INFINITY, 0.0f));
  scan.points.push_back(origin.cast<float>());
  const VoxelIndex o = map.voxel_of(origin.cast<float>().cast<double>());
  hits.emplace(o.x(), o.y(), o.z());
  expected_free.erase({o.x(), o.y(), o.z()});
  integrate(map, scan);
  const WindowScan window = scan_window(map, expected_free, &hits);
  EXPECT_EQ(window.wrong, "");
  EXPECT_EQ(window.free, expected_free.size());
  EXPECT_EQ(window.hit, hits.size());
}

// A walk in lanes (8 rays at a time: AVX-512, 4: AVX2) against the walk one ray at a time: the
// same log-odds bit for bit and the same visit counts, over scans whose rays cross the ring's
// seams (the window has scrolled), leave the window, end beyond max range or have no return, on
// both the small-window path and the path that flags mark words. Skipped where the processor
// lacks the lanes' instructions.
void expect_lanes_walk_same_map(int lanes) {
  for (const int window : {100, 700}) {  // 700 x 700 x 40 voxels: over the flagging threshold
    auto params = small_params();
    params.window_x_vox = window;
    params.window_y_vox = window;
    params.window_z_vox = 40;
    params.max_range_m = 12.0;
    params.clearing_range_m = 9.0;
    OccupancyMap wide(params), narrow(params);
    wide.set_walk_lanes(lanes);
    narrow.set_walk_lanes(1);
    if (wide.walk_lanes() != lanes)
      GTEST_SKIP() << "no " << lanes << "-lane walk on this processor";
    ASSERT_EQ(narrow.walk_lanes(), 1);
    std::mt19937_64 rng(13);
    std::uniform_real_distribution<float> u(-16.0f, 16.0f);
    for (int s = 0; s < 6; ++s) {
      const Eigen::Vector3d origin(3.75 * s + 0.125, -2.25 * s + 0.0625,
                                   0.375 + 0.125 * s);  // exact in float
      Scan scan{origin, {}, {}};
      for (int i = 0; i < 3000; ++i) {
        scan.points.push_back(origin.cast<float>() +
                              Eigen::Vector3f(u(rng), u(rng), u(rng) / 5.0f));
      }
      for (int i = 0; i < 200; ++i) {
        scan.clearing.push_back(Eigen::Vector3f(u(rng), u(rng), u(rng) / 8.0f).normalized());
      }
      // Returns exactly at max range (kept) and just beyond it (clearing), on every axis.
      for (int a = 0; a < 3; ++a) {
        for (const float sign : {-1.0f, 1.0f}) {
          for (const float range : {12.0f, 12.001f}) {
            Eigen::Vector3f p = origin.cast<float>();
            p[a] += sign * range;
            scan.points.push_back(p);
          }
        }
      }
      for (OccupancyMap* map : {&wide, &narrow}) map->recenter(origin);
      daemon::ThreadPool pool(2);
      const auto a = wide.integrate(scan.origin, scan.points, scan.clearing, pool);
      const auto b = narrow.integrate(scan.origin, scan.points, scan.clearing, pool);
      EXPECT_EQ(a.voxel_visits, b.voxel_visits) << "scan " << s;
      EXPECT_EQ(a.miss_updates, b.miss_updates) << "scan " << s;
      EXPECT_EQ(a.hit_updates, b.hit_updates) << "scan " << s;
      EXPECT_EQ(a.outside_window, b.outside_window) << "scan " << s;
    }
    std::vector<float> la, lb;
    wide.export_log_odds(la);
    narrow.export_log_odds(lb);
    ASSERT_EQ(la.size(), lb.size());
    EXPECT_EQ(0, std::memcmp(la.data(), lb.data(), la.size() * sizeof(float))) << window;
  }
}

// Exact ties (the ray crosses two or three voxel faces at once, on every step): 0.25 m voxels
// and an origin on the lattice's quarter points make every parameter exact, so each axis's
// crossings coincide along the diagonals; the tie goes to the later axis both ways.
void expect_lanes_walk_breaks_ties_the_same(int lanes) {
  auto params = small_params();
  params.voxel_size_m = 0.25;
  OccupancyMap wide(params), narrow(params);
  wide.set_walk_lanes(lanes);
  narrow.set_walk_lanes(1);
  if (wide.walk_lanes() != lanes) GTEST_SKIP() << "no " << lanes << "-lane walk on this processor";
  const Eigen::Vector3d origin(0.125, 0.125, 0.125);
  Scan scan{origin, {}, {}};
  for (const int sx : {-1, 0, 1}) {
    for (const int sy : {-1, 0, 1}) {
      for (const int sz : {-1, 0, 1}) {
        if (sx == 0 && sy == 0 && sz == 0) continue;
        for (const float length : {1.5f, 2.25f}) {
          scan.points.push_back(origin.cast<float>() +
                                length * Eigen::Vector3f(static_cast<float>(sx),
                                                         static_cast<float>(sy),
                                                         static_cast<float>(sz)));
        }
      }
    }
  }
  for (OccupancyMap* map : {&wide, &narrow}) {
    map->recenter(origin);
    integrate(*map, scan);
  }
  std::vector<float> la, lb;
  wide.export_log_odds(la);
  narrow.export_log_odds(lb);
  ASSERT_EQ(la.size(), lb.size());
  EXPECT_EQ(0, std::memcmp(la.data(), lb.data(), la.size() * sizeof(float)));
}

// Random small scenes against the walk one ray at a time: windows a few voxels wide (walks wrap
// and leave on every axis), origins on the lattice, off-centre or outside the window, returns in
// the origin's voxel or on the lattice, non-finite returns, zero and NaN clearing directions,
// scans of fewer rays than lanes, on one thread and two. Counts and log-odds must be the same.
void expect_lanes_walk_same_on_random_scenes(int lanes) {
  RandomDraws draw(42);
  const auto u = [&](double a, double b) { return draw.real(a, b); };
  const auto pick = [&](int a, int b) { return draw.pick(a, b); };
  daemon::ThreadPool pool(2);
  SerialRunner serial;
  int scans = 0;
  for (int it = 0; it < 60; ++it) {
    OccupancyParams p;
    const double sizes[] = {0.05, 0.1, 0.2, 0.25, 0.5, 1.0};
    p.voxel_size_m = sizes[pick(0, 5)];
    p.window_x_vox = pick(4, 40);
    p.window_y_vox = pick(4, 40);
    p.window_z_vox = pick(4, 24);
    p.window_below_m = u(0.0, p.window_z_vox * p.voxel_size_m);
    p.max_range_m = u(0.01, 30.0);
    p.clearing_range_m = it % 5 == 0 ? 0.0 : u(0.0, 40.0);
    ASSERT_TRUE(p.validate().ok());
    OccupancyMap wide(p), narrow(p);
    wide.set_walk_lanes(lanes);
    narrow.set_walk_lanes(1);
    if (wide.walk_lanes() != lanes) {
      GTEST_SKIP() << "no " << lanes << "-lane walk on this processor";
    }
    Eigen::Vector3d origin(u(-5.0, 5.0), u(-5.0, 5.0), u(-2.0, 2.0));
    for (int s = 0; s < 4; ++s) {
      if (pick(0, 2) == 0) {  // on the lattice's quarter points: exact ties
        for (int a = 0; a < 3; ++a) {
          origin[a] = std::round(origin[a] / p.voxel_size_m * 4.0) * p.voxel_size_m / 4.0;
        }
      }
      const Eigen::Vector3f o = origin.cast<float>();
      const auto v = static_cast<float>(p.voxel_size_m);
      std::vector<Eigen::Vector3f> points, dirs;
      const int n = pick(0, 3) == 0 ? pick(0, 9) : pick(10, 400);
      for (int i = 0; i < n; ++i) {
        const int kind = pick(0, 8);
        if (kind == 0) {
          points.push_back(o);  // the origin's voxel
        } else if (kind == 1) {
          Eigen::Vector3f q = o;
          q[pick(0, 2)] += static_cast<float>(pick(-8, 8)) * v;  // along an axis
          points.push_back(q);
        } else if (kind == 2) {
          points.push_back(o + v * Eigen::Vector3f(static_cast<float>(pick(-5, 5)),
                                                   static_cast<float>(pick(-5, 5)),
                                                   static_cast<float>(pick(-5, 5))));
        } else if (kind == 3) {
          points.emplace_back(std::nanf(""), 0.0f, 0.0f);
        } else {
          const Eigen::Vector3d d = Eigen::Vector3d(u(-1, 1), u(-1, 1), u(-1, 1)).normalized();
          points.push_back((origin + d * u(0.0, 40.0)).cast<float>());
        }
      }
      for (int i = pick(0, 40); i > 0; --i) {
        const int kind = pick(0, 5);
        if (kind == 0) {
          dirs.push_back(Eigen::Vector3f::Zero());
        } else if (kind == 1) {
          dirs.emplace_back(std::nanf(""), 0.0f, 1.0f);
        } else if (kind == 2) {
          Eigen::Vector3f d = Eigen::Vector3f::Zero();
          d[pick(0, 2)] = pick(0, 1) == 0 ? 1.0f : -1.0f;
          dirs.push_back(d);
        } else {
          dirs.push_back(Eigen::Vector3d(u(-1, 1), u(-1, 1), u(-1, 1)).cast<float>());
        }
      }
      TaskRunner& runner = s % 2 == 0 ? static_cast<TaskRunner&>(serial) : pool;
      if (s > 0 && pick(0, 1) == 0) origin += Eigen::Vector3d(u(-10, 10), u(-10, 10), u(-2, 2));
      wide.recenter(origin, runner);
      narrow.recenter(origin, runner);
      Eigen::Vector3d sensor = origin;  // sometimes off-centre, or outside the window
      if (pick(0, 4) == 0) sensor += Eigen::Vector3d(u(-8, 8), u(-8, 8), u(-3, 3));
      const auto a = wide.integrate(sensor, points, dirs, runner);
      const auto b = narrow.integrate(sensor, points, dirs, runner);
      ASSERT_EQ(a.voxel_visits, b.voxel_visits) << "scene " << it << " scan " << s;
      ASSERT_EQ(a.miss_updates, b.miss_updates) << "scene " << it << " scan " << s;
      ASSERT_EQ(a.hit_updates, b.hit_updates) << "scene " << it << " scan " << s;
      ASSERT_EQ(a.outside_window, b.outside_window) << "scene " << it << " scan " << s;
      std::vector<float> la, lb;
      wide.export_log_odds(la);
      narrow.export_log_odds(lb);
      ASSERT_EQ(la.size(), lb.size());
      ASSERT_EQ(0, std::memcmp(la.data(), lb.data(), la.size() * sizeof(float)))
          << "scene " << it << " scan " << s;
      ++scans;
    }
  }
  EXPECT_EQ(scans, 240);
}

TEST(OccupancyMap, WideWalk_SameMapAsOneRayAtATime) {
  expect_lanes_walk_same_map(8);
}
TEST(OccupancyMap, WideWalk_BreaksTiesAsOneRayAtATime) {
  expect_lanes_walk_breaks_ties_the_same(8);
}
TEST(OccupancyMap, Lanes4Walk_SameMapAsOneRayAtATime) {
  expect_lanes_walk_same_map(4);
}
TEST(OccupancyMap, Lanes4Walk_BreaksTiesAsOneRayAtATime) {
  expect_lanes_walk_breaks_ties_the_same(4);
}
TEST(OccupancyMap, WideWalk_RandomScenesSameAsOneRayAtATime) {
  expect_lanes_walk_same_on_random_scenes(8);
}
TEST(OccupancyMap, Lanes4Walk_RandomScenesSameAsOneRayAtATime) {
  expect_lanes_walk_same_on_random_scenes(4);
}

}  // namespace
}  // namespace tarmac::core
