#include "tarmac/core/organised_scan.hpp"

#include <cmath>
#include <limits>
#include <numbers>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// A spinning LiDAR's organised sweep: `rows` beams evenly spaced over elevations [lo, hi] deg,
/// `cols` azimuths 2π·c/cols; returns at `range` where `hit(r, c)`, NaN (or the origin) elsewhere.
template <typename Hit>
PointCloud sweep(int rows, int cols, double lo_deg, double hi_deg, Hit hit, bool zeros = false) {
  PointCloud cloud;
  for (int r = 0; r < rows; ++r) {
    const double el = (lo_deg + (hi_deg - lo_deg) * r / (rows - 1)) * std::numbers::pi / 180.0;
    for (int c = 0; c < cols; ++c) {
      const double az = 2.0 * std::numbers::pi * c / cols;
      const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az),
                              std::sin(el));
      if (hit(r, c)) {
        cloud.points_S.push_back(((10.0 + 0.1 * (c % 7)) * d).cast<float>());
      } else {
        cloud.points_S.push_back(zeros ? Eigen::Vector3f::Zero() : Eigen::Vector3f::Constant(kNaN));
      }
      cloud.intensity.push_back(static_cast<float>(r * cols + c));
    }
  }
  return cloud;
}

/// The direction the sweep's beam (r, c) has.
Eigen::Vector3f beam(int r, int c, int rows, int cols, double lo_deg, double hi_deg) {
  const double el = (lo_deg + (hi_deg - lo_deg) * r / (rows - 1)) * std::numbers::pi / 180.0;
  const double az = 2.0 * std::numbers::pi * c / cols;
  return Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el))
      .cast<float>();
}

TEST(OrganisedScan, SkyRowsAndEmptyColumns_DirectionsRebuiltFromTheReturns) {
  // 16 beams over -15..15 deg, 64 columns: the upper 6 rows return nothing (sky), nor do columns
  // 10..14 (an opening), nor every 5th cell below (dropouts).
  const int rows = 16, cols = 64;
  const auto hit = [](int r, int c) {
    return r < 10 && !(c >= 10 && c <= 14) && (r * cols + c) % 5;
  };
  PointCloud cloud = sweep(rows, cols, -15.0, 15.0, hit);
  OrganisedScratch scratch;
  const OrganisedCounts counts = split_organised(cloud, rows, cols, scratch);
  std::uint64_t expected_returns = 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) expected_returns += hit(r, c) ? 1 : 0;
  EXPECT_EQ(counts.returns, expected_returns);
  EXPECT_EQ(counts.no_returns, rows * cols - expected_returns);
  EXPECT_EQ(counts.underivable, 0u);
  ASSERT_EQ(cloud.size(), expected_returns);
  ASSERT_TRUE(cloud.consistent());
  ASSERT_EQ(cloud.no_return_S.size(), counts.no_returns);
  // Returns keep their order and their channels; no-returns come in row-major order.
  std::size_t k = 0, n = 0;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      if (hit(r, c)) {
        EXPECT_EQ(cloud.intensity[k++], static_cast<float>(r * cols + c));
        continue;
      }
      const Eigen::Vector3f truth = beam(r, c, rows, cols, -15.0, 15.0);
      const Eigen::Vector3f got = cloud.no_return_S[n++];
      EXPECT_NEAR(got.norm(), 1.0f, 1e-5f);
      EXPECT_LT((got - truth).norm(), 1e-5f) << "row " << r << " col " << c;
    }
  }
}

TEST(OrganisedScan, OriginPointsAreNoReturnsToo_ColumnsRoundTheWrap) {
  // No return as (0, 0, 0); the empty columns straddle azimuth 0 (columns 62, 63, 0, 1).
  const int rows = 8, cols = 64;
  const auto hit = [](int r, int c) { return r < 5 && c >= 2 && c <= 61; };
  PointCloud cloud = sweep(rows, cols, -10.0, 10.0, hit, /*zeros=*/true);
  OrganisedScratch scratch;
  const OrganisedCounts counts = split_organised(cloud, rows, cols, scratch);
  EXPECT_EQ(counts.returns, 5u * 60u);
  EXPECT_EQ(cloud.no_return_S.size(), rows * cols - 5u * 60u);
  // The first no-return is row 0, column 0: azimuth 0, elevation -10 deg.
  EXPECT_LT((cloud.no_return_S.front() - beam(0, 0, rows, cols, -10.0, 10.0)).norm(), 1e-4f);
  // Row 7 (extrapolated), column 63 (interpolated round the wrap).
  EXPECT_LT((cloud.no_return_S.back() - beam(7, 63, rows, cols, -10.0, 10.0)).norm(), 1e-4f);
}

TEST(OrganisedScan, TooFewReturnsToRebuildDirections_CountedNotGuessed) {
  const int rows = 4, cols = 8;
  PointCloud cloud = sweep(rows, cols, -10.0, 10.0, [](int r, int) { return r == 1; });
  OrganisedScratch scratch;
  const OrganisedCounts counts = split_organised(cloud, rows, cols, scratch);
  EXPECT_EQ(counts.returns, 8u);
  EXPECT_EQ(counts.no_returns, 0u);
  EXPECT_EQ(counts.underivable, 24u);
  EXPECT_TRUE(cloud.no_return_S.empty());
  EXPECT_EQ(cloud.size(), 8u);
}

}  // namespace
}  // namespace tarmac::core
