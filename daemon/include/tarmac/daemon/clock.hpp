#pragma once
/// @file POSIX clock reads and absolute sleeps in integer nanoseconds, shared by the executor
/// (CLOCK_MONOTONIC deadlines, CLOCK_REALTIME stamps) and tarmac-replay (CLOCK_REALTIME
/// publish times). RT-safe: no allocation, no locks.

#include <time.h>

#include <cerrno>
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

}  // namespace tarmac::daemon
