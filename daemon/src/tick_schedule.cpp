#include "tick_schedule.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>

#include "tarmac/daemon/executor.hpp"
#include "tarmac/daemon/realtime.hpp"

namespace tarmac::daemon {

namespace {

constexpr std::int64_t kNsPerMs = 1'000'000;

/// Below this the stamp clock's drift against CLOCK_MONOTONIC is left alone (slew, read noise).
constexpr std::int64_t kClockStepMinNs = 50'000'000;

}  // namespace

bool sleep_until_or_stopped(std::int64_t deadline_ns, const std::function<bool()>& stop_requested) {
  constexpr std::int64_t kSliceNs =
      std::chrono::duration_cast<std::chrono::nanoseconds>(Executor::kStopPollSlice).count();
  while (!stop_requested()) {
    const std::int64_t now = monotonic_ns();
    if (now >= deadline_ns) return true;
    sleep_until_monotonic(std::min(deadline_ns, now + kSliceNs));
  }
  return false;
}

core::Status check_schedule(const config::ExecutorConfig& e) {
  if (!std::isfinite(e.rate_hz) || e.rate_hz < config::kMinRateHz ||
      e.rate_hz > config::kMaxRateHz) {
    return core::Error{"config.range",
                       fmt::format("executor.rate_hz: must be a finite number in [{}, {}], got {}",
                                   config::kMinRateHz, config::kMaxRateHz, e.rate_hz)};
  }
  const std::pair<const char*, double> ms[] = {{"executor.input_delay_ms", e.input_delay_ms},
                                               {"executor.pose_wait_ms", e.pose_wait_ms},
                                               {"executor.max_future_ms", e.max_future_ms},
                                               {"executor.sensor_phase_ms", e.sensor_phase_ms}};
  for (const auto& [key, value] : ms) {
    if (!std::isfinite(value) || value < 0.0 || value > 3.6e6) {
      return core::Error{
          "config.range",
          fmt::format("{}: must be a finite number in [0, 3600000], got {}", key, value)};
    }
  }
  return core::Ok{};
}

std::int64_t clock_step_ns(std::int64_t drift_ns, std::int64_t period_ns) {
  if (std::abs(drift_ns) < std::max(kClockStepMinNs, period_ns / 2)) return 0;
  const std::int64_t half = drift_ns >= 0 ? period_ns / 2 : -period_ns / 2;
  return (drift_ns + half) / period_ns * period_ns;
}

void warn_if_watchdog_too_short(std::int64_t period_ns) {
  std::uint64_t watchdog_us = 0;
  if (sd_watchdog_enabled(0, &watchdog_us) <= 0) return;
  if (2 * period_ns > static_cast<std::int64_t>(watchdog_us) * 1000) {
    spdlog::warn(
        "executor: the period ({} ms) is more than half the systemd watchdog interval ({} ms), "
        "which is pinged once per tick: raise WatchdogSec= or executor.rate_hz",
        period_ns / kNsPerMs, watchdog_us / 1000);
  }
}

void raise_dds_threads(const config::ExecutorConfig& e, const std::vector<int>& dds_threads) {
  if (e.realtime_priority < 2 || dds_threads.empty()) return;
  const int priority = e.realtime_priority - 1;
  std::size_t raised = 0;
  std::string why;
  for (const int tid : dds_threads) {
    const int err = set_thread_fifo_priority(tid, priority);
    if (err == 0) {
      ++raised;
    } else if (err != ESRCH) {  // a thread that has ended since is no failure
      why = std::string("sched_setscheduler(SCHED_FIFO): ") + std::strerror(err);
    }
  }
  if (why.empty()) {
    spdlog::info("executor: {} DDS thread(s) at SCHED_FIFO priority {} (below the cycle's {})",
                 raised, priority, e.realtime_priority);
  } else {
    spdlog::warn(
        "executor: DDS threads left at their priority ({}); under load they may delay "
        "ticks",
        why);
  }
}

std::unique_ptr<ThreadPool> real_time_setup(const config::ExecutorConfig& e,
                                            const std::function<void()>& on_thread_start) {
  if (!e.cpus.empty()) {
    if (auto why = pin_current_thread(e.cpus[0]); !why.empty()) {
      spdlog::warn("executor: pinning to CPU {} refused ({}); running unpinned", e.cpus[0], why);
    }
  }
  if (e.realtime_priority > 0) {
    if (auto why = set_fifo_priority(e.realtime_priority); !why.empty()) {
      spdlog::warn("executor: SCHED_FIFO priority {} refused ({}); running SCHED_OTHER",
                   e.realtime_priority, why);
    } else {
      spdlog::info("executor: SCHED_FIFO priority {} (workers inherit it)", e.realtime_priority);
    }
  }
  if (e.lock_memory) {
    // Heap faulted in for the first cycles: a queue of deserialised 64-beam scans (~1.3 MB
    // each) and the outgoing grids fit several times over.
    constexpr std::size_t kHeapReserveBytes = std::size_t{32} << 20;
    if (auto why = lock_all_memory(kHeapReserveBytes); !why.empty()) {
      spdlog::warn("executor: memory lock refused ({}); pages may fault in the cycle", why);
    } else {
      spdlog::info("executor: all memory locked (mlockall)");
    }
  }
  std::vector<int> worker_cpus;
  for (std::uint32_t i = 1; i < e.workers && !e.cpus.empty(); ++i) {
    worker_cpus.push_back(e.cpus[i % e.cpus.size()]);
  }
  auto pool = std::make_unique<ThreadPool>(e.workers, worker_cpus, on_thread_start);
  if (pool->pin_failures() > 0) {
    spdlog::warn("executor: {} of {} workers could not be pinned; they run unpinned",
                 pool->pin_failures(), worker_cpus.size());
  }
  return pool;
}

}  // namespace tarmac::daemon
