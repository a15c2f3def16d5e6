#pragma once
/// @file POSIX clock reads and absolute sleeps in integer nanoseconds, shared by the executor
/// (CLOCK_MONOTONIC deadlines, CLOCK_REALTIME stamps) and tarmac-replay (CLOCK_REALTIME
/// publish times). RT-safe: no allocation, no locks.

#include <time.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>

namespace tarmac::daemon {

/// The clock's current time, ns.
inline std::int64_t clock_now_ns(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// Sleeps until the clock reads `deadline_ns` (absolute), resuming after signals.
inline void clock_sleep_until_ns(clockid_t clock, std::int64_t deadline_ns) {
  timespec ts{};
  ts.tv_sec = deadline_ns / 1'000'000'000;
  ts.tv_nsec = deadline_ns % 1'000'000'000;
  while (clock_nanosleep(clock, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

/// `ms` milliseconds in nanoseconds, rounded (config durations are given in ms).
inline std::int64_t ms_to_ns(double ms) {
  return static_cast<std::int64_t>(std::llround(ms * 1e6));
}

/// The time from `a` to `b` in milliseconds: for measuring, never for deciding.
inline double ms_between(std::chrono::steady_clock::time_point a,
                         std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

}  // namespace tarmac::daemon
