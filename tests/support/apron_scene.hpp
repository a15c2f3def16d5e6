#pragma once
/// @file A flat apron for core tests: a 32 × 32 × 8 m window at 0.2 m (bottom 3 m below the
/// base at the origin), ground returns at z 0.05 every 0.1 m within 12 m, seen from a sensor
/// 2 m up; objects are boxes of returns. Header-only: core tests link no test support library.

#include <vector>

#include <Eigen/Core>

#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::test {

/// A window of nx × ny × nz voxels, its bottom `below_m` under the base, rays up to `range_m`.
inline core::OccupancyParams window_params(int nx, int ny, int nz, double below_m, double range_m) {
  core::OccupancyParams p;
  p.window_x_vox = nx;
  p.window_y_vox = ny;
  p.window_z_vox = nz;
  p.window_below_m = below_m;
  p.max_range_m = range_m;
  return p;
}

inline core::OccupancyParams apron_window_params() {
  return window_params(160, 160, 40, 3.0, 40.0);
}

/// Returns filling the box [lo, hi] every 5 cm.
inline void add_box(std::vector<Eigen::Vector3f>& points, Eigen::Vector3f lo, Eigen::Vector3f hi) {
  for (float x = lo.x(); x <= hi.x(); x += 0.05f)
    for (float y = lo.y(); y <= hi.y(); y += 0.05f)
      for (float z = lo.z(); z <= hi.z(); z += 0.05f) points.emplace_back(x, y, z);
}

/// Integrates `objects` plus the apron's ground `times` times from the sensor 2 m up.
inline void scan_apron(core::OccupancyMap& map, const std::vector<Eigen::Vector3f>& objects,
                       int times = 3) {
  std::vector<Eigen::Vector3f> points = objects;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f)
      points.emplace_back(x + 0.013f, y + 0.017f, 0.05f);
  }
  core::SerialRunner runner;
  for (int i = 0; i < times; ++i)
    map.integrate(Eigen::Vector3d(0.05, 0.05, 2.0), points, {}, runner);
}

}  // namespace tarmac::test
