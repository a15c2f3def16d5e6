// tarmac-dds-bench: the cost of DDS Security on this machine. Two participants in one process
// (intra-process delivery off, so every sample goes through the transport and, with security,
// through the crypto plugin): the time from creating them to the writer matching the reader
// (discovery, including the authentication handshake), then the latency of scans published
// one at a time (write -> the reader's listener wakes) and the CPU time they cost.
// Localhost-only transport; run it in a private network namespace next to other sessions.

#include <fastrtps/xmlparser/XMLProfileManager.h>

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac/config/cli.hpp"
#include "tarmac/transport/participant.hpp"

namespace {

using namespace tarmac;
using Clock = std::chrono::steady_clock;
using CloudWriter = transport::Writer<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
using CloudReader = transport::Reader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// CPU time (user + system, all threads) of this process so far, ms.
double cpu_ms() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const auto ms = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_usec) / 1e3;
  };
  return ms(usage.ru_utime) + ms(usage.ru_stime);
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(std::lround(p * static_cast<double>(v.size() - 1)));
  return v[i];
}

}  // namespace

int main(int argc, char** argv) {
  std::string security_dir, mode = "localhost";
  int points = 65536, scans = 100;
  std::uint32_t domain = 7;
  cli::App app("tarmac-dds-bench",
               "The cost of DDS Security on this machine: discovery time, then the latency and "
               "CPU time of scans published one at a time between two participants in one "
               "process.");
  app.add_option("--security", security_dir,
                 "the output of tools/make-dds-security.sh (identities 'publisher' and "
                 "'tarmacd'); without it, no security")
      ->check(CLI::ExistingDirectory);
  app.add_option("--transport", mode, "localhost (UDP) or shm")
      ->check(CLI::IsMember({"localhost", "shm"}));
  app.add_option("--points", points, "points per scan (65536: 2 MB, an Ouster-64 scan)")
      ->transform(cli::positive<int>());
  app.add_option("--scans", scans, "scans timed one by one")->transform(cli::positive<int>());
  app.add_option("--domain", domain, "DDS domain id")
      ->transform(cli::in_range<std::uint32_t>(0, 232));
  app.footer("CPU: user + system time of the process (both sides) per timed scan.");
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  eprosima::fastrtps::LibrarySettingsAttributes library;
  library.intraprocess_delivery = eprosima::fastrtps::INTRAPROCESS_OFF;
  eprosima::fastrtps::xmlparser::XMLProfileManager::library_settings(library);

  const auto config = [&](const char* name, const char* identity) {
    transport::ParticipantConfig c;
    c.domain_id = domain;
    c.name = name;
    c.transport = mode == "shm" ? transport::TransportMode::kSharedMemoryOnly
                                : transport::TransportMode::kLocalhost;
    if (!security_dir.empty()) {
      auto& s = c.security;
      s.identity_ca = security_dir + "/ca.cert.pem";
      s.permissions_ca = security_dir + "/ca.cert.pem";
      s.governance = security_dir + "/governance.p7s";
      s.permissions = security_dir + "/permissions.p7s";
      s.use_identity_dir(security_dir + "/" + identity);
    }
    return c;
  };

  const auto t_create = Clock::now();
  auto pub = transport::Participant::create(config("bench-pub", "publisher"));
  auto sub = transport::Participant::create(config("bench-sub", "tarmacd"));
  if (!pub || !sub) {
    std::fprintf(stderr, "tarmac-dds-bench: %s\n",
                 (!pub ? pub.error().message : sub.error().message).c_str());
    return 69;
  }
  const double create_ms = ms_since(t_create);
  const std::string topic = "rt/tarmac/lidar/front/points";
  const transport::QosSpec qos{transport::Reliability::kReliable, transport::Durability::kVolatile,
                               4};
  auto reader = CloudReader::create(sub.value(), topic, qos, 8);
  auto writer = CloudWriter::create(pub.value(), topic, qos);
  if (!reader || !writer) {
    std::fprintf(stderr, "tarmac-dds-bench: %s\n",
                 (!reader ? reader.error().message : writer.error().message).c_str());
    return 69;
  }
  if (!writer.value()->wait_for_readers(1, std::chrono::seconds(30))) {
    std::fprintf(stderr, "tarmac-dds-bench: no match within 30 s\n");
    return 69;
  }
  const double match_ms = ms_since(t_create);

  core::PointCloud cloud;
  cloud.frame_id = "lidar_front";
  for (int i = 0; i < points; ++i) {
    cloud.points_S.emplace_back(0.001f * static_cast<float>(i),
                                std::sin(0.01f * static_cast<float>(i)), -0.5f);
    cloud.intensity.push_back(static_cast<float>(i % 4096));
    cloud.ring.push_back(static_cast<std::uint16_t>(i % 64));
    cloud.time_offset_s.push_back(1e-6f * static_cast<float>(i));
  }
  auto msg = transport::to_point_cloud2(cloud);
  std::vector<transport::PointCloud2Msg> got;
  std::vector<double> latency;
  int lost = 0;
  double cpu_start = 0.0;
  for (int k = 0; k < scans + 5; ++k) {  // the first 5 warm up
    if (k == 5) cpu_start = cpu_ms();
    msg.header().stamp().nanosec(static_cast<std::uint32_t>(k));
    const auto t0 = Clock::now();
    writer.value()->write(msg);
    if (!reader.value()->wait_for_sample(std::chrono::seconds(2))) {
      ++lost;
      continue;
    }
    const double ms = ms_since(t0);
    got.clear();
    reader.value()->take_all(got);
    if (k >= 5) latency.push_back(ms);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const double cpu_per_scan = (cpu_ms() - cpu_start) / static_cast<double>(scans);
  const double mb = static_cast<double>(msg.data().size()) / 1e6;
  std::printf(
      "security %-3s transport %-9s scan %.2f MB: create %.1f ms, then match %.1f ms; latency "
      "p50 %.2f p99 %.2f max %.2f ms, CPU %.2f ms/scan (%zu scans, %d lost)\n",
      security_dir.empty() ? "off" : "on", mode.c_str(), mb, create_ms, match_ms - create_ms,
      percentile(latency, 0.5), percentile(latency, 0.99), percentile(latency, 1.0), cpu_per_scan,
      latency.size(), lost);
  return 0;
}
