// Fast DDS round trips on this machine only: PointCloud2 and OccupancyGrid through two tarmac
// participants, every field compared, with a packet capture proving nothing left loopback.

#include <chrono>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "loopback_only.hpp"
#include "msg_dump.hpp"
#include "nav_msgsPubSubTypes.h"
#include "rtps_sniffer.hpp"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac/transport/inputs.hpp"
#include "tarmac/transport/participant.hpp"
#include "test_env.hpp"

namespace tarmac::transport {
namespace {

using namespace std::chrono_literals;
using CloudWriter = Writer<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
using CloudReader = Reader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
using GridWriter = Writer<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
using GridReader = Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;

Participant make_participant(std::uint32_t domain, const char* name,
                             TransportMode mode = TransportMode::kLocalhost) {
  ParticipantConfig config;
  config.domain_id = domain;
  config.name = name;
  config.transport = mode;
  auto p = Participant::create(config);
  EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
  return std::move(p).value();
}

template <typename T>
std::unique_ptr<T> must(core::Result<std::unique_ptr<T>> r) {
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().message);
  return std::move(r).value();
}

/// A cloud of ~1.4 MB (an Ouster-64 scan is about that): larger than any single UDP datagram.
PointCloud2Msg big_cloud() {
  core::PointCloud cloud;
  cloud.frame_id = "lidar_front";
  cloud.stamp_ns = 1'700'000'000'000'000'042;
  for (int i = 0; i < 65536; ++i) {
    cloud.points_S.emplace_back(0.001f * i, std::sin(0.01f * i), -0.5f + 1e-5f * i);
    cloud.intensity.push_back(static_cast<float>(i % 4096));
    cloud.ring.push_back(static_cast<std::uint16_t>(i % 64));
    cloud.time_offset_s.push_back(1e-6f * i);
  }
  return to_point_cloud2(cloud);
}

OccupancyGridMsg sample_grid() {
  core::Costmap costmap(core::GridGeometry2D{-12.5, 7.25, 0.2, 401, 399}, core::kCostUnknown);
  for (std::size_t i = 0; i < costmap.cells().size(); ++i) {
    costmap.cells()[i] = static_cast<std::int8_t>(static_cast<int>((i * 7) % 102) - 1);
  }
  auto msg = to_occupancy_grid(costmap, 1'700'000'001'500'000'000, "map");
  msg.info().origin().position().z(0.5);
  msg.info().map_load_time(to_time_msg(1'600'000'000'000'000'007));
  return msg;
}

/// Every test here runs under a packet capture when permitted: no RTPS packet may appear on an
/// interface other than lo.
class Loopback : public test::LoopbackOnly {};

TEST_F(Loopback, PointCloud2_EveryFieldArrives) {
  auto pub = make_participant(test::kDomainLoopbackCloud, "cloud-pub");
  auto sub = make_participant(test::kDomainLoopbackCloud, "cloud-sub");
  const QosSpec reliable{Reliability::kReliable, Durability::kVolatile, 2};
  auto reader = must(CloudReader::create(sub, "rt/tarmac/lidar/front/points", reliable, 4));
  auto writer = must(CloudWriter::create(pub, "rt/tarmac/lidar/front/points", reliable));
  ASSERT_TRUE(writer->wait_for_readers(1, 10s));

  const auto sent = big_cloud();
  ASSERT_GT(sent.data().size(), 1'400'000u);
  ASSERT_TRUE(writer->write(sent));
  ASSERT_TRUE(reader->wait_for_sample(10s));
  std::vector<PointCloud2Msg> got;
  ASSERT_EQ(reader->take_all(got), 1u);
  EXPECT_EQ(test::dump(got[0]), test::dump(sent));
  EXPECT_TRUE(got[0] == sent);
}

TEST_F(Loopback, OccupancyGrid_LateJoinerGetsTransientLocalSample) {
  auto pub = make_participant(test::kDomainLoopbackGrid, "grid-pub");
  auto writer = must(GridWriter::create(pub, "rt/tarmac/costmap", qos::kCostmap));
  const auto sent = sample_grid();
  ASSERT_TRUE(writer->write(sent));  // before any reader exists

  auto sub = make_participant(test::kDomainLoopbackGrid, "grid-sub");
  auto reader = must(GridReader::create(sub, "rt/tarmac/costmap", qos::kCostmap, 2));
  ASSERT_TRUE(reader->wait_for_sample(10s));
  std::vector<OccupancyGridMsg> got;
  ASSERT_EQ(reader->take_all(got), 1u);
  EXPECT_EQ(test::dump(got[0]), test::dump(sent));
  EXPECT_TRUE(got[0] == sent);
}

TEST_F(Loopback, ReaderQueue_OverflowDropsOldestAndCounts) {
  auto pub = make_participant(test::kDomainReaderQueue, "queue-pub");
  auto sub = make_participant(test::kDomainReaderQueue, "queue-sub");
  const QosSpec reliable{Reliability::kReliable, Durability::kVolatile, 10};
  auto reader = must(GridReader::create(sub, "rt/tarmac/costmap", reliable, 2));
  auto writer = must(GridWriter::create(pub, "rt/tarmac/costmap", reliable));
  ASSERT_TRUE(writer->wait_for_readers(1, 10s));
  auto msg = sample_grid();
  for (int i = 0; i < 5; ++i) {
    msg.header().stamp().sec(100 + i);
    ASSERT_TRUE(writer->write(msg));
  }
  ASSERT_TRUE(writer->wait_for_acknowledgments(10000ms));
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while (reader->received() < 5 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(5ms);
  }
  std::vector<OccupancyGridMsg> got;
  ASSERT_EQ(reader->take_all(got), 2u);
  EXPECT_EQ(reader->dropped(), 3u);
  EXPECT_EQ(got[0].header().stamp().sec(), 103);  // the two newest, oldest first
  EXPECT_EQ(got[1].header().stamp().sec(), 104);
}

/// What a TrajectoryInput hands on: the accepted paths (made-at stamp, pose stamps) and the
/// rejection reasons, in order.
class RecordingTrajectorySink final : public TrajectorySink {
 public:
  void trajectory(std::int64_t stamp_ns, std::span<const PoseSample> poses) override {
    std::vector<std::int64_t> stamps;
    for (const auto& p : poses) stamps.push_back(p.stamp_ns);
    accepted.emplace_back(stamp_ns, stamps);
  }
  void reject(std::string_view reason) override { rejected.emplace_back(reason); }
  std::vector<std::pair<std::int64_t, std::vector<std::int64_t>>> accepted;
  std::vector<std::string> rejected;
};

PathMsg path_of(const std::string& frame, std::int64_t made_ns,
                const std::vector<std::int64_t>& stamps) {
  PathMsg path;
  path.header().frame_id(frame);
  path.header().stamp(to_time_msg(made_ns));
  for (const std::int64_t t : stamps) {
    geometry_msgs::msg::dds_::PoseStamped_ ps;
    ps.header().stamp(to_time_msg(t));
    ps.pose(to_pose_msg(Eigen::Isometry3d::Identity()));
    path.poses().push_back(ps);
  }
  return path;
}

TEST_F(Loopback, PathCorrection_AcceptedOrRejectedWholeWithItsReason) {
  using PathWriter = Writer<nav_msgs::msg::dds_::Path_PubSubType>;
  auto pub = make_participant(test::kDomainLoopbackPath, "path-pub");
  auto sub = make_participant(test::kDomainLoopbackPath, "path-sub");
  const QosSpec reliable{Reliability::kReliable, Durability::kVolatile, 10};
  auto input = must(TrajectoryInput::create(sub, "rt/tarmac/pose_correction", "map", reliable, 8));
  auto writer = must(PathWriter::create(pub, "rt/tarmac/pose_correction", reliable));
  ASSERT_TRUE(writer->wait_for_readers(1, 10s));
  ASSERT_TRUE(writer->write(path_of("map", 500, {100, 200, 300})));  // accepted
  ASSERT_TRUE(writer->write(path_of("odom", 500, {100, 200})));      // another frame
  ASSERT_TRUE(writer->write(path_of("map", 500, {})));               // no pose
  ASSERT_TRUE(writer->write(path_of("map", 500, {200, 100})));       // stamps not increasing
  auto bad_pose = path_of("map", 500, {100});
  bad_pose.poses()[0].pose().orientation().w(0.0);  // zero quaternion
  ASSERT_TRUE(writer->write(bad_pose));
  ASSERT_TRUE(writer->write(path_of("map", 0, {400, 450})));  // no made-at stamp: the newest pose's
  ASSERT_TRUE(writer->wait_for_acknowledgments(10000ms));
  RecordingTrajectorySink sink;
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  std::size_t taken = 0;
  while (taken < 6 && std::chrono::steady_clock::now() < deadline) {
    taken += input->drain(sink);
    std::this_thread::sleep_for(5ms);
  }
  ASSERT_EQ(taken, 6u);
  ASSERT_EQ(sink.accepted.size(), 2u);
  EXPECT_EQ(sink.accepted[0].first, 500);
  EXPECT_EQ(sink.accepted[0].second, (std::vector<std::int64_t>{100, 200, 300}));
  EXPECT_EQ(sink.accepted[1].first, 450);
  EXPECT_EQ(sink.rejected,
            (std::vector<std::string>{"correction.unknown_frame", "correction.empty",
                                      "correction.unsorted", "pose.bad_quaternion"}));
  EXPECT_EQ(input->overflow_drops(), 0u);
}

TEST_F(Loopback, SharedMemoryOnly_RoundTrip) {
  auto pub =
      make_participant(test::kDomainSharedMemoryOnly, "shm-pub", TransportMode::kSharedMemoryOnly);
  auto sub =
      make_participant(test::kDomainSharedMemoryOnly, "shm-sub", TransportMode::kSharedMemoryOnly);
  auto reader = must(GridReader::create(sub, "rt/tarmac/costmap", qos::kCostmap, 1));
  auto writer = must(GridWriter::create(pub, "rt/tarmac/costmap", qos::kCostmap));
  ASSERT_TRUE(writer->wait_for_readers(1, 10s));
  const auto sent = sample_grid();
  ASSERT_TRUE(writer->write(sent));
  ASSERT_TRUE(reader->wait_for_sample(10s));
  std::vector<OccupancyGridMsg> got;
  reader->take_all(got);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_TRUE(got[0] == sent);
}

// The capture itself must work, or the off-host checks above prove nothing: a localhost
// participant pair must be seen talking RTPS on lo.
TEST_F(Loopback, Sniffer_SeesLoopbackDiscovery) {
  auto a = make_participant(test::kDomainConfinement, "sniff-a");
  auto b = make_participant(test::kDomainConfinement, "sniff-b");
  auto reader = must(GridReader::create(b, "rt/tarmac/costmap", qos::kCostmap, 1));
  auto writer = must(GridWriter::create(a, "rt/tarmac/costmap", qos::kCostmap));
  ASSERT_TRUE(writer->wait_for_readers(1, 10s));
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  while (sniffer_->counts().loopback == 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(10ms);
  }
  EXPECT_GT(sniffer_->counts().loopback, 0u);
}

TEST(ParticipantConfig, NetworkModeNeedsExplicitInterfaces) {
  ParticipantConfig config;
  config.transport = TransportMode::kNetwork;
  auto status = config.validate();
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.error().message.find("dds.network_interfaces"), std::string::npos);
  config.network_interfaces = {"10.0.0.300"};
  EXPECT_FALSE(config.validate().ok());
  config.network_interfaces = {"10.0.0.3"};
  EXPECT_TRUE(config.validate().ok());
}

TEST(ParticipantConfig, LocalhostRefusesNetworkInterfaces) {
  ParticipantConfig config;
  config.network_interfaces = {"10.0.0.3"};
  EXPECT_FALSE(config.validate().ok());
  config.network_interfaces.clear();
  config.domain_id = 233;
  EXPECT_FALSE(Participant::create(config).ok());
}

TEST(ParticipantConfig, UdpBuffersBelowOneDatagramAreRefused) {
  ParticipantConfig config;
  config.udp_receive_buffer_bytes = 65535;
  ASSERT_FALSE(config.validate().ok());
  EXPECT_NE(config.validate().error().message.find("dds.udp_receive_buffer_bytes"),
            std::string::npos);
  config.udp_receive_buffer_bytes = 65536;
  config.udp_send_buffer_bytes = 1000;
  ASSERT_FALSE(config.validate().ok());
  EXPECT_NE(config.validate().error().message.find("dds.udp_send_buffer_bytes"), std::string::npos);
}

/// The kernel's cap on socket receive buffers (net.core.rmem_max), or 0 when unreadable.
std::uint64_t rmem_max() {
  std::ifstream in("/proc/sys/net/core/rmem_max");
  std::uint64_t v = 0;
  in >> v;
  return v;
}

TEST(UdpBuffers, ShortfallNamesTheKeyAndTheSysctl_NoneWhenGranted) {
  const std::uint64_t cap = rmem_max();
  TARMAC_REQUIRE_OR_SKIP(cap > 0 && cap < (1u << 29), "net.core.rmem_max unreadable");
  ParticipantConfig config;
  config.udp_receive_buffer_bytes = static_cast<std::uint32_t>(cap + (1u << 20));
  config.udp_send_buffer_bytes = 65536;
  const auto shortfalls = udp_buffer_shortfalls(config);
  ASSERT_EQ(shortfalls.size(), 1u);
  EXPECT_NE(shortfalls[0].find("dds.udp_receive_buffer_bytes"), std::string::npos) << shortfalls[0];
  EXPECT_NE(shortfalls[0].find("net.core.rmem_max = " + std::to_string(cap)), std::string::npos)
      << shortfalls[0];
  config.udp_receive_buffer_bytes = 65536;
  EXPECT_TRUE(udp_buffer_shortfalls(config).empty());
  config.udp_receive_buffer_bytes = static_cast<std::uint32_t>(cap + (1u << 20));
  config.transport = TransportMode::kSharedMemoryOnly;  // no sockets: nothing to warn about
  EXPECT_TRUE(udp_buffer_shortfalls(config).empty());
}

}  // namespace
}  // namespace tarmac::transport
