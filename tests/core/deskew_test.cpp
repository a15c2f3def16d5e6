// Deskew: a sensor that moves and turns during its sweep sees a wall; with per-point times and
// the poses at the sweep's ends, the compensated points lie on the wall (to the time-bin error),
// while taking the sweep as rigid smears them by the distance travelled.

#include "tarmac/core/deskew.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "tarmac/core/mapper.hpp"

namespace tarmac::core {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// Base pose at time t: 10 m/s along x, yawing at 90 °/s, from the origin at t = 0.
Eigen::Isometry3d base_at(double t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(10.0 * t, 0.0, 0.0);
  T.linear() = Eigen::AngleAxisd(0.5 * kPi * t, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

/// A 100 ms sweep (stamp at its start) of a wall at x = 20 m: beam i at yaw −60°..60° in the
/// sensor frame, fired at t_i, returns where it meets the wall.
PointCloud sweep_of_wall(const Eigen::Isometry3d& T_B_S, int beams = 2000) {
  PointCloud cloud;
  for (int i = 0; i < beams; ++i) {
    const double t = 0.1 * i / (beams - 1);
    const double yaw = (-60.0 + 120.0 * i / (beams - 1)) * kPi / 180.0;
    const Eigen::Isometry3d T_W_S = base_at(t) * T_B_S;
    const Eigen::Vector3d dir_W =
        T_W_S.linear() * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), -0.05);
    const Eigen::Vector3d o = T_W_S.translation();
    const double range = (20.0 - o.x()) / dir_W.x();
    const Eigen::Vector3d p_W = o + range * dir_W;
    cloud.points_S.push_back((T_W_S.inverse() * p_W).cast<float>());
    cloud.time_offset_s.push_back(static_cast<float>(t));
  }
  return cloud;
}

double worst_wall_error(const std::vector<Eigen::Vector3f>& points_S,
                        const Eigen::Isometry3d& T_W_S) {
  double worst = 0.0;
  for (const auto& p : points_S) {
    worst = std::max(worst, std::abs((T_W_S * p.cast<double>()).x() - 20.0));
  }
  return worst;
}

TEST(Deskew, MovingTurningSensor_PointsLandOnTheWallAtTheStampPose) {
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation() = Eigen::Vector3d(1.5, 0.3, 2.0);  // lever arm: rotation moves the sensor
  const PointCloud cloud = sweep_of_wall(T_B_S);
  ScanMotion motion;
  motion.t0_s = 0.0;
  motion.t1_s = 0.1;
  motion.T_W_B_0 = base_at(0.0);
  motion.T_W_B_1 = base_at(0.1);
  std::vector<Eigen::Vector3f> out;
  deskew_points(cloud, motion, base_at(0.0), T_B_S, out);
  ASSERT_EQ(out.size(), cloud.size());
  const Eigen::Isometry3d T_W_S0 = base_at(0.0) * T_B_S;
  // Float rounding at up to ~45 m range (the blend within a bin is exact to ~1e-7 of it).
  EXPECT_LT(worst_wall_error(out, T_W_S0), 0.002);
  // Rigid: the last points are off by about the metre travelled (and the turn).
  EXPECT_GT(worst_wall_error(cloud.points_S, T_W_S0), 0.9);
}

TEST(Deskew, StampAtSweepEnd_NegativeOffsetsAndNonFiniteTimes) {
  const Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  PointCloud cloud = sweep_of_wall(T_B_S);
  for (auto& t : cloud.time_offset_s) t -= 0.1f;  // stamped at the end: −100..0 ms
  cloud.time_offset_s[7] = std::nanf("");         // counts as the stamp
  ScanMotion motion;
  motion.t0_s = -0.1;
  motion.t1_s = 0.0;
  motion.T_W_B_0 = base_at(0.0);
  motion.T_W_B_1 = base_at(0.1);
  std::vector<Eigen::Vector3f> out;
  deskew_points(cloud, motion, base_at(0.1), T_B_S, out);
  const Eigen::Isometry3d T_W_S1 = base_at(0.1) * T_B_S;
  std::vector<Eigen::Vector3f> finite_times = out;
  finite_times.erase(finite_times.begin() + 7);
  EXPECT_LT(worst_wall_error(finite_times, T_W_S1), 0.002);
  // Point 7 (fired at 0.35 ms) is taken at the stamp: it moves as if fired at the sweep's end.
  EXPECT_NEAR((T_W_S1 * out[7].cast<double>()).x(), (T_W_S1 * cloud.points_S[7].cast<double>()).x(),
              1e-4);
}

TEST(Deskew, MapperIngest_UsesTheMotionOnlyWhenGiven) {
  MapperParams params;
  params.filters.outlier_min_neighbors = 0;
  params.filters.ego_box_enabled = false;
  Mapper mapper(params);
  const Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  const PointCloud cloud = sweep_of_wall(T_B_S);
  ScanMotion motion{0.0, 0.1, base_at(0.0), base_at(0.1)};
  double worst = 0.0;
  for (const auto& p : mapper.ingest(cloud, base_at(0.0), T_B_S, &motion).points_W) {
    worst = std::max(worst, std::abs(p.x() - 20.0));
  }
  EXPECT_LT(worst, 0.002);
  worst = 0.0;
  for (const auto& p : mapper.ingest(cloud, base_at(0.0), T_B_S).points_W) {
    worst = std::max(worst, std::abs(p.x() - 20.0));
  }
  EXPECT_GT(worst, 0.9);
}

}  // namespace
}  // namespace tarmac::core
