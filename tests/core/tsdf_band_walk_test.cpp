// The TSDF's band walk (core/src/tsdf_band_walk.hpp) against OpenVDB's DDA: the same voxels in
// the same order on random rays, and the band and carving rules on rays whose answer is known.

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <openvdb/math/DDA.h>
#include <openvdb/math/Ray.h>

#include "tsdf_band_walk.hpp"

namespace tarmac::core {
namespace {

struct Visit {
  int x, y, z;
  bool operator==(const Visit&) const = default;
};

/// Every voxel of the segment, band or not (trunc larger than any distance here).
std::vector<Visit> ours(const Eigen::Vector3d& o, const Eigen::Vector3d& dir, double t0, double t1,
                        double v) {
  std::vector<Visit> out;
  walk_band<false>(o, dir, 0.0, t0, t1, v, 1e9, [&](int x, int y, int z, float) {
    out.push_back({x, y, z});
  });
  return out;
}

std::vector<Visit> dda(const Eigen::Vector3d& o, const Eigen::Vector3d& dir, double t0, double t1,
                       double v) {
  using Ray = openvdb::math::Ray<double>;
  const Ray ray(openvdb::Vec3d(o.x() / v, o.y() / v, o.z() / v),
                openvdb::Vec3d(dir.x(), dir.y(), dir.z()), t0 / v, t1 / v);
  openvdb::math::DDA<Ray, 0> walk(ray);
  std::vector<Visit> out;
  do {
    out.push_back({walk.voxel().x(), walk.voxel().y(), walk.voxel().z()});
  } while (walk.step());
  return out;
}

TEST(TsdfBandWalk, SameVoxelsInTheSameOrderAsOpenVdbsDda) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> pos(-30.0, 30.0), len(0.05, 8.0), ang(-1.0, 1.0);
  int compared = 0;
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d o(pos(rng), pos(rng), 0.1 * pos(rng));
    Eigen::Vector3d dir(ang(rng), ang(rng), 0.3 * ang(rng));
    if (dir.norm() < 1e-3) continue;
    dir.normalize();
    const double t0 = 20.0 * std::abs(ang(rng));
    const double t1 = t0 + len(rng);
    for (const double v : {0.1, 0.2}) {
      const auto a = ours(o, dir, t0, t1, v);
      const auto b = dda(o, dir, t0, t1, v);
      ASSERT_EQ(a, b) << "ray " << i << " voxel " << v;
      ++compared;
    }
  }
  EXPECT_GT(compared, 39000);
}

TEST(TsdfBandWalk, EmitsOnlyTheBandAndCarvingClampsInFront) {
  // Along +x from a voxel centre, return 1.02 m away, 0.1 m voxels, band 0.3 m, segment to
  // 1.32 m: the voxels k = 0 … 13 from the sensor's, at distance 1.02 − 0.1·k from the return.
  const Eigen::Vector3d o(0.05, 0.05, 0.05), dir(1.0, 0.0, 0.0);
  std::vector<float> band;
  const std::size_t n = walk_band<false>(o, dir, 1.02, 0.0, 1.32, 0.1, 0.3,
                                         [&](int, int, int, float sdf) { band.push_back(sdf); });
  ASSERT_EQ(n, 6u);  // k = 8 … 13 are within ±0.3 m
  ASSERT_EQ(band.size(), 6u);
  EXPECT_NEAR(band.front(), 0.22f, 1e-5f);
  EXPECT_NEAR(band.back(), -0.28f, 1e-5f);
  std::vector<float> carved;
  walk_band<true>(o, dir, 1.02, 0.0, 1.32, 0.1, 0.3,
                  [&](int, int, int, float sdf) { carved.push_back(sdf); });
  ASSERT_EQ(carved.size(), 14u);  // every voxel from the sensor's, k = 0 … 7 clamped
  EXPECT_EQ(carved.front(), 0.3f);
  EXPECT_EQ(carved[7], 0.3f);
  EXPECT_NEAR(carved[8], 0.22f, 1e-5f);
}

}  // namespace
}  // namespace tarmac::core
