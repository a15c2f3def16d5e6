#pragma once
/// @file Scores a costmap cycle by cycle against the obstacle columns a costmap must show
/// (tarmac-sim's obstacle_columns.txt) and the ground it must leave drivable (ground_cells.txt):
/// the safety figures of DESIGN.md §4 ("judged cycle by cycle against ground truth").

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/lethal_causes.hpp"

namespace tarmac::tools {

/// The cells of the ground a vehicle may drive on, on the world lattice of `cell_m`, with the
/// ground's height at their centres (m, scene frame): tarmac-sim's ground_cells.txt, written for
/// its terrain scenes. A cell where the ground steps is none.
struct GroundTruth {
  double cell_m = 0.2;
  std::unordered_map<std::int64_t, float> z_m;  ///< key(ix, iy) (ObstacleTruth::key) -> height
  /// The same as a dense grid over their bounding box (cell (x0 + i, y0 + j) at j·w + i), NaN
  /// where no ground or an obstacle column: what the reachable-ground walk reads per costmap
  /// (read_dataset_truth builds it; empty: the walk looks cells up in z_m).
  std::int64_t x0 = 0, y0 = 0, w = 0, h = 0;
  std::vector<float> drivable_z;
};

/// The columns whose envelope span meets a static object, on the world lattice of `cell_m`, with
/// the first scan that returned a point from that span (−1: none did); and the ground cells.
struct ObstacleTruth {
  double cell_m = 0.2;
  std::unordered_map<std::int64_t, int> first_seen;  ///< key(ix, iy) -> scan, −1 never
  /// Nothing: every cell is ground (the plane z = 0 of tarmac-sim's flat scenes, which write no
  /// ground_cells.txt).
  std::optional<GroundTruth> ground;
  /// The curbs' columns among them (curb_columns.txt), first seen by a return from a curb;
  /// empty: the scene has none.
  std::unordered_map<std::int64_t, int> curb_first_seen;

  static std::int64_t key(std::int64_t ix, std::int64_t iy) {
    return (ix << 32) ^ (iy & 0xffffffff);
  }
  [[nodiscard]] bool is_column(std::int64_t ix, std::int64_t iy) const {
    return first_seen.count(key(ix, iy)) != 0;
  }
  [[nodiscard]] bool is_ground(std::int64_t ix, std::int64_t iy) const {
    return !ground || ground->z_m.count(key(ix, iy)) != 0;
  }
};

/// Reads obstacle_columns.txt. Errors: "truth.open", "truth.parse" (with the line number),
/// "truth.frame" (a tilted world frame: the columns are in the scene frame).
core::Result<ObstacleTruth> read_obstacle_truth(const std::filesystem::path& file);

/// Reads ground_cells.txt. Errors as read_obstacle_truth's.
core::Result<GroundTruth> read_ground_truth(const std::filesystem::path& file);

/// A tarmac-sim dataset's truth: DIR/obstacle_columns.txt and, when they are there,
/// DIR/ground_cells.txt and DIR/curb_columns.txt. Errors: read_obstacle_truth's,
/// read_ground_truth's, "truth.cells" (the lattices differ).
core::Result<ObstacleTruth> read_dataset_truth(const std::filesystem::path& dir);

/// One cycle's figures, over the obstacle columns within `radius_m` of the vehicle.
struct SafetyCycle {
  int scan = 0;
  std::size_t visible = 0;        ///< columns seen (a return from their span) by this scan
  std::size_t lethal_near = 0;    ///< of those, with a lethal cell within one cell
  std::size_t read_free = 0;      ///< of those, whose own cell reads free (0)
  std::size_t read_inflated = 0;  ///< of those, whose own cell reads 1..99 with no lethal near
  std::size_t read_unknown = 0;   ///< of those, whose own cell reads unknown (−1)
  std::size_t lethal_cells = 0;   ///< lethal cells within radius_m
  /// Of those, more than one cell from every obstacle column and from every moving object's
  /// box at this scan (a moving object's former place still lethal counts: a ghost).
  std::size_t false_lethal = 0;
  /// Open ground within kOpenRadiusM of the vehicle: cells more than one cell from every obstacle
  /// column (what a planner may drive), and of those the ones reading unknown (the cost of a
  /// conservative free rule).
  std::size_t open_cells = 0;
  std::size_t open_unknown = 0;
  [[nodiscard]] double share_open_known() const {
    return open_cells == 0
               ? 1.0
               : 1.0 - static_cast<double>(open_unknown) / static_cast<double>(open_cells);
  }
  [[nodiscard]] double share_lethal() const {
    return visible == 0 ? 1.0 : static_cast<double>(lethal_near) / static_cast<double>(visible);
  }
  /// Drivable ground within kGroundRadiusM of the vehicle: ground cells more than one cell from
  /// every obstacle column and from every moving object's box at this scan, and of those the
  /// ones reading lethal (the ground model taking ground for an obstacle).
  std::size_t ground_cells = 0;
  std::size_t ground_lethal = 0;
  /// The false lethal cells and the ground cells read lethal by the rule that made them lethal,
  /// when score_costmap was given the costmap's rules.
  LethalCauseCounts false_lethal_by_cause, ground_lethal_by_cause;
  /// Of those, the ones the vehicle can drive to inside the costmap's window: joined to the
  /// ground under it by ground cells (never an obstacle column) whose heights step by at most
  /// kReachStepM. Ground the window holds no way to (an upper level beyond walls whose ramp lies
  /// outside the window) is not; a local costmap cannot tell it from a plateau.
  std::size_t reach_cells = 0;
  std::size_t reach_lethal = 0;
  /// Of the visible columns, the curbs' (first seen by a return from a curb), and of those the
  /// ones with a lethal cell within one cell.
  std::size_t curb_visible = 0;
  std::size_t curb_lethal_near = 0;
  [[nodiscard]] double share_curb_lethal() const {
    return curb_visible == 0
               ? 1.0
               : static_cast<double>(curb_lethal_near) / static_cast<double>(curb_visible);
  }
  [[nodiscard]] double share_ground_lethal() const {
    return ground_cells == 0
               ? 0.0
               : static_cast<double>(ground_lethal) / static_cast<double>(ground_cells);
  }
  [[nodiscard]] double share_reach_lethal() const {
    return reach_cells == 0 ? 0.0
                            : static_cast<double>(reach_lethal) / static_cast<double>(reach_cells);
  }
};

struct SafetyReport {
  std::size_t cycles = 0;
  double worst_share = 1.0, mean_share = 1.0;  ///< lethal_near / visible over the cycles
  int worst_scan = -1;
  std::size_t read_free = 0, read_inflated = 0, read_unknown = 0;  ///< summed over cycles
  std::size_t lethal_cells = 0, false_lethal = 0;                  ///< summed over cycles
  double worst_false_share = 0.0;  ///< max over cycles of false_lethal / lethal_cells
  double worst_open_known = 1.0, mean_open_known = 1.0;  ///< SafetyCycle::share_open_known
  std::size_t ground_cells = 0, ground_lethal = 0;       ///< summed over cycles
  LethalCauseCounts false_lethal_by_cause, ground_lethal_by_cause;  ///< summed over cycles
  /// SafetyCycle::share_ground_lethal: the worst cycle (and its scan; −1: no cycle read any
  /// ground lethal) and the mean over the cycles with ground cells.
  double worst_ground_lethal = 0.0, mean_ground_lethal = 0.0;
  int worst_ground_scan = -1;
  /// The same for the ground the vehicle can reach inside the window (SafetyCycle::reach_cells).
  std::size_t reach_cells = 0, reach_lethal = 0;
  double worst_reach_lethal = 0.0, mean_reach_lethal = 0.0;
  int worst_reach_scan = -1;
  /// The truth has curbs; then SafetyCycle::share_curb_lethal over the cycles that saw one: the
  /// worst (and its scan; −1: none below 100 %) and the mean.
  bool curbs = false;
  double worst_curb_share = 1.0, mean_curb_share = 1.0;
  int worst_curb_scan = -1;
};

/// The radius of the open-ground figure (SafetyCycle::open_cells), m.
inline constexpr double kOpenRadiusM = 10.0;
/// The radius of the drivable-ground figure (SafetyCycle::ground_cells), m.
inline constexpr double kGroundRadiusM = 30.0;
/// The largest height step between neighbouring ground cells (0.2 m) that joins them for
/// SafetyCycle::reach_cells, m: a 50 % grade; tarmac-sim's curbs are obstacle columns anyway.
inline constexpr double kReachStepM = 0.1;

/// Scores one costmap (values 0..100, −1) whose cells lie on the truth's lattice (the costmap's
/// resolution must equal cell_m and its origin a lattice point). `moving` are the moving
/// objects' boxes at this scan (tarmac-sim's dynamic_boxes.txt), scene frame. The obstacle
/// figures are taken within radius_m, the ground figure within kGroundRadiusM. `causes`, when
/// known, are the costmap's rules: the false lethal cells and the ground read lethal are then
/// counted by the rule that made them lethal.
SafetyCycle score_costmap(const core::Costmap& costmap, const ObstacleTruth& truth, int scan,
                          const Eigen::Vector2d& vehicle_xy, double radius_m = 20.0,
                          std::span<const DynamicBox> moving = {},
                          const LethalCauseView& causes = {});

/// Accumulates cycles into a report.
class SafetyTracker {
 public:
  explicit SafetyTracker(ObstacleTruth truth) : truth_(std::move(truth)) {}
  const SafetyCycle& observe(const core::Costmap& costmap, int scan,
                             const Eigen::Vector2d& vehicle_xy, double radius_m = 20.0,
                             std::span<const DynamicBox> moving = {},
                             const LethalCauseView& causes = {});
  [[nodiscard]] SafetyReport report() const;
  [[nodiscard]] const std::vector<SafetyCycle>& cycles() const { return cycles_; }

 private:
  ObstacleTruth truth_;
  std::vector<SafetyCycle> cycles_;
};

/// The one-line summary that tarmac-map and tarmac-audit print ("safety (...)"), no newline.
std::string safety_summary(const SafetyReport& report);

/// The report and every cycle as one JSON object (the value of "safety" in tarmac-map's
/// timing.json and tarmac-audit's --json): the report's fields, "cycle_fields" naming the columns
/// and "per_cycle", one array per cycle in observation order.
nlohmann::ordered_json safety_json(const SafetyTracker& tracker);

}  // namespace tarmac::tools
