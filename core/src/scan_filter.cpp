#include "tarmac/core/scan_filter.hpp"

namespace tarmac::core {

Status FilterParams::validate() const {
  if (!(min_range_m >= 0.0)) return Error{"config.range", "filters.min_range_m: must be >= 0"};
  if (ego_box_enabled && !(ego_box_min_B.array() < ego_box_max_B.array()).all()) {
    return Error{"config.range", "filters.ego_box: min must be < max on every axis"};
  }
  return Ok{};
}

FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W) {
  FilterCounts counts;
  points_W.clear();
  counts.input = cloud.size();
  const double min_sq = params.min_range_m * params.min_range_m;
  const Eigen::Matrix3f R_W_S = T_W_S.linear().cast<float>();
  const Eigen::Vector3f t_W_S = T_W_S.translation().cast<float>();
  const Eigen::Matrix3d R_B_S = T_B_S.linear();
  const Eigen::Vector3d t_B_S = T_B_S.translation();
  for (const auto& p : cloud.points_S) {
    if (!p.allFinite()) {
      ++counts.non_finite;
      continue;
    }
    if (static_cast<double>(p.squaredNorm()) < min_sq) {
      ++counts.too_close;
      continue;
    }
    if (params.ego_box_enabled) {
      const Eigen::Vector3d p_B = R_B_S * p.cast<double>() + t_B_S;
      if ((p_B.array() >= params.ego_box_min_B.array()).all() &&
          (p_B.array() <= params.ego_box_max_B.array()).all()) {
        ++counts.ego_vehicle;
        continue;
      }
    }
    points_W.push_back(R_W_S * p + t_W_S);
  }
  counts.kept = points_W.size();
  return counts;
}

}  // namespace tarmac::core
