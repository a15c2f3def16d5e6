#pragma once
/// @file Counters by reason (drops, rejections) for the cycle report: this tick and since start.
/// Known reasons are declared up front; an undeclared one gets its entry the first time it occurs
/// (one allocation, ever). Counting is RT-safe afterwards.

#include <cstdint>
#include <string_view>
#include <vector>

#include "tarmac/transport/cycle_report.hpp"

namespace tarmac::daemon {

class ReasonCounters {
 public:
  ReasonCounters() { entries_.reserve(32); }
  void add(std::string_view reason, std::uint64_t n = 1) {
    if (n == 0) return;
    for (auto& e : entries_) {
      if (e.reason == reason) {
        e.count += n;
        e.total += n;
        return;
      }
    }
    entries_.push_back(transport::ReasonReport{std::string(reason), n, n});
  }
  /// Registers a reason with zero counts, so it is reported (as 0) from the start and counting
  /// it later never allocates.
  void declare(std::string_view reason) {
    for (const auto& e : entries_) {
      if (e.reason == reason) return;
    }
    entries_.push_back(transport::ReasonReport{std::string(reason), 0, 0});
  }
  /// Zeroes the per-tick counts, keeps the totals.
  void begin_tick() {
    for (auto& e : entries_) e.count = 0;
  }
  [[nodiscard]] std::uint64_t total(std::string_view reason) const {
    for (const auto& e : entries_) {
      if (e.reason == reason) return e.total;
    }
    return 0;
  }
  [[nodiscard]] std::uint64_t tick_sum() const {
    std::uint64_t s = 0;
    for (const auto& e : entries_) s += e.count;
    return s;
  }
  [[nodiscard]] std::uint64_t total_sum() const {
    std::uint64_t s = 0;
    for (const auto& e : entries_) s += e.total;
    return s;
  }
  [[nodiscard]] const std::vector<transport::ReasonReport>& entries() const { return entries_; }

 private:
  std::vector<transport::ReasonReport> entries_;
};

}  // namespace tarmac::daemon
