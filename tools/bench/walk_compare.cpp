#include "walk_compare.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <openvdb/math/DDA.h>
#include <openvdb/math/Ray.h>

#include "tarmac/tools/stats.hpp"
#include "tsdf_band_walk.hpp"

namespace tarmac::bench {

namespace {

/// A ray's band voxels: how many, and the sum of their signed distances (to compare the walks).
struct BandTotal {
  std::uint64_t voxels = 0;
  double sdf_sum = 0.0;
};

/// The ray's segment in the band, as TsdfIntegrator walks it without space carving.
struct Segment {
  Eigen::Vector3d dir;
  double range, t0, t1;
};

bool segment_of(const Eigen::Vector3d& o, const Eigen::Vector3f& p, double trunc, double max_range,
                Segment& s) {
  const Eigen::Vector3d d = p.cast<double>() - o;
  s.range = d.norm();
  if (!std::isfinite(s.range) || s.range > max_range || s.range <= 0.0) return false;
  s.dir = d / s.range;
  s.t0 = std::max(0.0, s.range - trunc);
  s.t1 = s.range + trunc;
  return true;
}

BandTotal walk_ours(const Eigen::Vector3d& o, const Segment& s, double v, double trunc) {
  BandTotal total;
  total.voxels = core::walk_band<false>(o, s.dir, s.range, s.t0, s.t1, v, trunc,
                                        [&](int, int, int, float sdf) { total.sdf_sum += sdf; });
  return total;
}

/// OpenVDB's DDA in index space (voxel i is [i, i+1) there, [i·v, (i+1)·v) in the world: the
/// same lattice), t in voxels; the centre offset and distance computed per voxel as TSDF code
/// over OpenVDB does.
BandTotal walk_dda(const Eigen::Vector3d& o, const Segment& s, double v, double trunc) {
  using Ray = openvdb::math::Ray<double>;
  const Ray ray(openvdb::Vec3d(o.x() / v, o.y() / v, o.z() / v),
                openvdb::Vec3d(s.dir.x(), s.dir.y(), s.dir.z()), s.t0 / v, s.t1 / v);
  openvdb::math::DDA<Ray, 0> dda(ray);
  BandTotal total;
  do {
    const openvdb::Coord c = dda.voxel();
    const double cx = (c.x() + 0.5) * v - o.x(), cy = (c.y() + 0.5) * v - o.y(),
                 cz = (c.z() + 0.5) * v - o.z();
    const double sdf = s.range - std::sqrt(cx * cx + cy * cy + cz * cz);
    if (sdf <= trunc && sdf >= -trunc) {
      ++total.voxels;
      total.sdf_sum += static_cast<float>(sdf);
    }
  } while (dda.step());
  return total;
}

}  // namespace

void WalkCompare::add_scan(const Eigen::Vector3d& origin_W,
                           std::span<const Eigen::Vector3f> points_W, double voxel_m,
                           double truncation_m, double max_range_m) {
  std::vector<Segment> segments;
  segments.reserve(points_W.size());
  for (const auto& p : points_W) {
    Segment s{};
    if (segment_of(origin_W, p, truncation_m, max_range_m, s)) segments.push_back(s);
  }
  std::vector<BandTotal> ours(segments.size()), dda(segments.size());
  ours_ms.push_back(tools::timed_ms([&] {
    for (std::size_t i = 0; i < segments.size(); ++i) {
      ours[i] = walk_ours(origin_W, segments[i], voxel_m, truncation_m);
    }
  }));
  dda_ms.push_back(tools::timed_ms([&] {
    for (std::size_t i = 0; i < segments.size(); ++i) {
      dda[i] = walk_dda(origin_W, segments[i], voxel_m, truncation_m);
    }
  }));
  for (std::size_t i = 0; i < segments.size(); ++i) {
    ours_voxels += ours[i].voxels;
    dda_voxels += dda[i].voxels;
    rays_differing +=
        ours[i].voxels != dda[i].voxels || std::abs(ours[i].sdf_sum - dda[i].sdf_sum) > 1e-3;
  }
  rays += segments.size();
}

void WalkCompare::print() const {
  const auto row = [](const char* name, const std::vector<double>& ms) {
    std::printf("  %-26s %9.2f %9.2f %9.2f %9.2f\n", name, tools::mean(ms),
                tools::percentile(ms, 0.5), tools::percentile(ms, 0.99),
                tools::percentile(ms, 1.0));
  };
  std::printf("\ntarmac-bench: TSDF band walk against OpenVDB's DDA, one thread, same rays\n");
  std::printf("  %-26s %9s %9s %9s %9s   (ms per scan)\n", "", "mean", "p50", "p99", "max");
  row("tarmac walk_band", ours_ms);
  row("OpenVDB DDA", dda_ms);
  std::printf(
      "  DDA / tarmac: mean %.2fx, p50 %.2fx; band voxels: tarmac %llu, DDA %llu; rays whose band "
      "differs: %llu of %llu\n",
      tools::mean(dda_ms) / tools::mean(ours_ms),
      tools::percentile(dda_ms, 0.5) / tools::percentile(ours_ms, 0.5),
      static_cast<unsigned long long>(ours_voxels), static_cast<unsigned long long>(dda_voxels),
      static_cast<unsigned long long>(rays_differing), static_cast<unsigned long long>(rays));
}

}  // namespace tarmac::bench
