#include "tarmac/core/organised_scan.hpp"

#include <algorithm>
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

// ---- organise_sweep: each driver's layout back to beams x firings ----

/// The reference sweep of these tests, beams × firings (rows = beams, lowest first), as
/// ouster-ros would send it but for its ring order: 16 beams over -15..15 deg, 90 firings; the
/// top 4 beams see sky, every 7th cell below drops its return; ring = beam index when `ring`.
PointCloud reference_sweep(bool ring) {
  const auto hit = [](int r, int c) { return r < 12 && (r * 90 + c) % 7 != 3; };
  PointCloud cloud = sweep(16, 90, -15.0, 15.0, hit);
  if (ring) {
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      cloud.ring.push_back(static_cast<std::uint16_t>(i / 90));
    }
  }
  return cloud;
}

/// `cloud` (rows × cols) with its grid rearranged: cell (r, c) of the result is cell
/// `from(r, c)` of the source; the result has `rows` × `cols` cells too.
template <typename From>
PointCloud rearranged(const PointCloud& cloud, std::size_t rows, std::size_t cols, From from) {
  PointCloud out;
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const std::size_t i = from(r, c);
      out.points_S.push_back(cloud.points_S[i]);
      out.intensity.push_back(cloud.intensity[i]);
      if (cloud.has_ring()) out.ring.push_back(cloud.ring[i]);
    }
  }
  return out;
}

/// Expects `got` (organised by organise_sweep) to hold exactly what split_organised makes of
/// the reference sweep: the same returns with their channels, the same rebuilt directions.
void expect_as_reference(const PointCloud& got, const OrganisedCounts& counts, bool ring) {
  PointCloud want = reference_sweep(ring);
  OrganisedScratch scratch;
  const OrganisedCounts want_counts = split_organised(want, 16, 90, scratch);
  EXPECT_EQ(counts.returns, want_counts.returns);
  EXPECT_EQ(counts.no_returns, want_counts.no_returns);
  EXPECT_EQ(counts.underivable, want_counts.underivable);
  ASSERT_EQ(got.size(), want.size());
  EXPECT_EQ(got.points_S, want.points_S);
  EXPECT_EQ(got.intensity, want.intensity);
  EXPECT_EQ(got.ring, want.ring);
  ASSERT_EQ(got.no_return_S.size(), want.no_return_S.size());
  for (std::size_t k = 0; k < want.no_return_S.size(); ++k) {
    ASSERT_LT((got.no_return_S[k] - want.no_return_S[k]).norm(), 1e-6f) << "no-return " << k;
  }
}

TEST(OrganiseSweep, RowsAreBeams_OusterTopFirst_SameAsSplitOrganised) {
  // ouster-ros: ring 0 is the top beam, so the rows come highest first.
  for (const bool ring : {true, false}) {
    SCOPED_TRACE(ring ? "with ring" : "without ring");
    const PointCloud ref = reference_sweep(ring);
    PointCloud cloud =
        rearranged(ref, 16, 90, [](std::size_t r, std::size_t c) { return (15 - r) * 90 + c; });
    OrganisedScratch scratch;
    const OrganisedCounts counts = organise_sweep(cloud, 16, 90, scratch);
    EXPECT_EQ(counts.layout, SweepLayout::kRowsAreBeams);
    EXPECT_FALSE(counts.beams_reordered);  // monotonic, top first
    // The same cells, beams in the other order: the same returns and directions, beam by beam
    // from the top.
    PointCloud want =
        rearranged(ref, 16, 90, [](std::size_t r, std::size_t c) { return (15 - r) * 90 + c; });
    split_organised(want, 16, 90, scratch);
    EXPECT_EQ(cloud.points_S, want.points_S);
    ASSERT_EQ(cloud.no_return_S.size(), want.no_return_S.size());
    EXPECT_GT(counts.no_returns, 4u * 90u);  // the sky beams are rebuilt (extrapolated)
    EXPECT_EQ(counts.underivable, 0u);
  }
}

TEST(OrganiseSweep, RowsAreFirings_VelodyneColumnsInRingOrder_Transposed) {
  // velodyne organize_cloud: one row per firing, one column per laser (ring order).
  for (const bool ring : {true, false}) {
    SCOPED_TRACE(ring ? "with ring" : "without ring (elevation spread)");
    const PointCloud ref = reference_sweep(ring);
    PointCloud cloud =
        rearranged(ref, 90, 16, [](std::size_t r, std::size_t c) { return c * 90 + r; });
    OrganisedScratch scratch;
    EXPECT_EQ(sweep_layout(cloud, 90, 16, scratch), SweepLayout::kRowsAreFirings);
    const OrganisedCounts counts = organise_sweep(cloud, 90, 16, scratch);
    EXPECT_EQ(counts.layout, SweepLayout::kRowsAreFirings);
    EXPECT_FALSE(counts.beams_reordered);
    expect_as_reference(cloud, counts, ring);
  }
}

/// The reference sweep as rslidar_sdk sends it (ros_send_by_rows: false): one row per firing,
/// columns in the raw channel order, interleaved in elevation; XYZIRT's ring is the elevation
/// rank, XYZI (`ring` false) has none.
PointCloud robosense_sweep(bool ring) {
  constexpr std::size_t kChannel[16] = {0, 8, 1, 9, 2, 10, 3, 11, 4, 12, 5, 13, 6, 14, 7, 15};
  return rearranged(reference_sweep(ring), 90, 16,
                    [&](std::size_t r, std::size_t c) { return kChannel[c] * 90 + r; });
}

TEST(OrganiseSweep, RowsAreFirings_RoboSenseRawChannelOrder_BeamsSortedByRing) {
  PointCloud cloud = robosense_sweep(true);
  OrganisedScratch scratch;
  const OrganisedCounts counts = organise_sweep(cloud, 90, 16, scratch);
  EXPECT_EQ(counts.layout, SweepLayout::kRowsAreFirings);
  EXPECT_TRUE(counts.beams_reordered);
  expect_as_reference(cloud, counts, true);
}

TEST(OrganiseSweep, RawChannelOrderWithoutRing_SortedByElevation_BeamsWithoutReturnDropped) {
  // The same without a ring (rslidar_sdk's default XYZI): the beams that returned are sorted
  // by their measured elevation; the four sky beams cannot be placed and clear nothing.
  const PointCloud ref = reference_sweep(false);
  PointCloud cloud = robosense_sweep(false);
  OrganisedScratch scratch;
  const OrganisedCounts counts = organise_sweep(cloud, 90, 16, scratch);
  EXPECT_EQ(counts.layout, SweepLayout::kRowsAreFirings);
  EXPECT_TRUE(counts.beams_reordered);
  EXPECT_EQ(counts.underivable, 4u * 90u);
  // The twelve beams that returned: what split_organised makes of them alone.
  PointCloud want =
      rearranged(ref, 12, 90, [](std::size_t r, std::size_t c) { return r * 90 + c; });
  split_organised(want, 12, 90, scratch);
  EXPECT_EQ(cloud.points_S, want.points_S);
  ASSERT_EQ(cloud.no_return_S.size(), want.no_return_S.size());
  for (std::size_t k = 0; k < want.no_return_S.size(); ++k) {
    ASSERT_LT((cloud.no_return_S[k] - want.no_return_S[k]).norm(), 1e-6f) << k;
  }
}

TEST(OrganiseSweep, RingThatSaysNothing_ElevationDecidesLayoutAndOrder) {
  // A driver that fills ring with 0, columns in raw channel order: the elevation spread tells
  // firings from beams, and the beams are ordered by their measured elevation, not by the ring.
  PointCloud cloud = robosense_sweep(true);
  std::fill(cloud.ring.begin(), cloud.ring.end(), std::uint16_t{0});
  OrganisedScratch scratch;
  EXPECT_EQ(sweep_layout(cloud, 90, 16, scratch), SweepLayout::kRowsAreFirings);
  const OrganisedCounts counts = organise_sweep(cloud, 90, 16, scratch);
  EXPECT_TRUE(counts.beams_reordered);
  EXPECT_EQ(counts.underivable, 4u * 90u);  // the sky beams: their place is unknown
  PointCloud want = rearranged(reference_sweep(false), 12, 90,
                               [](std::size_t r, std::size_t c) { return r * 90 + c; });
  split_organised(want, 12, 90, scratch);
  EXPECT_EQ(cloud.points_S, want.points_S);
  EXPECT_EQ(cloud.no_return_S.size(), want.no_return_S.size());
}

TEST(OrganiseSweep, LayoutThatCannotBeTold_IntegratedAsUnorganised_NoReturnsDropped) {
  // Returns at random elevations in both directions of the grid (no beam axis), NaN between.
  PointCloud cloud;
  std::uint32_t state = 12345;
  const auto next = [&] {
    state = state * 1664525u + 1013904223u;
    return static_cast<double>(state >> 8) / static_cast<double>(1u << 24);
  };
  std::size_t returns = 0;
  for (int i = 0; i < 32 * 32; ++i) {
    if (i % 5 == 0) {
      cloud.points_S.push_back(Eigen::Vector3f::Constant(kNaN));
      continue;
    }
    const double el = (next() - 0.5) * 0.6, az = next() * 6.28;
    cloud.points_S.emplace_back(static_cast<float>(10 * std::cos(el) * std::cos(az)),
                                static_cast<float>(10 * std::cos(el) * std::sin(az)),
                                static_cast<float>(10 * std::sin(el)));
    ++returns;
  }
  OrganisedScratch scratch;
  const OrganisedCounts counts = organise_sweep(cloud, 32, 32, scratch);
  EXPECT_EQ(counts.layout, SweepLayout::kUndecided);
  EXPECT_EQ(counts.returns, returns);
  EXPECT_EQ(counts.underivable, 32u * 32u - returns);
  EXPECT_EQ(counts.no_returns, 0u);
  EXPECT_TRUE(cloud.no_return_S.empty());
  EXPECT_EQ(cloud.size(), returns);
}

// ---- bin_by_ring: unorganised sweeps that carry a ring ----

/// A spinning LiDAR's sweep as a driver that publishes lists sends it: the returns only, in
/// firing order (for each azimuth step, every beam), each with its ring (0 = lowest). Beam r
/// has its own azimuth offset (as Velodyne's and Hesai's lasers do); `hit(r, c)` says which
/// cells return; `marker(r, c)` which of the others are sent as NaN with their ring.
struct RingSweep {
  int rows = 16, cols = 360;
  double lo_deg = -15.0, hi_deg = 15.0;
  double offset_deg(int r) const { return 0.3 * ((r * 7) % 5 - 2); }  // ±0.6°
  Eigen::Vector3f dir(int r, int c) const {
    const double el = (lo_deg + (hi_deg - lo_deg) * r / (rows - 1)) * std::numbers::pi / 180.0;
    const double az =
        std::remainder(2.0 * std::numbers::pi * c / cols + offset_deg(r) * std::numbers::pi / 180.0,
                       2.0 * std::numbers::pi);
    return Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el))
        .cast<float>();
  }
  template <typename Hit, typename Marker>
  PointCloud cloud(Hit hit, Marker marker) const {
    PointCloud out;
    for (int c = 0; c < cols; ++c) {
      for (int r = 0; r < rows; ++r) {
        if (hit(r, c)) {
          out.points_S.push_back((10.0f + 0.1f * static_cast<float>(c % 7)) * dir(r, c));
        } else if (marker(r, c)) {
          out.points_S.push_back(Eigen::Vector3f::Constant(kNaN));
        } else {
          continue;
        }
        out.ring.push_back(static_cast<std::uint16_t>(r));
        out.intensity.push_back(static_cast<float>(r * cols + c));
      }
    }
    return out;
  }
};

/// The largest angle (deg) between a rebuilt direction and the nearest of `want`.
double worst_match_deg(const std::vector<Eigen::Vector3f>& got,
                       const std::vector<Eigen::Vector3f>& want) {
  double worst = 0.0;
  for (const auto& g : got) {
    double best = 180.0;
    for (const auto& w : want) {
      const double cosine = std::clamp(static_cast<double>(g.normalized().dot(w)), -1.0, 1.0);
      best = std::min(best, std::acos(cosine) * 180.0 / std::numbers::pi);
    }
    worst = std::max(worst, best);
  }
  return worst;
}

TEST(BinByRing, DroppedReturnsSkyRingAndMarkers_BecomeBeamsWithinATenthOfADegree) {
  // Rings 0..9 hit the ground but every 7th cell is lost; ring 12 returns nothing (its cells
  // absent, not even markers) between rings that return; rings 13..15 return only where an
  // aircraft stands (columns 40..80) and send NaN markers elsewhere; ring 10 and 11 return
  // everywhere. Columns 300..359 are cut away by the driver (no ring returned there).
  const RingSweep s;
  const auto covered = [](int c) { return c < 300; };
  const auto hit = [&](int r, int c) {
    if (!covered(c)) return false;
    if (r <= 9) return (r * 360 + c) % 7 != 0;
    if (r <= 11) return true;
    if (r == 12) return false;
    return c >= 40 && c <= 80;
  };
  const auto marker = [&](int r, int c) { return covered(c) && r >= 13; };
  PointCloud cloud = s.cloud(hit, marker);
  std::vector<Eigen::Vector3f> want;
  std::size_t returns = 0;
  for (int r = 0; r < s.rows; ++r) {
    for (int c = 0; c < s.cols; ++c) {
      if (hit(r, c)) {
        ++returns;
      } else if (covered(c)) {
        want.push_back(s.dir(r, c));
      }
    }
  }
  OrganisedScratch scratch;
  const OrganisedCounts counts = bin_by_ring(cloud, scratch);
  EXPECT_EQ(counts.layout, SweepLayout::kRingBinned);
  EXPECT_EQ(counts.returns, returns);
  ASSERT_EQ(cloud.size(), returns);
  ASSERT_EQ(cloud.ring.size(), returns);
  ASSERT_EQ(cloud.intensity.size(), returns);
  for (std::size_t i = 0; i < cloud.size(); ++i) ASSERT_TRUE(cloud.points_S[i].allFinite());
  // Each rebuilt direction is a true one: the ring's elevation, the gap's azimuth. The empty
  // ring has no azimuths of its own in the data: it takes those where other rings returned, one
  // per 1° bin, so within the lasers' offsets (±0.6°) of its own. At the cut's edges, a bin is
  // left out: a ring may lose a beam there, never gain one in the cut.
  const std::vector<Eigen::Vector3f> sky(cloud.no_return_S.begin(), cloud.no_return_S.end());
  std::vector<Eigen::Vector3f> ring12, others;
  for (const auto& d : sky) {
    const double el =
        std::asin(std::clamp(static_cast<double>(d.z()), -1.0, 1.0)) * 180.0 / std::numbers::pi;
    (std::abs(el - s.lo_deg - 12 * 2.0) < 0.5 ? ring12 : others).push_back(d);
  }
  EXPECT_LT(worst_match_deg(others, want), 0.1);
  EXPECT_LT(worst_match_deg(ring12, want), 1.2);
  EXPECT_NEAR(static_cast<double>(ring12.size()), 300.0, 2.0);
  // One per missing cell of the covered sectors; none in the cut-away one.
  EXPECT_EQ(counts.no_returns, sky.size());
  EXPECT_LE(sky.size(), want.size());
  EXPECT_GE(sky.size(), want.size() - 2 * static_cast<std::size_t>(s.rows));
  for (const auto& d : sky) {
    const double az = std::atan2(d.y(), d.x()) * 180.0 / std::numbers::pi;
    const double az360 = az < 0.0 ? az + 360.0 : az;
    EXPECT_TRUE(az360 < 299.7) << "a beam in the cut-away sector at " << az360;
  }
}

TEST(BinByRing, OneRingValueOrMergedClouds_NotASweep_NothingInvented) {
  const RingSweep s;
  const auto all = [](int, int) { return true; };
  const auto none = [](int, int) { return false; };
  OrganisedScratch scratch;
  {
    // ring 0 everywhere (a driver that fills it with 0): a plain list, left as it came.
    PointCloud cloud = s.cloud([](int r, int c) { return (r + c) % 3 != 0; }, none);
    std::fill(cloud.ring.begin(), cloud.ring.end(), 0);
    const std::size_t n = cloud.size();
    const OrganisedCounts counts = organise(cloud, scratch);
    EXPECT_EQ(counts.layout, SweepLayout::kUnorganised);
    EXPECT_EQ(cloud.size(), n);
    EXPECT_TRUE(cloud.no_return_S.empty());
    EXPECT_TRUE(cloud.organised);
  }
  {
    // The ring field is not the beam (shuffled): elevations spread within the rings as much as
    // across them. Undecided: the returns stay, the markers go, no beam is invented.
    PointCloud cloud = s.cloud(all, none);
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      cloud.ring[i] = static_cast<std::uint16_t>(((i * 2654435761u) >> 11) % 16);
    }
    cloud.points_S.push_back(Eigen::Vector3f::Constant(kNaN));
    cloud.ring.push_back(3);
    cloud.intensity.push_back(0.0f);
    const OrganisedCounts counts = organise(cloud, scratch);
    EXPECT_EQ(counts.layout, SweepLayout::kUndecided);
    EXPECT_EQ(counts.underivable, 1u);
    EXPECT_EQ(cloud.size(), static_cast<std::size_t>(s.rows * s.cols));
    EXPECT_TRUE(cloud.no_return_S.empty());
  }
}

TEST(BinByRing, EveryBeamReturned_NoBeamWithoutReturn_AndOrganiseRunsOnce) {
  const RingSweep s;
  PointCloud cloud = s.cloud([](int, int) { return true; }, [](int, int) { return false; });
  OrganisedScratch scratch;
  const OrganisedCounts counts = organise(cloud, scratch);
  EXPECT_EQ(counts.layout, SweepLayout::kRingBinned);
  EXPECT_EQ(counts.no_returns, 0u);
  EXPECT_TRUE(cloud.no_return_S.empty());
  // Organised already: a second call leaves it.
  cloud.no_return_S.push_back(Eigen::Vector3f::UnitZ());
  EXPECT_EQ(organise(cloud, scratch).layout, SweepLayout::kUnorganised);
  EXPECT_EQ(cloud.no_return_S.size(), 1u);
}

TEST(BinByRing, CounterClockwiseOrShuffledLists_SameBeams) {
  // The order within a ring does not matter: firing order either way round, or none.
  const RingSweep s;
  const auto hit = [](int r, int c) { return r < 12 && (r * 31 + c) % 11 != 0; };
  const auto none = [](int, int) { return false; };
  OrganisedScratch scratch;
  PointCloud forward = s.cloud(hit, none);
  bin_by_ring(forward, scratch);
  PointCloud backward = s.cloud(hit, none);
  std::reverse(backward.points_S.begin(), backward.points_S.end());
  std::reverse(backward.ring.begin(), backward.ring.end());
  std::reverse(backward.intensity.begin(), backward.intensity.end());
  bin_by_ring(backward, scratch);
  PointCloud shuffled = s.cloud(hit, none);
  for (std::size_t i = 0; i + 1 < shuffled.size(); i += 2) {
    const std::size_t j = (i * 48271) % shuffled.size();
    std::swap(shuffled.points_S[i], shuffled.points_S[j]);
    std::swap(shuffled.ring[i], shuffled.ring[j]);
    std::swap(shuffled.intensity[i], shuffled.intensity[j]);
  }
  bin_by_ring(shuffled, scratch);
  ASSERT_FALSE(forward.no_return_S.empty());
  EXPECT_EQ(backward.no_return_S.size(), forward.no_return_S.size());
  EXPECT_EQ(shuffled.no_return_S.size(), forward.no_return_S.size());
  EXPECT_LT(worst_match_deg(backward.no_return_S, forward.no_return_S), 1e-3);
  EXPECT_LT(worst_match_deg(shuffled.no_return_S, forward.no_return_S), 1e-3);
}

}  // namespace
}  // namespace tarmac::core
