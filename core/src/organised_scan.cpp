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

// ---- bin_by_ring ----

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr std::size_t kMaxRings = 1024;           // beyond any sensor: a ring field that is not one
constexpr std::size_t kMaxAzimuthBins = 1 << 16;  // a 0.0055° resolution
constexpr double kMinGapRad = 1e-5;               // closer: the same firing (dual returns)

/// Per ring index: whether any cell names it, its returns' count and elevation moments; then
/// the returns' azimuths grouped by ring (a counting sort: cloud order within a ring). False
/// when a ring index is beyond kMaxRings.
bool gather_rings(const PointCloud& cloud, OrganisedScratch& s) {
  const std::uint16_t top = *std::max_element(cloud.ring.begin(), cloud.ring.end());
  if (top >= kMaxRings) return false;
  const std::size_t rings = std::size_t{top} + 1;
  s.ring_seen.assign(rings, 0);
  s.ring_n.assign(rings, 0);
  s.ring_sum.assign(rings, 0.0);
  s.ring_sq.assign(rings, 0.0);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::uint16_t r = cloud.ring[i];
    s.ring_seen[r] = 1;
    const Eigen::Vector3f& p = cloud.points_S[i];
    if (!is_return(p) || (p.x() == 0.0f && p.y() == 0.0f)) continue;
    const double e = elevation_of(p);
    s.ring_sum[r] += e;
    s.ring_sq[r] += e * e;
    ++s.ring_n[r];
  }
  s.ring_start.assign(rings + 1, 0);
  for (std::size_t r = 0; r < rings; ++r) s.ring_start[r + 1] = s.ring_start[r] + s.ring_n[r];
  s.azimuth.resize(s.ring_start[rings]);
  s.order.assign(s.ring_start.begin(), s.ring_start.end() - 1);  // each ring's next slot
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points_S[i];
    if (!is_return(p) || (p.x() == 0.0f && p.y() == 0.0f)) continue;
    s.azimuth[s.order[cloud.ring[i]]++] =
        static_cast<float>(std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x())));
  }
  return true;
}

/// Sorts a[0, n) when it rises but for at most one wrap (a spinning sensor's firing order) by
/// rotating it; false, untouched, otherwise.
bool rotate_if_wrapped(float* a, std::size_t n) {
  std::size_t descents = 0, at = 0;
  for (std::size_t k = 1; k < n && descents < 2; ++k) {
    if (a[k] < a[k - 1]) {
      ++descents;
      at = k;
    }
  }
  if (descents == 0) return true;
  if (descents > 1 || a[n - 1] > a[0]) return false;
  std::rotate(a, a + at, a + n);
  return true;
}

/// Each ring's azimuths in ascending order: drivers list a ring in firing order, clockwise or
/// counter-clockwise, which a rotation (and a reversal) sorts without a sort.
void sort_ring_azimuths(OrganisedScratch& s) {
  for (std::size_t r = 0; r + 1 < s.ring_start.size(); ++r) {
    float* a = s.azimuth.data() + s.ring_start[r];
    const std::size_t n = s.ring_n[r];
    if (n < 2 || rotate_if_wrapped(a, n)) continue;
    std::reverse(a, a + n);
    if (!rotate_if_wrapped(a, n)) std::sort(a, a + n);
  }
}

/// The median gap between azimuth-neighbouring returns of a ring (rad), NaN with fewer than 16
/// gaps or a resolution finer than kMaxAzimuthBins allows.
double ring_resolution(OrganisedScratch& s) {
  s.gaps.clear();
  for (std::size_t r = 0; r + 1 < s.ring_start.size(); ++r) {
    const float* a = s.azimuth.data() + s.ring_start[r];
    for (std::size_t k = 1; k < s.ring_n[r]; ++k) {
      if (a[k] - a[k - 1] > kMinGapRad) s.gaps.push_back(a[k] - a[k - 1]);
    }
  }
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  if (s.gaps.size() < 16) return nan;
  const auto mid = s.gaps.begin() + static_cast<std::ptrdiff_t>(s.gaps.size() / 2);
  std::nth_element(s.gaps.begin(), mid, s.gaps.end());
  const double resolution = *mid;
  return kTwoPi / resolution <= static_cast<double>(kMaxAzimuthBins) ? resolution : nan;
}

std::size_t azimuth_bin(double azimuth, double resolution, std::size_t bins) {
  const auto b = static_cast<std::ptrdiff_t>(std::floor((azimuth + std::numbers::pi) / resolution));
  return static_cast<std::size_t>(
      std::clamp<std::ptrdiff_t>(b, 0, static_cast<std::ptrdiff_t>(bins) - 1));
}

/// Each ring's elevation: its returns' mean; for a ring without returns, interpolated by ring
/// index (fill_rows) when the returning rings' elevations follow their indices. False when the
/// cloud is no single sensor's sweep: fewer than two rings with returns, or elevations spread
/// within the rings by more than a tenth of their spread across them (variances).
bool ring_elevations(OrganisedScratch& s, bool& fill_empty) {
  const std::size_t rings = s.ring_n.size();
  s.ring_elevation.assign(rings, 0.0);
  double across_sum = 0.0, across_sq = 0.0;
  std::size_t with_returns = 0;
  bool rising = true, falling = true;
  double last = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t r = 0; r < rings; ++r) {
    if (s.ring_n[r] == 0) continue;
    const double mean = s.ring_sum[r] / s.ring_n[r];
    s.ring_elevation[r] = mean;
    across_sum += mean;
    across_sq += mean * mean;
    ++with_returns;
    if (!std::isnan(last)) {
      rising = rising && mean > last;
      falling = falling && mean < last;
    }
    last = mean;
  }
  if (with_returns < 2) return false;
  const double within = within_spread(s.ring_sum, s.ring_sq, s.ring_n);
  const double across = (across_sq - across_sum * across_sum / static_cast<double>(with_returns)) /
                        static_cast<double>(with_returns);
  if (!(within < 0.1 * across)) return false;
  fill_empty = rising || falling;
  if (fill_empty) fill_rows(s.ring_elevation, s.ring_n);
  return true;
}

/// Some ring returned in azimuth bin b and in both its neighbours: well inside what the
/// driver sent. At the edge of a sector it cut away, a beam's own azimuth offset can put it a
/// bin beyond the last return of the other rings; that bin is left out.
bool inside_coverage(const std::vector<float>& covered, std::size_t b) {
  const std::size_t n = covered.size();
  return !std::isnan(covered[b]) && !std::isnan(covered[(b + 1) % n]) &&
         !std::isnan(covered[(b + n - 1) % n]);
}

Eigen::Vector3f direction(double elevation, double azimuth) {
  return {static_cast<float>(std::cos(elevation) * std::cos(azimuth)),
          static_cast<float>(std::cos(elevation) * std::sin(azimuth)),
          static_cast<float>(std::sin(elevation))};
}

/// Appends ring r's beams without return to `out`: the gaps between its azimuth-neighbouring
/// returns (round the circle), at azimuths some ring returned in.
void ring_gaps(const OrganisedScratch& s, std::size_t r, double resolution,
               std::vector<Eigen::Vector3f>& out) {
  const float* a = s.azimuth.data() + s.ring_start[r];
  const std::size_t n = s.ring_n[r];
  const std::size_t bins = s.covered.size();
  for (std::size_t k = 0; k < n; ++k) {
    const double from = a[k];
    const double gap = n == 1 ? kTwoPi : (k + 1 < n ? a[k + 1] : a[0] + kTwoPi) - from;
    const long steps = std::lround(gap / resolution);
    for (long j = 1; j < steps; ++j) {
      double azimuth = from + gap * static_cast<double>(j) / static_cast<double>(steps);
      if (azimuth > std::numbers::pi) azimuth -= kTwoPi;
      if (inside_coverage(s.covered, azimuth_bin(azimuth, resolution, bins))) {
        out.push_back(direction(s.ring_elevation[r], azimuth));
      }
    }
  }
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

OrganisedCounts bin_by_ring(PointCloud& cloud, OrganisedScratch& scratch) {
  TARMAC_ASSERT(cloud.consistent(), "bin_by_ring: channels must match the points");
  OrganisedCounts counts;
  counts.layout = SweepLayout::kUndecided;
  cloud.no_return_S.clear();
  auto& s = scratch;
  bool fill_empty = false;
  const bool sweep = cloud.has_ring() && gather_rings(cloud, s) && ring_elevations(s, fill_empty);
  const double resolution = sweep ? (sort_ring_azimuths(s), ring_resolution(s))
                                  : std::numeric_limits<double>::quiet_NaN();
  if (std::isnan(resolution)) {
    counts.returns = keep_returns(cloud, [&](std::size_t) { ++counts.underivable; });
    return counts;
  }
  counts.layout = SweepLayout::kRingBinned;
  const auto bins = static_cast<std::size_t>(std::ceil(kTwoPi / resolution));
  s.covered.assign(bins, std::numeric_limits<float>::quiet_NaN());
  for (const float azimuth : s.azimuth) {  // grouped by ring, lowest index first
    float& bin = s.covered[azimuth_bin(azimuth, resolution, bins)];
    if (std::isnan(bin)) bin = azimuth;
  }
  // Rings without returns lie between the lowest and highest ring index with returns, or were
  // named by a marker.
  std::size_t low = s.ring_n.size(), high = 0;
  for (std::size_t r = 0; r < s.ring_n.size(); ++r) {
    if (s.ring_n[r] == 0) continue;
    low = std::min(low, r);
    high = r;
  }
  for (std::size_t r = 0; r < s.ring_n.size(); ++r) {
    if (s.ring_n[r] > 0) {
      ring_gaps(s, r, resolution, cloud.no_return_S);
    } else if (fill_empty && (s.ring_seen[r] != 0 || (r > low && r < high))) {
      for (std::size_t b = 0; b < bins; ++b) {
        if (!inside_coverage(s.covered, b)) continue;
        cloud.no_return_S.push_back(direction(s.ring_elevation[r], s.covered[b]));
      }
    }
  }
  counts.no_returns = cloud.no_return_S.size();
  counts.returns = keep_returns(cloud, [](std::size_t) {});
  return counts;
}

OrganisedCounts organise(PointCloud& cloud, OrganisedScratch& scratch) {
  TARMAC_ASSERT(cloud.consistent(), "organise: channels must match the points");
  OrganisedCounts counts;
  counts.layout = SweepLayout::kUnorganised;
  if (cloud.organised) return counts;
  const std::size_t rows = cloud.grid_rows;
  if (rows > 0 && cloud.size() % rows == 0) {
    counts = organise_sweep(cloud, rows, cloud.size() / rows, scratch);
  } else if (rows > 0) {  // not a grid after all: integrated as unorganised
    counts.layout = SweepLayout::kUndecided;
    cloud.no_return_S.clear();
    counts.returns = keep_returns(cloud, [&](std::size_t) { ++counts.underivable; });
  } else if (cloud.has_ring() && std::any_of(cloud.ring.begin(), cloud.ring.end(),
                                             [&](auto r) { return r != cloud.ring.front(); })) {
    // One ring value for all (a driver filling 0) names no beam: a plain list of points.
    counts = bin_by_ring(cloud, scratch);
  }
  cloud.grid_rows = 0;
  cloud.organised = true;
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
