// tarmacd's debris output end to end over loopback DDS: the simulated airside sequence (its
// 10 cm debris beside the path) replayed into the executor; the DebrisArray stamped with the last
// scan equals the core's debris offline after the same scans, and the CycleReport counts it.

#include <algorithm>
#include <chrono>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "executor_harness.hpp"
#include "loopback_only.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/replay/replayer.hpp"
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

/// The core offline on the sequence's first `scans` scans, poses as they travel over the wire.
std::vector<core::Debris> offline_debris(const config::Config& cfg, std::size_t scans,
                                         std::int64_t last_stamp_ns) {
  core::Mapper mapper(cfg.mapping);
  core::SerialRunner runner;
  const auto& seq = test::sequence();
  const Eigen::Isometry3d& T_B_S = cfg.sensors[0].T_base_sensor;
  core::PointCloud cloud;
  core::OrganisedScratch scratch;
  for (std::size_t k = 0; k < scans; ++k) {
    EXPECT_TRUE(tools::read_sequence_scan(seq, k, cloud, scratch).ok());
    const auto T_W_B =
        transport::from_pose_msg(transport::to_pose_msg(tools::base_pose(seq.T_W_S[k], T_B_S)));
    const auto scan = mapper.ingest(cloud, T_W_B.value(), T_B_S);
    mapper.integrate(scan, runner);
  }
  mapper.update_costmap(mapper.vehicle_pose(), {}, last_stamp_ns, runner);
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
  options.pace = test::paced_by(executor.get());
  const auto stats = tools::replay(participant, test::sequence(), options);
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

  const std::vector<core::Debris> want = offline_debris(cfg, stats.value().scans, last_ns);
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
