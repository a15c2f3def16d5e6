#include "tarmac/core/grid2d.hpp"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

GridGeometry2D geometry() {
  return GridGeometry2D{-2.0, 1.0, 0.5, 8, 4};
}

TEST(GridGeometry2D, CellOf_HalfOpenCellsFromOrigin) {
  const auto g = geometry();
  EXPECT_EQ(g.cell_of(-2.0, 1.0), Eigen::Vector2i(0, 0));
  EXPECT_EQ(g.cell_of(-1.5001, 1.4999), Eigen::Vector2i(0, 0));
  EXPECT_EQ(g.cell_of(-1.5, 1.5), Eigen::Vector2i(1, 1));
  EXPECT_EQ(g.cell_of(1.9999, 2.9999), Eigen::Vector2i(7, 3));
}

TEST(GridGeometry2D, CellOf_RejectsOutsideAndNonFinite) {
  const auto g = geometry();
  EXPECT_FALSE(g.cell_of(2.0, 1.0));  // x == origin + width*res is outside
  EXPECT_FALSE(g.cell_of(-2.0001, 1.0));
  EXPECT_FALSE(g.cell_of(0.0, 3.0));
  EXPECT_FALSE(g.cell_of(std::nan(""), 1.5));
  EXPECT_FALSE(g.cell_of(0.0, std::numeric_limits<double>::infinity()));
}

TEST(GridGeometry2D, CenterOf_IsHalfACellFromTheCorner) {
  const auto c = geometry().center_of(3, 2);
  EXPECT_DOUBLE_EQ(c.x(), -2.0 + 3.5 * 0.5);
  EXPECT_DOUBLE_EQ(c.y(), 1.0 + 2.5 * 0.5);
}

TEST(Grid2D, RowMajorXFastest) {
  Costmap grid(geometry(), kCostUnknown);
  grid.at(5, 2) = kCostLethal;
  EXPECT_EQ(grid.cells()[2 * 8 + 5], kCostLethal);
  EXPECT_EQ(grid.cells().size(), 32u);
}

TEST(Grid2D, CloneIsDeepAndEqual) {
  Costmap grid(geometry(), kCostFree);
  grid.at(1, 1) = 42;
  Costmap copy = grid.clone();
  EXPECT_EQ(copy.geometry(), grid.geometry());
  EXPECT_EQ(copy.cells(), grid.cells());
  copy.at(1, 1) = 7;
  EXPECT_EQ(grid.at(1, 1), 42);
}

}  // namespace
}  // namespace tarmac::core
