#include "ray_order.hpp"

#include <algorithm>

#include "../lanes4.hpp"

namespace tarmac::core::occupancy {
namespace {

/// The direction buckets of four rays (x, y, z: four lanes each), without a branch: a scan's
/// directions are as good as random. Any input gives a bucket in range (NaN and infinities
/// land in a valid one; such rays are not walked anyway).
void direction_buckets(Float4 x, Float4 y, Float4 z, std::uint16_t* out) {
  const Float4 zero = {0.0f, 0.0f, 0.0f, 0.0f};
  const Float4 ax = x < zero ? -x : x, ay = y < zero ? -y : y, az = z < zero ? -z : z;
  const Int4 x_dom = (ax >= ay) & (ax >= az);
  const Int4 y_dom = ~x_dom & (ay >= az);
  const Int4 z_dom = ~x_dom & ~y_dom;
  const Float4 big = x_dom ? ax : (y_dom ? ay : az);
  const Float4 u = x_dom ? y : x;
  const Float4 v = z_dom ? y : z;
  // A comparison gives −1 where true: face 2·axis, +1 when the dominant coordinate is positive.
  const Int4 face = (x_dom & -(x > zero)) | (y_dom & (2 - (y > zero))) | (z_dom & (4 - (z > zero)));
  const Float4 one = {1.0f, 1.0f, 1.0f, 1.0f};
  // In [0, 2) on the face; anything else (a zero or non-finite direction) to 0.
  Float4 fu = u / big + one, fv = v / big + one;
  const Float4 two = one + one;
  fu = ((fu >= zero) & (fu < two)) ? fu : zero;
  fv = ((fv >= zero) & (fv < two)) ? fv : zero;
  const Float4 half_bins = one * (0.5f * kDirBins), half_bands = one * (0.5f * kDirBands);
  const Int4 bin = __builtin_convertvector(fu * half_bins, Int4);
  const Int4 band = __builtin_convertvector(fv * half_bands, Int4);
  const Int4 bucket = (face * kDirBands + band) * kDirBins + bin;
  for (int k = 0; k < 4; ++k) {
    out[k] =
        static_cast<std::uint16_t>(std::clamp(bucket[k], 0, static_cast<int>(kDirBuckets) - 1));
  }
}

}  // namespace

void sort_rays_by_direction(const Eigen::Vector3d& origin_W,
                            std::span<const Eigen::Vector3f> points,
                            std::span<const Eigen::Vector3f> dirs,
                            std::vector<std::uint16_t>& bucket, std::vector<std::uint32_t>& count,
                            std::vector<std::uint32_t>& order, TaskRunner& runner) {
  const std::size_t n_points = points.size();
  const std::size_t n_rays = n_points + dirs.size();
  const std::size_t n_quads = (n_rays + 3) / 4;
  bucket.resize(4 * n_quads);
  order.resize(n_rays);
  count.resize(kBucketTasks * kDirBuckets);
  const Eigen::Vector3f o = origin_W.cast<float>();
  runner.parallel_for(kBucketTasks, [&](std::size_t task) {
    const std::size_t q0 = n_quads * task / kBucketTasks, q1 = n_quads * (task + 1) / kBucketTasks;
    for (std::size_t i = 4 * q0; i < 4 * q1; i += 4) {
      Float4 x{}, y{}, z{};
      if (i + 4 <= n_points) {  // four returns, contiguous
        load_xyz4(points.data() + i, x, y, z);
        const Float4 zero{};
        direction_buckets(x - (zero + o.x()), y - (zero + o.y()), z - (zero + o.z()),
                          bucket.data() + i);
        continue;
      }
      for (std::size_t k = 0; k < 4 && i + k < n_rays; ++k) {
        const std::size_t r = i + k;
        const Eigen::Vector3f q =
            r < n_points ? Eigen::Vector3f(points[r] - o) : dirs[r - n_points];
        x[k] = q.x();
        y[k] = q.y();
        z[k] = q.z();
      }
      direction_buckets(x, y, z, bucket.data() + i);
    }
    // The range's own histogram (a counting sort split by range: the order is the serial one).
    std::uint32_t* const c = count.data() + task * kDirBuckets;
    std::fill_n(c, kDirBuckets, 0u);
    for (std::size_t r = 4 * q0; r < std::min(4 * q1, n_rays); ++r) ++c[bucket[r]];
  });
  // Each range's first place per bucket: buckets in order, within a bucket the ranges in order,
  // so rays keep their scan order within a bucket (stable), as one serial pass would.
  std::uint32_t next = 0;
  for (std::size_t b = 0; b < kDirBuckets; ++b) {
    for (std::size_t t = 0; t < kBucketTasks; ++t) {
      std::uint32_t& c = count[t * kDirBuckets + b];
      const std::uint32_t n = c;
      c = next;
      next += n;
    }
  }
  runner.parallel_for(kBucketTasks, [&](std::size_t task) {
    const std::size_t q0 = n_quads * task / kBucketTasks, q1 = n_quads * (task + 1) / kBucketTasks;
    std::uint32_t* const c = count.data() + task * kDirBuckets;
    for (std::size_t r = 4 * q0; r < std::min(4 * q1, n_rays); ++r) {
      order[c[bucket[r]]++] = static_cast<std::uint32_t>(r);
    }
  });
}

}  // namespace tarmac::core::occupancy
