#pragma once
/// @file Per-scan filters before integration, each counted: non-finite points, points closer than
/// min range (the sensor's blind zone, spray on the housing) and points inside the ego-vehicle box
/// (in the base frame). Survivors are transformed into the world frame.

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::core {

struct FilterParams {
  double min_range_m = 1.0;  ///< from the sensor origin
  /// Ego-vehicle box in the base frame; points inside are the vehicle itself.
  Eigen::Vector3d ego_box_min_B{-2.5, -1.2, -0.5};
  Eigen::Vector3d ego_box_max_B{2.5, 1.2, 2.5};
  bool ego_box_enabled = true;
  /// Isolated-outlier filter (rain, spray, dust, multipath): a point closer than
  /// outlier_max_range_m is dropped when fewer than outlier_min_neighbors other points of the
  /// scan lie in its cell or the 26 cells around it (cells of outlier_cell_m). 0 disables.
  int outlier_min_neighbors = 2;
  double outlier_cell_m = 0.5;
  double outlier_max_range_m = 30.0;

  [[nodiscard]] Status validate() const;
};

/// Why points were dropped in one scan.
struct FilterCounts {
  std::uint64_t input = 0;
  std::uint64_t non_finite = 0;
  std::uint64_t too_close = 0;
  std::uint64_t ego_vehicle = 0;
  std::uint64_t isolated = 0;
  std::uint64_t kept = 0;
  std::uint64_t no_returns = 0;          ///< beams without return kept (clear free space)
  std::uint64_t no_returns_refused = 0;  ///< their directions not finite or not ~unit length
  /// Of the kept, those that descend to the vehicle's ground plane within the clearing range:
  /// their return was lost, so they clear nothing (Mapper::ingest).
  std::uint64_t no_returns_grounded = 0;
  /// Of the rest, those that meet a voxel the map held occupied before this scan: they end
  /// before it (a surface's lost return does not see behind the surface).
  std::uint64_t no_returns_stopped = 0;
  /// 1 when the scan came as a grid, or as a list with rings, whose layout could not be told
  /// (Mapper::ingest, organise()): integrated as a list of points, no beam without return.
  std::uint64_t layout_undecided = 0;
};

/// Buffers of the filter, reused across scans (no allocation after warm-up).
struct FilterScratch {
  /// One slot of the open-addressing table of cells: the cell's key (0 = empty), its points, and
  /// its state: bit 0, a candidate near enough to be tested lies in the cell; bit 1, the cell
  /// and its 26 neighbours hold enough points (decided once per cell, not per point). In one
  /// aligned 16-byte slot (3 bytes of padding), so an insert or a lookup touches one cache line
  /// instead of one per field.
  struct alignas(16) Cell {
    std::uint64_t key;
    std::uint32_t count;
    std::uint8_t state;
  };
  std::vector<Cell> cells;
  /// Distinct cells of the last scan: the next table is sized from it (see filter_scan).
  std::size_t last_cells = 0;
  std::vector<std::uint64_t> point_key;  ///< cell key per candidate (hash path only)
  /// Per candidate: its cell's slot in the outlier table (hash path) or index in the grid (grid
  /// path, set for candidates in the region only).
  std::vector<std::uint32_t> point_slot;
  std::vector<std::uint8_t> point_near;  ///< per candidate: near enough to be tested
  /// Candidates (points that passed the per-point tests) in the sensor and world frames. Both
  /// are indexed by input position: each of the filter's fixed point ranges keeps its
  /// candidates at the front of its own range.
  std::vector<Eigen::Vector3f> candidates_S, candidates_W;
  std::vector<std::uint8_t> keep;  ///< per candidate: survives the outlier test
  /// Candidates per cell of the outlier test's region, when it is counted in a grid (see
  /// filter_scan): a byte per cell, zero between scans but for the cells in grid_touched (the
  /// last scan's, emptied by the next).
  std::vector<std::uint8_t> grid;
  std::vector<std::uint32_t> grid_touched;  ///< its first n_grid_touched (no per-scan fill)
  std::size_t n_grid_touched = 0;
  /// Regions of more cells than this are counted in the hash table `cells` instead (small cells
  /// with a long outlier range). Both give the same result; tests lower it to compare them.
  std::size_t grid_cell_limit = std::size_t{1} << 23;

  /// Sizes (and writes once, so the first scan does not pay their page faults) every buffer for
  /// scans of up to `points` points, and the outlier grid for `params`.
  void reserve(std::size_t points, const FilterParams& params = {});
};

/// Filters `cloud` (sensor frame) and writes survivors into `points_W` (cleared first, capacity
/// kept). T_W_S: sensor to world; T_B_S: sensor to vehicle base (extrinsic). RT-safe after warm-up.
/// The work is split into a fixed number of point ranges run on `runner`; the result (points and
/// their order, counts) is the same for any runner.
/// With `points_S`, the survivors are also written there in the sensor frame (same order).
FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W, FilterScratch& scratch,
                         TaskRunner& runner, std::vector<Eigen::Vector3f>* points_S = nullptr);
/// The same on the calling thread.
FilterCounts filter_scan(const PointCloud& cloud, const Eigen::Isometry3d& T_W_S,
                         const Eigen::Isometry3d& T_B_S, const FilterParams& params,
                         std::vector<Eigen::Vector3f>& points_W, FilterScratch& scratch);

}  // namespace tarmac::core
