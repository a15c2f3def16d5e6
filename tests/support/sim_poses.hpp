#pragma once
/// @file tarmac-sim's poses.txt read back for the simulator's tests (row-major 3×4
/// T_world_sensor per line). Header-only: sim_tests link no test support library.

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace tarmac::test {

inline std::vector<Eigen::Isometry3d> read_sim_poses(const std::filesystem::path& file) {
  std::vector<Eigen::Isometry3d> poses;
  std::ifstream in(file);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) s >> T.matrix()(r, c);
    }
    EXPECT_TRUE(static_cast<bool>(s)) << line;
    poses.push_back(T);
  }
  return poses;
}

}  // namespace tarmac::test
