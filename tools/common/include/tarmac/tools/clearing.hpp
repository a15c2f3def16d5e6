#pragma once
/// @file Dynamic-clearing figures against a moving object's ground truth (tarmac-sim's
/// dynamic_boxes.txt): time-to-clear (from the object leaving a costmap cell to that cell reading
/// free) and ghost cells (cells of the object's path, not under it at the end, still blocking).

#include <cstdint>
#include <filesystem>
#include <map>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::tools {

/// One moving object's axis-aligned box at one scan, scene frame, m.
struct DynamicBox {
  int scan = 0;
  int id = 0;
  Eigen::Vector3d min_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d max_W = Eigen::Vector3d::Zero();
};

struct DynamicTruth {
  Eigen::Isometry3d T_world_scene = Eigen::Isometry3d::Identity();
  std::vector<DynamicBox> boxes;  ///< in file order (scan ascending)
};

/// Reads dynamic_boxes.txt. Errors: "truth.open", "truth.parse" (with the line number).
core::Result<DynamicTruth> read_dynamic_truth(const std::filesystem::path& file);

struct ClearingReport {
  std::size_t path_cells = 0;   ///< cells the objects covered at some scan
  std::size_t measured = 0;     ///< cells that blocked under the object, then were left
  std::size_t cleared = 0;      ///< of those, cells that read free afterwards
  std::size_t not_cleared = 0;  ///< measured − cleared (blocking or unknown at the end)
  double p50_s = 0.0, p90_s = 0.0, max_s = 0.0;  ///< time-to-clear over the cleared cells
  std::size_t ghost_cells = 0;  ///< path cells not under an object at the end that block
};

/// Follows the costmap scan by scan. A cell is under an object at a scan when its square meets the
/// xy bounds of the object's box (map frame) at that scan. Time-to-clear of a cell: from the stamp
/// of the last scan it was under the object (an upper bound on when the object left it) to the
/// first later scan at which it reads free; only cells that blocked while under the object are
/// measured (the others never showed it).
class ClearingTracker {
 public:
  explicit ClearingTracker(DynamicTruth truth) : truth_(std::move(truth)) {}

  /// After the costmap of scan `scan` (stamp `stamp_s`) was built.
  void observe(int scan, double stamp_s, const core::Grid2D<std::uint8_t>& column_class);
  /// The figures, with the ghost count from the last observed costmap.
  [[nodiscard]] ClearingReport report() const;

 private:
  struct Cell {
    int last_under_scan = -1;
    double last_under_s = 0.0;
    bool blocked_under = false;  ///< blocked while under the object (since it last came)
    bool pending = false;        ///< left, blocked, not yet read free
    bool ghost = false;          ///< at the last scan: not under an object and blocking
  };
  DynamicTruth truth_;
  std::size_t next_box_ = 0;
  std::map<std::pair<int, int>, Cell> cells_;  ///< by global cell index of the map frame
  std::vector<double> ttc_s_;
  double resolution_m_ = 0.0;
};

}  // namespace tarmac::tools
