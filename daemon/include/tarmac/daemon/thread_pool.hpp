#pragma once
/// @file A fixed pool of worker threads implementing core::TaskRunner. Workers are created once
/// (optionally pinned to CPUs) and reused every cycle; parallel_for hands out task indices and
/// waits for all of them. Which thread runs which task never changes a result: core stages write
/// disjoint data per task (DESIGN.md §3).

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
  [[nodiscard]] std::size_t concurrency() const override { return workers_.size() + 1; }

  /// Number of workers whose CPU pinning failed (0 when none requested).
  [[nodiscard]] std::size_t pin_failures() const { return pin_failures_; }

 private:
  void work_loop();
  void drain(std::unique_lock<std::mutex>& lock);

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_, done_;
  const core::TaskFn* job_ = nullptr;
  std::size_t count_ = 0, next_ = 0, finished_ = 0;
  std::uint64_t generation_ = 0;
  bool stop_ = false;
  std::size_t pin_failures_ = 0;
};

}  // namespace tarmac::daemon
