/// @file OccupancyMap::integrate's changed columns against a brute-force diff of the window: the
/// log-odds and rises of every voxel before and after each scan, on random scenes (every walk
/// path, one thread and two, windows whose layers are not whole mark words) and on a scene
/// scanned until its voxels sit at the clamps and join, then leave, the static layer.

#include "tarmac/core/occupancy_map.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/daemon/thread_pool.hpp"

#include "../support/apron_scene.hpp"
#include "occupancy_test_util.hpp"

namespace tarmac::core {
namespace {

/// Every voxel's log-odds and rise, window order (z slowest, x fastest).
struct Snapshot {
  std::vector<float> log_odds;
  std::vector<std::uint8_t> rise;
};

Snapshot snapshot(const OccupancyMap& map) {
  Snapshot s;
  map.export_log_odds(s.log_odds);
  const Eigen::Vector3i d = map.window_size();
  for (int z = 0; z < d.z(); ++z) {
    const std::uint8_t* layer = map.ring_layer_rise_cm(z);
    for (int y = 0; y < d.y(); ++y) {
      for (int x = 0; x < d.x(); ++x) {
        s.rise.push_back(layer[static_cast<std::size_t>(map.ring_y(y)) * d.x() + map.ring_x(x)]);
      }
    }
  }
  return s;
}

/// The columns whose voxels differ between `a` and `b`, against what integrate() returned: the
/// first column where they disagree, or "" (and the count of changed columns in `n`).
std::string compare(const OccupancyMap& map, const Snapshot& a, const Snapshot& b,
                    const ChangedColumns& changed, std::size_t& n) {
  const Eigen::Vector3i d = map.window_size();
  n = 0;
  for (int y = 0; y < d.y(); ++y) {
    for (int x = 0; x < d.x(); ++x) {
      bool differs = false;
      for (int z = 0; z < d.z() && !differs; ++z) {
        const std::size_t i = (static_cast<std::size_t>(z) * d.y() + y) * d.x() + x;
        // Bitwise: kUnknown and the clamps are exact values.
        differs = a.log_odds[i] != b.log_odds[i] || a.rise[i] != b.rise[i];
      }
      n += differs ? 1 : 0;
      if (differs != changed.contains(x, y)) {
        return "column " + std::to_string(x) + "," + std::to_string(y) +
               (differs ? " changed, not returned" : " returned, unchanged");
      }
    }
  }
  if (changed.count() != n) return "count " + std::to_string(changed.count());
  return "";
}

TEST(OccupancyChanged, RandomScenesReturnExactlyTheColumnsWhoseVoxelsChanged) {
  occupancy_test::RandomDraws draw(7);
  const auto u = [&](double a, double b) { return draw.real(a, b); };
  const auto pick = [&](int a, int b) { return draw.pick(a, b); };
  daemon::ThreadPool pool(2);
  SerialRunner serial;
  std::size_t changed_total = 0, scans = 0;
  for (int it = 0; it < 40; ++it) {
    OccupancyParams p;
    p.voxel_size_m = it % 2 == 0 ? 0.2 : 0.5;
    p.window_x_vox = pick(5, 48);  // layers of any length, rarely whole mark words
    p.window_y_vox = pick(5, 48);
    p.window_z_vox = pick(4, 16);
    p.window_below_m = u(0.5, p.window_z_vox * p.voxel_size_m);
    p.max_range_m = u(2.0, 20.0);
    p.clearing_range_m = u(0.0, 20.0);
    p.static_promote_scans = pick(0, 4);
    p.static_demote_scans = pick(1, 3);
    ASSERT_TRUE(p.validate().ok());
    OccupancyMap map(p);
    const int lanes[] = {1, 4, 8};
    map.set_walk_lanes(lanes[it % 3]);
    Eigen::Vector3d origin(u(-3.0, 3.0), u(-3.0, 3.0), u(-1.0, 1.0));
    // A few fixed surfaces the scans return from again and again (the clamps, the static
    // layer), and scattered returns.
    std::vector<Eigen::Vector3f> fixed;
    for (int i = pick(5, 60); i > 0; --i) {
      fixed.emplace_back(static_cast<float>(u(-6, 6)), static_cast<float>(u(-6, 6)),
                         static_cast<float>(u(-1.5, 1.5)));
    }
    for (int s = 0; s < 12; ++s) {
      std::vector<Eigen::Vector3f> points, dirs;
      for (const Eigen::Vector3f& f : fixed) {
        if (pick(0, 5) != 0) points.push_back(f);
      }
      for (int i = pick(0, 200); i > 0; --i) {
        const Eigen::Vector3d dir = Eigen::Vector3d(u(-1, 1), u(-1, 1), u(-1, 1)).normalized();
        points.push_back((origin + dir * u(0.0, 25.0)).cast<float>());
      }
      if (pick(0, 6) == 0) points.emplace_back(std::nanf(""), 0.0f, 0.0f);
      for (int i = pick(0, 20); i > 0; --i) {
        dirs.push_back(Eigen::Vector3d(u(-1, 1), u(-1, 1), u(-1, 1)).cast<float>());
      }
      TaskRunner& runner = s % 2 == 0 ? static_cast<TaskRunner&>(serial) : pool;
      if (pick(0, 3) == 0) origin += Eigen::Vector3d(u(-2, 2), u(-2, 2), u(-0.5, 0.5));
      map.recenter(origin, runner);
      const Snapshot before = snapshot(map);
      const OccupancyUpdate update = map.integrate(origin, points, dirs, runner);
      std::size_t n = 0;
      ASSERT_EQ("", compare(map, before, snapshot(map), update.changed, n))
          << "scene " << it << " scan " << s;
      changed_total += n;
      ++scans;
    }
  }
  EXPECT_EQ(scans, 480u);
  EXPECT_GT(changed_total, 1000u);  // the scans did change the windows
}

TEST(OccupancyChanged, AScanThatChangesNothingReturnsNoColumn) {
  // The apron's ground and a box, scanned until every voxel the rays cross sits at a clamp: the
  // next identical scan changes no voxel and returns no column; a box gone changes its columns.
  OccupancyParams p = test::apron_window_params();
  p.static_promote_scans = 0;  // no static layer: the box's voxels leave after their misses
  OccupancyMap map(p);
  std::vector<Eigen::Vector3f> box;
  test::add_box(box, {3.0f, -0.5f, 0.0f}, {4.0f, 0.5f, 1.0f});
  std::vector<Eigen::Vector3f> ground;
  for (float x = -12.0f; x <= 12.0f; x += 0.1f) {
    for (float y = -12.0f; y <= 12.0f; y += 0.1f)
      ground.emplace_back(x + 0.013f, y + 0.017f, 0.05f);
  }
  std::vector<Eigen::Vector3f> with_box = ground;
  with_box.insert(with_box.end(), box.begin(), box.end());
  SerialRunner runner;
  const Eigen::Vector3d sensor(0.05, 0.05, 2.0);
  OccupancyUpdate first = map.integrate(sensor, with_box, {}, runner);
  EXPECT_GT(first.changed.count(), 10000u);
  for (int i = 0; i < 30; ++i) map.integrate(sensor, with_box, {}, runner);
  Snapshot before = snapshot(map);
  OccupancyUpdate same = map.integrate(sensor, with_box, {}, runner);
  std::size_t n = 0;
  EXPECT_EQ("", compare(map, before, snapshot(map), same.changed, n));
  EXPECT_EQ(0u, same.changed.count());
  before = snapshot(map);
  OccupancyUpdate gone = map.integrate(sensor, ground, {}, runner);
  EXPECT_EQ("", compare(map, before, snapshot(map), gone.changed, n));
  EXPECT_GT(n, 0u);
  // Only the box's columns and those whose rays the box used to block.
  const Eigen::Vector3i w = map.window_min();
  const int box_x = static_cast<int>(std::floor(3.5 / p.voxel_size_m)) - w.x();
  const int box_y = static_cast<int>(std::floor(0.0 / p.voxel_size_m)) - w.y();
  EXPECT_TRUE(gone.changed.contains(box_x, box_y));
  EXPECT_FALSE(gone.changed.contains(box_x - 25, box_y));  // behind the sensor
}

}  // namespace
}  // namespace tarmac::core
