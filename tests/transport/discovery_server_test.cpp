// Fleet scale: participants configured with dds.discovery_servers find each other through a
// Fast DDS discovery server (`fastdds discovery`, Debian fastdds-tools) on loopback, and not
// without it. Six vehicles' fleet summaries reach every other vehicle.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "loopback_only.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::transport {
namespace {

using namespace std::chrono_literals;
using BevWriter = Writer<tarmac_msgs::msg::dds_::FleetBev_PubSubType>;
using BevReader = Reader<tarmac_msgs::msg::dds_::FleetBev_PubSubType>;

constexpr int kServerPort = 24121;
constexpr const char* kTopic = "rt/tarmac/fleet/bev";

/// `fastdds discovery -i 0 -l 127.0.0.1 -p kServerPort`, stopped (SIGINT, then SIGKILL) with
/// the object.
class DiscoveryServer {
 public:
  DiscoveryServer() {
    const std::string port = std::to_string(kServerPort);
    pid_ = fork();
    if (pid_ == 0) {
      execlp("fastdds", "fastdds", "discovery", "-i", "0", "-l", "127.0.0.1", "-p", port.c_str(),
             static_cast<char*>(nullptr));
      _exit(127);
    }
  }
  ~DiscoveryServer() {
    if (pid_ <= 0) return;
    kill(pid_, SIGINT);
    for (int i = 0; i < 50; ++i) {
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) return;
      std::this_thread::sleep_for(100ms);
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
  }
  DiscoveryServer(const DiscoveryServer&) = delete;
  DiscoveryServer& operator=(const DiscoveryServer&) = delete;
  [[nodiscard]] bool running() const { return pid_ > 0 && waitpid(pid_, nullptr, WNOHANG) == 0; }

 private:
  pid_t pid_ = -1;
};

bool have_fastdds_tool() {
  return std::system("command -v fastdds > /dev/null 2>&1") == 0;
}

ParticipantConfig client(const std::string& name) {
  ParticipantConfig c;
  c.domain_id = test::kDomainDiscoveryServer;
  c.name = name;
  c.discovery_servers = {"127.0.0.1:" + std::to_string(kServerPort)};
  return c;
}

/// One vehicle: its participant, a writer of its summaries and a reader of everyone's.
struct Vehicle {
  std::string id;
  Participant participant;
  std::unique_ptr<BevWriter> writer;
  std::unique_ptr<BevReader> reader;
};

std::unique_ptr<Vehicle> make_vehicle(const std::string& id) {
  auto p = Participant::create(client(id));
  EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
  if (!p.ok()) return nullptr;
  auto v = std::make_unique<Vehicle>(Vehicle{id, std::move(p).value(), nullptr, nullptr});
  const QosSpec q{Reliability::kReliable, Durability::kVolatile, 8};
  auto w = BevWriter::create(v->participant, kTopic, q);
  auto r = BevReader::create(v->participant, kTopic, q, 64);
  EXPECT_TRUE(w.ok() && r.ok());
  if (!w.ok() || !r.ok()) return nullptr;
  v->writer = std::move(w).value();
  v->reader = std::move(r).value();
  return v;
}

class DiscoveryServerTest : public test::LoopbackOnly {};

TEST_F(DiscoveryServerTest, SixVehiclesFindEachOtherThroughTheServer_NoneWithoutIt) {
  TARMAC_REQUIRE_OR_SKIP(have_fastdds_tool(), "fastdds (Debian fastdds-tools) not installed");
  // Without a server, clients announce themselves to it only: nobody is found.
  {
    auto a = make_vehicle("lone-a");
    auto b = make_vehicle("lone-b");
    ASSERT_TRUE(a && b);
    EXPECT_FALSE(a->writer->wait_for_readers(2, 3s)) << "clients matched without their server";
  }
  DiscoveryServer server;
  ASSERT_TRUE(server.running()) << "fastdds discovery did not start";
  constexpr int kVehicles = 6;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<Vehicle>> fleet;
  for (int i = 0; i < kVehicles; ++i) {
    fleet.push_back(make_vehicle("tug-" + std::to_string(i)));
    ASSERT_TRUE(fleet.back());
  }
  // Each writer matches every reader, its own participant's included.
  for (auto& v : fleet) ASSERT_TRUE(v->writer->wait_for_readers(kVehicles, 20s)) << v->id;
  const double discovery_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("discovery of %d clients through the server: %.2f s\n", kVehicles, discovery_s);

  for (auto& v : fleet) {
    core::BevMessage m;
    m.vehicle_id = v->id;
    m.stamp_ns = 1'000'000'000;
    m.keyframe = true;
    m.tiles = {
        core::BevTile{0, 0, {63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63}}};
    ASSERT_TRUE(v->writer->write(to_fleet_bev(m, "map")));
  }
  for (auto& v : fleet) {
    std::vector<FleetBevMsg> got;
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (got.size() < kVehicles && std::chrono::steady_clock::now() < deadline) {
      v->reader->wait_for_sample(100ms);
      v->reader->take_all(got);
    }
    std::vector<std::string> from;
    for (const auto& msg : got) from.push_back(msg.vehicle_id());
    std::sort(from.begin(), from.end());
    EXPECT_EQ(from.size(), static_cast<std::size_t>(kVehicles)) << v->id;
    for (int i = 0; i < kVehicles && i < static_cast<int>(from.size()); ++i) {
      EXPECT_EQ(from[static_cast<std::size_t>(i)], "tug-" + std::to_string(i)) << v->id;
    }
  }
}

TEST(DiscoveryServerConfig, ServersAreIpv4PortOnLoopbackForLocalhost_AndNeedUdp) {
  ParticipantConfig c = client("x");
  EXPECT_TRUE(c.validate().ok());
  for (const char* bad : {"127.0.0.1", "127.0.0.1:0", "127.0.0.1:65536", "localhost:11811",
                          "127.0.0.1:11811x", ":11811"}) {
    c.discovery_servers = {bad};
    const auto v = c.validate();
    ASSERT_FALSE(v.ok()) << bad;
    EXPECT_NE(v.error().message.find("dds.discovery_servers"), std::string::npos) << bad;
  }
  c.discovery_servers = {"10.0.0.5:11811"};
  EXPECT_FALSE(c.validate().ok()) << "transport localhost must not reach another address";
  c.transport = TransportMode::kNetwork;
  c.network_interfaces = {"10.0.0.2"};
  EXPECT_TRUE(c.validate().ok());
  c.transport = TransportMode::kSharedMemoryOnly;
  c.network_interfaces.clear();
  EXPECT_FALSE(c.validate().ok());
}

}  // namespace
}  // namespace tarmac::transport
