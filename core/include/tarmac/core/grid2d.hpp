#pragma once
/// @file A dense 2D grid on the horizontal plane of the map frame (costmaps, ESDF slices).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

/// Placement of a 2D grid: cell (ix, iy) covers [origin + i·resolution, origin + (i+1)·resolution)
/// along each axis, in metres of the map frame. Row-major: index = iy·width + ix, x fastest.
struct GridGeometry2D {
  double origin_x_m = 0.0;
  double origin_y_m = 0.0;
  double resolution_m = 0.2;
  std::uint32_t width = 0;   ///< cells along x
  std::uint32_t height = 0;  ///< cells along y

  [[nodiscard]] std::size_t cell_count() const { return std::size_t{width} * height; }
  /// Cell containing a map-frame point, or nothing when the point lies outside the grid.
  [[nodiscard]] std::optional<Eigen::Vector2i> cell_of(double x_m, double y_m) const;
  /// Centre of a cell in the map frame, m.
  [[nodiscard]] Eigen::Vector2d center_of(int ix, int iy) const;
  friend bool operator==(const GridGeometry2D&, const GridGeometry2D&) = default;
};

/// floor(value) clamped to [lo, hi] as an int: safe for values far outside the int range,
/// infinities and NaN (→ lo), e.g. a virtual zone's vertex 1e30 m away or its z range ±1e9 m.
inline int clamped_floor(double value, int lo, int hi) {
  const double f = std::floor(value);
  if (!(f > lo)) return lo;
  if (!(f < hi)) return hi;
  return static_cast<int>(f);
}

/// Dense row-major grid of T. Move-only: grids are large and copies should be deliberate
/// (use clone()).
template <typename T>
class Grid2D {
 public:
  Grid2D() = default;
  Grid2D(const GridGeometry2D& geometry, T fill)
      : geometry_(geometry), cells_(geometry.cell_count(), fill) {}
  Grid2D(Grid2D&&) noexcept = default;
  Grid2D& operator=(Grid2D&&) noexcept = default;
  Grid2D(const Grid2D&) = delete;
  Grid2D& operator=(const Grid2D&) = delete;

  [[nodiscard]] Grid2D clone() const {
    Grid2D g;
    g.geometry_ = geometry_;
    g.cells_ = cells_;
    return g;
  }

  [[nodiscard]] const GridGeometry2D& geometry() const { return geometry_; }
  [[nodiscard]] std::uint32_t width() const { return geometry_.width; }
  [[nodiscard]] std::uint32_t height() const { return geometry_.height; }

  T& at(std::uint32_t ix, std::uint32_t iy) {
    TARMAC_ASSERT(ix < geometry_.width && iy < geometry_.height, "Grid2D index out of range");
    return cells_[std::size_t{iy} * geometry_.width + ix];
  }
  const T& at(std::uint32_t ix, std::uint32_t iy) const {
    TARMAC_ASSERT(ix < geometry_.width && iy < geometry_.height, "Grid2D index out of range");
    return cells_[std::size_t{iy} * geometry_.width + ix];
  }

  [[nodiscard]] std::vector<T>& cells() { return cells_; }
  [[nodiscard]] const std::vector<T>& cells() const { return cells_; }

  /// Sets every cell to `value`, keeping capacity.
  void fill(T value) { std::fill(cells_.begin(), cells_.end(), value); }
  /// Gives the grid a new geometry and fills it, keeping the storage when the cell count does
  /// not grow (a rolling window moves its origin every few cycles: no allocation for that).
  void reset(const GridGeometry2D& geometry, T value) {
    geometry_ = geometry;
    cells_.assign(geometry.cell_count(), value);
  }

 private:
  GridGeometry2D geometry_;
  std::vector<T> cells_;
};

/// Costmap cell values in ROS nav_msgs/OccupancyGrid convention.
inline constexpr std::int8_t kCostFree = 0;
inline constexpr std::int8_t kCostInscribed = 99;
inline constexpr std::int8_t kCostLethal = 100;
inline constexpr std::int8_t kCostUnknown = -1;

/// A 2D costmap: 0 free … 99 inscribed, 100 lethal, −1 unknown.
using Costmap = Grid2D<std::int8_t>;

}  // namespace tarmac::core
