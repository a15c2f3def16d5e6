#include "tarmac/core/scan_filter.hpp"

#include <cmath>

namespace tarmac::core {

Status FilterParams::validate() const {
  if (!(min_range_m >= 0.0)) return Error{"config.range", "filters.min_range_m: must be >= 0"};
  if (ego_box_enabled && !(ego_box_min_B.array() < ego_box_max_B.array()).all()) {
    return Error{"config.range", "filters.ego_box: min must be < max on every axis"};
  }
  if (outlier_min_neighbors < 0 || outlier_min_neighbors > 26) {
    return Error{"config.range", "filters.outlier_min_neighbors: must be in [0, 26]"};
  }
  if (!(outlier_cell_m >= 0.05 && outlier_cell_m <= 5.0)) {
    return Error{"config.range", "filters.outlier_cell_m: must be in [0.05, 5]"};
  }
  return Ok{};
}

namespace {

/// Packs a cell coordinate (each within ±2^20 cells) into a non-zero key.
std::uint64_t cell_key(const Eigen::Vector3f& p, float inv_cell) {
  const auto c = [&](float v) {
    return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(v * inv_cell)) +
                                      (1 << 20)) &
           0x1fffff;
  };
  return (c(p.x()) << 42) | (c(p.y()) << 21) | c(p.z()) | (1ull << 63);
}

std::size_t slot_of(std::uint64_t key, std::size_t mask) {
  return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> 40) & mask;
}

}  // namespace

FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W, FilterScratch& scratch) {
  FilterCounts counts;
  points_W.clear();
  scratch.candidates_S.clear();
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
    scratch.candidates_S.push_back(p);
  }
  // Isolated outliers, counted in the sensor frame: a hash of occupied cells, then each near
  // point looks at its 27 cells. Membership only, so the result does not depend on order.
  const auto& cand = scratch.candidates_S;
  const bool outliers = params.outlier_min_neighbors > 0;
  const float inv_cell = static_cast<float>(1.0 / params.outlier_cell_m);
  const float near_sq = static_cast<float>(params.outlier_max_range_m * params.outlier_max_range_m);
  std::size_t mask = 0;
  if (outliers) {
    std::size_t capacity = 1024;
    while (capacity < 2 * cand.size()) capacity *= 2;
    mask = capacity - 1;
    scratch.keys.assign(capacity, 0);
    scratch.counts.assign(capacity, 0);
    scratch.point_key.resize(cand.size());
    for (std::size_t i = 0; i < cand.size(); ++i) {
      const std::uint64_t key = cell_key(cand[i], inv_cell);
      scratch.point_key[i] = key;
      std::size_t s = slot_of(key, mask);
      while (scratch.keys[s] != 0 && scratch.keys[s] != key) s = (s + 1) & mask;
      scratch.keys[s] = key;
      ++scratch.counts[s];
    }
  }
  const auto count_in = [&](std::uint64_t key) -> std::uint32_t {
    std::size_t s = slot_of(key, mask);
    while (scratch.keys[s] != 0) {
      if (scratch.keys[s] == key) return scratch.counts[s];
      s = (s + 1) & mask;
    }
    return 0;
  };
  for (std::size_t i = 0; i < cand.size(); ++i) {
    const Eigen::Vector3f& p = cand[i];
    if (outliers && p.squaredNorm() < near_sq) {
      std::uint32_t others = 0;
      const std::uint64_t key = scratch.point_key[i];
      for (int dx = -1;
           dx <= 1 && others < static_cast<std::uint32_t>(params.outlier_min_neighbors) + 1; ++dx) {
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dz = -1; dz <= 1; ++dz) {
            const std::uint64_t k =
                key + (static_cast<std::uint64_t>(static_cast<std::int64_t>(dx)) << 42) +
                (static_cast<std::uint64_t>(static_cast<std::int64_t>(dy)) << 21) +
                static_cast<std::uint64_t>(static_cast<std::int64_t>(dz));
            others += count_in(k);
          }
        }
      }
      if (others - 1 < static_cast<std::uint32_t>(params.outlier_min_neighbors)) {  // minus itself
        ++counts.isolated;
        continue;
      }
    }
    points_W.push_back(R_W_S * p + t_W_S);
  }
  counts.kept = points_W.size();
  return counts;
}

}  // namespace tarmac::core
