#include "tarmac/daemon/thread_pool.hpp"

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/daemon/realtime.hpp"

namespace tarmac::daemon {
namespace {

/// Runs `calls` parallel_for calls of 1..9 tasks; every task index must run exactly once per
/// call, and the call must not return before all have run.
void expect_each_task_once(ThreadPool& pool, int calls, std::chrono::microseconds pause) {
  std::vector<std::atomic<int>> runs(9);
  for (int c = 0; c < calls; ++c) {
    const std::size_t count = 1 + static_cast<std::size_t>(c % 9);
    for (auto& r : runs) r.store(0);
    pool.parallel_for(count, [&](std::size_t task) {
      std::this_thread::sleep_for(std::chrono::microseconds(task % 3));
      runs[task].fetch_add(1);
    });
    for (std::size_t t = 0; t < runs.size(); ++t) {
      ASSERT_EQ(runs[t].load(), t < count ? 1 : 0) << "call " << c << " task " << t;
    }
    if (pause.count() > 0) std::this_thread::sleep_for(pause);
  }
}

// Back-to-back calls find the workers still polling for work; calls apart by more than the
// polling time find them asleep on the condition variable. Both must run every task once.
TEST(ThreadPool, EveryTaskOnce_BackToBackAndAfterTheWorkersSlept) {
  for (const std::size_t threads : {2u, 3u}) {
    ThreadPool pool(threads);
    expect_each_task_once(pool, 2000, std::chrono::microseconds(0));
    expect_each_task_once(pool, 20, ThreadPool::kSpin * 5);
  }
}

// wake() between calls (once, twice, then a call at once, within the polling time or after the
// workers slept again) hands out no task of its own and loses none of the next call's; a pool
// destroyed right after a wake stops and joins.
TEST(ThreadPool, WakeBetweenCallsLosesNoTask) {
  for (const std::size_t threads : {1u, 2u, 3u}) {
    ThreadPool pool(threads);
    for (int c = 0; c < 300; ++c) {
      if (c % 2 == 0) pool.wake();
      if (c % 3 == 0) pool.wake();
      if (c % 50 == 0) std::this_thread::sleep_for(ThreadPool::kSpin * 3);
      if (c % 7 == 0) std::this_thread::sleep_for(ThreadPool::kWakeLead);
      expect_each_task_once(pool, 1 + c % 4, std::chrono::microseconds(0));
    }
    pool.wake();
  }
  for (int i = 0; i < 50; ++i) {
    ThreadPool pool(2);
    pool.wake();
  }
}

// Pools destroyed right after a call (workers polling) and right after construction (workers
// asleep or not started) stop and join.
TEST(ThreadPool, StopsWhetherWorkersPollOrSleep) {
  for (int i = 0; i < 50; ++i) {
    ThreadPool pool(2);
    if (i % 2 == 0) pool.parallel_for(4, [](std::size_t) {});
  }
  SUCCEED();
}

// How tarmacd finds Fast DDS's threads (those created while its DDS entities are made) and
// raises them below the cycle: a thread started between two listings is found, and only it.
TEST(Realtime, ThreadsSince_FindsTheThreadsStartedInBetween_AndTheyCanBeRaised) {
  const std::vector<int> before = thread_ids();
  ASSERT_FALSE(before.empty());
  EXPECT_TRUE(std::is_sorted(before.begin(), before.end()));
  std::mutex m;
  std::condition_variable cv;
  bool done = false;
  std::thread t([&] {
    std::unique_lock lock(m);
    cv.wait(lock, [&] { return done; });
  });
  const std::vector<int> created = threads_since(before);
  ASSERT_EQ(created.size(), 1u);
  EXPECT_EQ(std::count(before.begin(), before.end(), created[0]), 0);
  const int err = set_thread_fifo_priority(created[0], 1);
  if (err == 0) {
    EXPECT_EQ(sched_getscheduler(created[0]), SCHED_FIFO);
  } else {
    // Unprivileged: refused, and the thread keeps its policy.
    EXPECT_EQ(err, EPERM) << std::strerror(err);
    EXPECT_NE(sched_getscheduler(created[0]), SCHED_FIFO);
  }
  {
    std::lock_guard lock(m);
    done = true;
  }
  cv.notify_one();
  t.join();
  EXPECT_TRUE(threads_since(before).empty());
}

}  // namespace
}  // namespace tarmac::daemon
