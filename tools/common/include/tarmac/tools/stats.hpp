#pragma once
/// @file Summary statistics of per-scan or per-cycle timings, shared by the offline tools so that
/// every table's p50 and p99 mean the same thing.

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

}  // namespace tarmac::tools
