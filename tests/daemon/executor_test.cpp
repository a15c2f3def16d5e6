// tarmacd's executor end to end over loopback DDS: a simulated airside sequence is replayed as a
// ROS 2 publisher would (PointCloud2 + PoseWithCovarianceStamped), the executor runs in this
// process, and the received costmap is compared with the core run offline on the same sequence.
// Every test has its own DDS domain and runs under the packet capture (nothing off loopback).

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <thread>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "executor_harness.hpp"
#include "geometry_msgs.h"
#include "loopback_only.hpp"
#include "nav_msgsPubSubTypes.h"
#include "rtps_sniffer.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tarmac/daemon/cycle.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/replay/driver_message.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/tools/array_io.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::daemon {
namespace {

using namespace std::chrono_literals;
using test::kScans;
using test::kTimeScale;
using test::peer;
using test::ReportReader;
using test::RunningExecutor;
using test::sequence;
using test::test_config;
using test::total_of;
using test::wait_for_report;
using GridReader = transport::Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
using VolumeReader = transport::Reader<tarmac_msgs::msg::dds_::DistanceMapVolume_PubSubType>;

/// A scan's base pose as the daemon sees it after a wire round trip (quaternions).
core::StampedPose wire_pose(std::int64_t stamp_ns, const Eigen::Isometry3d& T_W_S,
                            const Eigen::Isometry3d& T_B_S) {
  return {stamp_ns,
          transport::from_pose_msg(transport::to_pose_msg(tools::base_pose(T_W_S, T_B_S))).value()};
}

/// Organised sweep k of `seq` as tarmac-replay --layout list --ring sends it: the returns only,
/// in firing order (column by column), each with its beam's index as ring.
void read_ring_list(const tools::KittiSequence& seq, std::size_t k, core::PointCloud& cloud) {
  core::PointCloud grid;
  ASSERT_TRUE(tools::read_kitti_scan(seq.organised[k], grid).ok());
  cloud.clear();
  for (std::size_t c = 0; c < seq.cols; ++c) {
    for (std::size_t r = 0; r < seq.rows; ++r) {
      const Eigen::Vector3f& p = grid.points_S[r * seq.cols + c];
      if (!p.allFinite() || p.isZero(0.0f)) continue;
      cloud.points_S.push_back(p);
      cloud.intensity.push_back(grid.intensity[r * seq.cols + c]);
      cloud.ring.push_back(static_cast<std::uint16_t>(r));
    }
  }
}

/// Runs the core offline, scan by scan, on the poses as they travel over the wire
/// (quaternions), with the TSDF stage when `tsdf` (no quota shedding); the sweeps as lists with
/// rings when `ring_lists`.
void run_offline(core::Mapper& mapper, const config::Config& cfg, std::size_t scans, bool tsdf,
                 bool ring_lists = false, std::optional<sim::Driver> driver = std::nullopt) {
  core::SerialRunner runner;
  const auto& seq = sequence();
  const Eigen::Isometry3d& T_B_S = cfg.sensors[0].T_base_sensor;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  for (std::size_t k = 0; k < scans; ++k) {
    if (driver) {  // the driver's message of the sweep, read by tarmac's transport
      core::PointCloud grid;
      ASSERT_TRUE(tools::read_kitti_scan(seq.organised[k], grid).ok());
      const auto msg = tools::driver_sweep_message(grid, seq.rows, seq.cols, *driver, 0, 0.0, "s");
      ASSERT_TRUE(transport::from_point_cloud2(msg, cloud).ok());
    } else if (ring_lists) {
      read_ring_list(seq, k, cloud);
    } else {
      EXPECT_TRUE(tools::read_sequence_scan(seq, k, cloud, scratch).ok());
    }
    const auto scan = mapper.ingest(cloud, wire_pose(0, seq.T_W_S[k], T_B_S).T_W_B, T_B_S);
    mapper.integrate(scan, runner);
    if (tsdf) mapper.integrate_tsdf(scan, runner);
  }
}

std::string offline_costmap_digest(const config::Config& cfg, std::size_t scans,
                                   std::int64_t last_stamp_ns, bool ring_lists = false,
                                   std::optional<sim::Driver> driver = std::nullopt) {
  core::Mapper mapper(cfg.mapping);
  run_offline(mapper, cfg, scans, false, ring_lists, driver);
  core::SerialRunner runner;
  mapper.update_costmap(mapper.vehicle_pose(), {}, last_stamp_ns, runner);
  const auto& cells = mapper.costmap().costmap.cells();
  return tools::digest({reinterpret_cast<const std::uint8_t*>(cells.data()), cells.size()});
}

/// The TSDF the core builds offline on the same scans.
std::uint64_t offline_tsdf_digest(const config::Config& cfg, std::size_t scans) {
  core::Mapper mapper(cfg.mapping);
  run_offline(mapper, cfg, scans, true);
  return mapper.tsdf().digest();
}

std::string digest_of(const transport::OccupancyGridMsg& grid) {
  return tools::digest(
      {reinterpret_cast<const std::uint8_t*>(grid.data().data()), grid.data().size()});
}

/// Waits for the costmap whose stamp is `stamp_ns`; returns false on timeout.
bool wait_for_costmap(GridReader& reader, std::int64_t stamp_ns, transport::OccupancyGridMsg& out,
                      std::chrono::seconds timeout = kTimeScale * 20s) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::vector<transport::OccupancyGridMsg> batch;
  while (std::chrono::steady_clock::now() < deadline) {
    reader.wait_for_sample(100ms);
    batch.clear();
    reader.take_all(batch);
    for (auto& g : batch) {
      if (transport::from_time_msg(g.header().stamp()) == stamp_ns) {
        out = std::move(g);
        return true;
      }
    }
  }
  return false;
}

class Daemon : public test::LoopbackOnly {
 protected:
  Daemon() { expect_loopback_traffic_ = true; }

  /// Replays the sequence into an executor with `workers` threads and returns the digest of the
  /// costmap stamped with the last scan.
  std::string replayed_digest(std::uint32_t domain, std::uint32_t workers, double jitter_ms,
                              const std::function<void(config::Config&)>& tweak = {},
                              const tools::KittiSequence& seq = sequence(), double rate_scale = 2.0,
                              const std::function<void(tools::ReplayOptions&)>& replay_tweak = {}) {
    const auto n_scans = static_cast<std::uint64_t>(seq.scans.size());
    auto cfg = test_config(domain, workers);
    test::take_late_input(cfg);  // paced below: the map must not depend on the machine's load
    if (tweak) tweak(cfg);
    RunningExecutor executor(cfg);
    auto participant = peer(domain);
    auto grids = GridReader::create(participant, cfg.outputs.costmap_topic, cfg.dds.qos.costmap, 8);
    EXPECT_TRUE(grids.ok());
    tools::ReplayOptions options;
    options.lidar_qos = cfg.dds.qos.lidar;
    // Default 20 Hz into a 10 Hz executor: two scans per tick (both slowed by kTimeScale).
    options.rate_scale = rate_scale / kTimeScale;
    options.jitter_ms = jitter_ms * kTimeScale;
    options.seed = 7;
    options.pace = test::paced_by(executor.get());
    if (replay_tweak) replay_tweak(options);
    auto stats = tools::replay(participant, seq, options);
    EXPECT_TRUE(stats.ok()) << (stats.ok() ? "" : stats.error().message);
    if (!stats.ok()) return "";
    EXPECT_EQ(stats.value().scans, n_scans);
    transport::OccupancyGridMsg grid;
    EXPECT_TRUE(wait_for_costmap(*grids.value(), stats.value().last_stamp_ns, grid))
        << "no costmap stamped with the last scan";
    EXPECT_EQ(grid.header().frame_id(), "map");
    // The totals are updated right after the tick publishes: give it a moment.
    test::eventually([&] { return executor.get().totals().scans_integrated >= n_scans; });
    EXPECT_EQ(executor.get().totals().scans_integrated, n_scans);
    first_stamp_ns_ = stats.value().first_stamp_ns;
    last_stamp_ns_ = stats.value().last_stamp_ns;
    corrections_sent_ = stats.value().corrections;
    executor.stop();
    totals_ = executor.get().totals();
    tsdf_digest_ = executor.get().tsdf().digest();
    tsdf_voxels_ = executor.get().tsdf().voxel_count();
    return digest_of(grid);
  }

  void check_path_correction(std::uint32_t domain, double lead_s);
  /// Runs an executor with `cfg`, replays the first `max_scans` scans at 20 Hz (poses for the
  /// first `pose_count` only; 0: all) and collects CycleReports until `done`; returns the last
  /// one. `totals_` holds the executor's totals at that point.
  transport::CycleReport replay_until_report(
      const config::Config& cfg, std::size_t max_scans, std::size_t pose_count,
      const std::function<bool(const transport::CycleReport&)>& done);

  std::int64_t first_stamp_ns_ = 0;
  std::int64_t last_stamp_ns_ = 0;
  std::size_t corrections_sent_ = 0;
  ExecutorTotals totals_;
  std::uint64_t tsdf_digest_ = 0;
  std::size_t tsdf_voxels_ = 0;
};

TEST_F(Daemon, Replay_CostmapEqualsOfflineCore_1Worker) {
  const std::string got = replayed_digest(test::kDomainDaemonWorkers1, 1, 0.0);
  const std::string want = offline_costmap_digest(test_config(0, 1), kScans, last_stamp_ns_);
  EXPECT_EQ(got, want);
  // The digest sees a single missing scan, so equality above means every scan made it.
  EXPECT_NE(want, offline_costmap_digest(test_config(0, 1), kScans - 1, last_stamp_ns_));
  // The TSDF stage too: bit-identical to the core offline, every scan integrated.
  EXPECT_EQ(totals_.tsdf_scans, static_cast<std::uint64_t>(kScans));
  EXPECT_GT(tsdf_voxels_, 0u);
  EXPECT_EQ(tsdf_digest_, offline_tsdf_digest(test_config(0, 1), kScans));
}

TEST_F(Daemon, Replay_CostmapEqualsOfflineCore_2Workers) {
  const std::string got = replayed_digest(test::kDomainDaemonWorkers2, 2, 0.0);
  EXPECT_EQ(got, offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_));
}

TEST_F(Daemon, Replay_CostmapEqualsOfflineCore_4Workers) {
  const std::string got = replayed_digest(test::kDomainDaemonWorkers4, 4, 0.0);
  EXPECT_EQ(got, offline_costmap_digest(test_config(0, 4), kScans, last_stamp_ns_));
  EXPECT_EQ(tsdf_digest_, offline_tsdf_digest(test_config(0, 4), kScans));
}

TEST_F(Daemon, Replay_CostmapEqualsOfflineCore_WithRandomPublishJitter) {
  // Every message up to 25 ms late, in random order between scan and pose: within the 40 ms
  // input delay, so the integrated sequence (and the map) must not change.
  const std::string got = replayed_digest(test::kDomainDaemonJitter, 2, 25.0);
  EXPECT_EQ(got, offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_));
  EXPECT_EQ(tsdf_digest_, offline_tsdf_digest(test_config(0, 2), kScans));
}

TEST_F(Daemon, Replay_RowsAreFirings_CostmapEqualsOfflineCore) {
  // The sweeps as velodyne's driver (organize_cloud) sends them: one row per firing, one column
  // per laser; with a ring field, then without (the elevation spread tells the layout). tarmacd
  // puts them back as beams: the same map as the rows = beams sweeps offline, bit for bit.
  for (const bool ring : {true, false}) {
    SCOPED_TRACE(ring ? "with ring" : "without ring");
    const std::string got =
        replayed_digest(ring ? test::kDomainDaemonLayoutRing : test::kDomainDaemonLayoutElevation,
                        2, 0.0, {}, sequence(), 2.0, [ring](tools::ReplayOptions& o) {
                          o.layout = tools::ReplayOptions::Layout::kRowsAreFirings;
                          o.ring_field = ring;
                        });
    EXPECT_EQ(got, offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_));
  }
}

TEST_F(Daemon, Replay_ListsWithRings_CostmapEqualsOfflineCore) {
  // The sweeps as HesaiLidar_ROS_2.0 (and velodyne without organize_cloud) sends them: height 1,
  // the returns only, in firing order, with their ring. tarmacd finds the beams without return
  // from the gaps in the rings: the map the core makes offline of the same lists, bit for bit.
  const std::string got = replayed_digest(test::kDomainDaemonLayoutList, 2, 0.0, {}, sequence(),
                                          2.0, [](tools::ReplayOptions& o) {
                                            o.layout = tools::ReplayOptions::Layout::kUnorganised;
                                            o.ring_field = true;
                                          });
  EXPECT_EQ(got, offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_, true));
  EXPECT_EQ(totals_.scans_integrated, static_cast<std::uint64_t>(kScans));
}

TEST_F(Daemon, Replay_DriversMessages_CostmapEqualsOfflineCore) {
  // tarmac-replay --driver: the sweeps as velodyne's driver (organised, 22-byte points, rows =
  // firings), Hesai's (a list with (0, 0, 0) markers, f64 absolute times) and Autoware's
  // PointXYZIRCAEDT (a list, u8 intensity, u32 ns times) publish them. tarmacd reads each into
  // the map the core makes offline of the same messages, bit for bit, every scan integrated.
  for (const auto driver :
       {sim::Driver::kVelodyne, sim::Driver::kHesai, sim::Driver::kAutowareXYZIRCAEDT}) {
    SCOPED_TRACE(std::string(sim::driver_name(driver)));
    const std::string got =
        replayed_digest(test::kDomainDaemonLayoutDriver, 2, 0.0, {}, sequence(), 2.0,
                        [driver](tools::ReplayOptions& o) { o.driver = driver; });
    EXPECT_EQ(got,
              offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_, false, driver));
    EXPECT_EQ(totals_.scans_integrated, static_cast<std::uint64_t>(kScans));
  }
}

TEST_F(Daemon, EsdfBand_PublishedBoxEqualsOfflineCore) {
  const auto band_config = [](config::Config& c) {
    c.mapping.esdf_band.enabled = true;
    c.mapping.esdf_band.publish_radius_m = 5.0;
    // The band is placed from the base: the simulated LiDAR sits 2 m above it.
    c.sensors[0].T_base_sensor.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
    // Reliable here: the comparison needs the last band, not the newest that made it.
    c.dds.qos.esdf_band = {transport::Reliability::kReliable, transport::Durability::kVolatile, 1};
  };
  config::Config cfg = test_config(test::kDomainDaemonEsdfBand, 2);
  band_config(cfg);
  auto participant = peer(test::kDomainDaemonEsdfBand);
  auto volumes =
      VolumeReader::create(participant, cfg.outputs.esdf_band_topic, cfg.dds.qos.esdf_band, 64);
  ASSERT_TRUE(volumes.ok());
  const std::string costmap = replayed_digest(
      test::kDomainDaemonEsdfBand, 2, 0.0, band_config, sequence(), 2.0,
      [&](tools::ReplayOptions& o) { o.T_base_sensor = cfg.sensors[0].T_base_sensor; });
  config::Config plain = test_config(0, 2);
  plain.sensors[0].T_base_sensor = cfg.sensors[0].T_base_sensor;
  EXPECT_EQ(costmap, offline_costmap_digest(plain, kScans, last_stamp_ns_))
      << "the band stage leaves the costmap alone";
  std::vector<transport::DistanceMapVolumeMsg> got;
  for (int i = 0; i < 50 && got.empty(); ++i) {
    volumes.value()->wait_for_sample(100ms);
    volumes.value()->take_all(got);
  }
  volumes.value()->take_all(got);
  ASSERT_FALSE(got.empty()) << "no band published";
  const auto last = std::find_if(got.begin(), got.end(), [&](const auto& m) {
    return transport::from_time_msg(m.header().stamp()) == last_stamp_ns_;
  });
  ASSERT_NE(last, got.end()) << "no band stamped with the last scan";

  // The core offline on the same scans, its band boxed by the same rule.
  core::Mapper mapper(cfg.mapping);
  run_offline(mapper, cfg, kScans, false);
  core::SerialRunner runner;
  mapper.update_costmap(mapper.vehicle_pose(), {}, last_stamp_ns_, runner);
  mapper.update_esdf_band(mapper.vehicle_pose(), {}, last_stamp_ns_, runner);
  transport::DistanceMapVolumeMsg want;
  transport::fill_distance_volume(mapper.esdf_band(), mapper.vehicle_pose().translation().head<2>(),
                                  5.0, last_stamp_ns_, "map", want);
  EXPECT_EQ(last->width(), 51u);  // 2 · 25 + 1 voxels of 0.2 m around the vehicle's voxel
  EXPECT_EQ(last->height(), 51u);
  EXPECT_EQ(last->depth(), want.depth());
  EXPECT_GE(last->depth(), 16u);
  EXPECT_EQ(last->origin().position().x(), want.origin().position().x());
  EXPECT_EQ(last->origin().position().z(), want.origin().position().z());
  ASSERT_EQ(last->distance().size(), want.distance().size());
  EXPECT_EQ(0, std::memcmp(last->distance().data(), want.distance().data(),
                           want.distance().size() * sizeof(float)));
  EXPECT_EQ(last->gradient_z(), want.gradient_z());
  // Not a trivial field: obstacles in the band, some within a few metres of the box's voxels.
  EXPECT_GT(core::esdf_band_obstacles(mapper.esdf_band()), 0u);
  const auto& d = last->distance();
  EXPECT_GT(std::count_if(d.begin(), d.end(), [](float x) { return x < 5.0f; }), 0);
}

TEST_F(Daemon, TsdfQuota_ShedsTheTsdfStageFirst_OccupancyAndCostmapUnchanged) {
  // A TSDF quota below one scan's points: every scan skips the TSDF (counted), none is deferred
  // or decimated, and the costmap is still the offline core's, bit for bit.
  const std::string got = replayed_digest(test::kDomainDaemonTsdfShed, 2, 0.0,
                                          [](auto& c) { c.quotas.tsdf_points_per_cycle = 1; });
  EXPECT_EQ(got, offline_costmap_digest(test_config(0, 2), kScans, last_stamp_ns_));
  EXPECT_EQ(totals_.tsdf_shed_scans, static_cast<std::uint64_t>(kScans));
  EXPECT_EQ(totals_.tsdf_scans, 0u);
  EXPECT_EQ(tsdf_voxels_, 0u);
}

/// The terminal walls with the localiser drifting 1 m sideways over 0.5 s and snapping back to
/// the true poses at scan 20 (a jump of 1 m in the pose stream), 40 scans, 16 beams.
const tools::KittiSequence& drift_sequence() {
  static const tools::KittiSequence seq = [] {
    const auto dir = std::filesystem::temp_directory_path() /
                     ("tarmac-executor-drift-" + std::to_string(::getpid()));
    sim::SequenceParams p;
    p.scans = 40;
    p.lidar.beams = 16;
    p.lidar.azimuth_steps = 512;
    p.drift_m = 1.0;
    p.drift_ramp_s = 0.5;
    p.correct_at_scan = 20;
    const auto written = sim::write_sequence(sim::Scene::terminal_walls(), p, dir);
    EXPECT_TRUE(written.ok()) << written.error;
    auto opened = tools::open_kitti(dir);
    EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
    return std::move(opened).value();
  }();
  return seq;
}

void pose_jump_config(config::Config& c) {
  c.mapping.corrections.retain_scans = 10;
  c.mapping.corrections.rebuild_points_per_cycle = 20000;  // 2-3 of these scans per step
}

struct OfflineCorrected {
  std::string costmap_digest;
  std::uint64_t jumps = 0;
  std::uint64_t rebuilds = 0;
};

/// The core offline on the drift sequence with the daemon's correction logic: jump detection on
/// the wire poses (a rigid correction of the retained scans), the corrected trajectory
/// `correction` (if any) applied right after its scan (after the scan's rebuild step: before the
/// next scan, as `tarmac-map --corrections` does), the daemon's stages (daemon::Cycle) a scan a
/// tick. `stamps`: the scans' stamps (the replay's; empty: 100 ms apart,
/// times kTimeScale as the replay spaces them).
OfflineCorrected offline_corrected(const config::Config& cfg,
                                   const std::vector<std::int64_t>& stamps = {},
                                   const tools::Correction* correction = nullptr) {
  core::Mapper mapper(cfg.mapping);
  core::PoseJumpDetector detector(cfg.mapping.corrections);
  core::SerialRunner runner;
  daemon::Cycle cycle(mapper, runner, {});
  const auto& seq = drift_sequence();
  const Eigen::Isometry3d& T_B_S = cfg.sensors[0].T_base_sensor;
  const auto stamp_of = [&](std::size_t k) {
    return stamps.empty() ? static_cast<std::int64_t>(k) * 100'000'000 * kTimeScale : stamps[k];
  };
  OfflineCorrected out;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  for (std::size_t k = 0; k < seq.scans.size(); ++k) {
    EXPECT_TRUE(tools::read_sequence_scan(seq, k, cloud, scratch).ok());
    const core::StampedPose wire = wire_pose(stamp_of(k), seq.T_W_S[k], T_B_S);
    if (const auto jump = detector.feed(wire)) {
      mapper.correct_rigid(*jump, wire.stamp_ns);
      ++out.jumps;
    }
    cloud.stamp_ns = wire.stamp_ns;
    cycle.begin();
    cycle.scan(cloud, wire.T_W_B, T_B_S);  // with its rebuild step
    if (correction == nullptr || k != correction->after_scan) continue;
    std::vector<core::StampedPose> trajectory;
    for (const auto& p : correction->trajectory_W_S) {
      const auto i = static_cast<std::size_t>(
          std::find_if(seq.times_s.begin(), seq.times_s.end(),
                       [&](double t) { return std::llround(t * 1e9) == p.stamp_ns; }) -
          seq.times_s.begin());
      EXPECT_LT(i, seq.scans.size()) << "correction stamp off the scan stamps";
      if (i < seq.scans.size()) trajectory.push_back(wire_pose(stamp_of(i), p.T_W_B, T_B_S));
    }
    EXPECT_GT(mapper.correct_trajectory(trajectory), 0u);
  }
  EXPECT_FALSE(mapper.rebuilding());
  out.rebuilds = mapper.correction_stats().rebuilds_completed;
  mapper.update_costmap(mapper.vehicle_pose(), {}, 0, runner);
  const auto& cells = mapper.costmap().costmap.cells();
  out.costmap_digest =
      tools::digest({reinterpret_cast<const std::uint8_t*>(cells.data()), cells.size()});
  return out;
}

TEST_F(Daemon, PoseJump_RebuildsTheWindow_CostmapEqualsOfflineCore) {
  // At the recorded 10 Hz: each rebuild step re-integrates two more scans per scan.
  const std::string got =
      replayed_digest(test::kDomainDaemonPoseJump, 2, 0.0, pose_jump_config, drift_sequence(), 1.0);
  auto cfg = test_config(0, 2);
  pose_jump_config(cfg);
  const OfflineCorrected want = offline_corrected(cfg);
  EXPECT_EQ(want.jumps, 1u);
  EXPECT_EQ(want.rebuilds, 1u);
  EXPECT_EQ(totals_.pose_jumps, 1u);
  EXPECT_EQ(totals_.rebuilds_completed, 1u);
  EXPECT_GE(totals_.scans_reintegrated, 10u);
  EXPECT_EQ(got, want.costmap_digest);
  // Without the correction handling the costmap differs (the drifted wall stays).
  cfg.mapping.corrections.enabled = false;
  EXPECT_NE(want.costmap_digest, offline_corrected(cfg).costmap_digest);
}

/// The localiser publishes its corrected trajectory (nav_msgs/Path) stamped with scan 19,
/// `lead_s` before that scan (0: right after it); the jump in the live poses at scan 20 is not
/// taken as one (threshold out of reach), so the map is corrected by the Path alone. tarmacd
/// applies it after every scan stamped up to the Path's stamp and before any later one, whatever
/// the arrival: the offline core with the correction after scan 19 gives the same costmap.
void Daemon::check_path_correction(std::uint32_t domain, double lead_s) {
  const auto& seq = drift_sequence();
  auto corrections = tools::read_corrections(seq.dir / "corrections.txt");
  ASSERT_TRUE(corrections.ok()) << corrections.error().message;
  ASSERT_EQ(corrections.value().size(), 1u);
  ASSERT_EQ(corrections.value()[0].after_scan, 19u);
  const auto tweak = [](config::Config& c) {
    pose_jump_config(c);
    c.mapping.corrections.jump_threshold_m = 1000.0;
    c.mapping.corrections.jump_threshold_deg = 180.0;
  };
  const std::string got =
      replayed_digest(domain, 2, 0.0, tweak, seq, 1.0, [&](tools::ReplayOptions& o) {
        o.corrections = corrections.value();
        o.correction_lead_s = lead_s * kTimeScale;
      });
  EXPECT_EQ(corrections_sent_, 1u);
  EXPECT_EQ(totals_.trajectory_corrections, 1u);
  EXPECT_EQ(totals_.late_corrections, 0u);
  EXPECT_EQ(totals_.pose_jumps, 0u);
  EXPECT_EQ(totals_.rebuilds_completed, 1u);

  std::vector<std::int64_t> stamps(seq.scans.size());
  for (std::size_t k = 0; k < stamps.size(); ++k) {
    stamps[k] =
        first_stamp_ns_ + std::llround((seq.times_s[k] - seq.times_s[0]) * 1e9 * kTimeScale);
  }
  EXPECT_EQ(stamps.back(), last_stamp_ns_);
  auto offline_cfg = test_config(0, 2);
  tweak(offline_cfg);
  const OfflineCorrected want = offline_corrected(offline_cfg, stamps, &corrections.value()[0]);
  EXPECT_EQ(want.jumps, 0u);
  EXPECT_EQ(want.rebuilds, 1u);
  EXPECT_EQ(got, want.costmap_digest);
  // Without the Path the drifted walls stay: a different costmap.
  EXPECT_NE(want.costmap_digest, offline_corrected(offline_cfg, stamps).costmap_digest);
}

TEST_F(Daemon, PathCorrection_RightAfterItsScan_CostmapEqualsOfflineCore) {
  check_path_correction(test::kDomainDaemonPathCorrection, 0.0);
}

TEST_F(Daemon, PathCorrection_ArrivingEarly_WaitsForItsStamp_CostmapEqualsOfflineCore) {
  // Sent 1.5 s (15 scans) before scan 19: applied on arrival it would find no scan to correct.
  check_path_correction(test::kDomainDaemonPathEarly, 1.5);
}

transport::CycleReport Daemon::replay_until_report(
    const config::Config& cfg, std::size_t max_scans, std::size_t pose_count,
    const std::function<bool(const transport::CycleReport&)>& done) {
  RunningExecutor executor(cfg);
  auto participant = peer(cfg.dds.participant.domain_id);
  auto reports = ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 200);
  EXPECT_TRUE(reports.ok());
  if (!reports.ok()) return {};
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.max_scans = max_scans;
  options.pose_count = pose_count;
  // At most four scans ahead of the executor: scans without a pose are never integrated, so
  // the tests using this give every scan from the fifth on a pose, or send at most eight.
  options.pace = test::paced_by(executor.get());
  auto stats = tools::replay(participant, sequence(), options);
  EXPECT_TRUE(stats.ok()) << (stats.ok() ? "" : stats.error().message);
  const auto last = wait_for_report(*reports.value(), done);
  totals_ = executor.get().totals();
  return last;
}

TEST_F(Daemon, ScanWithoutPose_IsDroppedAndCounted) {
  auto cfg = test_config(test::kDomainDaemonNoPose, 2);
  // Scans with poses reach a stalled executor late, stamps unchanged: never stale here.
  cfg.sensors[0].max_age_ms = 60'000.0 * kTimeScale;
  // Scans 5, 6, 7 never get a pose.
  const auto last = replay_until_report(cfg, 8, 5, [](const transport::CycleReport& r) {
    return total_of(r.drops, "scan.pose_timeout") >= 3;
  });
  EXPECT_EQ(total_of(last.drops, "scan.pose_timeout"), 3u);
  EXPECT_EQ(totals_.scans_integrated, 5u);
  EXPECT_EQ(last.config_hash, config::config_hash(cfg));
  bool pose_age_reported = false;
  for (const auto& a : last.input_ages) pose_age_reported |= a.input == "pose";
  EXPECT_TRUE(pose_age_reported);
}

TEST_F(Daemon, TinyBudget_ProducesOverrunsInCycleReport) {
  auto cfg = test_config(test::kDomainDaemonOverrun, 2);
  cfg.budgets.integrate_ms = 0.001;  // no scan integrates in 1 µs
  const auto last = replay_until_report(
      cfg, 4, 0, [](const transport::CycleReport& r) { return r.points_in > 0; });
  ASSERT_GT(last.points_in, 0u) << "no report of a tick that integrated a scan";
  EXPECT_TRUE(last.overrun);
  bool found = false;
  for (const auto& s : last.stages) {
    if (s.name != "integrate") continue;
    found = true;
    EXPECT_TRUE(s.overrun);
    EXPECT_GT(s.duration_ms, s.budget_ms);
    EXPECT_FLOAT_EQ(s.budget_ms, 0.001f);
  }
  EXPECT_TRUE(found);
  EXPECT_GT(totals_.overruns, 0u);
  // The TSDF stage is reported like the others, with its own budget.
  bool tsdf_found = false;
  for (const auto& s : last.stages) {
    if (s.name != "tsdf") continue;
    tsdf_found = true;
    EXPECT_FLOAT_EQ(s.budget_ms, static_cast<float>(cfg.budgets.tsdf_ms));
    EXPECT_GT(s.duration_ms, 0.0);
    EXPECT_EQ(s.shed_items, 0u);
  }
  EXPECT_TRUE(tsdf_found);
  EXPECT_EQ(total_of(last.drops, "scan.tsdf_shed_quota"), 0u);
}

/// Replays the first four scans of the sequence into `executor` (domain and QoS of `cfg`) and
/// waits until it has integrated them.
void replay_four_scans(RunningExecutor& executor, const config::Config& cfg) {
  auto participant = peer(cfg.dds.participant.domain_id);
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.max_scans = 4;
  options.pace = test::paced_by(executor.get());
  ASSERT_TRUE(tools::replay(participant, sequence(), options).ok());
  test::eventually([&] { return executor.get().totals().scans_integrated >= 4; });
  ASSERT_EQ(executor.get().totals().scans_integrated, 4u);
}

TEST_F(Daemon, PeriodicSave_WritesTheTsdfFromASnapshotWhileTheCycleRuns) {
  auto cfg = test_config(test::kDomainDaemonPeriodicSave, 2);
  test::take_late_input(cfg);  // replay_four_scans paces its input
  const auto dir = std::filesystem::temp_directory_path() /
                   ("tarmac-periodic-save-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  cfg.state.dir = dir.string();
  cfg.state.save_period_s = 0.3 * kTimeScale;  // every 3 ticks
  {
    RunningExecutor executor(cfg);
    ASSERT_NO_FATAL_FAILURE(replay_four_scans(executor, cfg));
    // One save may be in flight with a snapshot from before the last scan: wait for two more.
    const std::uint64_t saves_then = executor.get().totals().tsdf_saves;
    test::eventually([&] { return executor.get().totals().tsdf_saves >= saves_then + 2; });
    executor.stop();
    const auto t = executor.get().totals();
    EXPECT_GE(t.tsdf_saves, saves_then + 2);
    EXPECT_EQ(t.tsdf_save_failures, 0u);
    // The last periodic save saw every scan (it ran after they were integrated).
    const auto saved = core::load_tsdf(dir / cfg.state.tsdf_file);
    ASSERT_TRUE(saved.ok()) << saved.error().message;
    EXPECT_EQ(saved.value().layer.digest(), executor.get().tsdf().digest());
    EXPECT_GT(saved.value().layer.voxel_count(), 0u);
    EXPECT_EQ(saved.value().info.frame_id, cfg.outputs.frame_id);
  }
  std::filesystem::remove_all(dir);
}

TEST_F(Daemon, Paging_TheTileStoreIsTheMapAfterSaveAndRestart) {
  // tsdf.resident_limit_mb > 0 in tarmacd: the TSDF and the static occupancy go to
  // state.dir/tsdf_tiles on save; the .vdb holds neither; a restart resumes from the tiles
  // (absent until near).
  auto cfg = test_config(test::kDomainDaemonPaging, 2);
  test::take_late_input(cfg);  // replay_four_scans paces its input
  const auto dir =
      std::filesystem::temp_directory_path() / ("tarmac-paging-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  cfg.state.dir = dir.string();
  cfg.state.save_period_s = 0.0;
  cfg.mapping.tsdf.resident_limit_mb = 1;
  cfg.mapping.occupancy.static_promote_scans = 2;  // four scans build a static layer
  std::uint64_t digest = 0;
  std::vector<core::VoxelIndex> statics;
  {
    RunningExecutor executor(cfg);
    ASSERT_NO_FATAL_FAILURE(replay_four_scans(executor, cfg));
    executor.stop();
    digest = executor.get().tsdf().digest();
    executor.get().occupancy().export_static(statics);
    ASSERT_NE(executor.get().tsdf().block_count(), 0u);
    ASSERT_FALSE(statics.empty());
    ASSERT_TRUE(executor.get().save_tsdf().ok());
  }
  const auto saved = core::load_tsdf(dir / cfg.state.tsdf_file);
  ASSERT_TRUE(saved.ok()) << saved.error().message;
  EXPECT_EQ(saved.value().layer.block_count(), 0u);     // the TSDF is in the tiles
  EXPECT_TRUE(saved.value().occupancy.voxels.empty());  // and so is the static layer
  // The store alone holds the map.
  core::TsdfLayer layer(cfg.mapping.tsdf.voxel_size_m, cfg.mapping.tsdf.truncation_m);
  core::OccupancyMap occupancy(cfg.mapping.occupancy);
  auto pager = daemon::TsdfPager::open(
      daemon::TsdfPagerParams::for_mapper(cfg.mapping, dir / "tsdf_tiles"), layer, &occupancy);
  ASSERT_TRUE(pager.ok()) << pager.error().message;
  EXPECT_GT(pager.value()->stats().stored_tiles, 0u);
  EXPECT_GT(pager.value()->stats().static_tiles_stored, 0u);
  EXPECT_EQ(pager.value()->site(layer).digest(), digest);
  std::vector<core::VoxelIndex> stored;
  ASSERT_TRUE(pager.value()->site(layer).static_voxels(stored));
  EXPECT_EQ(stored, statics);
  pager.value().reset();
  // tarmacd restarted over it: the tiles are absent until the vehicle is near, the map the same.
  {
    auto created = daemon::Executor::create(cfg);
    ASSERT_TRUE(created.ok());
    EXPECT_EQ(created.value()->load_tsdf().kind, daemon::TsdfLoadResult::Kind::kLoaded);
    created.value()->prepare();
    EXPECT_EQ(created.value()->tsdf().block_count(), 0u);
    EXPECT_GT(created.value()->tsdf().absent_count(), 0u);
  }
  std::filesystem::remove_all(dir);
}

std::int8_t cell_at(const transport::OccupancyGridMsg& g, double x_m, double y_m) {
  const auto& info = g.info();
  const auto ix =
      static_cast<std::uint32_t>((x_m - info.origin().position().x()) / info.resolution());
  const auto iy =
      static_cast<std::uint32_t>((y_m - info.origin().position().y()) / info.resolution());
  return g.data()[std::size_t{iy} * info.width() + ix];
}

TEST_F(Daemon, VirtualObstacle_IsLethalInTheNextCostmap) {
  auto cfg = test_config(test::kDomainDaemonZones, 2);
  test::take_late_input(cfg);  // every scan integrated, however late on a loaded machine
  // After four scans of the 16-beam test LiDAR (3 deg between beams) few envelopes are observed
  // whole: the any-voxel rule gives the free space this test needs to see inflation.
  cfg.mapping.costmap.free_rule = core::FreeRule::kAnyVoxel;
  cfg.outputs.obstacle_grid_topic = "rt/tarmac/obstacle_grid";
  cfg.outputs.esdf_slice_grid_topic = "rt/tarmac/esdf_slice_grid";
  RunningExecutor executor(cfg);
  auto participant = peer(test::kDomainDaemonZones);
  auto grids = GridReader::create(participant, cfg.outputs.costmap_topic, cfg.dds.qos.costmap, 8);
  ASSERT_TRUE(grids.ok());
  auto obstacle_grids =
      GridReader::create(participant, cfg.outputs.obstacle_grid_topic, cfg.dds.qos.costmap, 8);
  ASSERT_TRUE(obstacle_grids.ok());
  auto esdf_grids =
      GridReader::create(participant, cfg.outputs.esdf_slice_grid_topic, cfg.dds.qos.costmap, 8);
  ASSERT_TRUE(esdf_grids.ok());
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / kTimeScale;
  options.max_scans = 4;
  auto stats = tools::replay(participant, sequence(), options);
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  transport::OccupancyGridMsg before;
  ASSERT_TRUE(wait_for_costmap(*grids.value(), stats.value().last_stamp_ns, before));
  // 5 m ahead of the vehicle on open apron: observed, not lethal before the zone.
  const Eigen::Vector3d ahead = sequence().T_W_S[3].translation() + Eigen::Vector3d(5.0, 0, 0);
  ASSERT_NE(cell_at(before, ahead.x(), ahead.y()), 100);
  // The uninflated grid of the same tick: same stamp and geometry, lethal and unknown exactly
  // where the costmap has them, every other cell free (no inflation values).
  transport::OccupancyGridMsg plain;
  ASSERT_TRUE(wait_for_costmap(*obstacle_grids.value(), stats.value().last_stamp_ns, plain));
  ASSERT_EQ(plain.data().size(), before.data().size());
  EXPECT_EQ(plain.info().width(), before.info().width());
  EXPECT_EQ(plain.info().origin().position().x(), before.info().origin().position().x());
  std::size_t inflated = 0;
  for (std::size_t i = 0; i < before.data().size(); ++i) {
    const std::int8_t v = before.data()[i];
    const std::int8_t want = v == 100 || v == -1 ? v : std::int8_t{0};
    ASSERT_EQ(plain.data()[i], want) << "cell " << i << ", costmap value " << int{v};
    inflated += v > 0 && v < 100 ? 1 : 0;
  }
  EXPECT_GT(inflated, 0u) << "the costmap has inflated cells the plain grid leaves out";
  // The ESDF display grid of the same tick: 100 (distance 0) exactly on the costmap's obstacles.
  transport::OccupancyGridMsg shade;
  ASSERT_TRUE(wait_for_costmap(*esdf_grids.value(), stats.value().last_stamp_ns, shade));
  ASSERT_EQ(shade.data().size(), before.data().size());
  for (std::size_t i = 0; i < before.data().size(); ++i) {
    ASSERT_EQ(shade.data()[i] == 100, before.data()[i] == 100) << "cell " << i;
  }

  using ZoneWriter = transport::Writer<tarmac_msgs::msg::dds_::VirtualObstacleArray_PubSubType>;
  auto zones = ZoneWriter::create(participant, cfg.outputs.virtual_obstacles_topic,
                                  cfg.dds.qos.virtual_obstacles);
  ASSERT_TRUE(zones.ok());
  ASSERT_TRUE(zones.value()->wait_for_readers(1, test::kPatience));
  transport::VirtualObstacleArrayMsg msg;
  tarmac_msgs::msg::dds_::VirtualObstacle_ zone;
  zone.id("fuel-spill-1");
  zone.kind(tarmac_msgs::msg::VirtualObstacle_Constants::KIND_FUEL_SPILL);
  for (const auto& [dx, dy] : {std::pair{-1.0, -1.0}, {1.0, -1.0}, {1.0, 1.0}, {-1.0, 1.0}}) {
    geometry_msgs::msg::dds_::Point_ p;
    p.x(ahead.x() + dx);
    p.y(ahead.y() + dy);
    zone.polygon().push_back(p);
  }
  zone.min_z(-100.0);
  zone.max_z(100.0);
  msg.obstacles().push_back(zone);
  // No scan comes after the four: the executor publishes a costmap only when something changed,
  // so the next costmap is the one of the tick that drained the zone, and it must hold it.
  // Judged by that order, not by the time it took (which depends on the machine).
  std::vector<transport::OccupancyGridMsg> batch;
  grids.value()->take_all(batch);
  ASSERT_TRUE(batch.empty()) << "a costmap after the last scan's, before any zone";
  const auto t_sent = std::chrono::steady_clock::now();
  ASSERT_TRUE(zones.value()->write(msg));
  const auto deadline = t_sent + kTimeScale * 30s;
  while (batch.empty() && std::chrono::steady_clock::now() < deadline) {
    grids.value()->wait_for_sample(50ms);
    grids.value()->take_all(batch);
  }
  const double elapsed_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_sent).count();
  ASSERT_FALSE(batch.empty()) << "no costmap after the zone";
  EXPECT_EQ(cell_at(batch.front(), ahead.x(), ahead.y()), 100)
      << "the first costmap after the zone does not hold it";
  std::printf("zone: lethal in the first costmap after it, %.1f ms after it was sent\n",
              elapsed_ms);
}

}  // namespace
}  // namespace tarmac::daemon
