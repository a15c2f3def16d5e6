#pragma once
/// @file How SIGTERM and SIGINT stop tarmacd within one second, whatever it is doing
/// (DESIGN.md §6: clean stop on SIGTERM, map saved).
///
/// install() blocks both signals in the calling thread — main() calls it before any other
/// thread exists, so every thread (DDS, workers, saver) inherits the mask and no signal lands in
/// the middle of their work — and starts one thread that waits for them (sigwait). What a
/// signal does depends on where main() is:
/// - **starting** (before begin_loop()): the process exits at once with status 0. Startup only
///   reads the state directory (a refused TSDF is renamed, atomically), so there is nothing to
///   save, and main() may be inside a call that cannot be interrupted (creating the DDS
///   participant, loading a large TSDF);
/// - **running** (begin_loop() .. loop_ended()): requested() becomes true. The executor checks
///   it at least every Executor::kStopPollSlice (100 ms) while it sleeps and after every tick,
///   so the loop ends within 100 ms, or when the current tick completes: a stop never cuts a
///   cycle in half. If the loop has not ended kStopGrace after the signal (a stage is stuck),
///   the process exits with kExitStuck without saving; the last periodic save stands, as after
///   a crash;
/// - **stopping** (after loop_ended()): the map is being saved; further signals are ignored
///   (systemd's TimeoutStopSec bounds the save).
/// A signal that arrives before install() (while the config is read) has its default action.

#include <atomic>
#include <chrono>

namespace tarmac::daemon {

class StopSignals {
 public:
  /// Exit status when the tick loop did not end within kStopGrace of a stop signal (EX_SOFTWARE).
  static constexpr int kExitStuck = 70;
  /// How long a tick may still run after a stop signal before the process gives up on it.
  static constexpr std::chrono::milliseconds kStopGrace{900};

  /// Blocks SIGTERM and SIGINT in the calling thread and starts the waiting thread. Call once,
  /// from main(), before any other thread exists. The object lives until the process exits.
  static StopSignals& install();

  /// Startup is over: from now on a stop signal is left to the loop (requested()). If a signal
  /// already ended the startup, this does not return (the process is exiting).
  void begin_loop();
  /// The tick loop has ended: the grace timer stops, the save on exit may take its time. If
  /// kStopGrace already ran out, this does not return (the process is exiting).
  void loop_ended();

  /// True once SIGTERM or SIGINT arrived while running. RT-safe: one atomic load.
  [[nodiscard]] bool requested() const { return signal_.load(std::memory_order_acquire) != 0; }
  /// The signal that asked for the stop (SIGTERM or SIGINT), 0 when none.
  [[nodiscard]] int signal() const { return signal_.load(std::memory_order_acquire); }

 private:
  enum class Phase { kStarting, kRunning, kStopping, kExiting };
  StopSignals() = default;
  [[noreturn]] void wait_loop();
  /// Moves from `from` to `to`; false when the waiting thread moved to kExiting first.
  bool advance(Phase from, Phase to);

  std::atomic<Phase> phase_{Phase::kStarting};
  std::atomic<int> signal_{0};
};

}  // namespace tarmac::daemon
