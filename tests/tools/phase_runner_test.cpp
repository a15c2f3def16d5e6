// tarmac-bench --phases: the PhaseRunner runs every task exactly once on the wrapped runner and
// records each parallel_for call and the serial stretches around them, per stage.

#include <atomic>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/tools/phase_runner.hpp"

namespace tarmac::tools {
namespace {

using namespace std::chrono_literals;

/// A stage of two calls (3 tasks, then 5) with a serial stretch of `serial` between them.
StagePhases run_stage(PhaseRunner& runner, std::vector<std::atomic<int>>& runs,
                      std::chrono::milliseconds task1_sleep, std::chrono::milliseconds serial) {
  runner.begin_stage();
  runner.parallel_for(3, [&](std::size_t t) {
    ++runs[t];
    if (t == 1) std::this_thread::sleep_for(task1_sleep);
  });
  std::this_thread::sleep_for(serial);
  runner.parallel_for(5, [&](std::size_t t) { ++runs[3 + t]; });
  return runner.end_stage();
}

TEST(PhaseRunner, RunsEveryTaskOnceAndTimesCallsAndSerialStretches) {
  daemon::ThreadPool pool(2);
  PhaseRunner runner(pool);
  EXPECT_EQ(runner.concurrency(), 2u);
  std::vector<std::atomic<int>> runs(8);
  const StagePhases s = run_stage(runner, runs, 20ms, 10ms);
  for (const auto& r : runs) EXPECT_EQ(r.load(), 1);
  ASSERT_EQ(s.calls.size(), 2u);
  ASSERT_EQ(s.serial_ms.size(), 3u);  // before, between, after
  ASSERT_EQ(s.calls[0].task_ms.size(), 3u);
  ASSERT_EQ(s.calls[1].task_ms.size(), 5u);
  // Sleeps last at least as long as asked; the call lasts at least as long as its task.
  EXPECT_GE(s.calls[0].task_ms[1], 20.0);
  EXPECT_LT(s.calls[0].task_ms[0], 20.0);
  EXPECT_GE(s.calls[0].wall_ms, s.calls[0].task_ms[1]);
  EXPECT_GE(s.serial_ms[1], 10.0);
  EXPECT_LT(s.serial_ms[0], 10.0);
}

TEST(PhaseRunner, SummaryListsEachCallOfTheCommonShapeAndLeavesOutOthers) {
  core::SerialRunner serial;
  PhaseRunner runner(serial);
  std::vector<StagePhases> scans;
  std::vector<std::atomic<int>> runs(8);
  // First a scan whose stage made one call only, then three of the common shape.
  runner.begin_stage();
  runner.parallel_for(3, [](std::size_t) {});
  scans.push_back(runner.end_stage());
  for (int k = 0; k < 3; ++k) scans.push_back(run_stage(runner, runs, 1ms, 1ms));
  const std::string text = summarize_phases("demo", scans, 4);
  EXPECT_NE(text.find("demo: 2 parallel_for calls, 3 of 4 scans alike"), std::string::npos) << text;
  EXPECT_NE(text.find("parallel_for #1,  3 tasks"), std::string::npos) << text;
  EXPECT_NE(text.find("task p50:"), std::string::npos) << text;  // 3 tasks: listed
  EXPECT_NE(text.find("parallel_for #2,  5 tasks"), std::string::npos) << text;
  EXPECT_NE(text.find("longest task"), std::string::npos) << text;  // 5 tasks: summarised
  EXPECT_NE(text.find("serial (end)"), std::string::npos) << text;
  EXPECT_TRUE(summarize_phases("none", {}).empty());
}

}  // namespace
}  // namespace tarmac::tools
