#include "tarmac/tools/stamped_safety.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace tarmac::tools {

StampedSafetyScorer::StampedSafetyScorer(ObstacleTruth truth,
                                         std::vector<Eigen::Vector2d> vehicle_xy,
                                         std::vector<DynamicBox> moving, double radius_m)
    : tracker_(truth),
      cell_m_(truth.cell_m),
      radius_m_(radius_m),
      vehicle_xy_(std::move(vehicle_xy)),
      moving_(std::move(moving)),
      scan_scored_(vehicle_xy_.size(), false) {}

core::Status StampedSafetyScorer::add_scan_stamp(std::int64_t stamp_ns) {
  if (scan_stamps_ns_.size() >= vehicle_xy_.size()) {
    return core::Error{"safety.too_many_scans", "more scans stamped than the dataset has (" +
                                                    std::to_string(vehicle_xy_.size()) + ")"};
  }
  if (!scan_stamps_ns_.empty() && stamp_ns <= scan_stamps_ns_.back()) {
    return core::Error{"safety.stamp_order", "scan " + std::to_string(scan_stamps_ns_.size()) +
                                                 " is not stamped after the previous scan"};
  }
  scan_stamps_ns_.push_back(stamp_ns);
  // Costmaps arrive in stamp order: those at the front that this stamp settles are scored.
  while (!waiting_.empty() && waiting_.front().first <= stamp_ns) {
    score(waiting_.front().second, waiting_.front().first);
    waiting_.pop_front();
  }
  return core::Ok{};
}

core::Status StampedSafetyScorer::add_costmap(core::Costmap costmap, std::int64_t stamp_ns) {
  // nav_msgs/OccupancyGrid carries the resolution as float32: compare to that precision.
  if (std::abs(costmap.geometry().resolution_m - cell_m_) > 1e-6 * cell_m_) {
    return core::Error{"safety.resolution", "the costmap's cells are " +
                                                std::to_string(costmap.geometry().resolution_m) +
                                                " m, the truth's " + std::to_string(cell_m_) +
                                                " m"};
  }
  if (waiting_.empty() && !scan_stamps_ns_.empty() && scan_stamps_ns_.back() >= stamp_ns) {
    score(costmap, stamp_ns);
  } else {
    waiting_.emplace_back(stamp_ns, std::move(costmap));
  }
  return core::Ok{};
}

void StampedSafetyScorer::finish() {
  for (const auto& [stamp_ns, costmap] : waiting_) score(costmap, stamp_ns);
  waiting_.clear();
}

void StampedSafetyScorer::score(const core::Costmap& costmap, std::int64_t stamp_ns) {
  // The latest scan stamped at or before the costmap: the newest scan it can hold.
  const auto after = std::upper_bound(scan_stamps_ns_.begin(), scan_stamps_ns_.end(), stamp_ns);
  if (after == scan_stamps_ns_.begin()) {
    ++before_first_scan_;
    return;
  }
  const auto scan = static_cast<std::size_t>(after - scan_stamps_ns_.begin() - 1);
  if (scan_stamps_ns_[scan] != stamp_ns) ++stamp_not_a_scan_;
  if (!scan_scored_[scan]) {
    scan_scored_[scan] = true;
    ++scans_with_costmap_;
  }
  moving_now_.clear();
  for (const DynamicBox& b : moving_) {
    if (b.scan == static_cast<int>(scan)) moving_now_.push_back(b);
  }
  tracker_.observe(costmap, static_cast<int>(scan), vehicle_xy_[scan], radius_m_, moving_now_);
  if (small_) small_->observe(costmap, static_cast<int>(scan), vehicle_xy_[scan], radius_m_);
}

}  // namespace tarmac::tools
