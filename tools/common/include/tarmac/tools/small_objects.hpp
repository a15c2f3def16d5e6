#pragma once
/// @file The score per small object (issue 39): for each cone, piece of debris, pole of
/// tarmac-sim's small_objects.txt, the first scan that returned two points from it and the
/// vehicle's distance then, the first costmap that read it lethal, and, from that first scan
/// with two returns on, the share of the cycles within the radius whose costmap read it lethal
/// (any cell of its footprint or next to it at 100).

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::tools {

/// One small object of the truth and what the costmaps read of it.
struct SmallObject {
  int id = 0;
  std::string name, kind;
  Eigen::Vector3d min_W = Eigen::Vector3d::Zero(), max_W = Eigen::Vector3d::Zero();
  std::map<int, int> returns;  ///< scan -> points returned from it
  int first_two = -1;          ///< the first scan with at least two returns, −1: none
  // Scored:
  double first_two_range_m = -1.0;  ///< the vehicle's distance at first_two
  int first_lethal = -1;            ///< the first scored cycle that read it lethal
  double first_lethal_range_m = -1.0;
  int cycles_near = 0;    ///< cycles within the radius from first_two on
  int cycles_lethal = 0;  ///< of those, read lethal

  [[nodiscard]] double height_m() const { return max_W.z() - min_W.z(); }
};

/// Reads small_objects.txt (tarmac-sim). Errors: "objects.open", "objects.parse" (with the line).
core::Result<std::vector<SmallObject>> read_small_objects(const std::filesystem::path& path);

class SmallObjectTracker {
 public:
  explicit SmallObjectTracker(std::vector<SmallObject> objects) : objects_(std::move(objects)) {}
  /// Scores the costmap of `scan` (values 0..100, −1) with the vehicle at `vehicle_xy`.
  void observe(const core::Grid2D<std::int8_t>& costmap, int scan,
               const Eigen::Vector2d& vehicle_xy, double radius_m = 20.0);
  [[nodiscard]] const std::vector<SmallObject>& objects() const { return objects_; }

 private:
  std::vector<SmallObject> objects_;
};

/// The lines tarmac-map prints: a summary ("small objects (...)") over the objects at least
/// `min_height_m` high (costmap.min_obstacle_height_m: a lower one is not an obstacle), and one
/// line per object, each ending in a newline.
std::string small_objects_summary(const SmallObjectTracker& tracker, double min_height_m,
                                  double radius_m = 20.0);
/// The objects as JSON (tarmac-map's timing.json "small_objects").
nlohmann::ordered_json small_objects_json(const SmallObjectTracker& tracker);

}  // namespace tarmac::tools
