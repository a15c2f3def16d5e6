// Interop with an independent DDS implementation: a Cyclone DDS C program, with types that
// Cyclone's idlc generated from the same idl/ files, receives tarmac's OccupancyGrid on
// rt/tarmac/costmap and publishes a PointCloud2 on rt/tarmac/lidar/front/points that tarmac's
// reader receives. Every field is compared both ways (see tests/interop/cyclone_peer.c).

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "msg_dump.hpp"
#include "nav_msgsPubSubTypes.h"
#include "rtps_sniffer.hpp"
#include "sensor_msgsPubSubTypes.h"
#include "test_env.hpp"

extern char** environ;

namespace tarmac::transport {
namespace {

using namespace std::chrono_literals;

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

/// Compares two field dumps line by line, so a failure names the field that differs.
void expect_same_fields(const std::string& tarmac_view, const std::string& cyclone_view) {
  std::istringstream a(tarmac_view), b(cyclone_view);
  std::string la, lb;
  int n = 0;
  while (true) {
    const bool more_a = static_cast<bool>(std::getline(a, la));
    const bool more_b = static_cast<bool>(std::getline(b, lb));
    if (!more_a && !more_b) break;
    ASSERT_EQ(more_a, more_b) << "field lists differ in length after " << n << " fields";
    EXPECT_EQ(la.substr(0, 200), lb.substr(0, 200)) << "field " << n;
    if (la != lb) ADD_FAILURE() << "field differs: " << la.substr(0, la.find('='));
    ++n;
  }
  EXPECT_GT(n, 10);
}

TEST(CycloneInterop, CostmapOutAndPointCloudIn_EveryField) {
  std::unique_ptr<test::RtpsSniffer> sniffer;
  if (auto s = test::RtpsSniffer::start()) sniffer = std::move(s).value();
  TARMAC_REQUIRE_OR_SKIP(sniffer != nullptr, "packet capture unavailable (needs root)");

  char dir_template[] = "/tmp/tarmac-interop-XXXXXX";
  ASSERT_NE(mkdtemp(dir_template), nullptr);
  const std::filesystem::path out_dir = dir_template;

  ParticipantConfig config;
  config.domain_id = test::kDomainCycloneInterop;
  config.name = "tarmac-interop";
  auto participant = Participant::create(config);
  ASSERT_TRUE(participant.ok()) << participant.error().message;
  // The costmap as tarmacd publishes it (reliable, transient local, keep last 1), every field
  // non-default, including a rotated origin that tarmac itself never produces.
  auto writer = Writer<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>::create(
      participant.value(), "rt/tarmac/costmap", qos::kCostmap);
  ASSERT_TRUE(writer.ok()) << writer.error().message;
  const QosSpec reliable{Reliability::kReliable, Durability::kVolatile, 1};
  auto reader = Reader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>::create(
      participant.value(), "rt/tarmac/lidar/front/points", reliable, 4);
  ASSERT_TRUE(reader.ok()) << reader.error().message;

  core::Costmap costmap(core::GridGeometry2D{-31.4, 15.9, 0.1, 123, 77}, core::kCostUnknown);
  for (std::size_t i = 0; i < costmap.cells().size(); ++i) {
    costmap.cells()[i] = static_cast<std::int8_t>(static_cast<int>((i * 13) % 102) - 1);
  }
  auto grid = to_occupancy_grid(costmap, 1'700'000'222'333'444'555, "map");
  grid.info().map_load_time(to_time_msg(1'699'999'999'000'000'001));
  grid.info().origin().position().z(-0.75);
  grid.info().origin().orientation().z(0.3826834323650898);
  grid.info().origin().orientation().w(0.9238795325112867);
  ASSERT_TRUE(writer.value()->write(grid));

  // The Cyclone peer, confined to lo by its config.
  const std::string uri =
      "CYCLONEDDS_URI=file://" + (test::source_dir() / "config/cyclonedds_localhost.xml").string();
  std::vector<std::string> env_strings = {uri};
  for (char** e = environ; *e != nullptr; ++e) {
    if (std::string(*e).rfind("CYCLONEDDS_URI=", 0) != 0) env_strings.emplace_back(*e);
  }
  std::vector<char*> envp;
  for (auto& s : env_strings) envp.push_back(s.data());
  envp.push_back(nullptr);
  std::string peer = TARMAC_CYCLONE_PEER;
  std::string domain = std::to_string(test::kDomainCycloneInterop);
  std::string out = out_dir.string();
  char* argv[] = {peer.data(), domain.data(), out.data(), nullptr};
  pid_t pid = 0;
  ASSERT_EQ(posix_spawn(&pid, peer.c_str(), nullptr, nullptr, argv, envp.data()), 0);

  const bool got_cloud = reader.value()->wait_for_sample(40s);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "cyclone peer failed";
  ASSERT_TRUE(got_cloud) << "no PointCloud2 from the Cyclone peer";

  // tarmac -> Cyclone: the grid as Cyclone decoded it equals the grid tarmac sent.
  expect_same_fields(test::dump(grid), read_file(out_dir / "costmap_received.txt"));

  // Cyclone -> tarmac: the cloud as tarmac decoded it equals the cloud Cyclone sent.
  std::vector<PointCloud2Msg> clouds;
  ASSERT_EQ(reader.value()->take_all(clouds), 1u);
  expect_same_fields(test::dump(clouds[0]), read_file(out_dir / "points_sent.txt"));

  // And tarmac's parser reads Cyclone's big-endian, row-padded layout.
  core::PointCloud cloud;
  ASSERT_TRUE(from_point_cloud2(clouds[0], cloud).ok());
  EXPECT_EQ(cloud.size(), 74u);
  EXPECT_TRUE(cloud.has_intensity() && cloud.has_ring() && cloud.has_time());
  EXPECT_EQ(cloud.frame_id, "lidar_front");

  std::filesystem::remove_all(out_dir);
  std::this_thread::sleep_for(200ms);
  const auto counts = sniffer->counts();
  EXPECT_EQ(counts.off_host, 0u) << "RTPS left loopback: " << counts.first_off_host;
  EXPECT_GT(counts.loopback, 0u) << "Fast DDS and Cyclone must meet over UDP on lo";
}

}  // namespace
}  // namespace tarmac::transport
