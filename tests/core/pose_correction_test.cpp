// Pose-correction inputs (core/pose_correction.hpp): trajectory interpolation and the live jump
// detector, against exact answers.

#include "tarmac/core/pose_correction.hpp"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

constexpr std::int64_t kMs = 1'000'000;

Eigen::Isometry3d pose(double x, double y, double yaw_deg) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(x, y, 0.0);
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).matrix();
  return T;
}

/// A vehicle at 3 m/s along x turning at 10 deg/s, sampled every 100 ms.
StampedPose moving(int k) {
  return {k * 100 * kMs, pose(0.3 * k, 0.0, 1.0 * k)};
}

TEST(InterpolatePose, ExactSampleAndMidpoint) {
  const std::vector<StampedPose> traj = {{0, pose(0, 0, 0)}, {100 * kMs, pose(2, 4, 20)}};
  const auto exact = interpolate_pose(traj, 100 * kMs);
  ASSERT_TRUE(exact);
  EXPECT_TRUE(exact->isApprox(traj[1].T_W_B, 0.0));
  const auto mid = interpolate_pose(traj, 50 * kMs);
  ASSERT_TRUE(mid);
  EXPECT_NEAR(mid->translation().x(), 1.0, 1e-12);
  EXPECT_NEAR(mid->translation().y(), 2.0, 1e-12);
  EXPECT_NEAR(Eigen::AngleAxisd(mid->linear()).angle() * 180.0 / M_PI, 10.0, 1e-9);
}

TEST(InterpolatePose, NothingOutsideTheSpan) {
  const std::vector<StampedPose> traj = {{10 * kMs, pose(0, 0, 0)}, {20 * kMs, pose(1, 0, 0)}};
  EXPECT_FALSE(interpolate_pose(traj, 9 * kMs));
  EXPECT_FALSE(interpolate_pose(traj, 21 * kMs));
  EXPECT_FALSE(interpolate_pose({}, 10 * kMs));
}

TEST(PoseJumpDetector, SmoothMotionIsNoJump) {
  PoseJumpDetector d{CorrectionParams{}};
  for (int k = 0; k < 50; ++k) EXPECT_FALSE(d.feed(moving(k))) << k;
}

TEST(PoseJumpDetector, JumpAboveThresholdGivesTheCorrection) {
  CorrectionParams p;
  p.jump_threshold_m = 0.5;
  PoseJumpDetector d{p};
  for (int k = 0; k < 10; ++k) ASSERT_FALSE(d.feed(moving(k)));
  // The fix moves the vehicle 0.8 m to the left of where it was predicted.
  StampedPose fixed = moving(10);
  const Eigen::Isometry3d predicted = fixed.T_W_B;
  fixed.T_W_B.translation().y() += 0.8;
  const auto jump = d.feed(fixed);
  ASSERT_TRUE(jump);
  EXPECT_TRUE((*jump * predicted).isApprox(fixed.T_W_B, 1e-9));
  EXPECT_NEAR(jump->translation().norm(), 0.8, 1e-9);
  // The next samples continue from the corrected frame: no second jump.
  for (int k = 11; k < 20; ++k) {
    StampedPose s = moving(k);
    s.T_W_B = *jump * s.T_W_B;
    EXPECT_FALSE(d.feed(s)) << k;
  }
}

TEST(PoseJumpDetector, JumpBelowThresholdIsNone) {
  CorrectionParams p;
  p.jump_threshold_m = 0.5;
  p.jump_threshold_deg = 3.0;
  PoseJumpDetector d{p};
  for (int k = 0; k < 10; ++k) ASSERT_FALSE(d.feed(moving(k)));
  StampedPose s = moving(10);
  s.T_W_B.translation().y() += 0.45;  // below 0.5 m
  s.T_W_B.linear() =
      s.T_W_B.linear() * Eigen::AngleAxisd(2.5 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).matrix();
  EXPECT_FALSE(d.feed(s));
}

TEST(PoseJumpDetector, RotationJumpCounts) {
  PoseJumpDetector d{CorrectionParams{}};  // 3 deg
  for (int k = 0; k < 10; ++k) ASSERT_FALSE(d.feed(moving(k)));
  StampedPose s = moving(10);
  s.T_W_B.linear() =
      s.T_W_B.linear() * Eigen::AngleAxisd(4.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).matrix();
  EXPECT_TRUE(d.feed(s));
}

TEST(PoseJumpDetector, NoPredictionAcrossAGapOrBeforeTwoSamples) {
  CorrectionParams p;
  p.max_prediction_gap_s = 0.5;
  PoseJumpDetector d{p};
  EXPECT_FALSE(d.feed({0, pose(0, 0, 0)}));
  EXPECT_FALSE(d.feed({100 * kMs, pose(100, 0, 0)}));  // second sample: no prediction yet
  EXPECT_FALSE(d.feed({200 * kMs, pose(200, 0, 0)}));  // consistent
  EXPECT_FALSE(d.feed({900 * kMs, pose(0, 0, 0)}));    // 0.7 s gap: no prediction
  EXPECT_FALSE(d.feed({900 * kMs, pose(50, 0, 0)}));   // not newer: ignored
}

TEST(CorrectionParams, RangesAreChecked) {
  CorrectionParams p;
  EXPECT_TRUE(p.validate().ok());
  p.retain_scans = 0;
  EXPECT_FALSE(p.validate().ok());
  p = {};
  p.jump_threshold_m = 0.0;
  EXPECT_FALSE(p.validate().ok());
  p = {};
  p.jump_threshold_deg = 200.0;
  EXPECT_FALSE(p.validate().ok());
}

}  // namespace
}  // namespace tarmac::core
