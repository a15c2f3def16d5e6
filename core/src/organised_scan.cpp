#include "tarmac/core/organised_scan.hpp"

#include <cmath>
#include <limits>
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

/// Keeps the returns of `cloud` in place, in their order, with their channels; calls
/// `missing(i)` for each cell i without a return (in order) before it leaves. Returns the
/// number kept.
template <typename Missing>
std::size_t keep_returns(PointCloud& cloud, Missing&& missing) {
  const std::size_t n = cloud.size();
  const bool intensity = cloud.has_intensity();
  const bool ring = cloud.has_ring();
  const bool time = cloud.has_time();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!is_return(cloud.points_S[i])) {
      missing(i);
      continue;
    }
    if (kept != i) {
      cloud.points_S[kept] = cloud.points_S[i];
      if (intensity) cloud.intensity[kept] = cloud.intensity[i];
      if (ring) cloud.ring[kept] = cloud.ring[i];
      if (time) cloud.time_offset_s[kept] = cloud.time_offset_s[i];
    }
    ++kept;
  }
  cloud.points_S.resize(kept);
  if (intensity) cloud.intensity.resize(kept);
  if (ring) cloud.ring.resize(kept);
  if (time) cloud.time_offset_s.resize(kept);
  return kept;
}

double elevation_of(const Eigen::Vector3f& p) {
  return std::atan2(static_cast<double>(p.z()),
                    std::hypot(static_cast<double>(p.x()), static_cast<double>(p.y())));
}

/// The share of rows (`by_row`) or of columns along which the ring channel is constant.
double ring_constant_share(const PointCloud& cloud, std::size_t rows, std::size_t cols,
                           bool by_row) {
  const std::size_t lines = by_row ? rows : cols;
  const std::size_t along = by_row ? cols : rows;
  std::size_t constant = 0;
  for (std::size_t l = 0; l < lines; ++l) {
    const auto at = [&](std::size_t k) { return by_row ? l * cols + k : k * cols + l; };
    const std::uint16_t first = cloud.ring[at(0)];
    bool same = true;
    for (std::size_t k = 1; k < along && same; ++k) same = cloud.ring[at(k)] == first;
    constant += same ? 1 : 0;
  }
  return static_cast<double>(constant) / static_cast<double>(lines);
}

/// Σ over lines of the squared deviations of their returns' elevations from the line's mean,
/// over the returns: the mean spread of elevation within a line (rad²).
double within_spread(const std::vector<double>& sum, const std::vector<double>& sq,
                     const std::vector<std::uint32_t>& n) {
  double spread = 0.0;
  std::uint64_t count = 0;
  for (std::size_t l = 0; l < n.size(); ++l) {
    if (n[l] == 0) continue;
    spread += sq[l] - sum[l] * sum[l] / n[l];
    count += n[l];
  }
  return count > 0 ? spread / static_cast<double>(count) : 0.0;
}

/// Rebuilds `cloud` as `beams` × `firings` cells: beam b is the source beam order[b] (a row of
/// the source grid, or its column when `transposed`). Channels follow; capacity is kept.
void regrid(PointCloud& cloud, std::size_t cols, bool transposed, std::size_t firings,
            const std::vector<std::uint32_t>& order, PointCloud& moved) {
  const bool intensity = cloud.has_intensity();
  const bool ring = cloud.has_ring();
  const bool time = cloud.has_time();
  // Room for the whole sweep once: the buffers are swapped with the scan slots' below, so
  // every buffer that circulates holds a sweep after the first.
  const std::size_t n = order.size() * firings;
  moved.points_S.clear();
  moved.points_S.reserve(n);
  moved.intensity.clear();
  moved.ring.clear();
  moved.time_offset_s.clear();
  if (intensity) moved.intensity.reserve(n);
  if (ring) moved.ring.reserve(n);
  if (time) moved.time_offset_s.reserve(n);
  for (const std::uint32_t b : order) {
    for (std::size_t f = 0; f < firings; ++f) {
      const std::size_t i = transposed ? f * cols + b : b * cols + f;
      moved.points_S.push_back(cloud.points_S[i]);
      if (intensity) moved.intensity.push_back(cloud.intensity[i]);
      if (ring) moved.ring.push_back(cloud.ring[i]);
      if (time) moved.time_offset_s.push_back(cloud.time_offset_s[i]);
    }
  }
  cloud.points_S.swap(moved.points_S);
  cloud.intensity.swap(moved.intensity);
  cloud.ring.swap(moved.ring);
  cloud.time_offset_s.swap(moved.time_offset_s);
}

}  // namespace

SweepLayout sweep_layout(const PointCloud& cloud, std::size_t rows, std::size_t cols,
                         OrganisedScratch& scratch) {
  TARMAC_ASSERT(rows * cols == cloud.size() && cloud.consistent(),
                "sweep_layout: rows * cols must equal the point count");
  if (rows < 2 || cols < 2) return SweepLayout::kUndecided;
  // A ring constant along the rows and not along the columns names the beam axis.
  constexpr double kMost = 0.9, kFew = 0.5;
  if (cloud.has_ring()) {
    const double along_rows = ring_constant_share(cloud, rows, cols, true);
    const double along_cols = ring_constant_share(cloud, rows, cols, false);
    if (along_rows >= kMost && along_cols < kFew) return SweepLayout::kRowsAreBeams;
    if (along_cols >= kMost && along_rows < kFew) return SweepLayout::kRowsAreFirings;
  }
  // Else the returns' elevation: nearly constant along a beam, spread across the beams.
  auto& s = scratch;
  s.row_sum.assign(rows, 0.0);
  s.row_sq.assign(rows, 0.0);
  s.row_n.assign(rows, 0);
  s.col_sum.assign(cols, 0.0);
  s.col_sq.assign(cols, 0.0);
  s.col_n.assign(cols, 0);
  for (std::size_t r = 0; r < rows; ++r) {
    for (std::size_t c = 0; c < cols; ++c) {
      const Eigen::Vector3f& p = cloud.points_S[r * cols + c];
      if (!is_return(p)) continue;
      const double e = elevation_of(p);
      s.row_sum[r] += e;
      s.row_sq[r] += e * e;
      ++s.row_n[r];
      s.col_sum[c] += e;
      s.col_sq[c] += e * e;
      ++s.col_n[c];
    }
  }
  if (count_defined(s.row_n) < 2 || count_defined(s.col_n) < 2) return SweepLayout::kUndecided;
  const double in_rows = within_spread(s.row_sum, s.row_sq, s.row_n);
  const double in_cols = within_spread(s.col_sum, s.col_sq, s.col_n);
  constexpr double kRatio = 0.1;
  if (in_rows < kRatio * in_cols) return SweepLayout::kRowsAreBeams;
  if (in_cols < kRatio * in_rows) return SweepLayout::kRowsAreFirings;
  return SweepLayout::kUndecided;
}

OrganisedCounts organise_sweep(PointCloud& cloud, std::size_t rows, std::size_t cols,
                               OrganisedScratch& scratch) {
  TARMAC_ASSERT(rows * cols == cloud.size() && cloud.consistent(),
                "organise_sweep: rows * cols must equal the point count");
  const SweepLayout layout = sweep_layout(cloud, rows, cols, scratch);
  if (layout == SweepLayout::kUndecided) {
    OrganisedCounts counts;
    counts.layout = layout;
    cloud.no_return_S.clear();
    counts.returns = keep_returns(cloud, [&](std::size_t) { ++counts.underivable; });
    return counts;
  }
  const bool transposed = layout == SweepLayout::kRowsAreFirings;
  const std::size_t beams = transposed ? cols : rows;
  const std::size_t firings = transposed ? rows : cols;
  const auto cell = [&](std::size_t b, std::size_t f) {
    return transposed ? f * cols + b : b * cols + f;
  };
  // Each beam's key: its ring (the first return's, else its first cell's) when the beams' rings
  // are distinct, else its returns' mean elevation (NaN without any). A ring that does not
  // tell the beams apart (a driver that fills it with 0) must not order them.
  auto& s = scratch;
  s.key.assign(beams, std::numeric_limits<double>::quiet_NaN());
  bool by_ring = cloud.has_ring();
  if (by_ring) {
    for (std::size_t b = 0; b < beams; ++b) {
      std::size_t first = cell(b, 0);
      for (std::size_t f = 0; f < firings; ++f) {
        if (is_return(cloud.points_S[cell(b, f)])) {
          first = cell(b, f);
          break;
        }
      }
      s.key[b] = cloud.ring[first];
    }
    s.row_angle.assign(s.key.begin(), s.key.end());  // a scratch copy, sorted to find repeats
    std::sort(s.row_angle.begin(), s.row_angle.end());
    by_ring = std::adjacent_find(s.row_angle.begin(), s.row_angle.end()) == s.row_angle.end();
  }
  if (!by_ring) {
    for (std::size_t b = 0; b < beams; ++b) {
      double sum = 0.0;
      std::uint32_t n = 0;
      for (std::size_t f = 0; f < firings; ++f) {
        const Eigen::Vector3f& p = cloud.points_S[cell(b, f)];
        if (!is_return(p)) continue;
        sum += elevation_of(p);
        ++n;
      }
      s.key[b] = n > 0 ? sum / n : std::numeric_limits<double>::quiet_NaN();
    }
  }
  // Monotonic either way (ring 0 at the top or the bottom) over the defined keys: kept.
  bool rising = true, falling = true;
  double last = std::numeric_limits<double>::quiet_NaN();
  for (const double k : s.key) {
    if (std::isnan(k)) continue;
    if (!std::isnan(last)) {
      rising = rising && k >= last;
      falling = falling && k <= last;
    }
    last = k;
  }
  const bool reorder = !rising && !falling;
  s.order.clear();
  for (std::uint32_t b = 0; b < beams; ++b) {
    if (!reorder || !std::isnan(s.key[b])) s.order.push_back(b);
  }
  if (reorder) {
    // std::sort with the index as tie-break: the order of std::stable_sort without the
    // temporary buffer it allocates (this runs in the cycle).
    std::sort(s.order.begin(), s.order.end(), [&](std::uint32_t a, std::uint32_t b) {
      return s.key[a] < s.key[b] || (s.key[a] == s.key[b] && a < b);
    });
  }
  const std::uint64_t dropped_cells = (beams - s.order.size()) * firings;
  if (transposed || reorder) regrid(cloud, cols, transposed, firings, s.order, s.moved);
  OrganisedCounts counts = split_organised(cloud, s.order.size(), firings, scratch);
  counts.underivable += dropped_cells;
  counts.layout = layout;
  counts.beams_reordered = reorder;
  return counts;
}

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
  counts.returns = keep_returns(cloud, [&](std::size_t i) {
    if (!derivable) {
      ++counts.underivable;
      return;
    }
    const double elevation =
        std::clamp(s.row_angle[i / cols], -std::numbers::pi / 2, std::numbers::pi / 2);
    const double azimuth = s.col_angle[i % cols];
    cloud.no_return_S.emplace_back(static_cast<float>(std::cos(elevation) * std::cos(azimuth)),
                                   static_cast<float>(std::cos(elevation) * std::sin(azimuth)),
                                   static_cast<float>(std::sin(elevation)));
    ++counts.no_returns;
  });
  return counts;
}

}  // namespace tarmac::core
