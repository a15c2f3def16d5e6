#include "tarmac/core/scan_rays.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

/// The reference: every ray tested, as ScanRays::any_passes defines it.
bool brute_force(const Eigen::Vector3d& origin, const std::vector<Eigen::Vector3f>& points,
                 const std::vector<Eigen::Vector3f>& dirs, double max_range, double clear_range,
                 const Eigen::Vector3d& lo_W, const Eigen::Vector3d& hi_W, double behind) {
  const auto passes = [&](const Eigen::Vector3d& end, bool returned) {
    const Eigen::Vector3d lo = lo_W - origin, hi = hi_W - origin;
    double t0 = 0.0, t1 = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double e = static_cast<float>(end[a]);  // ScanRays keeps the ends in float
      if (e == 0.0) {
        if (lo[a] > 0.0 || hi[a] < 0.0) return false;
        continue;
      }
      const double ta = std::min(lo[a] / e, hi[a] / e), tb = std::max(lo[a] / e, hi[a] / e);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      if (t0 > t1) return false;
    }
    return !returned || (1.0 - t1) * static_cast<float>(end.norm()) > behind;
  };
  for (const auto& p : points) {
    const Eigen::Vector3d rel = p.cast<double>() - origin;
    const double range = rel.norm();
    if (range <= max_range ? passes(rel, true)
                           : clear_range > 0.0 && passes(rel * (clear_range / range), false)) {
      return true;
    }
  }
  for (const auto& d : dirs) {
    if (passes(d.cast<double>() * (clear_range / d.cast<double>().norm()), false)) return true;
  }
  return false;
}

TEST(ScanRays, AnyPasses_SameAsTestingEveryRay) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::size_t agreed_true = 0, agreed_false = 0;
  ScanRays rays;
  for (int scene = 0; scene < 40; ++scene) {
    const Eigen::Vector3d origin(10.0 * u(rng), 10.0 * u(rng), 2.0 + u(rng));
    std::vector<Eigen::Vector3f> points, dirs;
    for (int i = 0; i < 3000; ++i) {
      const Eigen::Vector3d d = Eigen::Vector3d(u(rng), u(rng), 0.4 * u(rng)).normalized();
      // Ranges up to beyond max range (those clear up to the clearing range instead).
      points.push_back((origin + d * (0.5 + 30.0 * std::abs(u(rng)))).cast<float>());
    }
    for (int i = 0; i < 200; ++i) {
      dirs.push_back(Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized().cast<float>());
    }
    // Axis-aligned rays too (zero components take the slab test's other branch).
    points.push_back((origin + Eigen::Vector3d(5.0, 0.0, 0.0)).cast<float>());
    points.push_back((origin + Eigen::Vector3d(0.0, 0.0, -1.5)).cast<float>());
    rays.build(origin, points, dirs, 25.0, 12.0);
    for (int q = 0; q < 400; ++q) {
      // Boxes from voxel-sized to a few metres, some over the origin (every azimuth), some
      // behind it across the -x axis (the azimuth range wraps).
      const double size = q % 4 == 0 ? 2.0 * std::abs(u(rng)) : 0.2 * std::abs(u(rng)) + 0.01;
      Eigen::Vector3d centre = origin + Eigen::Vector3d(12.0 * u(rng), 12.0 * u(rng), u(rng));
      if (q % 10 == 0) centre.head<2>() = origin.head<2>();
      if (q % 10 == 1) centre = origin + Eigen::Vector3d(-6.0, 0.05 * u(rng), 0.3 * u(rng));
      const Eigen::Vector3d lo = centre - Eigen::Vector3d::Constant(size / 2);
      const Eigen::Vector3d hi = centre + Eigen::Vector3d::Constant(size / 2);
      const bool expected = brute_force(origin, points, dirs, 25.0, 12.0, lo, hi, 0.2);
      ASSERT_EQ(rays.any_passes(lo, hi, 0.2), expected) << "scene " << scene << " box " << q;
      (expected ? agreed_true : agreed_false) += 1;
    }
  }
  // Both answers were exercised.
  EXPECT_GT(agreed_true, 1000u);
  EXPECT_GT(agreed_false, 1000u);
}

TEST(ScanRays, MeasuredOnly_LeavesOutBeamsWithoutReturn) {
  // A box 5 m along x: crossed by a beam without a return, and by a return beyond max range
  // (a measured ray, clearing up to the clearing range).
  const Eigen::Vector3d lo(4.9, -0.1, -0.1), hi(5.1, 0.1, 0.1);
  ScanRays rays;
  const std::vector<Eigen::Vector3f> dirs{{1.0f, 0.0f, 0.0f}};
  rays.build(Eigen::Vector3d::Zero(), {}, dirs, 10.0, 20.0);
  EXPECT_TRUE(rays.any_passes(lo, hi, 0.0));
  EXPECT_FALSE(rays.any_passes(lo, hi, 0.0, /*measured_only=*/true));
  const std::vector<Eigen::Vector3f> far{{50.0f, 0.0f, 0.0f}};
  rays.build(Eigen::Vector3d::Zero(), far, {}, 10.0, 20.0);
  EXPECT_TRUE(rays.any_passes(lo, hi, 0.0, /*measured_only=*/true));
}

TEST(ScanRays, ReturnEndingJustBehindTheBox_HasNotShownItEmpty) {
  ScanRays rays;
  const std::vector<Eigen::Vector3f> points{{5.1f, 0.0f, 0.0f}};
  rays.build(Eigen::Vector3d::Zero(), points, {}, 50.0, 30.0);
  const Eigen::Vector3d lo(4.8, -0.1, -0.1), hi(5.0, 0.1, 0.1);
  EXPECT_FALSE(rays.any_passes(lo, hi, 0.2));  // ends 0.1 m behind: the same surface
  EXPECT_TRUE(rays.any_passes(lo, hi, 0.05));
  EXPECT_FALSE(rays.any_passes(lo + Eigen::Vector3d(0, 0.3, 0), hi + Eigen::Vector3d(0, 0.3, 0),
                               0.0));  // beside the ray
}

}  // namespace
}  // namespace tarmac::core
