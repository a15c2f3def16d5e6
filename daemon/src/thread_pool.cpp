#include "tarmac/daemon/thread_pool.hpp"

#include <pthread.h>
#include <sched.h>

namespace tarmac::daemon {

ThreadPool::ThreadPool(std::size_t threads, const std::vector<int>& cpus,
                       const std::function<void()>& on_worker_start) {
  const std::size_t workers = threads > 1 ? threads - 1 : 0;
  workers_.reserve(workers);
  for (std::size_t i = 0; i < workers; ++i) {
    workers_.emplace_back([this, on_worker_start] {
      if (on_worker_start) on_worker_start();
      work_loop();
    });
    if (i < cpus.size()) {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(cpus[i], &set);
      if (pthread_setaffinity_np(workers_.back().native_handle(), sizeof set, &set) != 0) {
        ++pin_failures_;
      }
    }
  }
}

namespace {

/// Polls `done` until it holds or `spin` has passed (the caller then sleeps on its condition).
template <typename Done>
void poll_for(std::chrono::microseconds spin, Done&& done) {
  const auto until = std::chrono::steady_clock::now() + spin;
  for (unsigned k = 1; !done(); ++k) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
    if ((k & 63) == 0) {
      if (std::chrono::steady_clock::now() >= until) return;
      std::this_thread::yield();  // more threads than cores: let the one with work run
    }
  }
}

}  // namespace

ThreadPool::~ThreadPool() {
  {
    std::lock_guard lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  for (auto& t : workers_) t.join();
}

void ThreadPool::drain(std::unique_lock<std::mutex>& lock) {
  // Runs tasks (lock released while running) until none are left to hand out.
  while (next_ < count_) {
    const std::size_t task = next_++;
    const auto* job = job_;
    lock.unlock();
    (*job)(task);
    lock.lock();
    if (++finished_ == count_) done_.notify_all();
  }
}

void ThreadPool::work_loop() {
  std::uint64_t seen = 0;
  std::unique_lock lock(mutex_);
  while (true) {
    if (!stop_ && generation_ == seen) {
      lock.unlock();
      poll_for(kSpin, [&] {
        return stop_.load(std::memory_order_relaxed) ||
               generation_.load(std::memory_order_acquire) != seen;
      });
      lock.lock();
    }
    wake_.wait(lock, [&] { return stop_ || generation_ != seen; });
    if (stop_) return;
    seen = generation_;
    drain(lock);
  }
}

void ThreadPool::wake() {
  if (workers_.empty()) return;
  {
    // A new generation with no tasks (count_ is 0 between calls): each worker wakes, finds
    // nothing to run, and polls for kSpin before sleeping again.
    std::lock_guard lock(mutex_);
    ++generation_;
  }
  wake_.notify_all();
}

void ThreadPool::parallel_for(std::size_t count, core::TaskFn fn) {
  if (count == 0) return;
  if (workers_.empty() || count == 1) {
    for (std::size_t i = 0; i < count; ++i) fn(i);
    return;
  }
  std::unique_lock lock(mutex_);
  job_ = &fn;
  count_ = count;
  next_ = 0;
  finished_ = 0;
  ++generation_;
  wake_.notify_all();
  drain(lock);
  if (finished_ != count_) {
    lock.unlock();
    poll_for(kSpin, [&] { return finished_.load(std::memory_order_acquire) == count; });
    lock.lock();
  }
  done_.wait(lock, [&] { return finished_ == count_; });
  job_ = nullptr;
  count_ = 0;
}

}  // namespace tarmac::daemon
