#pragma once
/// @file What the OccupancyMap tests share: a small window, a scan, the sampled reference
/// traversal of a segment, and a check of what the window holds.

#include <cstddef>
#include <cstdint>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/task_runner.hpp"

#include "../support/apron_scene.hpp"

namespace tarmac::core::occupancy_test {

/// 100 × 100 × 20 voxels of 0.2 m round the origin, 2 m of it below, rays to 8 m, clearing to 5.
inline OccupancyParams small_params() {
  OccupancyParams p = test::window_params(100, 100, 20, 2.0, 8.0);
  p.voxel_size_m = 0.2;
  p.clearing_range_m = 5.0;
  return p;
}

/// Draws for the random-scene tests, from one seeded generator: the same scenes every run.
class RandomDraws {
 public:
  explicit RandomDraws(std::uint64_t seed) : rng_(seed) {}
  /// Uniform in [a, b).
  double real(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }
  /// Uniform in [a, b].
  int pick(int a, int b) { return std::uniform_int_distribution<int>(a, b)(rng_); }

 private:
  std::mt19937_64 rng_;
};

struct Scan {
  Eigen::Vector3d origin;
  std::vector<Eigen::Vector3f> points;
  std::vector<Eigen::Vector3f> clearing;
};

inline OccupancyUpdate integrate(OccupancyMap& map, const Scan& scan) {
  SerialRunner runner;
  return map.integrate(scan.origin, scan.points, scan.clearing, runner);
}

/// Reference traversal: voxels crossed by the segment, found by sampling it every 1e-4 voxel.
inline std::set<std::tuple<int, int, int>> sampled_voxels(const Eigen::Vector3d& a,
                                                          const Eigen::Vector3d& b, double v) {
  std::set<std::tuple<int, int, int>> out;
  const int n = static_cast<int>((b - a).norm() / v * 1e4) + 1;
  for (int i = 0; i <= n; ++i) {
    const Eigen::Vector3d p = a + (b - a) * (static_cast<double>(i) / n);
    const Eigen::Vector3i q = (p / v).array().floor().cast<int>();
    out.emplace(q.x(), q.y(), q.z());
  }
  return out;
}

using VoxelSet = std::set<std::tuple<int, int, int>>;

/// What the small window (100 × 100 × 20 voxels around the origin) holds: the voxels reading
/// free and those reading one hit, and the first that has no business there (free but not in
/// `free`; with `hits`, hit but not in `hits`, or neither free, hit nor unknown).
struct WindowScan {
  std::size_t free = 0, hit = 0;
  std::string wrong;
};
inline WindowScan scan_window(const OccupancyMap& map, const VoxelSet& free, const VoxelSet* hits) {
  WindowScan out;
  const auto flag = [&](const char* what, int x, int y, int z) {
    if (out.wrong.empty()) {
      out.wrong = std::string(what) + " " + std::to_string(x) + "," + std::to_string(y) + "," +
                  std::to_string(z);
    }
  };
  for (int z = -10; z < 10; ++z)
    for (int y = -50; y < 50; ++y)
      for (int x = -50; x < 50; ++x) {
        const float l = map.log_odds(VoxelIndex(x, y, z));
        if (l == map.miss_log_odds()) {
          ++out.free;
          if (free.count({x, y, z}) == 0) flag("extra free voxel", x, y, z);
        } else if (hits == nullptr) {
          continue;
        } else if (l == map.hit_log_odds()) {
          ++out.hit;
          if (hits->count({x, y, z}) == 0) flag("extra hit voxel", x, y, z);
        } else if (l != OccupancyMap::kUnknown) {
          flag("voxel neither free, hit nor unknown", x, y, z);
        }
      }
  return out;
}

}  // namespace tarmac::core::occupancy_test
