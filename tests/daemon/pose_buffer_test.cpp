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

}  // namespace
}  // namespace tarmac::daemon
