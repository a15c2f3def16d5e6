#include "tarmac/core/pose_correction.hpp"

#include <algorithm>
#include <cmath>

namespace tarmac::core {

Status CorrectionParams::validate() const {
  if (!(retain_scans >= 1 && retain_scans <= 10000)) {
    return Error{"config.range", "corrections.retain_scans: must be in [1, 10000]"};
  }
  if (!(jump_threshold_m > 0.0 && jump_threshold_m <= 1000.0)) {
    return Error{"config.range", "corrections.jump_threshold_m: must be in (0, 1000]"};
  }
  if (!(jump_threshold_deg > 0.0 && jump_threshold_deg <= 180.0)) {
    return Error{"config.range", "corrections.jump_threshold_deg: must be in (0, 180]"};
  }
  if (!(max_prediction_gap_s > 0.0 && max_prediction_gap_s <= 60.0)) {
    return Error{"config.range", "corrections.max_prediction_gap_s: must be in (0, 60]"};
  }
  if (rebuild_points_per_cycle > 100'000'000ull) {
    return Error{"config.range", "corrections.rebuild_points_per_cycle: must be in [0, 1e8]"};
  }
  return Ok{};
}

PoseDifference pose_difference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  PoseDifference d;
  d.translation_m = (a.translation() - b.translation()).norm();
  d.rotation_rad = Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
  return d;
}

namespace {

/// a at f = 0, b at f = 1; f outside [0, 1] extrapolates (constant velocity).
Eigen::Isometry3d blend(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double f) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = a.translation() + f * (b.translation() - a.translation());
  const Eigen::Quaterniond qa(a.linear());
  const Eigen::Quaterniond qb(b.linear());
  if (f >= 0.0 && f <= 1.0) {
    T.linear() = qa.slerp(f, qb).normalized().toRotationMatrix();
  } else {
    // Extrapolated rotation: the relative rotation a -> b scaled by f.
    const Eigen::AngleAxisd rel(qa.conjugate() * qb);
    T.linear() = (qa * Eigen::Quaterniond(Eigen::AngleAxisd(rel.angle() * f, rel.axis())))
                     .normalized()
                     .toRotationMatrix();
  }
  return T;
}

}  // namespace

std::optional<Eigen::Isometry3d> interpolate_pose(std::span<const StampedPose> trajectory,
                                                  std::int64_t stamp_ns) {
  if (trajectory.empty()) return std::nullopt;
  if (stamp_ns < trajectory.front().stamp_ns || stamp_ns > trajectory.back().stamp_ns) {
    return std::nullopt;
  }
  const auto it =
      std::lower_bound(trajectory.begin(), trajectory.end(), stamp_ns,
                       [](const StampedPose& p, std::int64_t s) { return p.stamp_ns < s; });
  if (it->stamp_ns == stamp_ns) return it->T_W_B;
  const StampedPose& b = *it;
  const StampedPose& a = *(it - 1);
  const double f =
      static_cast<double>(stamp_ns - a.stamp_ns) / static_cast<double>(b.stamp_ns - a.stamp_ns);
  return blend(a.T_W_B, b.T_W_B, f);
}

std::optional<Eigen::Isometry3d> PoseJumpDetector::predict(std::int64_t stamp_ns) const {
  if (count_ < 2) return std::nullopt;
  const double max_gap_ns = params_.max_prediction_gap_s * 1e9;
  if (static_cast<double>(last_.stamp_ns - prev_.stamp_ns) > max_gap_ns ||
      static_cast<double>(stamp_ns - last_.stamp_ns) > max_gap_ns || stamp_ns <= last_.stamp_ns) {
    return std::nullopt;
  }
  const double f = static_cast<double>(stamp_ns - prev_.stamp_ns) /
                   static_cast<double>(last_.stamp_ns - prev_.stamp_ns);
  return blend(prev_.T_W_B, last_.T_W_B, f);
}

std::optional<Eigen::Isometry3d> PoseJumpDetector::feed(const StampedPose& sample) {
  if (count_ > 0 && sample.stamp_ns <= last_.stamp_ns) return std::nullopt;  // not newer
  std::optional<Eigen::Isometry3d> jump;
  if (const auto predicted = predict(sample.stamp_ns)) {
    const PoseDifference d = pose_difference(*predicted, sample.T_W_B);
    const double max_rad = params_.jump_threshold_deg * M_PI / 180.0;
    if (d.translation_m > params_.jump_threshold_m || d.rotation_rad > max_rad) {
      jump = sample.T_W_B * predicted->inverse();
      rebase(*jump);
    }
  }
  prev_ = last_;
  last_ = sample;
  count_ = std::min(count_ + 1, 2);
  return jump;
}

void PoseJumpDetector::rebase(const Eigen::Isometry3d& delta) {
  prev_.T_W_B = delta * prev_.T_W_B;
  last_.T_W_B = delta * last_.T_W_B;
}

void PoseJumpDetector::reset(std::span<const StampedPose> history) {
  count_ = 0;
  for (const StampedPose& p : history.last(std::min<std::size_t>(history.size(), 2))) {
    prev_ = last_;
    last_ = p;
    ++count_;
  }
}

}  // namespace tarmac::core
