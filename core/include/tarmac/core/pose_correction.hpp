#pragma once
/// @file Pose-graph corrections (DESIGN.md §4): what counts as a correction of the trajectory and
/// how a revised pose is found for a retained scan. Two inputs:
///  (a) a corrected trajectory: revised poses T_W_B for past stamps (a loop closure's output,
///      `nav_msgs/Path`-like), looked up per retained scan by interpolate_pose();
///  (b) a jump in the live pose stream: a sample that lies farther than a threshold from the
///      constant-velocity prediction of the two samples before it (PoseJumpDetector). The jump
///      Δ = T_new · T_pred⁻¹ is taken as a rigid correction of everything older.
/// The Mapper (mapper.hpp) retains the last scans and rebuilds its maps from them with the
/// corrected poses. Pure functions of their arguments: no clock.

#include <cstdint>
#include <optional>
#include <span>

#include <Eigen/Geometry>

#include "tarmac/core/result.hpp"

namespace tarmac::core {

/// Config of the correction handling (`corrections:` in the YAML).
struct CorrectionParams {
  /// Retain scans and rebuild on corrections. Off: no retention, corrections are ignored.
  bool enabled = true;
  /// Scans kept for a rebuild (ring, oldest dropped first): the rebuilt window holds what these
  /// saw. At 10 Hz, 50 = the last 5 s.
  int retain_scans = 50;
  /// A live pose farther than this from its prediction is a jump (m, along any axis combined).
  double jump_threshold_m = 0.5;
  /// … or rotated farther than this from it (deg).
  double jump_threshold_deg = 3.0;
  /// No prediction (hence no jump detection) across a gap between pose samples longer than this.
  double max_prediction_gap_s = 0.5;
  /// Rebuild work: retained points re-integrated per rebuild_step() call, i.e. per ingested scan
  /// (at least two scans, so it always catches up; 0: the whole rebuild in one call). While a
  /// rebuild runs the published maps come from the live map.
  std::uint64_t rebuild_points_per_cycle = 80000;

  [[nodiscard]] Status validate() const;
};

/// A pose of the vehicle base in the world (map) frame at a stamp.
struct StampedPose {
  std::int64_t stamp_ns = 0;
  Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
};

/// Translation and rotation (rad) between two poses.
struct PoseDifference {
  double translation_m = 0.0;
  double rotation_rad = 0.0;
};
[[nodiscard]] PoseDifference pose_difference(const Eigen::Isometry3d& a,
                                             const Eigen::Isometry3d& b);

/// The pose at `stamp_ns` on a trajectory sorted by stamp: the exact sample when a stamp matches,
/// else lerp + slerp between the neighbours. Outside the trajectory's span, nothing (a corrected
/// trajectory says nothing about stamps it does not cover). Empty trajectory: nothing.
[[nodiscard]] std::optional<Eigen::Isometry3d> interpolate_pose(
    std::span<const StampedPose> trajectory, std::int64_t stamp_ns);

/// Detects jumps in a live pose stream. Feed every accepted sample in stamp order.
class PoseJumpDetector {
 public:
  explicit PoseJumpDetector(const CorrectionParams& params) : params_(params) {}

  /// The jump Δ (T_new = Δ · T_predicted) when `sample` is farther than the thresholds from the
  /// constant-velocity prediction of the two samples before it, else nothing. The first two
  /// samples, samples after a gap longer than max_prediction_gap_s and samples not newer than
  /// the last one never count as jumps. RT-safe.
  std::optional<Eigen::Isometry3d> feed(const StampedPose& sample);

  /// Re-expresses the history in a corrected frame (T ← Δ · T), so that the samples after a
  /// correction are predicted from corrected ones. feed() calls it itself on a jump.
  void rebase(const Eigen::Isometry3d& delta);
  /// Replaces the history by the given samples (the last two count), e.g. the tail of a
  /// corrected trajectory.
  void reset(std::span<const StampedPose> history);

  /// The prediction for `stamp_ns`, or nothing (fewer than two samples, gap too long).
  [[nodiscard]] std::optional<Eigen::Isometry3d> predict(std::int64_t stamp_ns) const;

 private:
  CorrectionParams params_;
  StampedPose prev_, last_;
  int count_ = 0;  // samples in history, 0..2
};

}  // namespace tarmac::core
