#pragma once
/// @file How the core asks for parallel work without knowing about threads: the caller (daemon,
/// tools) supplies a TaskRunner. Core stages split work into a fixed number of independent tasks
/// that write disjoint data, so results do not depend on how many threads run them, or in which
/// order (DESIGN.md §3, determinism contract).

#include <cstddef>
#include <memory>
#include <type_traits>

namespace tarmac::core {

/// A non-owning reference to a callable taking a task index: two pointers, no allocation, unlike
/// std::function, whose construction from a lambda that captures more than two pointers
/// allocates on every call of parallel_for (the daemon's cycle must not allocate after warm-up,
/// DESIGN.md §3). The referenced callable must outlive the TaskFn; parallel_for only runs it
/// before returning, so passing a lambda directly is safe.
class TaskFn {
 public:
  template <typename F,
            typename = std::enable_if_t<!std::is_same_v<std::remove_cvref_t<F>, TaskFn> &&
                                        std::is_invocable_v<F&, std::size_t>>>
  // NOLINTNEXTLINE(google-explicit-constructor): converts from any callable, like std::function
  TaskFn(F&& fn) noexcept
      : object_(const_cast<void*>(static_cast<const void*>(std::addressof(fn)))),
        call_([](void* object, std::size_t task) {
          (*static_cast<std::remove_reference_t<F>*>(object))(task);
        }) {}

  void operator()(std::size_t task) const { call_(object_, task); }

 private:
  void* object_;
  void (*call_)(void*, std::size_t);
};

class TaskRunner {
 public:
  virtual ~TaskRunner() = default;
  /// Runs fn(0) … fn(count−1), possibly concurrently, and returns when all have finished.
  /// Tasks must not depend on each other's order.
  virtual void parallel_for(std::size_t count, TaskFn fn) = 0;
  /// Worker count, for choosing task granularity only (never for choosing results).
  [[nodiscard]] virtual std::size_t concurrency() const = 0;
};

/// Runs every task on the calling thread, in index order.
class SerialRunner final : public TaskRunner {
 public:
  void parallel_for(std::size_t count, TaskFn fn) override {
    for (std::size_t i = 0; i < count; ++i) fn(i);
  }
  [[nodiscard]] std::size_t concurrency() const override { return 1; }
};

}  // namespace tarmac::core
