#include "tarmac/core/grid2d.hpp"

#include <cmath>

namespace tarmac::core {

std::optional<Eigen::Vector2i> GridGeometry2D::cell_of(double x_m, double y_m) const {
  const double fx = std::floor((x_m - origin_x_m) / resolution_m);
  const double fy = std::floor((y_m - origin_y_m) / resolution_m);
  if (!(fx >= 0.0 && fy >= 0.0 && fx < width && fy < height)) {  // also rejects NaN
    return std::nullopt;
  }
  return Eigen::Vector2i(static_cast<int>(fx), static_cast<int>(fy));
}

Eigen::Vector2d GridGeometry2D::center_of(int ix, int iy) const {
  return {origin_x_m + (ix + 0.5) * resolution_m, origin_y_m + (iy + 0.5) * resolution_m};
}

}  // namespace tarmac::core
