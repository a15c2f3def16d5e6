#pragma once
/// @file Summary statistics of per-scan or per-cycle timings, shared by the offline tools so that
/// every table's p50 and p99 mean the same thing.

#include <chrono>
#include <cstddef>
#include <vector>

namespace tarmac::tools {

/// The q-quantile by nearest rank: the smallest value with at least q of the values at or below
/// it (q = 0.99 of 21 values: the largest). 0 for no values.
double percentile(std::vector<double> values, double q);

/// Arithmetic mean; 0 for no values.
double mean(const std::vector<double>& values);

/// Where the largest value is (the first of equals); 0 for no values. With per-scan timings, the
/// scan to look at for a table's max.
std::size_t index_of_max(const std::vector<double>& values);

/// Wall time of fn() on the steady clock, ms: for measuring, never for deciding.
template <typename Fn>
double timed_ms(Fn&& fn) {
  const auto t0 = std::chrono::steady_clock::now();
  fn();
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace tarmac::tools
