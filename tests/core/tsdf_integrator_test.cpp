#include "tarmac/core/tsdf_integrator.hpp"

#include <cmath>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "tarmac/daemon/thread_pool.hpp"

namespace tarmac::core {
namespace {

TsdfParams params_01() {
  TsdfParams p;
  p.voxel_size_m = 0.1f;
  p.truncation_m = 0.3f;
  p.max_weight = 64.f;
  p.max_range_m = 100.f;
  return p;
}

/// Unit directions spread evenly over the sphere (Fibonacci lattice).
std::vector<Eigen::Vector3d> sphere_directions(int n) {
  std::vector<Eigen::Vector3d> dirs;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n;
    const double r = std::sqrt(1.0 - z * z);
    dirs.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return dirs;
}

struct ObservedVoxel {
  TsdfVoxelIndex v;
  TsdfVoxel value;
};

std::vector<ObservedVoxel> observed(const TsdfLayer& layer) {
  std::vector<ObservedVoxel> out;
  layer.for_each_block([&](const TsdfBlockView& b) {
    for (int i = 0; i < 8; ++i)
      for (int j = 0; j < 8; ++j)
        for (int k = 0; k < 8; ++k) {
          const int n = tsdf_voxel_offset(i, j, k);
          if (b.voxels[n].weight > 0.0f) {
            out.push_back({b.block * 8 + TsdfVoxelIndex(i, j, k), b.voxels[n]});
          }
        }
  });
  return out;
}

TEST(TsdfParams, Validate_RejectsBadValues) {
  EXPECT_TRUE(params_01().validate().ok());
  TsdfParams p = params_01();
  p.truncation_m = 0.05f;  // below one voxel
  EXPECT_FALSE(p.validate().ok());
  EXPECT_EQ(p.validate().error().message.rfind("tsdf.truncation_m", 0), 0u);
  p = params_01();
  p.max_weight = 0.5f;
  EXPECT_FALSE(p.validate().ok());
  p = params_01();
  p.voxel_size_m = std::nanf("");
  EXPECT_FALSE(p.validate().ok());
}

// A sphere of radius R centred on the sensor: every ray returns at range R, and the projective
// distance R − |c − o| of a voxel centre c *is* its Euclidean signed distance to the sphere. So
// the TSDF must equal the analytic value up to float rounding (values are computed in double,
// stored as float: |error| <= 2^-24·0.3 m per sample; merging k samples of one voxel adds k
// roundings of the sum: 1e-6 m is > 10× that bound for k <= 16).
TEST(TsdfIntegrator, Sphere_EqualsAnalyticSignedDistance) {
  const TsdfParams params = params_01();
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.537, -1.213, 0.771);
  const double R = 3.0;
  std::vector<Eigen::Vector3f> points;
  for (const auto& d : sphere_directions(40000)) points.push_back((o + R * d).cast<float>());
  SerialRunner runner;
  const TsdfUpdate& up = integrator.integrate(o, points, layer, runner);
  EXPECT_EQ(up.rays, points.size());
  const auto voxels = observed(layer);
  ASSERT_GT(voxels.size(), 20000u);
  EXPECT_EQ(up.voxel_updates, voxels.size());
  double max_err = 0.0;
  for (const auto& ov : voxels) {
    const double truth = R - (layer.center_of(ov.v) - o).norm();
    ASSERT_LE(std::abs(truth), params.truncation_m + 1e-6) << "voxel outside the band touched";
    max_err = std::max(max_err, std::abs(ov.value.distance_m - truth));
    EXPECT_EQ(ov.value.weight, 1.0f);
  }
  EXPECT_LE(max_err, 1e-6);
  // Completeness: every voxel centre within ±0.2 m of the sphere along a ray is observed.
  for (const auto& d : sphere_directions(500)) {
    for (const double t : {R - 0.2, R - 0.1, R, R + 0.1, R + 0.2}) {
      EXPECT_TRUE(layer.voxel(layer.voxel_of(o + t * d)).has_value()) << t;
    }
  }
}

// A wall x = X seen within ±alpha of its normal. The projective distance of a voxel centre at
// Euclidean distance s from the wall is s / cos(theta) for a ray through that centre, and the
// ray that actually sampled the voxel passes within half a voxel diagonal h of its centre,
// i.e. deviates by at most h / (X − trunc) rad, changing the range by
// dr/dtheta = X·tan(theta)/cos(theta) per rad. So |tsdf − s| <= trunc·(1/cos a − 1)
// + X·tan(a)/cos(a) · h/(X − trunc).
TEST(TsdfIntegrator, Plane_EqualsAnalyticSignedDistanceWithinProjectiveBound) {
  const TsdfParams params = params_01();
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.02, 0.03, 0.04);
  const double X = 10.07;
  const double alpha = 3.0 * M_PI / 180.0;
  std::vector<Eigen::Vector3f> points;
  const int n = 120;
  for (int i = -n; i <= n; ++i) {
    for (int j = -n; j <= n; ++j) {
      const double ay = alpha * i / n / std::sqrt(2.0), az = alpha * j / n / std::sqrt(2.0);
      const Eigen::Vector3d d = Eigen::Vector3d(1.0, std::tan(ay), std::tan(az)).normalized();
      const double r = (X - o.x()) / d.x();
      points.push_back((o + r * d).cast<float>());
    }
  }
  SerialRunner runner;
  integrator.integrate(o, points, layer, runner);
  const double v = params.voxel_size_m, trunc = params.truncation_m;
  const double h = 0.5 * std::sqrt(3.0) * v;
  const double Xr = X - o.x();
  const double bound = trunc * (1.0 / std::cos(alpha) - 1.0) +
                       Xr * std::tan(alpha) / std::cos(alpha) * h / (Xr - trunc) + 1e-5;
  const auto voxels = observed(layer);
  ASSERT_GT(voxels.size(), 300u);  // a 0.74 m square patch, 6 voxel layers deep
  std::set<int> layers_x;
  for (const auto& ov : voxels) {
    const double truth = X - layer.center_of(ov.v).x();
    EXPECT_LE(std::abs(ov.value.distance_m - truth), bound) << ov.v.transpose();
    layers_x.insert(ov.v.x());
  }
  // The band is 2·trunc thick: voxel layers x = 98..103 (centres 9.85 .. 10.35).
  EXPECT_EQ(*layers_x.begin(), 98);
  EXPECT_EQ(*layers_x.rbegin(), 103);
}

/// The voxels whose centre lies within the band, among those crossed by the segment
/// [r − trunc, r + trunc] of a ray: reference by dense sampling of the segment.
std::set<std::tuple<int, int, int>> band_reference(const Eigen::Vector3d& o,
                                                   const Eigen::Vector3d& p, double v,
                                                   double trunc) {
  std::set<std::tuple<int, int, int>> out;
  const double r = (p - o).norm();
  const Eigen::Vector3d d = (p - o) / r;
  const int steps = 200000;
  for (int i = 0; i <= steps; ++i) {
    const double t = r - trunc + 2.0 * trunc * i / steps;
    const Eigen::Vector3i q = ((o + t * d) / v).array().floor().cast<int>();
    const Eigen::Vector3d c = (q.cast<double>().array() + 0.5) * v;
    if (std::abs(r - (c - o).norm()) <= trunc) out.emplace(q.x(), q.y(), q.z());
  }
  return out;
}

TEST(TsdfIntegrator, Integrate_TouchesOnlyTheBandAlongEachRay) {
  const TsdfParams params = params_01();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    TsdfIntegrator integrator(params);
    TsdfLayer layer = integrator.make_layer();
    const Eigen::Vector3d o(u(rng), u(rng), u(rng));
    const Eigen::Vector3d p = o + Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized() * 7.3;
    const std::vector<Eigen::Vector3f> pts{p.cast<float>()};
    SerialRunner runner;
    integrator.integrate(o, pts, layer, runner);
    // The reference uses the float-rounded point, like the integrator.
    const auto ref =
        band_reference(o, pts[0].cast<double>(), params.voxel_size_m, params.truncation_m);
    std::set<std::tuple<int, int, int>> got;
    for (const auto& ov : observed(layer)) got.emplace(ov.v.x(), ov.v.y(), ov.v.z());
    EXPECT_EQ(got, ref) << "trial " << trial;
  }
}

TEST(TsdfIntegrator, Integrate_SkipsNonFiniteAndFarPoints) {
  TsdfParams params = params_01();
  params.max_range_m = 20.f;
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  const std::vector<Eigen::Vector3f> pts{
      {5.f, 0.f, 0.f}, {std::nanf(""), 0.f, 0.f}, {30.f, 0.f, 0.f}, {0.f, INFINITY, 0.f}};
  SerialRunner runner;
  const auto& up = integrator.integrate(Eigen::Vector3d::Zero(), pts, layer, runner);
  EXPECT_EQ(up.rays, 1u);
  EXPECT_FALSE(layer.voxel(layer.voxel_of({25.0, 0.05, 0.05})).has_value());
  EXPECT_TRUE(layer.voxel(layer.voxel_of({5.0, 0.05, 0.05})).has_value());
}

// Two returns in one scan observing the same voxel: one update, weight 1, their mean distance.
TEST(TsdfIntegrator, OncePerScan_MergesObservationsOfAVoxel) {
  TsdfIntegrator integrator(params_01());
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.05, 0.05, 0.05);
  // Both rays along +x through voxel centres (k, 0, 0); returns at 5.02 and 5.12 m.
  const std::vector<Eigen::Vector3f> pts{{5.07f, 0.05f, 0.05f}, {5.17f, 0.05f, 0.05f}};
  SerialRunner runner;
  const auto& up = integrator.integrate(o, pts, layer, runner);
  const TsdfVoxelIndex v(50, 0, 0);  // centre 5.05: sdf 5.02 − 5.0 and 5.12 − 5.0
  const auto vox = layer.voxel(v);
  ASSERT_TRUE(vox.has_value());
  EXPECT_EQ(vox->weight, 1.0f);
  const float a = static_cast<float>(5.07f - 0.05 - 5.0),
              b = static_cast<float>(5.17f - 0.05 - 5.0);
  EXPECT_NEAR(vox->distance_m, 0.5f * (a + b), 1e-6);
  EXPECT_LT(up.voxel_updates, up.samples);  // merged
}

// Weights count scans up to max_weight; below the cap the distance is the plain mean; at the
// cap it is an exponential moving average with factor 1/(max_weight + 1), so a moved surface is
// re-learnt: after k scans of a new value b the distance is b + (a − b)·(W/(W+1))^k.
TEST(TsdfIntegrator, WeightCap_SurfaceCanMove) {
  TsdfParams params = params_01();
  params.max_weight = 8.f;
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.05, 0.05, 0.05);
  const TsdfVoxelIndex v(50, 0, 0);  // centre at 5.0 m along the ray
  SerialRunner runner;
  const auto scan_at = [&](float range) {
    const std::vector<Eigen::Vector3f> pts{{0.05f + range, 0.05f, 0.05f}};
    integrator.integrate(o, pts, layer, runner);
  };
  const auto sdf_of = [](float range) {
    return static_cast<float>(static_cast<double>(0.05f + range) - 0.05 - 5.0);
  };
  // Below the cap: mean of the observations.
  scan_at(5.10f);
  scan_at(5.20f);
  scan_at(4.90f);
  EXPECT_EQ(layer.voxel(v)->weight, 3.0f);
  EXPECT_NEAR(layer.voxel(v)->distance_m, (sdf_of(5.10f) + sdf_of(5.20f) + sdf_of(4.90f)) / 3.0f,
              1e-6);
  for (int i = 0; i < 20; ++i) scan_at(5.10f);
  EXPECT_EQ(layer.voxel(v)->weight, 8.0f);
  const double a = layer.voxel(v)->distance_m;
  const double b = sdf_of(4.85f);
  for (int k = 1; k <= 30; ++k) {
    scan_at(4.85f);
    EXPECT_EQ(layer.voxel(v)->weight, 8.0f);
    EXPECT_NEAR(layer.voxel(v)->distance_m, b + (a - b) * std::pow(8.0 / 9.0, k), 1e-5) << k;
  }
  // The surface moved from +0.1 to −0.15: after 30 scans the voxel reads the new side.
  EXPECT_LT(layer.voxel(v)->distance_m, -0.13f);
}

TEST(TsdfIntegrator, SpaceCarving_MarksFreeSpaceInFrontOfTheBand) {
  TsdfParams params = params_01();
  const std::vector<Eigen::Vector3f> pts{{8.05f, 0.05f, 0.05f}};
  const Eigen::Vector3d o(0.05, 0.05, 0.05);
  SerialRunner runner;
  {
    TsdfIntegrator integrator(params);
    TsdfLayer layer = integrator.make_layer();
    integrator.integrate(o, pts, layer, runner);
    EXPECT_FALSE(layer.voxel({30, 0, 0}).has_value());
  }
  params.space_carving = true;
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  integrator.integrate(o, pts, layer, runner);
  for (int x = 0; x < 77; ++x) {
    const auto vox = layer.voxel({x, 0, 0});
    ASSERT_TRUE(vox.has_value()) << x;
    EXPECT_EQ(vox->distance_m, params.truncation_m) << x;
  }
  EXPECT_NEAR(layer.voxel({80, 0, 0})->distance_m, 0.0f, 1e-6);
}

/// A few scans of a small synthetic scene (ground, walls, a sphere) from a moving sensor.
std::vector<std::pair<Eigen::Vector3d, std::vector<Eigen::Vector3f>>> synthetic_scans() {
  std::vector<std::pair<Eigen::Vector3d, std::vector<Eigen::Vector3f>>> scans;
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int s = 0; s < 4; ++s) {
    const Eigen::Vector3d o(0.3 * s, 0.1 * s, 1.8);
    std::vector<Eigen::Vector3f> pts;
    for (int i = 0; i < 30000; ++i) {
      const double az = 2 * M_PI * u(rng), el = (-25.0 + 40.0 * u(rng)) * M_PI / 180.0;
      const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                              std::sin(el));
      double r = 1e9;
      if (d.z() < 0) r = std::min(r, -o.z() / d.z());          // ground
      if (d.x() > 0) r = std::min(r, (12.0 - o.x()) / d.x());  // wall
      if (d.y() < 0) r = std::min(r, (-9.0 - o.y()) / d.y());  // wall
      const Eigen::Vector3d c(4.0, 3.0, 1.0), oc = o - c;      // sphere
      const double bq = oc.dot(d), cq = oc.squaredNorm() - 1.0, disc = bq * bq - cq;
      if (disc > 0 && -bq - std::sqrt(disc) > 0) r = std::min(r, -bq - std::sqrt(disc));
      if (r < 40.0) pts.push_back((o + (r + 0.01 * (u(rng) - 0.5)) * d).cast<float>());
    }
    scans.emplace_back(o, std::move(pts));
  }
  return scans;
}

TEST(TsdfIntegrator, Determinism_DigestIdenticalFor1To4Threads) {
  const auto scans = synthetic_scans();
  std::vector<std::uint64_t> digests;
  std::vector<std::size_t> counts;
  for (const std::size_t threads : {1u, 2u, 4u}) {
    daemon::ThreadPool pool(threads);
    TsdfIntegrator integrator(params_01());
    TsdfLayer layer = integrator.make_layer();
    for (const auto& [o, pts] : scans) integrator.integrate(o, pts, layer, pool);
    digests.push_back(layer.digest());
    counts.push_back(layer.voxel_count());
  }
  EXPECT_GT(counts[0], 100000u);
  EXPECT_EQ(digests[0], digests[1]);
  EXPECT_EQ(digests[0], digests[2]);
  EXPECT_EQ(counts[0], counts[2]);
}

/// An integrator without spares and one with a reserve of `reserve_blocks`, each with its layer:
/// the two must build the same map.
struct PlainAndReserved {
  static TsdfParams with_reserve(std::uint32_t reserve_blocks) {
    TsdfParams p = params_01();
    p.reserve_blocks = reserve_blocks;
    return p;
  }
  explicit PlainAndReserved(std::uint32_t reserve_blocks)
      : reserved_params(with_reserve(reserve_blocks)), reserved(reserved_params) {}

  TsdfIntegrator plain{params_01()};
  TsdfLayer plain_layer = plain.make_layer();
  TsdfParams reserved_params;
  TsdfIntegrator reserved;
  TsdfLayer reserved_layer = reserved.make_layer();
};

TEST(TsdfIntegrator, ReserveBlocks_SameMapAndSparesTakenFirst) {
  const auto scans = synthetic_scans();
  SerialRunner runner;
  PlainAndReserved maps(100);  // fewer than the scans create: spares run out
  auto& [plain, plain_layer, reserved_params, reserved, reserved_layer] = maps;
  ASSERT_EQ(reserved.spare_blocks(), 112u);  // 7 per partition
  std::size_t created = 0;
  for (const auto& [o, pts] : scans) {
    plain.integrate(o, pts, plain_layer, runner);
    created += reserved.integrate(o, pts, reserved_layer, runner).blocks_created;
  }
  ASSERT_GT(created, 112u);
  EXPECT_EQ(reserved.spare_blocks(), 0u);
  EXPECT_EQ(plain_layer.digest(), reserved_layer.digest());
  reserved.reserve_blocks(20);
  EXPECT_EQ(reserved.spare_blocks(), 32u);  // 2 per partition
}

// The daemon's top-up (SpareBlocksFiller): spares built elsewhere between scans, handed over
// while the map grows, and the per-scan scratch reserved up front: the same map, and each
// scan after the first takes spares rather than allocating its new blocks.
TEST(TsdfIntegrator, SparesToppedUpBetweenScansAndScratchReserved_SameMap) {
  const auto scans = synthetic_scans();
  SerialRunner runner;
  PlainAndReserved maps(160);
  auto& [plain, plain_layer, topped_params, topped, topped_layer] = maps;
  topped.reserve_scan(4096);
  EXPECT_TRUE(topped.spare_shortfall().empty());
  EXPECT_EQ(topped.spares(), TsdfIntegrator::spare_target(160));
  std::size_t created = 0;
  for (const auto& [o, pts] : scans) {
    plain.integrate(o, pts, plain_layer, runner);
    const std::size_t before = topped.spare_blocks();
    const std::size_t made = topped.integrate(o, pts, topped_layer, runner).blocks_created;
    created += made;
    // New blocks come out of the spares first (a partition whose spares ran out allocates).
    EXPECT_LE(topped.spare_blocks(), before);
    EXPECT_GE(topped.spare_blocks() + made, before);
    if (made > 0) {
      EXPECT_LT(topped.spare_blocks(), before);
    }
    const TsdfSpareCount shortfall = topped.spare_shortfall();
    EXPECT_EQ(shortfall.blocks, 160u - topped.spare_blocks());
    TsdfSpareBlocks batch = TsdfSpareBlocks::build(topped_params, shortfall);
    EXPECT_EQ(batch.size(), shortfall);
    topped.add_spares(std::move(batch));
    EXPECT_TRUE(topped.spare_shortfall().empty());
  }
  ASSERT_GT(created, 160u);  // more blocks than one reserve: the top-ups were used
  EXPECT_EQ(plain_layer.digest(), topped_layer.digest());
  // The same tree, nodes included: spare nodes went exactly where the tree would build its own.
  EXPECT_EQ(plain_layer.memory_bytes(), topped_layer.memory_bytes());
  EXPECT_EQ(plain_layer.block_count(), topped_layer.block_count());
}

// The first scan into an empty map builds the tree's nodes too (the scans sit around the origin:
// all 8 top nodes): with a reserve, it takes spare nodes rather than building them, and the
// tree is the one built without spares.
TEST(TsdfIntegrator, ReserveBlocks_FirstScanTakesSpareNodes_SameTree) {
  const auto scans = synthetic_scans();
  SerialRunner runner;
  PlainAndReserved maps(4096);
  auto& [plain, plain_layer, reserved_params, reserved, reserved_layer] = maps;
  const TsdfSpareCount target = TsdfIntegrator::spare_target(4096);
  ASSERT_EQ(reserved.spares(), target);
  EXPECT_EQ(target.nodes, 64u);
  EXPECT_EQ(target.top_nodes, 8u);
  EXPECT_EQ(plain.spares(), TsdfSpareCount{});

  plain.integrate(scans[0].first, scans[0].second, plain_layer, runner);
  reserved.integrate(scans[0].first, scans[0].second, reserved_layer, runner);
  EXPECT_EQ(reserved.spares().top_nodes, 0u);  // one per octant around the origin
  EXPECT_LT(reserved.spares().nodes, target.nodes);
  EXPECT_EQ(plain_layer.digest(), reserved_layer.digest());
  EXPECT_EQ(plain_layer.memory_bytes(), reserved_layer.memory_bytes());
  // Without top nodes left, nodes still go under the top nodes the tree has; later scans build
  // what the spares do not cover, as without a reserve.
  const std::size_t nodes_left = reserved.spares().nodes;
  for (std::size_t k = 1; k < scans.size(); ++k) {
    plain.integrate(scans[k].first, scans[k].second, plain_layer, runner);
    reserved.integrate(scans[k].first, scans[k].second, reserved_layer, runner);
  }
  EXPECT_LE(reserved.spares().nodes, nodes_left);
  EXPECT_EQ(plain_layer.digest(), reserved_layer.digest());
  EXPECT_EQ(plain_layer.memory_bytes(), reserved_layer.memory_bytes());
  // A reserve tops the spares up again.
  reserved.reserve_blocks(4096);
  EXPECT_EQ(reserved.spares(), target);
}

TEST(TsdfIntegrator, Update_ReportsEveryChangedBlockOnce) {
  const auto scans = synthetic_scans();
  TsdfIntegrator integrator(params_01());
  TsdfLayer layer = integrator.make_layer();
  SerialRunner runner;
  const auto& up = integrator.integrate(scans[0].first, scans[0].second, layer, runner);
  std::set<std::tuple<int, int, int>> blocks;
  for (const auto& b : up.blocks) blocks.emplace(b.x(), b.y(), b.z());
  EXPECT_EQ(blocks.size(), up.blocks.size());
  EXPECT_EQ(blocks.size(), layer.block_count());
  EXPECT_EQ(up.blocks_created, layer.block_count());
  std::size_t in_layer = 0;
  layer.for_each_block([&](const TsdfBlockView& b) {
    in_layer += blocks.count({b.block.x(), b.block.y(), b.block.z()});
  });
  EXPECT_EQ(in_layer, blocks.size());
  // A second scan from the same place creates (almost) nothing new but updates blocks again.
  const auto& up2 = integrator.integrate(scans[0].first, scans[0].second, layer, runner);
  EXPECT_EQ(up2.blocks_created, 0u);
  EXPECT_EQ(up2.blocks.size(), blocks.size());
}

// The integrator caches leaf pointers inside the layer: clearing the layer (or any outside
// mutation through grids()) must drop them, so integrating afterwards equals a fresh layer.
TEST(TsdfIntegrator, LeafCache_ClearGivesTheSameMapAsAFreshLayer) {
  const auto scans = synthetic_scans();
  TsdfIntegrator integrator(params_01());
  SerialRunner runner;
  TsdfLayer fresh = integrator.make_layer();
  integrator.integrate(scans[1].first, scans[1].second, fresh, runner);
  TsdfLayer reused = integrator.make_layer();
  integrator.integrate(scans[0].first, scans[0].second, reused, runner);
  reused.clear();
  EXPECT_EQ(reused.block_count(), 0u);
  integrator.integrate(scans[1].first, scans[1].second, reused, runner);
  EXPECT_EQ(reused.digest(), fresh.digest());
}

}  // namespace
}  // namespace tarmac::core
