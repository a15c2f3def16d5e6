#pragma once
/// @file A TaskRunner that times what a stage does on it, for the benchmark's --phases: every
/// parallel_for call (its wall time and each task's time) and the serial stretches before,
/// between and after them. The core has no clock (DESIGN.md §2) and its stages split their work
/// into parallel_for calls with a fixed number of tasks, so these are the stage's phases: the
/// k-th call of a stage is the same phase on every scan (see the stage's source for which).
/// The tasks run on the wrapped runner exactly as without it: only timing is added.

#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

#include "tarmac/core/task_runner.hpp"

namespace tarmac::tools {

/// One stage run on a PhaseRunner: serial_ms[k] is the time on the calling thread before call
/// k (k = calls.size(): after the last call, up to end_stage()).
struct StagePhases {
  struct Call {
    double wall_ms = 0.0;
    std::vector<double> task_ms;  ///< per task index
  };
  std::vector<double> serial_ms;
  std::vector<Call> calls;
};

class PhaseRunner final : public core::TaskRunner {
 public:
  explicit PhaseRunner(core::TaskRunner& inner) : inner_(inner) {}

  /// Starts recording a stage (what it records until end_stage()).
  void begin_stage();
  /// Ends the stage begun last and returns what it did.
  StagePhases end_stage();

  void parallel_for(std::size_t count, core::TaskFn fn) override;
  [[nodiscard]] std::size_t concurrency() const override { return inner_.concurrency(); }

 private:
  using Clock = std::chrono::steady_clock;
  core::TaskRunner& inner_;
  StagePhases stage_;
  Clock::time_point last_{};
  /// Start of each task (written by the thread that runs it: one index per thread at a time).
  std::vector<Clock::time_point> task_start_;
};

/// Per-scan phases of one stage, summarised over the scans: for each position, the mean and
/// p50 (nearest rank, tools::percentile) of the serial stretches and of the calls' wall time; per
/// call, each task's p50 when it has at most `max_tasks_listed` tasks, else the p50 of its longest
/// task and of their sum. Only the scans whose stage made the most common sequence of calls (their
/// number of tasks) are summarised; the others are counted.
std::string summarize_phases(const std::string& stage, const std::vector<StagePhases>& scans,
                             std::size_t max_tasks_listed = 4);

}  // namespace tarmac::tools
