// tarmacd fed by an outside client on another DDS implementation, as a ROS 2 LiDAR driver in
// another process would feed it: tarmac-cyclone-replay (Cyclone DDS, UDP over loopback, best
// effort, ROS 2 types) sends real-size clouds (> 900 KB) at 10 Hz with poses and reads the
// costmaps and CycleReports back. With the shipped socket buffers at least 99 % of the scans are
// integrated; with a deliberately small receive buffer scans are lost, and the loss is counted in
// the CycleReport (transport.scan_lost.<sensor>) and logged, never silent.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "child_process.hpp"
#include "loopback_only.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "test_env.hpp"

namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr int kScans = 50;
/// A short scan (one datagram) before the sequence: a reader that has it counts every later loss
/// as a gap in sequence numbers, even when none of the big clouds gets through.
constexpr int kHeadScans = 1;
/// Short scans after the sequence, so a loss at its end shows as a gap in sequence numbers.
constexpr int kTailScans = 5;

/// A 64-beam sequence of clouds over 900 KB each (16 bytes a point), written once per process.
const fs::path& big_cloud_sequence() {
  static const fs::path dir = [] {
    const fs::path d =
        fs::temp_directory_path() / ("tarmac_cyclone_client_" + std::to_string(getpid()));
    tarmac::sim::SequenceParams p;
    p.scans = kScans;
    p.lidar.beams = 64;
    p.lidar.azimuth_steps = 2048;
    const auto written = tarmac::sim::write_sequence(tarmac::sim::Scene::airside_default(), p, d);
    EXPECT_TRUE(written.ok()) << written.error;
    return d;
  }();
  return dir;
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A number after `"key": ` in the replay's one-line JSON, or -1.
double json_number(const std::string& json, const std::string& key) {
  const std::regex re("\"" + key + "\": ([0-9.]+)");
  std::smatch m;
  return std::regex_search(json, m, re) ? std::stod(m[1].str()) : -1.0;
}

using tarmac::test::spawn;
using tarmac::test::wait_exit;

struct Outcome {
  long sent = 0;
  long integrated = -1;  ///< tarmacd's own count at exit
  double lost = -1, rejected = -1, overflow = -1;
  double p50_ms = -1, p99_ms = -1;
  double first_back = -1;  ///< index of the first scan that came back in a costmap
  std::string daemon_log;
};

/// tarmacd with the shipped defaults but `receive_buffer` (0: the default), fed by the Cyclone
/// client over UDP; tarmacd runs on a copy of the shipped config, state in a temp folder.
Outcome run(std::uint32_t domain, std::uint32_t receive_buffer) {
  const fs::path dir =
      fs::temp_directory_path() /
      ("tarmac_cyclone_run_" + std::to_string(getpid()) + "_" + std::to_string(domain));
  fs::remove_all(dir);
  fs::create_directories(dir);
  {
    std::ofstream cfg(dir / "tarmac.yaml");
    cfg << "version: 1\ndds:\n  domain_id: " << domain << "\n";
    if (receive_buffer != 0) cfg << "  udp_receive_buffer_bytes: " << receive_buffer << "\n";
    // Slow motion under a sanitizer (test_env.hpp): the shipped timing slowed by kTimeScale,
    // and the client's rate with it; a scan that reaches a busy tarmacd late still counts (the
    // client sends on its schedule, stamps on it).
    const auto timing = tarmac::test::scaled_timing_yaml(true);
    cfg << "executor: {realtime_priority: 0, lock_memory: false" << timing.executor_keys << "}\n"
        << timing.sections << "state: {dir: " << (dir / "state").string()
        << ", save_on_exit: false}\n";
  }
  Outcome out;
  const pid_t daemon =
      spawn({TARMAC_TARMACD, "--config", (dir / "tarmac.yaml").string()}, dir / "tarmacd.log");
  EXPECT_TRUE(tarmac::test::eventually([&] {
    return read_text(dir / "tarmacd.log").find("tarmacd: ready") != std::string::npos;
  })) << read_text(dir / "tarmacd.log");
  const std::string uri =
      "file://" + (tarmac::test::source_dir() / "config" / "cyclonedds_localhost.xml").string();
  const pid_t client =
      spawn({TARMAC_CYCLONE_REPLAY, "--dataset", big_cloud_sequence().string(), "--domain",
             std::to_string(domain), "--rate-hz", std::to_string(10.0 / tarmac::test::kTimeScale),
             "--idle-s", std::to_string(2 * tarmac::test::kTimeScale), "--head-scans",
             std::to_string(kHeadScans), "--tail-scans", std::to_string(kTailScans), "--json",
             (dir / "replay.json").string()},
            dir / "replay.log", {{"CYCLONEDDS_URI", uri}});
  EXPECT_EQ(wait_exit(client, tarmac::test::kTimeScale * 120s), 0) << read_text(dir / "replay.log");
  kill(daemon, SIGTERM);
  EXPECT_EQ(wait_exit(daemon, 20s), 0);
  out.daemon_log = read_text(dir / "tarmacd.log");
  const std::string json = read_text(dir / "replay.json");
  out.sent = static_cast<long>(json_number(json, "scans_sent"));
  out.lost = json_number(json, "transport_lost");
  out.rejected = json_number(json, "transport_rejected");
  out.overflow = json_number(json, "queue_overflow");
  out.p50_ms = json_number(json, "p50");
  out.p99_ms = json_number(json, "p99");
  out.first_back = json_number(json, "first_scan_back");
  std::smatch m;
  if (std::regex_search(out.daemon_log, m, std::regex("(\\d+) scans integrated"))) {
    out.integrated = std::stol(m[1].str());
  }
  EXPECT_GT(json_number(json, "bytes_per_cloud"), 900e3) << "the clouds must be real-size";
  std::printf(
      "sent %ld, integrated %ld, lost %.0f, rejected %.0f, overflow %.0f; scan stamp -> "
      "costmap received p50 %.1f ms, p99 %.1f ms\n",
      out.sent, out.integrated, out.lost, out.rejected, out.overflow, out.p50_ms, out.p99_ms);
  fs::remove_all(dir);
  return out;
}

class CycloneClient : public tarmac::test::LoopbackOnly {
 protected:
  CycloneClient() { expect_loopback_traffic_ = true; }
};

TEST_F(CycloneClient, RealSizeCloudsOverUdp_NoneLostInTransport) {
  const Outcome o = run(tarmac::test::kDomainCycloneUdpClouds, 0);
  ASSERT_EQ(o.sent, kHeadScans + kScans + kTailScans);
  // Nothing lost in transport (≤ 1 %, the bar), and every scan sent either integrated
  // or counted: lost or refused on the way, or shed from a full input queue by a stalled cycle
  // (late ones are taken: see the config above).
  EXPECT_LE(o.lost + o.rejected, 0.01 * static_cast<double>(o.sent)) << o.daemon_log;
  EXPECT_GE(static_cast<double>(o.integrated) + o.lost + o.rejected + o.overflow,
            static_cast<double>(o.sent))
      << o.daemon_log;
  EXPECT_GT(o.p50_ms, 0.0) << "no costmap reached the Cyclone subscriber";
}

TEST_F(CycloneClient, TinyReceiveBuffer_LostScansAreCounted) {
  const Outcome o = run(tarmac::test::kDomainCycloneTinyBuffer, 65536);
  ASSERT_EQ(o.sent, kHeadScans + kScans + kTailScans);
  ASSERT_GE(o.integrated, 0) << o.daemon_log;
  EXPECT_LT(o.integrated, kScans) << "a 64 KiB buffer should not hold 900 KB clouds";
  // Every scan sent and not integrated is counted as a transport loss, except those lost before
  // the first one DDS delivered: a reader counts a loss as a gap in the writer's sequence numbers
  // after a sample it has, and has no reference before. The short head scan (one datagram) gives
  // it that reference even when no big cloud gets through (a slow receiver, e.g. under a
  // sanitizer); the short tail scans arrive and show the gaps at the end; only a loss among the
  // last of them could stay unseen.
  const double missing = static_cast<double>(o.sent - o.integrated);
  ASSERT_GE(o.first_back, 0.0) << "no scan came back in a costmap";
  EXPECT_GE(o.lost + o.rejected, missing - o.first_back - 1.0)
      << "lost " << o.lost << ", rejected " << o.rejected << ", missing " << missing
      << ", first scan back " << o.first_back << "\n"
      << o.daemon_log;
  EXPECT_NE(o.daemon_log.find("lost and"), std::string::npos) << "the loss must be logged";
}

}  // namespace
