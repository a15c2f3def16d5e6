// The loop can always be stopped, and it pings the systemd watchdog only from ticks that
// complete (issue 19 item 2). In this process: a schedule the loop could not keep is refused
// before any DDS entity exists; a stop reaches a loop asleep in a long period within
// Executor::kStopPollSlice; a stalled tick stops the WATCHDOG=1 pings, and a stop waits for the
// tick to complete instead of cutting it. StopSignals, in child processes: a stop during startup
// exits 0 at once, a stop while running is left to the loop, a loop stuck past kStopGrace exits
// 70. (tarmacd_process_test.cpp sends SIGTERM to the daemon binary at several moments.)

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <mutex>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "loopback_only.hpp"
#include "notify_socket.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/daemon/stop_signals.hpp"
#include "test_env.hpp"

namespace tarmac::daemon {
namespace {

using namespace std::chrono_literals;
using SteadyClock = std::chrono::steady_clock;

/// A light executor: no real time, a small window, nothing saved.
config::Config light_config(std::uint32_t domain) {
  config::Config c;
  c.dds.participant.domain_id = domain;
  c.dds.participant.name = "tarmacd-stop-test";
  c.executor.realtime_priority = 0;
  c.executor.lock_memory = false;
  c.mapping.occupancy.window_x_vox = 200;
  c.mapping.occupancy.window_y_vox = 200;
  c.mapping.occupancy.window_z_vox = 30;
  c.mapping.tsdf.reserve_blocks = 0;
  c.state.save_on_exit = false;
  return c;
}

std::chrono::milliseconds since(SteadyClock::time_point t0) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(SteadyClock::now() - t0);
}

TEST(ExecutorSchedule, Create_RefusesARateOrDelayTheLoopCouldNotKeep) {
  // Refused before the participant exists (no DDS in this test). A NaN rate fails every range
  // comparison; before this check it made a loop that never ticked and never saw SIGTERM.
  const double inf = std::numeric_limits<double>::infinity();
  for (const double rate : {std::numeric_limits<double>::quiet_NaN(), inf, -inf, 0.0, 0.05, 1e6}) {
    SCOPED_TRACE(rate);
    auto c = light_config(test::kDomainDaemonStopAsleep);
    c.executor.rate_hz = rate;
    const auto created = Executor::create(c);
    ASSERT_FALSE(created.ok());
    EXPECT_EQ(created.error().code, "config.range");
    EXPECT_EQ(created.error().message.rfind(
                  "executor.rate_hz: must be a finite number in [0.1, 1000], got ", 0),
              0u)
        << created.error().message;
  }
  auto c = light_config(test::kDomainDaemonStopAsleep);
  c.executor.input_delay_ms = std::numeric_limits<double>::quiet_NaN();
  const auto created = Executor::create(c);
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.error().message,
            "executor.input_delay_ms: must be a finite number in [0, 3600000], got nan");
}

class ExecutorStop : public test::LoopbackOnly {};

TEST_F(ExecutorStop, Stop_ReachesALoopAsleepInALongPeriodWithinAPollSlice) {
  auto c = light_config(test::kDomainDaemonStopAsleep);
  c.executor.rate_hz = 0.5;  // 2 s between ticks
  auto created = Executor::create(c);
  ASSERT_TRUE(created.ok()) << created.error().message;
  Executor& executor = *created.value();
  std::atomic<int> ticks{0};
  RunHooks hooks;
  hooks.on_tick_end = [&](std::uint64_t) { ++ticks; };
  std::atomic<bool> stop{false};
  std::atomic<bool> returned{false};
  std::thread runner([&] {
    executor.run([&] { return stop.load(); }, hooks);
    returned = true;
  });
  const auto t0 = SteadyClock::now();
  while (ticks.load() == 0 && since(t0) < 5s) std::this_thread::sleep_for(1ms);
  EXPECT_EQ(ticks.load(), 1) << "no tick within 5 s at 0.5 Hz";
  std::this_thread::sleep_for(300ms);  // asleep now, ~1.7 s before the next tick
  const auto t_stop = SteadyClock::now();
  stop = true;
  while (!returned.load() && since(t_stop) < 5s) std::this_thread::sleep_for(1ms);
  const auto took = since(t_stop);
  runner.join();
  EXPECT_LE(took, Executor::kStopPollSlice + 150ms) << "the stop waited for the next tick";
  EXPECT_EQ(ticks.load(), 1);
  EXPECT_EQ(executor.totals().ticks, 1u);
}

TEST_F(ExecutorStop, Watchdog_StopsWhileATickIsStalled_AndAStopWaitsForTheTick) {
  const std::filesystem::path socket_path =
      std::filesystem::temp_directory_path() / ("tarmac-watchdog-" + std::to_string(getpid()));
  test::NotifySocket notify(socket_path);
  ASSERT_TRUE(notify.bound());
  // sd_notify() reads NOTIFY_SOCKET at each call: the executor's pings come to this socket.
  setenv("NOTIFY_SOCKET", socket_path.c_str(), 1);

  auto created = Executor::create(light_config(test::kDomainDaemonWatchdogStall));  // 10 Hz
  ASSERT_TRUE(created.ok()) << created.error().message;
  Executor& executor = *created.value();
  // Tick 3 stalls in its last step, before its ping, until released: a stuck stage.
  std::mutex mutex;
  std::condition_variable changed;
  bool stalled = false;
  bool release = false;
  RunHooks hooks;
  hooks.on_tick_end = [&](std::uint64_t tick) {
    if (tick != 3) return;
    std::unique_lock lock(mutex);
    stalled = true;
    changed.notify_all();
    changed.wait(lock, [&] { return release; });
  };
  std::atomic<bool> stop{false};
  std::atomic<bool> returned{false};
  std::thread runner([&] {
    executor.run([&] { return stop.load(); }, hooks);
    returned = true;
  });
  bool reached = false;
  {
    std::unique_lock lock(mutex);
    reached = changed.wait_for(lock, 5s, [&] { return stalled; });
  }
  EXPECT_TRUE(reached) << "tick 3 never came";
  notify.collect_for(100ms);
  EXPECT_EQ(notify.count("WATCHDOG=1"), 3) << "ticks 0, 1 and 2 completed, tick 3 has not";

  // Ten periods without a completed tick: no ping, so systemd would restart the service. A
  // stop meanwhile waits for the tick: a cycle is never cut in half.
  stop = true;
  notify.collect_for(1000ms);
  EXPECT_EQ(notify.count("WATCHDOG=1"), 3) << "a ping while no tick completed";
  EXPECT_FALSE(returned.load()) << "the stop interrupted a tick";

  {
    std::lock_guard lock(mutex);
    release = true;
  }
  changed.notify_all();
  const auto t_release = SteadyClock::now();
  runner.join();
  EXPECT_LT(since(t_release), 500ms);
  notify.collect_for(50ms);
  EXPECT_EQ(notify.count("WATCHDOG=1"), 4) << "the released tick pings, then the loop stops";
  EXPECT_EQ(executor.totals().ticks, 4u);
  unsetenv("NOTIFY_SOCKET");
}

/// StopSignals in a child process, tarmac-stop-signals-child PART (stop_signals_child.cpp says
/// why it is a program of its own): it reports through a pipe that it is set up; the parent then
/// sends SIGTERM and times the exit. Returns the wait status, or -1 when it had to be killed.
struct ChildStop {
  int wstatus = -1;
  std::chrono::milliseconds took{0};
};

ChildStop stop_child(const char* part) {
  int fds[2];
  if (pipe(fds) != 0) return {};
  const std::string ready_fd = std::to_string(fds[1]);  // made before fork: the child only execs
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    execl(TARMAC_STOP_SIGNALS_CHILD, TARMAC_STOP_SIGNALS_CHILD, part, ready_fd.c_str(),
          static_cast<char*>(nullptr));
    _exit(127);
  }
  close(fds[1]);
  char byte = 0;
  const bool set_up = read(fds[0], &byte, 1) == 1;
  close(fds[0]);
  ChildStop result;
  if (!set_up) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    return result;
  }
  const auto t0 = SteadyClock::now();
  kill(pid, SIGTERM);
  int wstatus = 0;
  pid_t waited = 0;
  while ((waited = waitpid(pid, &wstatus, WNOHANG)) == 0 && since(t0) < 5s) {
    std::this_thread::sleep_for(1ms);
  }
  result.took = since(t0);
  if (waited == 0) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
    return result;
  }
  result.wstatus = wstatus;
  return result;
}

TEST(StopSignals, DuringStartup_TheProcessExitsAtOnceWith0) {
  const ChildStop stopped = stop_child("startup");
  ASSERT_TRUE(WIFEXITED(stopped.wstatus)) << stopped.wstatus;
  EXPECT_EQ(WEXITSTATUS(stopped.wstatus), 0);
  EXPECT_LT(stopped.took, 500ms + test::kExitDelay);
}

TEST(StopSignals, WhileRunning_TheStopIsLeftToTheLoop) {
  const ChildStop stopped = stop_child("running");
  ASSERT_TRUE(WIFEXITED(stopped.wstatus)) << stopped.wstatus;
  EXPECT_EQ(WEXITSTATUS(stopped.wstatus), 42);
}

TEST(StopSignals, ALoopStuckPastTheGrace_EndsWithExitStatus70) {
  const ChildStop stopped = stop_child("stuck");
  ASSERT_TRUE(WIFEXITED(stopped.wstatus)) << stopped.wstatus;
  EXPECT_EQ(WEXITSTATUS(stopped.wstatus), StopSignals::kExitStuck);
  EXPECT_GE(stopped.took, StopSignals::kStopGrace);
  EXPECT_LT(stopped.took, 1500ms + test::kExitDelay);
}

}  // namespace
}  // namespace tarmac::daemon
