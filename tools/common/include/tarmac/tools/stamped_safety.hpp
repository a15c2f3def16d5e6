#pragma once
/// @file Scores costmaps that arrive stamped — tarmacd's, read over DDS — against a dataset's
/// ground truth, as tarmac-map scores its own costmap after every scan.
///
/// tarmacd stamps a costmap with the newest scan it has integrated (README "DDS types and
/// topics"), and a cycle may integrate several scans or none. A costmap is therefore scored as
/// the map of the latest scan whose stamp is at or before its own; the scans' stamps come from
/// outside, in scan order (tarmac-audit learns them from the replayed pose stream: one pose per
/// scan, stamped like it).

#include <cstdint>
#include <deque>
#include <optional>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/small_objects.hpp"

namespace tarmac::tools {

class StampedSafetyScorer {
 public:
  /// `vehicle_xy[k]`: the vehicle's position at scan k, map frame (one per scan of the
  /// dataset); `moving`: the moving objects' boxes (dynamic_boxes.txt; may be empty).
  StampedSafetyScorer(ObstacleTruth truth, std::vector<Eigen::Vector2d> vehicle_xy,
                      std::vector<DynamicBox> moving, double radius_m = 20.0);

  /// The stamp of the next scan (scan scans_stamped()). Errors: "safety.stamp_order" (not after
  /// the previous scan's), "safety.too_many_scans" (more scans than vehicle positions).
  core::Status add_scan_stamp(std::int64_t stamp_ns);

  /// A costmap stamped `stamp_ns`. Scored at once when its scan is known (a scan stamped at or
  /// after it has been added), else kept until one is or until finish(). Error:
  /// "safety.resolution" (its cells are not the truth's; nothing is scored).
  core::Status add_costmap(core::Costmap costmap, std::int64_t stamp_ns);

  /// Scores the costmaps still waiting against the latest scan added at or before their stamp;
  /// those older than every scan are counted in before_first_scan().
  void finish();

  /// Also scores each small object (small_objects.txt) in every costmap scored.
  void score_small_objects(std::vector<SmallObject> objects) { small_.emplace(std::move(objects)); }

  [[nodiscard]] const SafetyTracker& tracker() const { return tracker_; }
  /// The small objects' scores (score_small_objects()), or nullptr.
  [[nodiscard]] const SmallObjectTracker* small_objects() const {
    return small_ ? &*small_ : nullptr;
  }
  [[nodiscard]] std::size_t scans_stamped() const { return scan_stamps_ns_.size(); }
  /// Costmaps scored.
  [[nodiscard]] std::size_t costmaps() const { return tracker_.cycles().size(); }
  /// Scans that at least one costmap was scored against.
  [[nodiscard]] std::size_t scans_with_costmap() const { return scans_with_costmap_; }
  /// Costmaps whose stamp is not exactly a scan's (tarmacd's always are).
  [[nodiscard]] std::size_t stamp_not_a_scan() const { return stamp_not_a_scan_; }
  /// Costmaps stamped before the first scan (not scored).
  [[nodiscard]] std::size_t before_first_scan() const { return before_first_scan_; }

 private:
  /// Scores `costmap` against the latest scan at or before `stamp_ns`, if there is one.
  void score(const core::Costmap& costmap, std::int64_t stamp_ns);

  SafetyTracker tracker_;
  std::optional<SmallObjectTracker> small_;
  double cell_m_;
  double radius_m_;
  std::vector<Eigen::Vector2d> vehicle_xy_;
  std::vector<DynamicBox> moving_;
  std::vector<std::int64_t> scan_stamps_ns_;
  std::deque<std::pair<std::int64_t, core::Costmap>> waiting_;  ///< (stamp, costmap), in arrival
  std::vector<DynamicBox> moving_now_;
  std::vector<bool> scan_scored_;  ///< per scan: a costmap was scored against it
  std::size_t scans_with_costmap_ = 0;
  std::size_t stamp_not_a_scan_ = 0;
  std::size_t before_first_scan_ = 0;
};

}  // namespace tarmac::tools
