#include "tarmac/core/tsdf_changes.hpp"

#include <algorithm>
#include <cmath>

namespace tarmac::core {

Status ChangeParams::validate() const {
  if (!(min_weight > 0.0f)) return Error{"tsdf_changes.invalid", "min_weight must be > 0"};
  if (!(confident_weight >= min_weight)) {
    return Error{"tsdf_changes.invalid", "confident_weight must be >= min_weight"};
  }
  if (!(surface_band_m > 0.0f && off_surface_m > surface_band_m)) {
    return Error{"tsdf_changes.invalid", "need 0 < surface_band_m < off_surface_m"};
  }
  if (!(min_z_m <= max_z_m)) return Error{"tsdf_changes.invalid", "min_z_m must be <= max_z_m"};
  return Ok{};
}

void compare_blocks(const TsdfBlockView& before, const TsdfBlockView& now,
                    const ChangeParams& params, double v, const Eigen::Vector2i& origin,
                    std::uint32_t width, std::span<float> raster, ChangeCounts& counts) {
  const float band = params.surface_band_m, off = params.off_surface_m;
  for (int i = 0; i < kTsdfBlockEdge; ++i) {
    for (int j = 0; j < kTsdfBlockEdge; ++j) {
      const int x = now.block.x() * kTsdfBlockEdge + i - origin.x();
      const int y = now.block.y() * kTsdfBlockEdge + j - origin.y();
      float& cell = raster[static_cast<std::size_t>(y) * width + static_cast<std::size_t>(x)];
      for (int k = 0; k < kTsdfBlockEdge; ++k) {
        const double z_m = (now.block.z() * kTsdfBlockEdge + k + 0.5) * v;
        if (z_m < params.min_z_m || z_m > params.max_z_m) continue;
        const int n = tsdf_voxel_offset(i, j, k);
        const float wn = now.voxels[n].weight, wp = before.voxels[n].weight;
        if (!(wn >= params.min_weight && wp >= params.min_weight)) continue;
        ++counts.compared_voxels;
        if (std::isnan(cell)) cell = 0.0f;
        const float dn = std::abs(now.voxels[n].distance_m);
        const float dp = std::abs(before.voxels[n].distance_m);
        const float confidence = std::min(1.0f, std::min(wn, wp) / params.confident_weight);
        float signed_change = 0.0f;
        if (dn <= band && dp >= off) {
          ++counts.new_voxels;
          signed_change = confidence;
        } else if (dp <= band && dn >= off) {
          ++counts.removed_voxels;
          signed_change = -confidence;
        } else {
          continue;
        }
        const float a = std::abs(signed_change), c = std::abs(cell);
        if (a > c || (a == c && signed_change > 0.0f)) cell = signed_change;
      }
    }
  }
}

Status detect_changes(const TsdfLayer& prior, const TsdfLayer& current, const ChangeParams& params,
                      ChangeMap& out) {
  if (auto s = params.validate(); !s) return s;
  if (prior.voxel_size_m() != current.voxel_size_m()) {
    return Error{"tsdf_changes.mismatch", "the maps have different voxel sizes"};
  }
  // Extent: union of both maps' blocks, in voxels.
  Eigen::Vector2i lo(std::numeric_limits<int>::max(), std::numeric_limits<int>::max());
  Eigen::Vector2i hi(std::numeric_limits<int>::min(), std::numeric_limits<int>::min());
  const auto extend = [&](const TsdfBlockView& b) {
    lo = lo.cwiseMin(b.block.head<2>() * kTsdfBlockEdge);
    hi =
        hi.cwiseMax(b.block.head<2>() * kTsdfBlockEdge + Eigen::Vector2i::Constant(kTsdfBlockEdge));
  };
  prior.for_each_block(extend);
  current.for_each_block(extend);
  const double v = current.voxel_size_m();
  out = ChangeMap{};
  if (lo.x() >= hi.x()) return Ok{};
  out.geometry.origin_x_m = lo.x() * v;
  out.geometry.origin_y_m = lo.y() * v;
  out.geometry.resolution_m = v;
  out.geometry.width = static_cast<std::uint32_t>(hi.x() - lo.x());
  out.geometry.height = static_cast<std::uint32_t>(hi.y() - lo.y());
  out.change.assign(out.geometry.cell_count(), std::nanf(""));

  ChangeCounts counts;
  current.for_each_block([&](const TsdfBlockView& now) {
    const auto before = prior.find_block(now.block);
    if (before) compare_blocks(*before, now, params, v, lo, out.geometry.width, out.change, counts);
  });
  out.compared_voxels = counts.compared_voxels;
  out.new_voxels = counts.new_voxels;
  out.removed_voxels = counts.removed_voxels;
  return Ok{};
}

}  // namespace tarmac::core
