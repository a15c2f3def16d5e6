#include "vdbfusion_reference.hpp"

#include <algorithm>
#include <cmath>
#include <functional>

#include <openvdb/math/DDA.h>
#include <openvdb/math/Ray.h>
#include <openvdb/openvdb.h>

namespace tarmac::bench {

struct VdbFusionReference::Impl {
  float voxel_size_m;
  float truncation_m;
  openvdb::FloatGrid::Ptr tsdf;
  openvdb::FloatGrid::Ptr weights;
  /// VDBFusion takes the weighting function as a std::function; its default is a constant 1.
  std::function<float(float)> weighting = [](float) { return 1.0f; };
};

VdbFusionReference::VdbFusionReference(float voxel_size_m, float truncation_m)
    : impl_(std::make_unique<Impl>()) {
  openvdb::initialize();
  impl_->voxel_size_m = voxel_size_m;
  impl_->truncation_m = truncation_m;
  const auto xform = openvdb::math::Transform::createLinearTransform(voxel_size_m);
  impl_->tsdf = openvdb::FloatGrid::create(truncation_m);
  impl_->tsdf->setTransform(xform);
  impl_->weights = openvdb::FloatGrid::create(0.0f);
  impl_->weights->setTransform(xform);
}

VdbFusionReference::~VdbFusionReference() = default;

void VdbFusionReference::integrate(const Eigen::Vector3d& origin_W,
                                   std::span<const Eigen::Vector3f> points_W, double max_range_m) {
  Impl& m = *impl_;
  const openvdb::math::Transform& xform = m.tsdf->transform();
  const openvdb::Vec3R eye(origin_W.x(), origin_W.y(), origin_W.z());
  const double half = 0.5 * xform.voxelSize()[0];
  const float trunc = m.truncation_m;
  auto tsdf_acc = m.tsdf->getUnsafeAccessor();
  auto weights_acc = m.weights->getUnsafeAccessor();
  for (const Eigen::Vector3f& pf : points_W) {
    const Eigen::Vector3d point = pf.cast<double>();
    const Eigen::Vector3d direction = point - origin_W;
    const double range = direction.norm();
    if (!std::isfinite(range) || range <= 0.0 || range > max_range_m) continue;
    openvdb::Vec3R dir(direction.x(), direction.y(), direction.z());
    dir.normalize();
    const auto depth = static_cast<float>(range);
    const float t0 = depth - trunc;
    const float t1 = depth + trunc;
    const auto ray = openvdb::math::Ray<float>(eye, dir, t0, t1).worldToIndex(*m.tsdf);
    openvdb::math::DDA<std::remove_const_t<decltype(ray)>> dda(ray);
    do {
      const openvdb::Coord voxel = dda.voxel();
      const openvdb::Vec3d c = xform.indexToWorld(voxel) + half;
      const Eigen::Vector3d center(c.x(), c.y(), c.z());
      // VDBFusion's ComputeSDF: |return − centre|, negative behind the return along the ray.
      const Eigen::Vector3d to_point = point - center;
      const double dist = to_point.norm();
      const double proj = (center - origin_W).dot(to_point);
      const auto sdf = static_cast<float>(proj < 0.0 ? -dist : dist);
      if (sdf > -trunc) {
        const float tsdf = std::min(trunc, sdf);
        const float weight = m.weighting(sdf);
        const float last_weight = weights_acc.getValue(voxel);
        const float last_tsdf = tsdf_acc.getValue(voxel);
        const float new_weight = weight + last_weight;
        tsdf_acc.setValue(voxel, (last_tsdf * last_weight + tsdf * weight) / new_weight);
        weights_acc.setValue(voxel, new_weight);
      }
    } while (dda.step());
  }
}

std::size_t VdbFusionReference::voxel_count() const {
  return impl_->tsdf->tree().activeVoxelCount();
}

}  // namespace tarmac::bench
