#include "tarmac/tools/stats.hpp"

#include <algorithm>
#include <cmath>

namespace tarmac::tools {

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(values.size())));
  return values[std::min(rank == 0 ? 0 : rank - 1, values.size() - 1)];
}

std::size_t index_of_max(const std::vector<double>& values) {
  if (values.empty()) return 0;
  return static_cast<std::size_t>(std::max_element(values.begin(), values.end()) - values.begin());
}

double mean(const std::vector<double>& values) {
  double s = 0.0;
  for (const double x : values) s += x;
  return values.empty() ? 0.0 : s / static_cast<double>(values.size());
}

}  // namespace tarmac::tools
