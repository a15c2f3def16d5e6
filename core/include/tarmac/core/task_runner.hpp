#pragma once
/// @file How the core asks for parallel work without knowing about threads: the caller (daemon,
/// tools) supplies a TaskRunner. Core stages split work into a fixed number of independent tasks
/// that write disjoint data, so results do not depend on how many threads run them, or in which
/// order (DESIGN.md §3, determinism contract).

#include <cstddef>
#include <functional>

namespace tarmac::core {

class TaskRunner {
 public:
  virtual ~TaskRunner() = default;
  /// Runs fn(0) … fn(count−1), possibly concurrently, and returns when all have finished.
  /// Tasks must not depend on each other's order.
  virtual void parallel_for(std::size_t count, const std::function<void(std::size_t)>& fn) = 0;
  /// Worker count, for choosing task granularity only (never for choosing results).
  [[nodiscard]] virtual std::size_t concurrency() const = 0;
};

/// Runs every task on the calling thread, in index order.
class SerialRunner final : public TaskRunner {
 public:
  void parallel_for(std::size_t count, const std::function<void(std::size_t)>& fn) override {
    for (std::size_t i = 0; i < count; ++i) fn(i);
  }
  [[nodiscard]] std::size_t concurrency() const override { return 1; }
};

}  // namespace tarmac::core
