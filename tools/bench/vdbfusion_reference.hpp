#pragma once
/// @file A same-run TSDF baseline for tarmac-bench: VDBFusion's integration algorithm
/// (Vizzo et al., "VDBFusion", Sensors 22(3) 2022; PRBonn/vdbfusion VDBVolume::Integrate),
/// written here from its description so that tarmac's TSDF time is reported as a ratio measured
/// in the same process on the same points. OpenVDB stays in the .cpp.

#include <memory>
#include <span>

#include <Eigen/Core>

namespace tarmac::bench {

/// VDBFusion's TSDF as it runs by default: single-threaded, no space carving, constant weight 1,
/// no weight cap. Per point, an OpenVDB DDA over the ray segment [r − trunc, r + trunc] in index
/// space; every voxel crossed with signed distance sdf > −trunc (VDBFusion's ComputeSDF: the
/// distance from the voxel centre to the return, signed by which side of the return it lies on
/// along the ray) gets tsdf = min(sdf, trunc) folded into a running average through two
/// FloatGrid accessors (distance, weight), one getValue/setValue pair each per voxel visit.
class VdbFusionReference {
 public:
  VdbFusionReference(float voxel_size_m, float truncation_m);
  ~VdbFusionReference();
  VdbFusionReference(const VdbFusionReference&) = delete;
  VdbFusionReference& operator=(const VdbFusionReference&) = delete;

  /// Integrates one scan (world frame) seen from `origin_W`; returns beyond max_range_m skipped.
  void integrate(const Eigen::Vector3d& origin_W, std::span<const Eigen::Vector3f> points_W,
                 double max_range_m);

  /// Voxels written so far (active voxels of the distance grid).
  [[nodiscard]] std::size_t voxel_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::bench
