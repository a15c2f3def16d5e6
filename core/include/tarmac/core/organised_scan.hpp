#pragma once
/// @file Organised scans: a spinning LiDAR's sweep as a grid of rows (beams) by columns (firing
/// azimuths), row-major — a PointCloud2 with height > 1, or the organised files tarmac-sim
/// writes. A cell with a non-finite coordinate, or exactly at the origin (a convention of some
/// drivers), is a beam that returned nothing within the sensor's range.
///
/// Such a beam is evidence too: the air along it is free. The costmap's free-space rule needs it
/// (a column is free only when its whole envelope was observed, and above the sensor only beams
/// into the open sky observe it). The beam's direction is not in the data, so it is rebuilt from
/// the returns of the same scan: a row's elevation is the mean elevation of its returns, a
/// column's azimuth the circular mean of its returns' azimuths. A row or column without returns
/// takes the linear interpolation between the nearest rows (columns, round the circle) that have
/// returns, or the linear extrapolation of the two nearest on one side: beams evenly spaced in
/// elevation beyond the outermost returning ones, as on the sensors tarmac is used with.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tarmac/core/point_cloud.hpp"

namespace tarmac::core {

/// What split_organised found.
struct OrganisedCounts {
  std::uint64_t returns = 0;     ///< cells with a return (kept as points)
  std::uint64_t no_returns = 0;  ///< cells without a return, direction rebuilt (no_return_S)
  /// Cells without a return whose direction could not be rebuilt (fewer than two rows or no
  /// column with returns in the scan): dropped, they clear nothing.
  std::uint64_t underivable = 0;
};

/// Buffers for split_organised, kept by the caller so that steady-state calls do not allocate.
struct OrganisedScratch {
  std::vector<double> row_sum, col_x, col_y, row_angle, col_angle;
  std::vector<std::uint32_t> row_n, col_n;
};

/// Splits the organised `cloud` (rows × cols cells, row-major; its channels as long as its
/// points) in place: the returns stay in `points_S` (and the channels) in their order, the
/// cells without a return leave them and their rebuilt directions (sensor frame, unit, row-major
/// order) replace `no_return_S`.
/// @pre rows * cols == cloud.size() and cloud.consistent()
OrganisedCounts split_organised(PointCloud& cloud, std::size_t rows, std::size_t cols,
                                OrganisedScratch& scratch);

}  // namespace tarmac::core
