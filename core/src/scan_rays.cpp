#include "tarmac/core/scan_rays.hpp"

#include <algorithm>
#include <cmath>

namespace tarmac::core {

namespace {

/// The "diamond angle" of (x, y) in [0, 4): monotonic in atan2(y, x) taken in [0, 2π), one
/// division instead of a trigonometric call. (0, 0) gives 0.
double diamond_angle(double x, double y) {
  if (x == 0.0 && y == 0.0) return 0.0;
  if (y >= 0.0) return x >= 0.0 ? y / (x + y) : 1.0 + (-x) / (-x + y);
  return x < 0.0 ? 2.0 + (-y) / (-x - y) : 3.0 + x / (x - y);
}

int az_bin(double diamond) {
  return std::clamp(static_cast<int>(diamond * (ScanRays::kAzBins / 4.0)), 0,
                    ScanRays::kAzBins - 1);
}

/// Sine of the elevation, z / |(rho, z)|, of a point at horizontal distance rho and height z.
double elevation_sine(double z, double rho) {
  const double r = std::hypot(rho, z);
  return r > 0.0 ? z / r : 0.0;
}

int el_bin(double sine) {
  return std::clamp(static_cast<int>((sine + 1.0) * (ScanRays::kElBins / 2.0)), 0,
                    ScanRays::kElBins - 1);
}

}  // namespace

void ScanRays::build(const Eigen::Vector3d& origin_W, std::span<const Eigen::Vector3f> points_W,
                     std::span<const Eigen::Vector3f> dirs_W, double max_range_m,
                     double clear_range_m) {
  origin_W_ = origin_W;
  unsorted_.clear();
  ray_bin_.clear();
  // Room for half as many rays again as this scan has, so that scans varying in size (the
  // beams without return change with the scene) stop allocating once the largest has come.
  if (const std::size_t n = points_W.size() + dirs_W.size(); unsorted_.capacity() < n) {
    unsorted_.reserve(n + n / 2);
    ray_bin_.reserve(n + n / 2);
    rays_.reserve(n + n / 2);
  }
  const auto add = [&](const Eigen::Vector3d& end, bool returned, bool measured) {
    const double length = end.norm();
    if (!(length > 0.0)) return;
    unsorted_.push_back(Ray{end.cast<float>(), static_cast<float>(length), returned, measured});
    ray_bin_.push_back(static_cast<std::uint32_t>(el_bin(end.z() / length) * kAzBins +
                                                  az_bin(diamond_angle(end.x(), end.y()))));
  };
  for (const Eigen::Vector3f& p : points_W) {
    if (!p.allFinite()) continue;
    const Eigen::Vector3d rel = p.cast<double>() - origin_W;
    const double range = rel.norm();
    if (range <= max_range_m) {
      add(rel, true, true);
    } else if (clear_range_m > 0.0) {
      add(rel * (clear_range_m / range), false, true);
    }
  }
  for (const Eigen::Vector3f& d : dirs_W) {
    const double norm = d.cast<double>().norm();
    if (!d.allFinite() || norm == 0.0 || clear_range_m <= 0.0) continue;
    add(d.cast<double>() * (clear_range_m * std::min(norm, 1.0) / norm), false, false);
  }
  // Counting sort by bin (stable: the rays of a bin keep the scan's order).
  bin_first_.assign(static_cast<std::size_t>(kAzBins) * kElBins + 1, 0);
  for (const std::uint32_t b : ray_bin_) ++bin_first_[b + 1];
  for (std::size_t b = 1; b < bin_first_.size(); ++b) bin_first_[b] += bin_first_[b - 1];
  rays_.resize(unsorted_.size());
  // bin_first_[b] is used as the cursor of bin b, then restored by shifting back.
  for (std::size_t i = 0; i < unsorted_.size(); ++i)
    rays_[bin_first_[ray_bin_[i]]++] = unsorted_[i];
  for (std::size_t b = bin_first_.size() - 1; b > 0; --b) bin_first_[b] = bin_first_[b - 1];
  bin_first_[0] = 0;
}

bool ScanRays::ray_passes(const Ray& r, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                          double behind_m) const {
  // The segment t·end, t in [0, 1], against the box's three slabs.
  double t0 = 0.0, t1 = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double e = r.end[a];
    if (e == 0.0) {
      if (lo[a] > 0.0 || hi[a] < 0.0) return false;
      continue;
    }
    double ta = lo[a] / e, tb = hi[a] / e;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  if (!r.returned) return true;
  return (1.0 - t1) * r.length_m > behind_m;
}

bool ScanRays::any_passes(const Eigen::Vector3d& lo_W, const Eigen::Vector3d& hi_W, double behind_m,
                          bool measured_only) const {
  if (rays_.empty()) return false;
  const Eigen::Vector3d lo = lo_W - origin_W_, hi = hi_W - origin_W_;
  // Horizontal distances from the origin's vertical line to the box: nearest and farthest.
  const double dx = lo.x() > 0.0 ? lo.x() : (hi.x() < 0.0 ? -hi.x() : 0.0);
  const double dy = lo.y() > 0.0 ? lo.y() : (hi.y() < 0.0 ? -hi.y() : 0.0);
  const double rho_min = std::hypot(dx, dy);
  const double rho_max = std::hypot(std::max(std::abs(lo.x()), std::abs(hi.x())),
                                    std::max(std::abs(lo.y()), std::abs(hi.y())));
  // Elevations: z / range is largest at the top nearest (above the origin) or farthest (below).
  const double s_max =
      hi.z() >= 0.0 ? elevation_sine(hi.z(), rho_min) : elevation_sine(hi.z(), rho_max);
  const double s_min =
      lo.z() >= 0.0 ? elevation_sine(lo.z(), rho_max) : elevation_sine(lo.z(), rho_min);
  // One bin of margin each way: a ray on a bin edge may round either side.
  const int e0 = std::max(0, el_bin(s_min) - 1), e1 = std::min(kElBins - 1, el_bin(s_max) + 1);
  // Azimuths: every one when the box stands over the origin; else the corners' extremes (a box
  // beside the origin spans less than half a turn, so a span over 2 means it wraps past 0).
  int a0 = 0, a1 = kAzBins - 1;
  if (rho_min > 0.0) {
    double d_min = 4.0, d_max = 0.0;
    for (const double x : {lo.x(), hi.x()}) {
      for (const double y : {lo.y(), hi.y()}) {
        const double d = diamond_angle(x, y);
        d_min = std::min(d_min, d);
        d_max = std::max(d_max, d);
      }
    }
    if (d_max - d_min <= 2.0) {
      a0 = az_bin(d_min) - 1;
      a1 = az_bin(d_max) + 1;
    } else {
      a0 = az_bin(d_max) - 1;
      a1 = az_bin(d_min) + 1 + kAzBins;
    }
    if (a1 - a0 >= kAzBins) {
      a0 = 0;
      a1 = kAzBins - 1;
    }
  }
  for (int e = e0; e <= e1; ++e) {
    const std::size_t row = static_cast<std::size_t>(e) * kAzBins;
    // The azimuth range as at most two runs of the row (it may wrap).
    for (int a = a0; a <= a1;) {
      const int first = ((a % kAzBins) + kAzBins) % kAzBins;
      const int last = std::min(kAzBins - 1, first + (a1 - a));
      for (std::uint32_t i = bin_first_[row + first], end = bin_first_[row + last + 1]; i < end;
           ++i) {
        const Ray& r = rays_[i];
        if ((r.measured || !measured_only) && ray_passes(r, lo, hi, behind_m)) return true;
      }
      a += last - first + 1;
    }
  }
  return false;
}

std::size_t ScanRays::memory_bytes() const {
  return (rays_.capacity() + unsorted_.capacity()) * sizeof(Ray) +
         (bin_first_.capacity() + ray_bin_.capacity()) * sizeof(std::uint32_t);
}

}  // namespace tarmac::core
