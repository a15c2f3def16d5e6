// PoseBuffer: exact samples, interpolation (lerp + slerp), and every refusal.

#include "tarmac/daemon/pose_buffer.hpp"

#include <cmath>

#include <gtest/gtest.h>

namespace tarmac::daemon {
namespace {

transport::PoseSample pose(std::int64_t stamp_ns, double x, double yaw_rad) {
  transport::PoseSample s;
  s.stamp_ns = stamp_ns;
  s.T_W_B = Eigen::Isometry3d::Identity();
  s.T_W_B.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  s.T_W_B.translation() = Eigen::Vector3d(x, 2.0 * x, 0.5);
  return s;
}

double yaw_of(const Eigen::Isometry3d& T) {
  return std::atan2(T.linear()(1, 0), T.linear()(0, 0));
}

TEST(PoseBuffer, Lookup_ExactStampReturnsTheSampleBitForBit) {
  PoseBuffer buffer(8, 1'000'000'000);
  const auto a = pose(100, 1.0, 0.3);
  ASSERT_EQ(buffer.insert(a), PoseBuffer::Insert::kOk);
  ASSERT_EQ(buffer.insert(pose(200, 2.0, 0.4)), PoseBuffer::Insert::kOk);
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.lookup(100, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.matrix(), a.T_W_B.matrix());  // no arithmetic on an exact hit
}

TEST(PoseBuffer, Lookup_InterpolatesTranslationAndSlerpsRotation) {
  PoseBuffer buffer(8, 1'000'000'000);
  buffer.insert(pose(1'000, 0.0, 0.0));
  buffer.insert(pose(2'000, 4.0, 1.0));
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.lookup(1'250, T), PoseBuffer::Lookup::kOk);
  EXPECT_NEAR(T.translation().x(), 1.0, 1e-12);
  EXPECT_NEAR(T.translation().y(), 2.0, 1e-12);
  EXPECT_NEAR(yaw_of(T), 0.25, 1e-12);  // slerp about one axis: the angle is linear in t
  EXPECT_NEAR((T.linear() * T.linear().transpose() - Eigen::Matrix3d::Identity()).norm(), 0.0,
              1e-12);
}

TEST(PoseBuffer, Lookup_RefusesToExtrapolate) {
  PoseBuffer buffer(8, 1'000'000'000);
  Eigen::Isometry3d T;
  EXPECT_EQ(buffer.lookup(5, T), PoseBuffer::Lookup::kNotYet);  // empty
  buffer.insert(pose(100, 0.0, 0.0));
  buffer.insert(pose(200, 1.0, 0.0));
  EXPECT_EQ(buffer.lookup(201, T), PoseBuffer::Lookup::kNotYet);
  EXPECT_EQ(buffer.lookup(99, T), PoseBuffer::Lookup::kTooOld);
}

TEST(PoseBuffer, Lookup_RefusesAGapWiderThanAllowed) {
  PoseBuffer buffer(8, 50);
  buffer.insert(pose(100, 0.0, 0.0));
  buffer.insert(pose(151, 1.0, 0.0));
  Eigen::Isometry3d T;
  EXPECT_EQ(buffer.lookup(120, T), PoseBuffer::Lookup::kGap);
  EXPECT_EQ(buffer.lookup(151, T), PoseBuffer::Lookup::kOk);  // exact samples are always fine
}

TEST(PoseBuffer, Insert_RefusesOlderAndDuplicateStamps) {
  PoseBuffer buffer(8, 1'000);
  EXPECT_EQ(buffer.insert(pose(100, 0.0, 0.0)), PoseBuffer::Insert::kOk);
  EXPECT_EQ(buffer.insert(pose(100, 9.0, 0.0)), PoseBuffer::Insert::kDuplicate);
  EXPECT_EQ(buffer.insert(pose(90, 9.0, 0.0)), PoseBuffer::Insert::kOutOfOrder);
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.lookup(100, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.translation().x(), 0.0);
}

TEST(PoseBuffer, Ring_ForgetsTheOldestWhenFull) {
  PoseBuffer buffer(3, 1'000);
  for (int i = 0; i < 5; ++i) buffer.insert(pose(100 * (i + 1), i, 0.0));
  EXPECT_EQ(buffer.size(), 3u);
  Eigen::Isometry3d T;
  EXPECT_EQ(buffer.lookup(200, T), PoseBuffer::Lookup::kTooOld);
  ASSERT_EQ(buffer.lookup(350, T), PoseBuffer::Lookup::kOk);
  EXPECT_NEAR(T.translation().x(), 2.5, 1e-12);
  EXPECT_EQ(buffer.newest_stamp().value(), 500);
}

TEST(PoseBuffer, RebaseBefore_MovesOnlyOlderSamples) {
  PoseBuffer buffer(8, 1'000'000'000);
  for (int k = 0; k < 5; ++k) buffer.insert(pose(100 * k, k, 0.1 * k));
  Eigen::Isometry3d delta = Eigen::Isometry3d::Identity();
  delta.translation() = Eigen::Vector3d(0.0, -1.0, 0.0);
  EXPECT_EQ(buffer.rebase_before(300, delta), 3u);  // stamps 0, 100, 200
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.lookup(200, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.matrix(), (delta * pose(200, 2, 0.1 * 2).T_W_B).matrix());
  ASSERT_EQ(buffer.lookup(300, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.matrix(), pose(300, 3, 0.1 * 3).T_W_B.matrix());
}

TEST(PoseBuffer, ApplyTrajectory_ReplacesTheSpanAndMovesNewerSamplesUpToWhenItWasMade) {
  PoseBuffer buffer(8, 1'000'000'000);
  for (int k = 0; k < 5; ++k) buffer.insert(pose(100 * k, k, 0.0));
  // The corrected trajectory covers stamps 100..200, shifted 0.5 m in z, and was made at 300:
  // the sample at 400 came from the corrected localiser already.
  std::vector<core::StampedPose> traj;
  for (int k = 1; k <= 2; ++k) {
    auto T = pose(100 * k, k, 0.0).T_W_B;
    T.translation().z() += 0.5;
    traj.push_back({100 * k, T});
  }
  EXPECT_EQ(buffer.apply_trajectory(traj, 300), 3u);  // 100, 200 replaced; 300 moved
  Eigen::Isometry3d T;
  ASSERT_EQ(buffer.lookup(0, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.translation().z(), 0.5);  // before the span: untouched
  ASSERT_EQ(buffer.lookup(200, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.matrix(), traj[1].T_W_B.matrix());
  ASSERT_EQ(buffer.lookup(300, T), PoseBuffer::Lookup::kOk);
  EXPECT_DOUBLE_EQ(T.translation().z(), 1.0);  // moved by the correction at the span's end
  EXPECT_DOUBLE_EQ(T.translation().x(), 3.0);
  ASSERT_EQ(buffer.lookup(400, T), PoseBuffer::Lookup::kOk);
  EXPECT_EQ(T.matrix(), pose(400, 4, 0.0).T_W_B.matrix());  // after it was made: kept
  core::StampedPose tail[2];
  ASSERT_EQ(buffer.newest_two(tail), 2u);
  EXPECT_EQ(tail[0].stamp_ns, 300);
  EXPECT_EQ(tail[1].stamp_ns, 400);
}

}  // namespace
}  // namespace tarmac::daemon
