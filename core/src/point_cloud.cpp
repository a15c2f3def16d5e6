#include "tarmac/core/point_cloud.hpp"

namespace tarmac::core {

bool PointCloud::consistent() const {
  const auto n = points_S.size();
  const auto fits = [n](std::size_t m) { return m == 0 || m == n; };
  return fits(intensity.size()) && fits(ring.size()) && fits(time_offset_s.size());
}

void PointCloud::clear() {
  points_S.clear();
  intensity.clear();
  ring.clear();
  time_offset_s.clear();
  no_return_S.clear();
  grid_rows = 0;
  organised = false;
}

}  // namespace tarmac::core
