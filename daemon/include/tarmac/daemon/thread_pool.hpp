#pragma once
/// @file A fixed pool of worker threads implementing core::TaskRunner. Workers are created once
/// (optionally pinned to CPUs) and reused every cycle; parallel_for hands out task indices and
/// waits for all of them. Which thread runs which task never changes a result: core stages write
/// disjoint data per task (DESIGN.md §3).
///
/// Waking a sleeping thread takes 20–40 µs on the project's VMs, as long as a 4-task stage of
/// short tasks runs serially, and a stage calls parallel_for several times in a row. So a worker
/// that has finished its tasks, and the caller waiting for the last task, first poll for up to
/// kSpin before sleeping on the condition variable: back-to-back calls within a stage never
/// sleep; between cycles each thread sleeps after kSpin. wake() lets a caller that knows when
/// its next cycle starts (the executor's tick) have the workers up and polling by then.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "tarmac/core/task_runner.hpp"

namespace tarmac::daemon {

class ThreadPool final : public core::TaskRunner {
 public:
  /// @param threads total concurrency including the calling thread (>= 1); threads − 1 workers
  ///        are started. @param cpus optional CPU per worker for pinning (logged by the caller).
  /// @param on_worker_start runs first on each worker thread (instrumentation, e.g. tests).
  explicit ThreadPool(std::size_t threads, const std::vector<int>& cpus = {},
                      const std::function<void()>& on_worker_start = {});
  ~ThreadPool() override;
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  void parallel_for(std::size_t count, core::TaskFn fn) override;

  /// Wakes sleeping workers without giving them work: they poll for kSpin, so a parallel_for
  /// within that time starts on every thread at once instead of waiting for the wake-up (the
  /// first call of a cycle otherwise ran on the calling thread alone for tens of µs). Returns at
  /// once. Call it from the thread that calls parallel_for, not during a call.
  void wake();
  [[nodiscard]] std::size_t concurrency() const override { return workers_.size() + 1; }

  /// Number of workers whose CPU pinning failed (0 when none requested).
  [[nodiscard]] std::size_t pin_failures() const { return pin_failures_; }

  /// How long a thread polls for new work (worker) or for the last task (caller) before it
  /// sleeps.
  static constexpr std::chrono::microseconds kSpin{200};
  /// How long before a cycle its caller wakes the workers: past the 20–40 µs a wake-up takes,
  /// well within kSpin.
  static constexpr std::chrono::microseconds kWakeLead{100};

 private:
  void work_loop();
  void drain(std::unique_lock<std::mutex>& lock);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  const core::TaskFn* job_ = nullptr;
  std::size_t count_ = 0, next_ = 0;
  // Written under mutex_; atomic so that the polling threads can read them without it.
  std::atomic<std::size_t> finished_{0};
  std::atomic<std::uint64_t> generation_{0};
  std::atomic<bool> stop_{false};
  std::size_t pin_failures_ = 0;
};

}  // namespace tarmac::daemon
