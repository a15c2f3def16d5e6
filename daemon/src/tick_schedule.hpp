#pragma once
/// @file The executor's schedule (DESIGN.md §3) apart from the tick itself: the checks on the
/// config it is computed from, the sleep to a deadline that still sees a stop, how far a step of
/// the stamp clock moves the ticks, the watchdog's margin, and the real-time setup of the thread
/// that keeps the schedule.

#include <time.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "tarmac/config/config.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/daemon/clock.hpp"
#include "tarmac/daemon/thread_pool.hpp"

namespace tarmac::daemon {

inline std::int64_t monotonic_ns() {
  return clock_now_ns(CLOCK_MONOTONIC);
}

inline std::int64_t realtime_ns() {
  return clock_now_ns(CLOCK_REALTIME);
}

inline void sleep_until_monotonic(std::int64_t deadline_ns) {
  clock_sleep_until_ns(CLOCK_MONOTONIC, deadline_ns);
}

/// Sleeps until `deadline_ns` (CLOCK_MONOTONIC, absolute) in slices of at most
/// Executor::kStopPollSlice, checking `stop_requested` before each; false when it asked to stop.
/// The last slice ends on the deadline itself, so the wake is as precise as one long sleep.
bool sleep_until_or_stopped(std::int64_t deadline_ns, const std::function<bool()>& stop_requested);

/// What the tick schedule is computed from, checked before anything is created: a rate that is
/// not finite (NaN fails every comparison) or a NaN delay would give a loop that never ticks,
/// so it would never see a stop or ping the watchdog either.
core::Status check_schedule(const config::ExecutorConfig& e);

/// How far the tick times must move on the stamp clock when it has drifted `drift_ns` from the
/// offset the ticks were placed with: whole periods (the ticks stay on their grid), once the
/// drift reaches kClockStepMinNs and half a period; otherwise 0.
std::int64_t clock_step_ns(std::int64_t drift_ns, std::int64_t period_ns);

/// A period longer than half the systemd watchdog interval leaves no margin: one late tick and
/// the service is restarted. Said once at start, naming both.
void warn_if_watchdog_too_short(std::int64_t period_ns);

/// Pins the calling thread to `e.cpus[0]`, asks for SCHED_FIFO and mlockall as configured (each
/// refusal logged, never fatal), then starts the worker pool, which inherits the policy.
/// With executor.realtime_priority >= 2, SCHED_FIFO at realtime_priority - 1 for `dds_threads`
/// (Fast DDS's receive, event and discovery threads): above every normal-priority process, below
/// the cycle. Otherwise a busy computer starves them while they hold a lock the cycle's next DDS
/// call needs (a write while a new peer is being matched) and a tick is late. Logged once.
void raise_dds_threads(const config::ExecutorConfig& e, const std::vector<int>& dds_threads);

std::unique_ptr<ThreadPool> real_time_setup(const config::ExecutorConfig& e,
                                            const std::function<void()>& on_thread_start);

}  // namespace tarmac::daemon
