// Counts heap allocations made on the executor's threads (executor + workers) per tick, with
// scans flowing, after warm-up, and attributes each one by its call stack to its owner: tarmac's
// daemon/transport code ("ours") and the mapping core (both must be zero), Fast DDS, or other. Its
// own binary: it replaces the global operator new.

#include <cxxabi.h>
#include <execinfo.h>

#include <array>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <new>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "executor_harness.hpp"
#include "rtps_sniffer.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/tools/kitti.hpp"
#include "test_env.hpp"

namespace {

thread_local bool t_counted = false;
thread_local bool t_in_backtrace = false;
std::atomic<std::uint64_t> g_allocations{0};
std::atomic<bool> g_recording{false};

constexpr std::size_t kMaxStacks = 4096;
constexpr int kDepth = 24;
struct Stack {
  void* frames[kDepth];
  int depth;
};
std::array<Stack, kMaxStacks> g_stacks;
std::atomic<std::size_t> g_n_stacks{0};

void* counted_malloc(std::size_t size, std::size_t align = 0) {
  if (t_counted) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    if (g_recording.load(std::memory_order_relaxed) && !t_in_backtrace) {
      const std::size_t i = g_n_stacks.fetch_add(1);
      if (i < kMaxStacks) {
        t_in_backtrace = true;
        g_stacks[i].depth = backtrace(g_stacks[i].frames, kDepth);
        t_in_backtrace = false;
      }
    }
  }
  void* p = nullptr;
  if (align > alignof(std::max_align_t)) {
    if (posix_memalign(&p, align, size == 0 ? 1 : size) != 0) p = nullptr;
  } else {
    p = std::malloc(size == 0 ? 1 : size);
  }
  if (p == nullptr) throw std::bad_alloc();
  return p;
}

}  // namespace

// NOLINTBEGIN(misc-new-delete-overloads): counting replacements of the global allocation functions
// GCC's -Wmismatched-new-delete takes `new` for the library's operator new even when it is replaced
// here by malloc, and flags the matching free() once inlining reaches it (seen at -O1, the
// sanitizer builds): a false positive for replaced allocation functions.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  return counted_malloc(n);
}
void* operator new[](std::size_t n) {
  return counted_malloc(n);
}
void* operator new(std::size_t n, std::align_val_t a) {
  return counted_malloc(n, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t n, std::align_val_t a) {
  return counted_malloc(n, static_cast<std::size_t>(a));
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_malloc(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_malloc(n);
  } catch (...) {
    return nullptr;
  }
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete(void* p, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept {
  std::free(p);
}
#pragma GCC diagnostic pop
// NOLINTEND(misc-new-delete-overloads)

namespace tarmac::daemon {
namespace {

using namespace std::chrono_literals;

/// Owner of an allocation: the innermost named frame that is not the allocator or the standard
/// library (frames without a name, e.g. internal-linkage functions, are skipped).
std::string owner_of(const Stack& stack, std::string& where) {
  char** symbols = backtrace_symbols(stack.frames, stack.depth);
  std::string owner = "other";
  bool unnamed_before = false;
  for (int f = 0; f < stack.depth && symbols != nullptr; ++f) {
    const std::string text = symbols[f];
    const auto open = text.find('(');
    const auto plus = text.find('+', open);
    if (open == std::string::npos || plus == std::string::npos || plus == open + 1) {
      unnamed_before = true;
      continue;
    }
    const std::string mangled = text.substr(open + 1, plus - open - 1);
    int status = 0;
    char* demangled = abi::__cxa_demangle(mangled.c_str(), nullptr, nullptr, &status);
    const std::string name = status == 0 && demangled != nullptr ? demangled : mangled;
    std::free(demangled);
    // A std::function invoking a core or Fast DDS callable belongs to that callable.
    if (name.rfind("std::", 0) == 0 && name.find("tarmac::core::") != std::string::npos) {
      where = name.substr(0, 120);
      owner = "core";
      break;
    }
    if (name.rfind("std::", 0) == 0 && name.find("eprosima::") != std::string::npos) {
      where = name.substr(0, 120);
      owner = "fastdds";
      break;
    }
    // "backtrace": under a sanitizer the stack starts in its interceptor of backtrace().
    if (name.rfind("std::", 0) == 0 || name.rfind("operator new", 0) == 0 ||
        name.rfind("__gnu_cxx", 0) == 0 || name.find("counted_malloc") != std::string::npos ||
        name == "malloc" || name == "backtrace") {
      continue;
    }
    where = name.substr(0, 120);
    if (name.rfind("tarmac::daemon::ThreadPool::", 0) == 0 && unnamed_before) {
      // Inside a pool task (an internal-linkage lambda has no exported name). The executor
      // hands its pool to the core only, so the task is the core's.
      owner = "core";
    } else if (name.rfind("tarmac::core::", 0) == 0) {
      owner = "core";
    } else if (name.rfind("eprosima::", 0) == 0) {
      owner = "fastdds";
    } else if (name.rfind("tarmac::", 0) == 0) {
      owner = "ours";
    }
    break;
  }
  std::free(symbols);  // NOLINT(cppcoreguidelines-no-malloc): backtrace_symbols' contract
  return owner;
}

struct TickSample {
  std::uint64_t allocations = 0;
  std::uint64_t scans = 0;
};

TEST(Allocations, SteadyStateTicks_AllocateNothingOnTheExecutorThreads) {
  auto sniffer = test::RtpsSniffer::start();
  TARMAC_REQUIRE_OR_SKIP(sniffer.ok(), "packet capture unavailable");
  const auto dir =
      std::filesystem::temp_directory_path() / ("tarmac-alloc-test-" + std::to_string(::getpid()));
  sim::SequenceParams sp;
  sp.scans = 40;
  sp.lidar.beams = 16;
  sp.lidar.azimuth_steps = 512;
  ASSERT_TRUE(sim::write_sequence(sim::Scene::airside_default(), sp, dir).ok());
  auto seq = tools::open_kitti(dir);
  ASSERT_TRUE(seq.ok());

  config::Config cfg;
  cfg.dds.participant.domain_id = test::kDomainDaemonAllocations;
  cfg.dds.qos.lidar = {transport::Reliability::kReliable, transport::Durability::kVolatile, 8};
  cfg.executor.workers = 2;
  cfg.executor.realtime_priority = 0;
  cfg.executor.lock_memory = false;
  cfg.mapping.occupancy.window_x_vox = 200;
  cfg.mapping.occupancy.window_y_vox = 200;
  cfg.mapping.occupancy.window_z_vox = 30;
  cfg.state.save_on_exit = false;
  // Without the TSDF stage: its allocations are OpenVDB leaf growth over the whole site (excepted
  // by DESIGN.md §3, thousands per tick while the map grows) and would swamp the stack record;
  // the executor's side of that stage is one call into the core.
  cfg.mapping.tsdf.enabled = false;
  // With the 3D ESDF band and its publication: fixed shape, reserved on the first cycle.
  cfg.mapping.esdf_band.enabled = true;
  test::scale_time(cfg);  // slow motion under a sanitizer: one scan per tick as in the normal build
  test::take_late_input(cfg);  // paced below: every scan integrated on a loaded machine too
  auto created = Executor::create(cfg);
  ASSERT_TRUE(created.ok()) << created.error().message;
  Executor& executor = *created.value();

  static std::array<TickSample, 1024> samples;
  static std::atomic<std::size_t> n_samples{0};
  std::atomic<bool> stop{false};
  RunHooks hooks;
  hooks.on_thread_start = [] { t_counted = true; };
  static std::atomic<int> ticks_with_scans{0};
  hooks.on_tick_end = [&executor](std::uint64_t) {
    const std::size_t i = n_samples.load();
    const std::uint64_t scans = executor.totals().scans_integrated;
    if (i > 0 && scans != samples[i - 1].scans && ++ticks_with_scans == 10) {
      g_recording = true;  // warm-up over: record the stacks of what follows
    }
    if (i < samples.size()) {
      samples[i] = {g_allocations.load(), scans};
      n_samples.store(i + 1);
    }
  };
  {
    void* warm[4];
    backtrace(warm, 4);  // loads libgcc's unwinder now, not inside the counted section
  }
  std::thread runner([&] { executor.run([&] { return stop.load(); }, hooks); });

  transport::ParticipantConfig pc;
  pc.domain_id = test::kDomainDaemonAllocations;
  auto participant = transport::Participant::create(pc);
  ASSERT_TRUE(participant.ok());
  tools::ReplayOptions options;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.rate_scale = 1.0 / test::kTimeScale;
  // Each scan sent once the one before is integrated: one scan per tick, however busy the
  // machine, so the 40 scans make 40 ticks with a scan.
  options.pace = test::paced_by(executor, 1);
  auto stats = tools::replay(participant.value(), seq.value(), options);
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  EXPECT_TRUE(test::eventually([&] { return executor.totals().scans_integrated >= 40; }));
  g_recording = false;
  stop = true;
  runner.join();
  std::filesystem::remove_all(dir);

  // Ticks that integrated a scan, after the first 10 such ticks (warm-up: capacities grow).
  std::uint64_t steady_ticks = 0, steady_allocations = 0, worst = 0;
  int with_scans = 0;
  for (std::size_t i = 1; i < n_samples.load(); ++i) {
    if (samples[i].scans == samples[i - 1].scans) continue;
    if (++with_scans <= 10) continue;
    const std::uint64_t a = samples[i].allocations - samples[i - 1].allocations;
    ++steady_ticks;
    steady_allocations += a;
    worst = std::max(worst, a);
  }
  std::printf(
      "steady-state ticks with scans: %llu, allocations on executor threads: %llu "
      "(worst tick %llu)\n",
      static_cast<unsigned long long>(steady_ticks),
      static_cast<unsigned long long>(steady_allocations), static_cast<unsigned long long>(worst));
  ASSERT_GE(steady_ticks, 20u);
  // Every allocation recorded after warm-up, by owner (the stacks cover the same ticks and the
  // idle ticks between them).
  std::map<std::string, std::uint64_t> by_owner;
  std::map<std::string, std::uint64_t> ours_where;
  const std::size_t recorded = std::min(g_n_stacks.load(), kMaxStacks);
  for (std::size_t i = 0; i < recorded; ++i) {
    std::string where;
    const std::string owner = owner_of(g_stacks[i], where);
    ++by_owner[owner];
    ++ours_where[owner + ": " + where];
  }
  for (const auto& [owner, n] : by_owner) {
    std::printf("  %-8s %llu\n", owner.c_str(), static_cast<unsigned long long>(n));
  }
  for (const auto& [where, n] : ours_where) {
    std::printf("    %llu x %s\n", static_cast<unsigned long long>(n), where.c_str());
  }
  ASSERT_LT(g_n_stacks.load(), kMaxStacks) << "more allocations than stacks recorded";
  EXPECT_EQ(by_owner["ours"], 0u) << "tarmac's daemon/transport code allocates in the cycle";
  EXPECT_EQ(by_owner["core"], 0u) << "the mapping core allocates in the cycle";
  EXPECT_EQ(by_owner["other"], 0u) << "allocations of unknown owner in the cycle";
}

}  // namespace
}  // namespace tarmac::daemon
