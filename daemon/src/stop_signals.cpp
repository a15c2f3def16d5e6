#include "tarmac/daemon/stop_signals.hpp"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <thread>

namespace tarmac::daemon {

namespace {

sigset_t stop_set() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  return set;
}

/// One line on stderr with write(2): no lock another (possibly stuck) thread could hold.
void say(const char* what, int sig) {
  char line[160];
  const int n = std::snprintf(line, sizeof line, "tarmacd: SIG%s %s\n", sigabbrev_np(sig), what);
  if (n > 0) (void)!write(STDERR_FILENO, line, static_cast<std::size_t>(n));
}

/// Ends the process now, without destructors: other threads may be inside Fast DDS or
/// OpenVDB. No stdio flush either (a stuck thread may hold a stream's lock); the logger flushes
/// every line as it writes it.
[[noreturn]] void exit_now(int status) {
  _exit(status);
}

/// Never returns: the thread that called it waits for the process to exit (the waiting thread
/// is calling exit_now()).
[[noreturn]] void wait_for_exit() {
  while (true) pause();
}

}  // namespace

StopSignals& StopSignals::install() {
  // Lives until the process exits: the waiting thread uses it to the end (never destroyed, so
  // no destructor can race with a late signal).
  static StopSignals* const instance = [] {
    const sigset_t set = stop_set();
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
    auto* s = new StopSignals();
    std::thread([s] { s->wait_loop(); }).detach();
    return s;
  }();
  return *instance;
}

bool StopSignals::advance(Phase from, Phase to) {
  return phase_.compare_exchange_strong(from, to, std::memory_order_acq_rel);
}

void StopSignals::begin_loop() {
  if (!advance(Phase::kStarting, Phase::kRunning)) wait_for_exit();
}

void StopSignals::loop_ended() {
  if (!advance(Phase::kRunning, Phase::kStopping)) wait_for_exit();
}

void StopSignals::wait_loop() {
  const sigset_t set = stop_set();
  while (true) {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) continue;
    if (advance(Phase::kStarting, Phase::kExiting)) {
      say("during startup: exiting (nothing to save yet)", sig);
      exit_now(0);
    }
    if (phase_.load(std::memory_order_acquire) != Phase::kRunning || requested()) {
      continue;  // saving already, or a second signal while the loop winds down
    }
    signal_.store(sig, std::memory_order_release);
    // The loop sees the flag within 100 ms while asleep, or when its tick completes. A tick
    // still running after kStopGrace is stuck: give up on it rather than ignore the stop.
    const auto deadline = std::chrono::steady_clock::now() + kStopGrace;
    while (phase_.load(std::memory_order_acquire) == Phase::kRunning &&
           std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (advance(Phase::kRunning, Phase::kExiting)) {
      say("received, but the tick loop did not end within 900 ms: exiting without saving", sig);
      exit_now(kExitStuck);
    }
  }
}

}  // namespace tarmac::daemon
