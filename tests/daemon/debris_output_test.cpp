// tarmacd's debris output end to end over loopback DDS: the simulator's debris scene (cubes of 5,
// 10 and 20 cm beside the path) replayed into the executor; the DebrisArray stamped with the last
// scan equals the core's debris offline after the same scans, and the CycleReport counts it.

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "executor_harness.hpp"
#include "loopback_only.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/sim/scene_catalog.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac {
namespace {

using namespace std::chrono_literals;
using DebrisReader = transport::Reader<tarmac_msgs::msg::dds_::DebrisArray_PubSubType>;

class DebrisOutput : public test::LoopbackOnly {
 protected:
  DebrisOutput() { expect_loopback_traffic_ = true; }
};

/// `--scene debris` up to 18 m along the path, 32 beams: the first row's 10 and 20 cm cubes
/// (x = 25 m) are debris from about the 40th scan. Written once for the binary.
const tools::KittiSequence& debris_sequence() {
  static const tools::KittiSequence seq = [] {
    const auto dir = std::filesystem::temp_directory_path() /
                     ("tarmac-debris-output-test-" + std::to_string(::getpid()));
    const auto drive = sim::scene_drive("debris", std::nullopt, 2.0);
    EXPECT_TRUE(drive.has_value());
    sim::SequenceParams p;
    p.path = drive->path;
    p.scans = 60;
    p.lidar.beams = 32;
    p.lidar.azimuth_steps = 1024;
    const auto written = sim::write_sequence(drive->scene, p, dir);
    EXPECT_TRUE(written.ok()) << written.error;
    auto opened = tools::open_kitti(dir);
    EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
    return std::move(opened).value();
  }();
  return seq;
}

/// The core offline on the sequence's scans stamped `stamps_ns` (as replayed), poses as they
/// travel over the wire.
std::vector<core::Debris> offline_debris(const config::Config& cfg,
                                         const std::vector<std::int64_t>& stamps_ns) {
  core::Mapper mapper(cfg.mapping);
  core::SerialRunner runner;
  const auto& seq = debris_sequence();
  const Eigen::Isometry3d& T_B_S = cfg.sensors[0].T_base_sensor;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  for (std::size_t k = 0; k < stamps_ns.size(); ++k) {
    EXPECT_TRUE(tools::read_sequence_scan(seq, k, cloud, scratch).ok());
    cloud.stamp_ns = stamps_ns[k];  // the debris's first and last seen
    const auto T_W_B =
        transport::from_pose_msg(transport::to_pose_msg(tools::base_pose(seq.T_W_S[k], T_B_S)));
    const auto scan = mapper.ingest(cloud, T_W_B.value(), T_B_S);
    mapper.integrate(scan, runner);
  }
  mapper.update_costmap(mapper.vehicle_pose(), {}, stamps_ns.back(), runner);
  return mapper.debris();
}

template <typename Msg>
bool stamped(const Msg& m, std::int64_t stamp_ns) {
  return transport::from_time_msg(m.header().stamp()) == stamp_ns;
}

TEST_F(DebrisOutput, PublishedListAndCount_EqualTheOfflineCore) {
  const auto domain = test::kDomainDaemonDebris;
  auto cfg = test::test_config(domain, 2);
  test::take_late_input(cfg);  // paced below: the map must not depend on the machine's load
  // The simulated LiDAR sits 2 m above the base (the ground prior and the debris's heights).
  cfg.sensors[0].T_base_sensor.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
  test::RunningExecutor executor(cfg);
  auto participant = test::peer(domain);
  auto lists = DebrisReader::create(participant, cfg.outputs.debris_topic, cfg.dds.qos.debris, 64);
  ASSERT_TRUE(lists.ok());
  auto reports = test::ReportReader::create(participant, cfg.outputs.cycle_report_topic,
                                            cfg.dds.qos.diagnostics, 256);
  ASSERT_TRUE(reports.ok());
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 2.0 / test::kTimeScale;
  std::vector<std::int64_t> stamps_ns;  // per scan, as replayed
  options.pace = [&, paced = test::paced_by(executor.get())](std::size_t k, std::int64_t stamp_ns) {
    if (k == stamps_ns.size()) stamps_ns.push_back(stamp_ns);
    return paced(k, stamp_ns);
  };
  options.T_base_sensor = cfg.sensors[0].T_base_sensor;
  const auto stats = tools::replay(participant, debris_sequence(), options);
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  const std::int64_t last_ns = stats.value().last_stamp_ns;

  std::vector<transport::DebrisArrayMsg> lists_got;
  std::vector<transport::CycleReportMsg> reports_got;
  const auto both_in = [&] {
    lists.value()->take_all(lists_got);
    reports.value()->take_all(reports_got);
    const auto at_last = [&](const auto& m) { return stamped(m, last_ns); };
    return std::any_of(lists_got.begin(), lists_got.end(), at_last) &&
           std::any_of(reports_got.begin(), reports_got.end(), at_last);
  };
  test::eventually(both_in);
  ASSERT_TRUE(both_in()) << "no debris list and CycleReport stamped with the last scan";
  executor.stop();
  const auto list = std::find_if(lists_got.begin(), lists_got.end(),
                                 [&](const auto& m) { return stamped(m, last_ns); });
  EXPECT_EQ(list->header().frame_id(), "map");

  ASSERT_EQ(stamps_ns.size(), stats.value().scans);
  ASSERT_EQ(stamps_ns.back(), last_ns);
  const std::vector<core::Debris> want = offline_debris(cfg, stamps_ns);
  ASSERT_GE(want.size(), 2u) << "the first row's 10 and 20 cm cubes";
  const auto got = transport::from_debris_array(*list);
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(got[i].id, want[i].id);
    EXPECT_EQ(got[i].xy_W, want[i].xy_W);
    EXPECT_EQ(got[i].ground_z_m, want[i].ground_z_m);
    EXPECT_EQ(got[i].height_m, static_cast<float>(want[i].height_m));
    EXPECT_EQ(got[i].first_seen_ns, want[i].first_seen_ns);
    EXPECT_EQ(got[i].last_confirmed_ns, want[i].last_confirmed_ns);
    EXPECT_EQ(got[i].returns, want[i].returns);
  }
  // Every list holds each id once, in increasing order (ids name pieces).
  for (const auto& m : lists_got) {
    for (std::size_t i = 1; i < m.objects().size(); ++i) {
      EXPECT_LT(m.objects()[i - 1].id(), m.objects()[i].id());
    }
  }
  const auto report = std::find_if(reports_got.begin(), reports_got.end(),
                                   [&](const auto& m) { return stamped(m, last_ns); });
  EXPECT_EQ(report->debris(), want.size());
}

}  // namespace
}  // namespace tarmac
