#include "tarmac/core/organised_scan.hpp"

#include <cmath>
#include <numbers>

#include <algorithm>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

bool is_return(const Eigen::Vector3f& p) {
  return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()) &&
         !(p.x() == 0.0f && p.y() == 0.0f && p.z() == 0.0f);
}

/// Angle a − b wrapped to (−π, π].
double wrapped_difference(double a, double b) {
  double d = std::remainder(a - b, 2.0 * std::numbers::pi);
  if (d <= -std::numbers::pi) d += 2.0 * std::numbers::pi;
  return d;
}

/// How many entries have returns.
std::size_t count_defined(const std::vector<std::uint32_t>& n) {
  return static_cast<std::size_t>(
      std::count_if(n.begin(), n.end(), [](std::uint32_t k) { return k > 0; }));
}

/// Fills the rows without returns (n[i] == 0) of v: interpolated between the nearest rows with
/// returns on both sides, else extrapolated from the two nearest on the one side. False when
/// fewer than two rows have returns (then v is left as it is).
bool fill_rows(std::vector<double>& v, const std::vector<std::uint32_t>& n) {
  const std::size_t count = v.size();
  if (count_defined(n) < 2) return false;
  const auto nearest = [&](std::size_t from, int step) -> std::ptrdiff_t {
    for (auto i = static_cast<std::ptrdiff_t>(from) + step;
         i >= 0 && i < static_cast<std::ptrdiff_t>(count); i += step) {
      if (n[static_cast<std::size_t>(i)] > 0) return i;
    }
    return -1;
  };
  for (std::size_t i = 0; i < count; ++i) {
    if (n[i] > 0) continue;
    std::ptrdiff_t a = nearest(i, -1);
    std::ptrdiff_t b = nearest(i, +1);
    if (a < 0) {  // below every returning row: the two lowest of them
      a = b;
      b = nearest(static_cast<std::size_t>(a), +1);
    } else if (b < 0) {  // above every returning row: the two highest of them
      b = a;
      a = nearest(static_cast<std::size_t>(b), -1);
    }
    const double va = v[static_cast<std::size_t>(a)];
    const double vb = v[static_cast<std::size_t>(b)];
    v[i] = va + (vb - va) * (static_cast<double>(i) - static_cast<double>(a)) /
                    static_cast<double>(b - a);
  }
  return true;
}

/// The same round the circle for column azimuths: interpolated between the nearest columns with
/// returns on either side, the step taken the short way round. False when fewer than two columns
/// have returns.
bool fill_columns(std::vector<double>& v, const std::vector<std::uint32_t>& n) {
  const std::size_t count = v.size();
  if (count_defined(n) < 2) return false;
  for (std::size_t i = 0; i < count; ++i) {
    if (n[i] > 0) continue;
    std::size_t da = 1;
    while (n[(i + count - da) % count] == 0) ++da;
    std::size_t db = 1;
    while (n[(i + db) % count] == 0) ++db;
    const double va = v[(i + count - da) % count];
    const double vb = v[(i + db) % count];
    const double span = static_cast<double>(da + db);
    // Between two neighbours the columns are evenly spaced: the step is their difference the
    // short way round over the columns between them.
    v[i] = va + wrapped_difference(vb, va) * static_cast<double>(da) / span;
  }
  return true;
}

}  // namespace

OrganisedCounts split_organised(PointCloud& cloud, std::size_t rows, std::size_t cols,
                                OrganisedScratch& scratch) {
  TARMAC_ASSERT(rows * cols == cloud.size() && cloud.consistent(),
                "split_organised: rows * cols must equal the point count");
  OrganisedCounts counts;
  auto& s = scratch;
  s.row_sum.assign(rows, 0.0);
  s.row_n.assign(rows, 0);
  s.col_x.assign(cols, 0.0);
  s.col_y.assign(cols, 0.0);
  s.col_n.assign(cols, 0);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const Eigen::Vector3f& p = cloud.points_S[r * cols + c];
      if (!is_return(p)) continue;
      const double x = p.x();
      const double y = p.y();
      const double planar = std::hypot(x, y);
      s.row_sum[r] += std::atan2(static_cast<double>(p.z()), planar);
      ++s.row_n[r];
      if (planar > 0.0) {  // a return straight up or down says nothing of its column's azimuth
        s.col_x[c] += x / planar;
        s.col_y[c] += y / planar;
        ++s.col_n[c];
      }
    }
  }
  s.row_angle.resize(rows);
  s.col_angle.resize(cols);
  for (std::size_t r = 0; r < rows; ++r) {
    s.row_angle[r] = s.row_n[r] > 0 ? s.row_sum[r] / s.row_n[r] : 0.0;
  }
  for (std::size_t c = 0; c < cols; ++c) {
    s.col_angle[c] = s.col_n[c] > 0 ? std::atan2(s.col_y[c], s.col_x[c]) : 0.0;
  }
  const bool derivable = fill_rows(s.row_angle, s.row_n) && fill_columns(s.col_angle, s.col_n);

  // Compact the returns in place (order kept) and rebuild the others' directions.
  cloud.no_return_S.clear();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < rows * cols; ++i) {
    if (!is_return(cloud.points_S[i])) {
      if (!derivable) {
        ++counts.underivable;
        continue;
      }
      const double elevation =
          std::clamp(s.row_angle[i / cols], -std::numbers::pi / 2, std::numbers::pi / 2);
      const double azimuth = s.col_angle[i % cols];
      cloud.no_return_S.emplace_back(static_cast<float>(std::cos(elevation) * std::cos(azimuth)),
                                     static_cast<float>(std::cos(elevation) * std::sin(azimuth)),
                                     static_cast<float>(std::sin(elevation)));
      ++counts.no_returns;
      continue;
    }
    if (kept != i) {
      cloud.points_S[kept] = cloud.points_S[i];
      if (cloud.has_intensity()) cloud.intensity[kept] = cloud.intensity[i];
      if (cloud.has_ring()) cloud.ring[kept] = cloud.ring[i];
      if (cloud.has_time()) cloud.time_offset_s[kept] = cloud.time_offset_s[i];
    }
    ++kept;
  }
  const bool intensity = cloud.has_intensity();
  const bool ring = cloud.has_ring();
  const bool time = cloud.has_time();
  cloud.points_S.resize(kept);
  if (intensity) cloud.intensity.resize(kept);
  if (ring) cloud.ring.resize(kept);
  if (time) cloud.time_offset_s.resize(kept);
  counts.returns = kept;
  return counts;
}

}  // namespace tarmac::core
