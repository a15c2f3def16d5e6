#pragma once
// What every tarmac test needs from its environment: distinct DDS domains, the data folder, and
// the CI rule that a missing prerequisite is a failure under CI=true and a skip elsewhere.

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include <gtest/gtest.h>

namespace tarmac::test {

/// One DDS domain per test that uses DDS, so ctest -j never cross-talks. Add new ones here.
enum Domain : std::uint32_t {
  kDomainLoopbackCloud = 110,
  kDomainLoopbackGrid = 111,
  kDomainReaderQueue = 112,
  kDomainSharedMemoryOnly = 113,
  kDomainCycloneInterop = 114,
  kDomainConfinement = 115,
  kDomainLoopbackPath = 120,
  kDomainDiscoveryServer = 121,  // and UDP port 24121 for its server
  // DDS Security (tests/transport/security_test.cpp): 116..119
  kDomainSecurityExchange = 116,
  kDomainSecurityUnauthenticated = 117,
  kDomainSecurityOtherCa = 118,
  kDomainSecurityDenied = 119,
  kDomainSecurityFleet = 122,
  // tarmacd integration tests (tests/daemon/): 130..152
  kDomainDaemonWorkers1 = 130,
  kDomainDaemonWorkers2 = 131,
  kDomainDaemonWorkers4 = 132,
  kDomainDaemonJitter = 133,
  kDomainDaemonNoPose = 134,
  kDomainDaemonOverrun = 135,
  kDomainDaemonProcess = 136,
  kDomainDaemonAllocations = 137,
  kDomainDaemonZones = 138,
  kDomainDaemonStateLoad = 139,
  kDomainDaemonStateRefuse = 140,
  kDomainDaemonTsdfShed = 141,
  kDomainDaemonPeriodicSave = 142,
  kDomainDaemonSecurity = 143,
  kDomainDaemonPoseJump = 144,
  kDomainDaemonPathCorrection = 145,
  kDomainDaemonPathEarly = 146,
  kDomainDaemonEsdfBand = 147,
  // Stopping and the watchdog (tests/daemon/executor_stop_test.cpp, tarmacd_process_test.cpp)
  kDomainDaemonWatchdogStall = 148,
  kDomainDaemonStopAsleep = 149,
  kDomainDaemonStopStartup = 150,
  kDomainDaemonStopReady = 151,
  kDomainDaemonStopSlowRate = 152,
  kDomainDaemonPaging = 153,
  kDomainDaemonLayoutRing = 154,
  kDomainDaemonLayoutElevation = 155,
  kDomainDaemonLayoutList = 156,
  kDomainDaemonLayoutDriver = 157,
  kDomainDaemonDebris = 158,
  // Outside clients on Cyclone DDS over UDP (tests/daemon/cyclone_client_test.cpp): 160..169
  kDomainCycloneUdpClouds = 160,
  kDomainCycloneTinyBuffer = 161,
  // Fault injection (tests/daemon/fault_injection_test.cpp, tarmacd_process_test.cpp) and the
  // short soak: 170..179
  kDomainFaultLidarStops = 170,
  kDomainFaultPoseStops = 171,
  kDomainFaultClockAhead = 172,
  kDomainFaultClockBack = 173,
  kDomainFaultOverload = 174,
  kDomainFaultKill = 175,
  kDomainSoakShort = 176,
  kDomainFaultSensorAhead = 177,
  // tarmacd's costmaps over DDS scored against the simulator's truth
  // (tests/daemon/safety_dds_test.cpp): 180..189
  kDomainSafetyDds = 180,
  // Fleet sharing between executors (tests/daemon/fleet_test.cpp): 190..199
  kDomainFleetTwoVehicles = 190,
  kDomainFleetExpiry = 191,
  kDomainFleetSiteView = 192,
};

/// How many times slower than the normal build this build runs: 1, or more under a sanitizer
/// (tools/sanitize.sh: ASan + UBSan, or TSan). Tests that run tarmacd against the clock play the
/// same inputs in slow motion by this factor — rates divided, periods, waits, ages and budgets
/// multiplied — and assert the same things; without it a sanitized tick outlasts its period and
/// the test measures the machine, not tarmac.
/// A power of two, so that stamps scaled by it stay exact.
#if defined(__SANITIZE_THREAD__)
inline constexpr int kTimeScale = 16;
#elif defined(__SANITIZE_ADDRESS__)
inline constexpr int kTimeScale = 8;
#else
inline constexpr int kTimeScale = 1;
#endif

/// What the sanitizer adds to every exit of a multi-threaded process (each tarmac process is
/// one from its start: OpenVDB's log4cplus starts a thread pool as it loads): TSan sleeps
/// atexit_sleep_ms, 1 s by default, before the process ends, so that threads still running can
/// show their races. Tests that time a process's exit add it; what tarmac does must still fit
/// the unchanged bound.
#if defined(__SANITIZE_THREAD__)
inline constexpr std::chrono::milliseconds kExitDelay{1000};
#else
inline constexpr std::chrono::milliseconds kExitDelay{0};
#endif

/// For a tarmacd process: the shipped timing in slow motion by kTimeScale, as YAML. Both parts
/// are empty when kTimeScale is 1 (the shipped values apply) and `late_input` is false.
/// `late_input`: the process takes input however late it comes (scans stale only after a
/// minute, a pose waited for up to 10 s), for tests that pace their input by what it
/// acknowledged (tarmac-replay --pace-costmap): on a busy machine such input arrives late,
/// stamps unchanged (docs/testing.md, "The suite under load").
struct ScaledTimingYaml {
  /// ", rate_hz: …, input_delay_ms: …, pose_wait_ms: …, max_future_ms: …": to go inside
  /// `executor: {…}` after its other keys.
  std::string executor_keys;
  /// Whole sections: one sensor `front` with its max_age_ms, `pose` ages and the cycle budget.
  std::string sections;
};

inline ScaledTimingYaml scaled_timing_yaml(bool late_input = false) {
  ScaledTimingYaml y;
  if (kTimeScale == 1 && !late_input) return y;
  const auto num = [](double v) { return std::to_string(v * kTimeScale); };
  y.executor_keys = ", rate_hz: " + std::to_string(10.0 / kTimeScale) +
                    ", input_delay_ms: " + num(20.0) +
                    ", pose_wait_ms: " + (late_input ? std::string("10000") : num(100.0)) +
                    ", max_future_ms: " + num(200.0);
  y.sections =
      "sensors: [{id: front, max_age_ms: " + (late_input ? std::string("60000") : num(500.0)) +
      "}]\n" + "pose: {max_gap_ms: " + num(250.0) + ", max_age_ms: " + num(1000.0) + "}\n" +
      "budgets: {cycle_ms: " + num(90.0) + "}\n";
  return y;
}

/// How long a test waits for an event that must come: long enough that only a hang or a defect
/// reaches it, whatever else loads the machine. A wait that ends early costs nothing.
inline constexpr std::chrono::seconds kPatience{30 * kTimeScale};

/// Polls `done` every 20 ms until it holds or `patience` has passed; returns its last value.
template <typename Done>
bool eventually(Done&& done, std::chrono::milliseconds patience = kPatience) {
  const auto deadline = std::chrono::steady_clock::now() + patience;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return done();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

inline bool running_in_ci() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

/// ../shared/data unless TARMAC_DATA_DIR says otherwise.
inline std::filesystem::path data_dir() {
  if (const char* env = std::getenv("TARMAC_DATA_DIR"); env != nullptr && *env != '\0') return env;
  return TARMAC_DEFAULT_DATA_DIR;
}

inline std::filesystem::path source_dir() {
  return TARMAC_SOURCE_DIR;
}

}  // namespace tarmac::test

/// A missing prerequisite: a failure under CI=true (CI must run everything), a skip elsewhere.
#define TARMAC_REQUIRE_OR_SKIP(condition, why)              \
  do {                                                      \
    if (!(condition)) {                                     \
      if (::tarmac::test::running_in_ci()) FAIL() << (why); \
      GTEST_SKIP() << (why);                                \
    }                                                       \
  } while (false)
