// tarmacd's costmaps as a planner receives them, scored against the simulator's ground truth:
// tarmac-sim writes a short loop round the parked aircraft, tarmac-replay publishes it over
// loopback DDS into tarmacd (the shipped defaults), tarmac-audit --score scores every costmap it
// receives, and tarmac-map maps the same sequence offline with the same config. Every costmap
// scored over DDS must carry a scan's stamp, none may show a seen obstacle column free, and, when
// tarmacd integrated every scan, each has the figures of tarmac-map's costmap after that scan.
// The short version of tools/safety-dds.sh.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "child_process.hpp"
#include "loopback_only.hpp"
#include "test_env.hpp"

namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr int kScans = 40;

std::string read_text(const fs::path& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

using tarmac::test::spawn;
using tarmac::test::wait_exit;

bool wait_for_line(const fs::path& log, const std::string& text, std::chrono::seconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (read_text(log).find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(50ms);
  }
  return false;
}

/// The number `json`[section][key], or -1 (none, or `json` is not JSON).
double json_number(const std::string& json, const std::string& section, const std::string& key) {
  const auto j = nlohmann::json::parse(json, nullptr, false);  // not JSON: a discarded value
  const auto s = j.is_object() ? j.find(section) : j.end();
  if (s == j.end() || !s->is_object()) return -1.0;
  const auto v = s->find(key);
  return v != s->end() && v->is_number() ? v->get<double>() : -1.0;
}

using CycleFigures = std::array<long, 8>;  ///< safety_json's cycle_fields, scan first

/// The "per_cycle" arrays of the "safety" object, in order.
std::vector<CycleFigures> per_cycle(const std::string& json) {
  std::vector<CycleFigures> cycles;
  const auto j = nlohmann::json::parse(json, nullptr, false);
  if (!j.is_object() || !j.contains("safety")) return cycles;
  for (const auto& row : j["safety"].value("per_cycle", nlohmann::json::array())) {
    cycles.push_back(row.get<CycleFigures>());
  }
  return cycles;
}

class SafetyDds : public tarmac::test::LoopbackOnly {
 protected:
  SafetyDds() { expect_loopback_traffic_ = true; }
};

TEST_F(SafetyDds, AircraftLoop_CostmapsOverDdsScoredLikeTarmacMap) {
  const fs::path dir =
      fs::temp_directory_path() / ("tarmac_safety_dds_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path data = dir / "sim";
  ASSERT_EQ(wait_exit(spawn({TARMAC_SIM, "--out", data.string(), "--scene", "aircraft", "--beams",
                             "16", "--scans", std::to_string(kScans)},
                            dir / "sim.log"),
                      120s),
            0)
      << read_text(dir / "sim.log");
  const fs::path config = dir / "tarmac.yaml";
  // Slow motion under a sanitizer (test_env.hpp): the shipped timing, the replay's rate and its
  // stamps' grid, the audit's idle time and every wait, all by kTimeScale.
  constexpr int kS = tarmac::test::kTimeScale;
  {
    // The shipped defaults (identity extrinsic: the "base" is the sensor), own domain and state;
    // the shipped timing in slow motion under a sanitizer, the input taken however late: the
    // replay is paced by tarmacd's costmaps (below), so that tarmacd integrates every scan
    // however busy the machine, and a late scan (stamp unchanged) must still count.
    const auto timing = tarmac::test::scaled_timing_yaml(true);
    std::ofstream out(config);
    out << "version: 1\ndds: {domain_id: " << tarmac::test::kDomainSafetyDds << "}\n"
        << "executor: {realtime_priority: 0, lock_memory: false" << timing.executor_keys << "}\n"
        << timing.sections << "state: {dir: " << (dir / "state").string()
        << ", save_on_exit: false}\n";
  }
  const pid_t daemon = spawn({TARMAC_TARMACD, "--config", config.string()}, dir / "tarmacd.log");
  ASSERT_TRUE(wait_for_line(dir / "tarmacd.log", "tarmacd: ready", tarmac::test::kPatience))
      << read_text(dir / "tarmacd.log");
  const pid_t audit = spawn({TARMAC_AUDIT, "--config", config.string(), "--score", data.string(),
                             "--idle-s", std::to_string(10 * kS), "--timeout-s",
                             std::to_string(120 * kS), "--json", (dir / "audit.json").string()},
                            dir / "audit.log");
  EXPECT_TRUE(wait_for_line(dir / "audit.log", "tarmac-audit: matched", tarmac::test::kPatience));
  const int replay_rc = wait_exit(
      spawn({TARMAC_REPLAY, "--dataset", data.string(), "--config", config.string(), "--rate-scale",
             std::to_string(1.0 / kS), "--align-ms", std::to_string(100 * kS), "--pose-readers",
             "2", "--pace-costmap", "2", "--pace-patience-s", std::to_string(60 * kS)},
            dir / "replay.log"),
      kS * 120s);
  const int audit_rc = wait_exit(audit, kS * 60s);
  kill(daemon, SIGTERM);
  EXPECT_EQ(wait_exit(daemon, 20s), 0) << read_text(dir / "tarmacd.log");
  ASSERT_EQ(replay_rc, 0) << read_text(dir / "replay.log");
  ASSERT_EQ(audit_rc, 0) << read_text(dir / "audit.log");
  ASSERT_EQ(wait_exit(spawn({TARMAC_MAP, "--dataset", data.string(), "--config", config.string(),
                             "--sensor-height", "0", "--out", (dir / "offline").string()},
                            dir / "offline.log"),
                      120s),
            0)
      << read_text(dir / "offline.log");

  const std::string audit_log = read_text(dir / "audit.log");
  const std::string daemon_log = read_text(dir / "tarmacd.log");
  const std::string dds = read_text(dir / "audit.json");
  const std::string offline = read_text(dir / "offline" / "timing.json");
  fs::remove_all(dir);
  if (const auto at = audit_log.find("safety ("); at != std::string::npos) {
    std::printf("%s", audit_log.substr(at).c_str());
  }

  // Every scan's stamp was learnt, and every costmap carries one of them (the newest scan
  // integrated), so none is scored against a scan it may not hold yet.
  EXPECT_EQ(json_number(dds, "scored", "scans_stamped"), kScans) << audit_log;
  EXPECT_EQ(json_number(dds, "scored", "stamp_not_a_scan"), 0.0) << audit_log;
  EXPECT_EQ(json_number(dds, "scored", "before_first_scan"), 0.0) << audit_log;
  // At 10 Hz a costmap per scan is the rule; under the suite's load a cycle may take two.
  EXPECT_GE(json_number(dds, "scored", "costmaps"), kScans / 2) << audit_log;
  // What must hold in every cycle: no seen obstacle column reads free.
  EXPECT_EQ(json_number(dds, "safety", "read_free"), 0.0) << audit_log;

  // Cycle by cycle against tarmac-map's costmap after the same scan: the daemon integrated
  // every scan (the replay went at its pace), so its maps are tarmac-map's.
  const auto dds_cycles = per_cycle(dds);
  const auto offline_cycles = per_cycle(offline);
  ASSERT_EQ(offline_cycles.size(), static_cast<std::size_t>(kScans)) << offline;
  ASSERT_EQ(dds_cycles.size(), static_cast<std::size_t>(json_number(dds, "scored", "costmaps")));
  std::smatch m;
  const bool all_integrated =
      std::regex_search(daemon_log, m, std::regex("(\\d+) scans integrated")) &&
      std::stol(m[1].str()) == kScans;
  ASSERT_TRUE(all_integrated) << "tarmacd did not integrate all " << kScans << " scans\n"
                              << daemon_log;
  for (const CycleFigures& c : dds_cycles) {
    ASSERT_GE(c[0], 0);
    ASSERT_LT(c[0], kScans);
    EXPECT_EQ(c, offline_cycles[static_cast<std::size_t>(c[0])]) << "scan " << c[0];
  }
}

}  // namespace
