#pragma once
/// @file Exact Euclidean distance field (ESDF) with gradient over a dense 2D or 3D grid.
///
/// Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions", Theory of Computing
/// 8 (2012): the squared Euclidean distance transform is separable into 1D lower envelopes of
/// parabolas, one pass per axis, O(n) per line. Squared distances between cell centres are
/// integers in cell units, so the result is exact (not quasi-Euclidean); the nearest obstacle
/// cell is tracked through the passes, which makes the gradient exact too:
/// ∇d = (p − site) / |p − site| (zero on obstacles). Passes: the nearest site along y in each
/// layer (two sweeps), the envelope along x of each layer's row (Meijster et al.'s integer
/// form), then in 3D the minimum over the layers z' of d²(z') + (z − z')², exact brute force
/// across x lanes: windows and bands have few layers, and this replaces the envelope pass per
/// column that cost most.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/task_runner.hpp"

namespace tarmac::core {

/// Cell states fed to the transform.
enum class CellState : std::uint8_t { kFree = 0, kOccupied = 1, kUnknown = 2 };

/// What to do with unknown cells.
enum class UnknownPolicy : std::uint8_t {
  /// Unknown cells are not obstacles; their distance is reported as NaN (unknown).
  kReportUnknown,
  /// Unknown cells count as obstacles (conservative: distance to the nearest occupied *or*
  /// unknown cell); they get distance 0.
  kUnknownIsOccupied,
};

/// A dense field, x fastest, then y, then z: index = (z·ny + y)·nx + x.
struct DistanceField {
  Eigen::Vector3i dims{0, 0, 1};
  double cell_size_m = 0.2;
  std::vector<float> distance_m;  ///< NaN unknown, +inf when no obstacle in the grid
  std::vector<float> gradient_x;  ///< unitless, 0 on obstacles and where unknown/no obstacle
  std::vector<float> gradient_y;
  std::vector<float> gradient_z;  ///< all zero for a 2D field
};

/// Scratch buffers, reused across calls so the cycle does not allocate after warm-up.
struct DistanceFieldScratch {
  std::vector<std::int16_t> off;  // per cell: y offset to the nearest site in its column
  std::vector<std::vector<std::int64_t>> task;  // per task: line and layer-row buffers
};

/// Computes the exact distance field of `states` (dims.z() == 1 for 2D). Lines are split into a
/// fixed number of tasks per pass; the result is identical for any runner.
/// @pre states.size() == dims.prod(); every dimension in [1, 4096] (the occupancy window's
///      limit, OccupancyParams::validate).
void compute_distance_field(const std::vector<CellState>& states, const Eigen::Vector3i& dims,
                            double cell_size_m, UnknownPolicy policy, DistanceField& out,
                            DistanceFieldScratch& scratch, TaskRunner& runner);

}  // namespace tarmac::core
