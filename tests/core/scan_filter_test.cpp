#include "tarmac/core/scan_filter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>

#include <gtest/gtest.h>

#include "tarmac/daemon/thread_pool.hpp"

namespace tarmac::core {
namespace {

struct Fixture {
  FilterParams params;
  FilterScratch scratch;
  std::vector<Eigen::Vector3f> out_W;
  FilterCounts run(const PointCloud& cloud,
                   const Eigen::Isometry3d& T_W_S = Eigen::Isometry3d::Identity(),
                   const Eigen::Isometry3d& T_B_S = Eigen::Isometry3d::Identity()) {
    return filter_scan(cloud, T_W_S, T_B_S, params, out_W, scratch);
  }
};

/// A dense 2 m × 2 m wall patch at x = 10 (points 5 cm apart), plus `extra`.
PointCloud wall_plus(std::vector<Eigen::Vector3f> extra) {
  PointCloud cloud;
  for (float y = -1.0f; y <= 1.0f; y += 0.05f)
    for (float z = -1.0f; z <= 1.0f; z += 0.05f) cloud.points_S.emplace_back(10.0f, y, z);
  for (const auto& p : extra) cloud.points_S.push_back(p);
  return cloud;
}

TEST(ScanFilter, ParamsOutOfRangeAreRejected) {
  EXPECT_TRUE(FilterParams{}.validate().ok());
  const auto rejected = [](auto&& set) {
    FilterParams p;
    set(p);
    return !p.validate().ok();
  };
  EXPECT_TRUE(rejected([](FilterParams& p) { p.min_range_m = -1.0; }));
  EXPECT_TRUE(rejected([](FilterParams& p) { p.outlier_min_neighbors = 27; }));
  EXPECT_TRUE(rejected([](FilterParams& p) { p.outlier_cell_m = 0.01; }));
  // The outlier test's region is sized from the range: bounded, as in the YAML config.
  EXPECT_TRUE(rejected([](FilterParams& p) { p.outlier_max_range_m = 1e9; }));
  EXPECT_TRUE(rejected([](FilterParams& p) { p.outlier_max_range_m = std::nan(""); }));
  EXPECT_FALSE(rejected([](FilterParams& p) { p.outlier_max_range_m = 1000.0; }));
}

TEST(ScanFilter, CountsEachReasonAndTransformsSurvivors) {
  Fixture f;
  f.params.outlier_min_neighbors = 0;
  PointCloud cloud;
  cloud.points_S = {
      {std::nanf(""), 0, 0}, {0.3f, 0.2f, 0.1f}, {1.5f, 0.0f, -1.0f}, {5.0f, 1.0f, 0.0f}};
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = 1.9;  // sensor 1.9 m above the base
  Eigen::Isometry3d T_W_S = Eigen::Isometry3d::Identity();
  T_W_S.translation() = Eigen::Vector3d(100, 200, 2);
  const auto c = f.run(cloud, T_W_S, T_B_S);
  EXPECT_EQ(c.input, 4u);
  EXPECT_EQ(c.non_finite, 1u);
  EXPECT_EQ(c.too_close, 1u);    // 0.37 m < 1 m
  EXPECT_EQ(c.ego_vehicle, 1u);  // (1.5, 0, 0.9) in the base frame is inside the vehicle box
  EXPECT_EQ(c.kept, 1u);
  ASSERT_EQ(f.out_W.size(), 1u);
  EXPECT_EQ(f.out_W[0], Eigen::Vector3f(105, 201, 2));
}

TEST(ScanFilter, IsolatedReturnsAreDroppedDenseSurfacesKept) {
  Fixture f;
  f.params.ego_box_enabled = false;
  // Two rain drops in the air, far from anything; one pair of points close together (each has
  // one neighbour: below the default of 2 others, so both go); a drop beyond 30 m is not tested.
  const auto cloud = wall_plus({{4.0f, 2.0f, 1.0f},
                                {6.0f, -3.0f, 0.5f},
                                {7.0f, 3.0f, 0.0f},
                                {7.05f, 3.0f, 0.0f},
                                {40.0f, 0.0f, 5.0f}});
  const auto c = f.run(cloud);
  EXPECT_EQ(c.isolated, 4u);
  EXPECT_EQ(c.kept, cloud.size() - 4);
  // Every wall point survived, and the far point.
  std::size_t wall = 0;
  for (const auto& p : f.out_W) wall += p.x() == 10.0f ? 1 : 0;
  EXPECT_EQ(wall, cloud.size() - 5);
  EXPECT_EQ(f.out_W.back(), Eigen::Vector3f(40.0f, 0.0f, 5.0f));
}

TEST(ScanFilter, OutlierDecisionDoesNotDependOnPointOrder) {
  Fixture a, b;
  auto cloud =
      wall_plus({{4.0f, 2.0f, 1.0f}, {7.0f, 3.0f, 0.0f}, {7.05f, 3.0f, 0.0f}, {7.1f, 3.0f, 0.05f}});
  const auto ca = a.run(cloud);
  std::reverse(cloud.points_S.begin(), cloud.points_S.end());
  const auto cb = b.run(cloud);
  EXPECT_EQ(ca.isolated, cb.isolated);
  EXPECT_EQ(ca.isolated, 1u);  // the triple has two neighbours each and stays
  auto sa = a.out_W, sb = b.out_W;
  const auto less = [](const Eigen::Vector3f& p, const Eigen::Vector3f& q) {
    return std::tie(p.x(), p.y(), p.z()) < std::tie(q.x(), q.y(), q.z());
  };
  std::sort(sa.begin(), sa.end(), less);
  std::sort(sb.begin(), sb.end(), less);
  EXPECT_EQ(sa, sb);
}

// The outlier decision against a brute-force count over the 27 cells around each point, on
// clusters of every density near and beyond the tested range; and the sensor-frame output is
// the same survivors, in the same order, that the world-frame output transforms.
TEST(ScanFilter, OutlierDecisionMatchesBruteForceCountAndSensorFrameOutputMatches) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> centre(-35.0f, 35.0f), spread(-0.6f, 0.6f);
  std::uniform_int_distribution<int> size(1, 6);
  PointCloud cloud;
  for (int c = 0; c < 1500; ++c) {
    const Eigen::Vector3f m(centre(rng), centre(rng), centre(rng) / 10.0f);
    for (int k = size(rng); k > 0; --k)
      cloud.points_S.push_back(m + Eigen::Vector3f(spread(rng), spread(rng), spread(rng)));
  }
  Fixture f;
  f.params.ego_box_enabled = false;
  f.params.min_range_m = 0.0;
  const float inv_cell = static_cast<float>(1.0 / f.params.outlier_cell_m);
  const float near_sq =
      static_cast<float>(f.params.outlier_max_range_m * f.params.outlier_max_range_m);
  const auto cell = [&](const Eigen::Vector3f& p) {
    return std::make_tuple(static_cast<int>(std::floor(p.x() * inv_cell)),
                           static_cast<int>(std::floor(p.y() * inv_cell)),
                           static_cast<int>(std::floor(p.z() * inv_cell)));
  };
  std::map<std::tuple<int, int, int>, int> counts;
  for (const auto& p : cloud.points_S) ++counts[cell(p)];
  std::vector<Eigen::Vector3f> expected;
  for (const auto& p : cloud.points_S) {
    int around = 0;
    const auto [x, y, z] = cell(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = counts.find({x + dx, y + dy, z + dz});
          around += it == counts.end() ? 0 : it->second;
        }
    if (p.squaredNorm() >= near_sq || around >= f.params.outlier_min_neighbors + 1) {
      expected.push_back(p);
    }
  }
  Eigen::Isometry3d T_W_S = Eigen::Isometry3d::Identity();
  T_W_S.translation() = Eigen::Vector3d(-4, 7, 0.5);
  T_W_S.linear() = Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  daemon::ThreadPool pool(2);
  // Counted in the grid (the defaults' region is small enough) and in the hash table.
  for (const std::size_t grid_limit : {f.scratch.grid_cell_limit, std::size_t{0}}) {
    SCOPED_TRACE(grid_limit);
    FilterScratch scratch;
    scratch.grid_cell_limit = grid_limit;
    std::vector<Eigen::Vector3f> out_S;
    const FilterCounts c = filter_scan(cloud, T_W_S, Eigen::Isometry3d::Identity(), f.params,
                                       f.out_W, scratch, pool, &out_S);
    EXPECT_EQ(scratch.grid.empty(), grid_limit == 0);
    EXPECT_GT(c.isolated, 100u);
    EXPECT_GT(c.kept, 1000u);
    EXPECT_EQ(out_S, expected);
    ASSERT_EQ(f.out_W.size(), out_S.size());
    const Eigen::Matrix3f R = T_W_S.linear().cast<float>();
    const Eigen::Vector3f t = T_W_S.translation().cast<float>();
    for (std::size_t i = 0; i < out_S.size(); ++i) ASSERT_EQ(f.out_W[i], R * out_S[i] + t) << i;
  }
}

TEST(ScanFilter, GridAndHashTableAgreeWithPointsFarOutsideTheTestedRegion) {
  // Points beyond the outlier range are never tested but may be neighbours of near ones; points
  // far beyond (where 32-bit cell coordinates end, or where the hash key's 21-bit fields would
  // wrap onto a near cell) must not count for any near cell. Scans in a row, so that the grid
  // is emptied between them.
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<float> near(-31.0f, 31.0f), unit(0.0f, 1.0f);
  FilterParams params;
  params.ego_box_enabled = false;
  params.min_range_m = 0.0;
  FilterScratch grid, table;
  table.grid_cell_limit = 0;
  for (int scan = 0; scan < 3; ++scan) {
    PointCloud cloud;
    for (int i = 0; i < 4000; ++i) {
      const Eigen::Vector3f p(near(rng), near(rng), near(rng));
      cloud.points_S.push_back(p);
      const float u = unit(rng);
      if (u < 0.2f) {
        cloud.points_S.push_back(p + Eigen::Vector3f(0.3f, 0, 0));  // one neighbour
      } else if (u < 0.3f) {  // the same cell 2^21 cells away (a wrapped key's twin)
        cloud.points_S.push_back(p + Eigen::Vector3f(1048576.0f, 0, 0));
        cloud.points_S.push_back(p - Eigen::Vector3f(0, 0, 1048576.0f));
      } else if (u < 0.35f) {
        cloud.points_S.push_back(p * 1e8f);
      }
    }
    std::vector<Eigen::Vector3f> out_grid, out_table;
    const FilterCounts a = filter_scan(cloud, Eigen::Isometry3d::Identity(),
                                       Eigen::Isometry3d::Identity(), params, out_grid, grid);
    const FilterCounts b = filter_scan(cloud, Eigen::Isometry3d::Identity(),
                                       Eigen::Isometry3d::Identity(), params, out_table, table);
    EXPECT_FALSE(grid.grid.empty());
    EXPECT_GT(a.isolated, 1000u);
    EXPECT_EQ(a.isolated, b.isolated);
    EXPECT_EQ(out_grid, out_table);
  }
}

TEST(ScanFilter, TableSizedFromASmallerScanGivesTheSameResult) {
  // The outlier table is sized from the previous scan's distinct cells: after a scan of a few
  // cells, a scan of thousands overflows that size and starts again with room for all its
  // candidates; after a large scan, a small one uses a table sized for the large one. Either
  // way every count, point and order equals a fresh scratch's.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(-25.0f, 25.0f);
  PointCloud scattered = wall_plus({});
  for (int i = 0; i < 6000; ++i) scattered.points_S.emplace_back(u(rng), u(rng), u(rng) / 5.0f);
  const PointCloud small = wall_plus({{4.0f, 4.0f, 0.0f}});
  Fixture fresh_small, fresh_scattered;
  const FilterCounts want_small = fresh_small.run(small);
  const FilterCounts want_scattered = fresh_scattered.run(scattered);
  EXPECT_GT(want_scattered.isolated, 1000u);
  Fixture f;
  const PointCloud* const sequence[] = {&small, &scattered, &small, &scattered};
  for (const PointCloud* cloud : sequence) {
    const bool is_small = cloud == &small;
    const FilterCounts c = f.run(*cloud);
    const FilterCounts& want = is_small ? want_small : want_scattered;
    EXPECT_EQ(c.kept, want.kept);
    EXPECT_EQ(c.isolated, want.isolated);
    EXPECT_EQ(f.out_W, is_small ? fresh_small.out_W : fresh_scattered.out_W);
  }
}

TEST(ScanFilter, PerPointTestsDecideAsTheDoublePrecisionRuleOnEdgeCases) {
  // The per-point tests run four points at a time in float lanes; each decision must be the
  // rule's own: |p|² (float) below min range² in double, and the ego box tested in double in
  // the base frame. Points on both sides of each edge by a few float steps, non-finite and huge
  // ones, shuffled so that every kind lands in every lane.
  FilterParams params;
  params.outlier_min_neighbors = 0;
  params.min_range_m = 1.9;  // 3.61 is not a float, and the nearest float lies below it
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.linear() = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) *
                    Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
  T_B_S.translation() = Eigen::Vector3d(1.2, -0.1, 1.9);
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> nudge(-3, 3);
  const auto step = [&](float v) {  // v moved by a few float steps
    const int k = nudge(rng);
    for (int i = 0; i < std::abs(k); ++i)
      v = std::nextafter(v, k > 0 ? std::numeric_limits<float>::infinity() : -1e30f);
    return v;
  };
  PointCloud cloud;
  for (int i = 0; i < 3000; ++i) {  // on the min-range sphere
    const Eigen::Vector3d d = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Eigen::Vector3f p = (d * params.min_range_m).cast<float>();
    cloud.points_S.emplace_back(step(p.x()), step(p.y()), step(p.z()));
  }
  for (int i = 0; i < 6000; ++i) {  // on a face of the ego box, in the base frame
    const int axis = i % 3;
    Eigen::Vector3d p_B;
    for (int a = 0; a < 3; ++a) {
      p_B[a] = params.ego_box_min_B[a] +
               (0.5 + 0.6 * u(rng)) * (params.ego_box_max_B[a] - params.ego_box_min_B[a]);
    }
    p_B[axis] = (i / 3) % 2 == 0 ? params.ego_box_min_B[axis] : params.ego_box_max_B[axis];
    const Eigen::Vector3f p = (T_B_S.inverse() * p_B).cast<float>();
    cloud.points_S.emplace_back(step(p.x()), step(p.y()), step(p.z()));
  }
  const float inf = std::numeric_limits<float>::infinity();
  for (const Eigen::Vector3f& p : {Eigen::Vector3f(std::nanf(""), 1, 1), Eigen::Vector3f(1, inf, 1),
                                   Eigen::Vector3f(1, 1, -inf), Eigen::Vector3f(0, 0, 1.1f),
                                   Eigen::Vector3f(1e30f, -1e30f, 1e30f),
                                   Eigen::Vector3f(3e9f, 5, 1), Eigen::Vector3f(0, 0, 0)}) {
    for (int k = 0; k < 5; ++k) cloud.points_S.push_back(p);
  }
  std::shuffle(cloud.points_S.begin(), cloud.points_S.end(), rng);
  FilterCounts want;
  want.input = cloud.size();
  std::vector<Eigen::Vector3f> want_S;
  for (const Eigen::Vector3f& p : cloud.points_S) {
    if (!p.allFinite()) {
      ++want.non_finite;
    } else if (static_cast<double>(p.squaredNorm()) < params.min_range_m * params.min_range_m) {
      ++want.too_close;
    } else {
      const Eigen::Vector3d p_B = T_B_S * p.cast<double>();
      if ((p_B.array() >= params.ego_box_min_B.array()).all() &&
          (p_B.array() <= params.ego_box_max_B.array()).all()) {
        ++want.ego_vehicle;
      } else {
        want_S.push_back(p);
      }
    }
  }
  EXPECT_GT(want.too_close, 1000u);
  EXPECT_GT(want.ego_vehicle, 1500u);
  EXPECT_GT(want_S.size(), 4000u);
  FilterScratch scratch;
  std::vector<Eigen::Vector3f> out_W, out_S;
  daemon::ThreadPool pool(2);
  const FilterCounts c = filter_scan(cloud, Eigen::Isometry3d::Identity(), T_B_S, params, out_W,
                                     scratch, pool, &out_S);
  EXPECT_EQ(c.non_finite, want.non_finite);
  EXPECT_EQ(c.too_close, want.too_close);
  EXPECT_EQ(c.ego_vehicle, want.ego_vehicle);
  EXPECT_EQ(c.kept, want_S.size());
  EXPECT_EQ(out_S, want_S);
}

TEST(ScanFilter, HugeCoordinatesAndUnvalidatedParamsDecideAsTheRule) {
  FilterParams params;
  params.ego_box_enabled = false;
  params.min_range_m = 0.0;
  // Two near points one cell apart, each with one neighbour (2 needed): both isolated. A point
  // at 1e30 m (beyond any cell coordinate) must not count as anyone's neighbour, whether it is
  // tested in the lanes or one at a time (a cloud of 3 takes the latter, of 7 the former).
  const Eigen::Vector3f a(0.2f, 0.0f, 1.2f), b(0.3f, 0.0f, 1.2f), g(1e30f, 0.0f, 1.2f);
  for (const std::vector<Eigen::Vector3f>& points :
       {std::vector<Eigen::Vector3f>{a, b, g},
        std::vector<Eigen::Vector3f>{a, b, g, g, g, g, Eigen::Vector3f(0, 0, 2e9f)}}) {
    for (const std::size_t grid_limit : {std::size_t{1} << 23, std::size_t{0}}) {
      PointCloud cloud;
      cloud.points_S = points;
      FilterScratch scratch;
      scratch.grid_cell_limit = grid_limit;
      std::vector<Eigen::Vector3f> out;
      const FilterCounts c = filter_scan(cloud, Eigen::Isometry3d::Identity(),
                                         Eigen::Isometry3d::Identity(), params, out, scratch);
      EXPECT_EQ(c.isolated, 2u) << points.size() << " points, grid limit " << grid_limit;
    }
  }
  // A scratch reserved for parameters without a grid, then used with one, starts from an
  // empty grid.
  {
    PointCloud dense = wall_plus({});
    PointCloud pair;
    pair.points_S = {a, b};
    FilterScratch scratch;
    std::vector<Eigen::Vector3f> out;
    filter_scan(dense, Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity(), params, out,
                scratch);
    FilterParams no_outliers = params;
    no_outliers.outlier_min_neighbors = 0;
    scratch.reserve(64, no_outliers);
    PointCloud near_wall;
    near_wall.points_S = {Eigen::Vector3f(10.0f, 0.0f, 0.0f), Eigen::Vector3f(10.1f, 0.0f, 0.0f)};
    const FilterCounts c = filter_scan(near_wall, Eigen::Isometry3d::Identity(),
                                       Eigen::Isometry3d::Identity(), params, out, scratch);
    EXPECT_EQ(c.isolated, 2u);  // the wall's counts are gone
  }
  // Unvalidated: an outlier range of 1e6 m. Forty points in one cell at 60 km have 39
  // neighbours each: none is isolated (the region covers 50 km; farther points are not tested).
  {
    FilterParams far = params;
    far.outlier_max_range_m = 1e6;
    PointCloud cloud;
    for (int i = 0; i < 40; ++i) cloud.points_S.emplace_back(60000.0f + 0.01f * i, 0.0f, 0.0f);
    FilterScratch scratch;
    std::vector<Eigen::Vector3f> out;
    const FilterCounts c = filter_scan(cloud, Eigen::Isometry3d::Identity(),
                                       Eigen::Isometry3d::Identity(), far, out, scratch);
    EXPECT_EQ(c.isolated, 0u);
  }
}

TEST(ScanFilter, EgoBoxDecidedByTheRuleWhenExtrinsicsOverflowFloats) {
  // A (degenerate) extrinsic beyond float's range: p_B = (1, 1, 0), inside the box, for every
  // point. The lanes' float pre-test cannot say "surely outside" for any of them.
  FilterParams params;
  params.outlier_min_neighbors = 0;
  params.min_range_m = 0.0;
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.linear() = Eigen::Vector3d(1e39, 0.1, 0.1).asDiagonal();
  PointCloud cloud;
  for (int i = 0; i < 32; ++i) cloud.points_S.emplace_back(1e-39f, 10.0f, 0.0f);
  FilterScratch scratch;
  std::vector<Eigen::Vector3f> out;
  const FilterCounts c =
      filter_scan(cloud, Eigen::Isometry3d::Identity(), T_B_S, params, out, scratch);
  EXPECT_EQ(c.ego_vehicle, 32u);
}

TEST(ScanFilter, SameResultForOneTwoAndFourThreads) {
  // Every reason in one cloud: a dense wall, scattered isolated points near and far, points in
  // the ego box and too close, non-finite ones; the point ranges split it unevenly.
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-40.0f, 40.0f);
  PointCloud cloud = wall_plus({});
  for (int i = 0; i < 5003; ++i) cloud.points_S.emplace_back(u(rng), u(rng), u(rng) / 8.0f);
  for (int i = 0; i < 300; ++i) cloud.points_S.emplace_back(u(rng) / 20.0f, u(rng) / 40.0f, 0.5f);
  cloud.points_S.insert(cloud.points_S.begin() + 17, Eigen::Vector3f(std::nanf(""), 0, 0));
  Eigen::Isometry3d T_W_S = Eigen::Isometry3d::Identity();
  T_W_S.translation() = Eigen::Vector3d(3, -2, 1);
  T_W_S.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  Fixture serial;
  const FilterCounts expected = serial.run(cloud, T_W_S);
  EXPECT_GT(expected.isolated, 0u);
  EXPECT_GT(expected.ego_vehicle, 0u);
  EXPECT_GT(expected.too_close, 0u);
  EXPECT_EQ(expected.non_finite, 1u);
  for (const std::size_t threads : {1u, 2u, 4u}) {
    daemon::ThreadPool pool(threads);
    Fixture f;
    const FilterCounts c = filter_scan(cloud, T_W_S, Eigen::Isometry3d::Identity(), f.params,
                                       f.out_W, f.scratch, pool);
    EXPECT_EQ(c.non_finite, expected.non_finite);
    EXPECT_EQ(c.too_close, expected.too_close);
    EXPECT_EQ(c.ego_vehicle, expected.ego_vehicle);
    EXPECT_EQ(c.isolated, expected.isolated);
    EXPECT_EQ(c.kept, expected.kept);
    EXPECT_EQ(f.out_W, serial.out_W);  // same points, same order
  }
}

}  // namespace
}  // namespace tarmac::core
