#pragma once
/// @file Dynamic-clearing figures against a moving object's ground truth (tarmac-sim's
/// dynamic_boxes.txt): time-to-clear (from the object leaving a costmap cell to that cell reading
/// free) and ghost cells (cells of the object's path, not under it at the end, still blocking).

#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
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
  /// Of the cleared cells, those inside the sensor's blind zone when the object left them.
  std::size_t blind_at_leave = 0;
  /// Time-to-clear over the other cleared cells (in view when left): the map model's own time,
  /// without the wait for the vehicle to move so that rays reach a cell's lower voxels.
  double in_view_p50_s = 0.0, in_view_p90_s = 0.0, in_view_max_s = 0.0;
  std::size_t ghost_cells = 0;  ///< path cells not under an object at the end that block
};

/// Follows the costmap scan by scan. A cell is under an object at a scan when its square meets the
/// xy bounds of the object's box (map frame) at that scan. Time-to-clear of a cell: from the stamp
/// of the last scan it was under the object (an upper bound on when the object left it) to the
/// first later scan at which it reads free; only cells that blocked while under the object are
/// measured (the others never showed it).
///
/// The blind zone of a scan is the disc around the sensor (xy) inside which no ray reaches the
/// ground: `blind_radius_m`, e.g. the horizontal distance of the scan's nearest ground return
/// (blind_radius_from_ground()). No ray passes through a cell's lowest voxels there, so a cell
/// left inside it clears only when the vehicle's motion brings rays through them; the in-view
/// figures are over the cells left outside it.
class ClearingTracker {
 public:
  explicit ClearingTracker(DynamicTruth truth) : truth_(std::move(truth)) {}
  [[nodiscard]] const DynamicTruth& truth() const { return truth_; }

  /// After the costmap of scan `scan` (stamp `stamp_s`) was built, the sensor at `sensor_xy`
  /// (map frame) with blind radius `blind_radius_m` (0: no blind zone).
  void observe(int scan, double stamp_s, const core::Grid2D<std::uint8_t>& column_class,
               const Eigen::Vector2d& sensor_xy = Eigen::Vector2d::Zero(),
               double blind_radius_m = 0.0);
  /// The figures, with the ghost count from the last observed costmap.
  [[nodiscard]] ClearingReport report() const;

 private:
  struct Cell {
    int last_under_scan = -1;
    double last_under_s = 0.0;
    bool blocked_under = false;   ///< blocked while under the object (since it last came)
    bool pending = false;         ///< left, blocked, not yet read free
    bool ghost = false;           ///< at the last scan: not under an object and blocking
    bool blind_at_leave = false;  ///< in the blind zone at the first scan after it was left
  };
  DynamicTruth truth_;
  std::size_t next_box_ = 0;
  std::map<std::pair<int, int>, Cell> cells_;  ///< by global cell index of the map frame
  std::vector<double> ttc_s_;
  std::vector<double> in_view_s_;
  std::size_t blind_at_leave_ = 0;
  double resolution_m_ = 0.0;
};

/// The horizontal distance from `sensor_W` to the nearest of `points_W` within `tolerance_m` of
/// the ground height `ground_z_m`: where this scan's rays first reach the ground (infinity when
/// none does).
double blind_radius_from_ground(const Eigen::Vector3d& sensor_W,
                                std::span<const Eigen::Vector3f> points_W, double ground_z_m,
                                double tolerance_m = 0.2);

}  // namespace tarmac::tools
