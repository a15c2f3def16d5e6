// Fleet scale: participants configured with dds.discovery_servers find each other through a
// Fast DDS discovery server (`fastdds discovery`, Debian fastdds-tools) on loopback, and not
// without it. Six vehicles' fleet summaries reach every other vehicle; the discovery's time and
// traffic on loopback are printed (docs/fleet.md).

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
#include "tarmac/transport/fleet.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::transport {
namespace {

using namespace std::chrono_literals;

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

/// One vehicle: its participant and its fleet link (tarmacd's: its own partition out, every
/// vehicle's in).
struct Vehicle {
  std::string id;
  Participant participant;
  std::unique_ptr<FleetLink> link;
};

std::unique_ptr<Vehicle> make_vehicle(const std::string& id) {
  auto p = Participant::create(client(id));
  EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
  if (!p.ok()) return nullptr;
  auto v = std::make_unique<Vehicle>(Vehicle{id, std::move(p).value(), nullptr});
  FleetLinkOptions o;
  o.topic = kTopic;
  o.vehicle_id = id;
  auto link = FleetLink::create(v->participant, o);
  EXPECT_TRUE(link.ok()) << (link.ok() ? "" : link.error().message);
  if (!link.ok()) return nullptr;
  v->link = std::move(link).value();
  return v;
}

bool wait_for_readers(const FleetLink& link, std::size_t n, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (link.matched_readers() < n) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(5ms);
  }
  return true;
}

/// The vehicle ids of the summaries a link hands over.
struct Ids final : FleetSink {
  void summary(core::BevMessage&& m) override { ids.push_back(m.vehicle_id); }
  void reject(std::string_view reason) override { refused.emplace_back(reason); }
  std::vector<std::string> ids, refused;
};

class DiscoveryServerTest : public test::LoopbackOnly {
 protected:
  [[nodiscard]] test::RtpsSniffer::Counts traffic() const {
    return sniffer_ ? sniffer_->counts() : test::RtpsSniffer::Counts{};
  }
};

TEST_F(DiscoveryServerTest, SixVehiclesFindEachOtherThroughTheServer_NoneWithoutIt) {
  TARMAC_REQUIRE_OR_SKIP(have_fastdds_tool(), "fastdds (Debian fastdds-tools) not installed");
  // Without a server, clients announce themselves to it only: nobody is found.
  {
    auto a = make_vehicle("lone-a");
    auto b = make_vehicle("lone-b");
    ASSERT_TRUE(a && b);
    EXPECT_FALSE(wait_for_readers(*a->link, 2, 3s)) << "clients matched without their server";
  }
  DiscoveryServer server;
  ASSERT_TRUE(server.running()) << "fastdds discovery did not start";
  constexpr int kVehicles = 6;
  std::this_thread::sleep_for(500ms);  // the server up and quiet
  const auto before = traffic();
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<Vehicle>> fleet;
  for (int i = 0; i < kVehicles; ++i) {
    fleet.push_back(make_vehicle("tug-" + std::to_string(i)));
    ASSERT_TRUE(fleet.back());
  }
  // Each writer matches every reader, its own participant's included.
  for (auto& v : fleet) ASSERT_TRUE(wait_for_readers(*v->link, kVehicles, 20s)) << v->id;
  const double discovery_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto discovered = traffic();
  // Then idle for 5 s: what discovery keeps sending (announcements, heartbeats) once all match.
  std::this_thread::sleep_for(5s);
  const auto idle = traffic();
  std::printf(
      "discovery of %d clients through the server: %.2f s, %.1f KiB in %llu RTPS packets on "
      "loopback; then idle %.2f KiB/s\n",
      kVehicles, discovery_s,
      static_cast<double>(discovered.loopback_bytes - before.loopback_bytes) / 1024.0,
      static_cast<unsigned long long>(discovered.loopback - before.loopback),
      static_cast<double>(idle.loopback_bytes - discovered.loopback_bytes) / 1024.0 / 5.0);

  for (auto& v : fleet) {
    core::BevMessage m;
    m.vehicle_id = v->id;
    m.stamp_ns = 1'000'000'000;
    m.keyframe = true;
    m.tiles = {
        core::BevTile{0, 0, {63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63, 63}}};
    ASSERT_TRUE(v->link->publish(m));
  }
  // Each vehicle hears the five others (its own summary is not handed over).
  for (auto& v : fleet) {
    Ids got;
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    while (got.ids.size() < kVehicles - 1 && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(20ms);
      v->link->drain(got);
    }
    std::sort(got.ids.begin(), got.ids.end());
    std::vector<std::string> want;
    for (int i = 0; i < kVehicles; ++i) {
      if ("tug-" + std::to_string(i) != v->id) want.push_back("tug-" + std::to_string(i));
    }
    EXPECT_EQ(got.ids, want) << v->id;
    EXPECT_TRUE(got.refused.empty()) << v->id;
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
