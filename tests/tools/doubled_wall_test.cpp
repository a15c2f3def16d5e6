// Pose-graph corrections on the simulator (issue 4 item 6): a vehicle drives past a terminal wall
// while its localiser drifts 1 m sideways, then a fix brings the poses back. Without correction
// handling the wall is mapped twice (1 m apart); with it the wall is single, where it is.
//
// Scene: sim::Scene::terminal_walls() (wall face at y = 8.1 m, in voxel [8.0, 8.2) at 0.2 m).
// Drive: y = 0 from x = 0 at 3 m/s, scans at 10 Hz, 60 scans. Written poses: true + 1 m along
// +y reached after 1 s (scan 10), true again from scan 40 on.

#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/core/mapper.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace tarmac {
namespace {

constexpr int kScans = 60;
constexpr int kCorrectAt = 40;
constexpr double kDriftM = 1.0;
constexpr double kWallFaceY = 8.1;

struct Sequence {
  std::vector<core::PointCloud> clouds;
  std::vector<Eigen::Isometry3d> written_W_B, true_W_B;
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
};

sim::SequenceParams sequence_params(double drift_m) {
  sim::SequenceParams p;
  p.lidar.azimuth_steps = 512;
  p.drift_m = drift_m;
  p.drift_ramp_s = 1.0;
  p.correct_at_scan = kCorrectAt;
  return p;
}

/// The scans are the same whatever the drift; only the written poses differ.
Sequence make_sequence(double drift_m) {
  const sim::Scene scene = sim::Scene::terminal_walls();
  const sim::SequenceParams p = sequence_params(drift_m);
  const sim::Lidar lidar(p.lidar);
  Sequence s;
  s.T_B_S.translation().z() = p.path.sensor_height_m;
  std::vector<sim::LidarReturn> returns;
  for (int i = 0; i < kScans; ++i) {
    const double t_s = p.stamp_s(i);
    lidar.scan(scene, p.path.T_W_S(t_s), t_s, nullptr, returns);
    core::PointCloud cloud;
    cloud.stamp_ns = static_cast<std::int64_t>(i) * 100'000'000;
    for (const auto& r : returns) cloud.points_S.push_back(r.point_S.cast<float>());
    s.clouds.push_back(std::move(cloud));
    s.written_W_B.push_back(p.written_T_O_S(i) * s.T_B_S.inverse());
    s.true_W_B.push_back(p.true_T_O_S(i) * s.T_B_S.inverse());
  }
  return s;
}

const Sequence& drifted() {
  static const Sequence s = make_sequence(kDriftM);
  return s;
}

enum class Handling { kNone, kTrajectory, kJump };

struct MapRun {
  core::CorrectionStats stats;
  std::vector<float> log_odds;
  Eigen::Vector3i window_min, dims;
  std::uint64_t tsdf_digest = 0;
  std::vector<int> rebuild_steps;  ///< scans re-integrated per step while rebuilding
};

core::MapperParams params(int retain_scans, std::uint64_t quota, bool corrections = true) {
  core::MapperParams p;
  p.corrections.enabled = corrections;
  p.corrections.retain_scans = retain_scans;
  p.corrections.rebuild_points_per_cycle = quota;
  p.corrections.jump_threshold_m = 0.5;
  return p;
}

/// Maps scans [first, kScans) with the given poses and correction handling, one pool of
/// `threads`, and a rebuild step after every scan (as the daemon does once per tick).
MapRun map(const Sequence& s, const core::MapperParams& mp, Handling handling,
           std::size_t threads = 2, int first = 0,
           const std::vector<Eigen::Isometry3d>* poses = nullptr) {
  daemon::ThreadPool pool(threads);
  core::Mapper mapper(mp);
  core::PoseJumpDetector detector(mp.corrections);
  MapRun run;
  const auto& W_B = poses ? *poses : s.written_W_B;
  for (int i = first; i < kScans; ++i) {
    const std::int64_t stamp = s.clouds[static_cast<std::size_t>(i)].stamp_ns;
    if (handling == Handling::kJump) {
      if (const auto jump = detector.feed({stamp, W_B[static_cast<std::size_t>(i)]})) {
        mapper.correct_rigid(*jump, stamp);
      }
    }
    const auto scan = mapper.ingest(s.clouds[static_cast<std::size_t>(i)],
                                    W_B[static_cast<std::size_t>(i)], s.T_B_S);
    mapper.integrate(scan, pool);
    mapper.integrate_tsdf(scan, pool);
    if (handling == Handling::kTrajectory && i == kCorrectAt - 1) {
      // The pose source publishes the corrected trajectory with its fix.
      std::vector<core::StampedPose> traj;
      for (int k = 0; k < kCorrectAt; ++k) {
        traj.push_back({s.clouds[static_cast<std::size_t>(k)].stamp_ns,
                        s.true_W_B[static_cast<std::size_t>(k)]});
      }
      mapper.correct_trajectory(traj);
    }
    if (mapper.rebuilding()) {
      run.rebuild_steps.push_back(static_cast<int>(mapper.rebuild_step(pool).scans));
    }
  }
  EXPECT_FALSE(mapper.rebuilding()) << "the rebuild must have caught up";
  run.stats = mapper.correction_stats();
  mapper.occupancy().export_log_odds(run.log_odds);
  run.window_min = mapper.occupancy().window_min();
  run.dims = mapper.occupancy().window_size();
  run.tsdf_digest = mapper.tsdf().digest();
  return run;
}

/// Runs of occupied voxels (log-odds > 0) across the wall (along y, from 6 to 11.6 m) in the
/// voxel column at (x_m, z_m); each run as [first, last] voxel index along y.
std::vector<std::pair<int, int>> wall_runs(const MapRun& r, double x_m, double z_m) {
  const double v = 0.2;
  const int wx = static_cast<int>(std::floor(x_m / v)) - r.window_min.x();
  const int wz = static_cast<int>(std::floor(z_m / v)) - r.window_min.z();
  std::vector<std::pair<int, int>> runs;
  bool in = false;
  for (int gy = 30; gy < 58; ++gy) {
    const int wy = gy - r.window_min.y();
    const std::size_t i =
        (static_cast<std::size_t>(wz) * r.dims.y() + static_cast<std::size_t>(wy)) * r.dims.x() +
        static_cast<std::size_t>(wx);
    const float l = r.log_odds[i];
    const bool occ = l != core::OccupancyMap::kUnknown && l > 0.0f;
    if (occ && !in) runs.push_back({gy, gy});
    if (occ) runs.back().second = gy;
    in = occ;
  }
  return runs;
}

std::string describe(const std::vector<std::pair<int, int>>& runs) {
  std::string s;
  for (const auto& [a, b] : runs) s += "[" + std::to_string(a) + "," + std::to_string(b) + "] ";
  return s;
}

/// The wall is single: one run, holding the truth voxel, at most 2 voxels thick.
void expect_single_wall(const MapRun& r) {
  const int truth = static_cast<int>(std::floor(kWallFaceY / 0.2));  // 40
  for (const double x : {6.0, 10.0, 14.0}) {
    for (const double z : {1.1, 2.5}) {
      const auto runs = wall_runs(r, x, z);
      ASSERT_EQ(runs.size(), 1u) << "x " << x << " z " << z << ": " << describe(runs);
      EXPECT_LE(runs[0].first, truth) << describe(runs);
      EXPECT_GE(runs[0].second, truth) << describe(runs);
      EXPECT_LE(runs[0].second - runs[0].first + 1, 2) << describe(runs);
    }
  }
}

TEST(DoubledWall, WithoutCorrectionHandlingTheWallIsDoubled) {
  const MapRun r = map(drifted(), params(50, 0, /*corrections=*/false), Handling::kNone);
  const int truth = static_cast<int>(std::floor(kWallFaceY / 0.2));
  const int drifted_voxel = static_cast<int>(std::floor((kWallFaceY + kDriftM) / 0.2));  // 45
  for (const double x : {6.0, 10.0, 14.0}) {
    for (const double z : {1.1, 2.5}) {
      const auto runs = wall_runs(r, x, z);
      ASSERT_GE(runs.size(), 2u) << "x " << x << " z " << z << ": " << describe(runs);
      EXPECT_LE(runs.front().first, truth) << describe(runs);
      EXPECT_GE(runs.back().second, drifted_voxel) << describe(runs);
    }
  }
}

TEST(DoubledWall, CorrectedTrajectoryGivesASingleWall) {
  const MapRun r = map(drifted(), params(64, 0), Handling::kTrajectory);
  EXPECT_EQ(r.stats.corrections, 1u);
  EXPECT_EQ(r.stats.rebuilds_completed, 1u);
  // Scheduled after scan 39, started once scan 40 is in: scans 0..40 re-integrated.
  EXPECT_EQ(r.stats.scans_reintegrated, static_cast<std::uint64_t>(kCorrectAt + 1));
  expect_single_wall(r);
}

TEST(DoubledWall, RebuildEqualsAFreshMapWithTheCorrectedPoses) {
  // Retention covers the whole drive, so the rebuilt occupancy and TSDF must be bit-identical to
  // a map built from the start with the true poses.
  const MapRun corrected = map(drifted(), params(64, 0), Handling::kTrajectory);
  const MapRun fresh = map(drifted(), params(64, 0), Handling::kNone, 2, 0, &drifted().true_W_B);
  EXPECT_EQ(corrected.window_min, fresh.window_min);
  EXPECT_TRUE(corrected.log_odds == fresh.log_odds);
  EXPECT_EQ(corrected.tsdf_digest, fresh.tsdf_digest);
}

TEST(DoubledWall, JumpInTheLivePosesGivesASingleWall) {
  // A rigid correction is exact for the scans whose drift had reached its full 1 m (scans
  // 10..39). The jump arrives with scan 40; the rebuild starts once scan 40 is in, so the 25
  // retained scans are 16..40 (all at full drift but 40, which already has its true pose).
  const MapRun r = map(drifted(), params(25, 0), Handling::kJump);
  EXPECT_EQ(r.stats.corrections, 1u);
  EXPECT_EQ(r.stats.rebuilds_completed, 1u);
  EXPECT_EQ(r.stats.scans_reintegrated, 25u);
  EXPECT_EQ(r.stats.scans_rolled_out, 0u);
  expect_single_wall(r);
}

TEST(DoubledWall, QuotaSpreadsTheRebuildAndStillEqualsTheFreshMap) {
  // 3 scans' worth of points per step: the rebuild of 25 scans catches up over several steps
  // while new scans arrive (+3 rebuilt, +1 new per step); the result equals one rebuild in a
  // single step, and a fresh map of scans 16..59 with the rigidly corrected (= true) poses.
  const std::uint64_t quota = 3 * drifted().clouds[20].points_S.size();
  const MapRun spread = map(drifted(), params(25, quota), Handling::kJump);
  const MapRun single = map(drifted(), params(25, 0), Handling::kJump);
  ASSERT_GT(spread.rebuild_steps.size(), 3u);
  EXPECT_EQ(single.rebuild_steps.size(), 1u);
  EXPECT_EQ(spread.stats.scans_rolled_out, 0u);
  EXPECT_TRUE(spread.log_odds == single.log_odds);
  const MapRun fresh = map(drifted(), params(25, 0), Handling::kNone, 2, 16, &drifted().true_W_B);
  EXPECT_TRUE(spread.log_odds == fresh.log_odds);
  EXPECT_EQ(spread.window_min, fresh.window_min);
}

TEST(DoubledWall, JumpBelowThresholdTriggersNoRebuild) {
  // A 0.4 m fix is below the 0.5 m threshold: nothing is rebuilt.
  static const Sequence small = make_sequence(0.4);
  const MapRun r = map(small, params(25, 0), Handling::kJump);
  EXPECT_EQ(r.stats.corrections, 0u);
  EXPECT_EQ(r.stats.rebuilds_started, 0u);
  EXPECT_EQ(r.stats.scans_reintegrated, 0u);
}

TEST(DoubledWall, RebuildIsIdenticalFor1To4Threads) {
  const std::uint64_t quota = 3 * drifted().clouds[20].points_S.size();
  const MapRun one = map(drifted(), params(25, quota), Handling::kJump, 1);
  for (const std::size_t threads : {2u, 4u}) {
    const MapRun r = map(drifted(), params(25, quota), Handling::kJump, threads);
    EXPECT_TRUE(r.log_odds == one.log_odds) << threads << " threads";
    EXPECT_EQ(r.tsdf_digest, one.tsdf_digest) << threads << " threads";
  }
}

}  // namespace
}  // namespace tarmac
