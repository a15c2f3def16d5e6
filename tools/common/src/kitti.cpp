#include "tarmac/tools/kitti.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace tarmac::tools {

core::Result<KittiSequence> open_kitti(const std::filesystem::path& dir,
                                       const std::string& poses_file) {
  KittiSequence seq;
  seq.dir = dir;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir / "scans", ec)) {
    return core::Error{"dataset.missing", (dir / "scans").string() + ": not a directory"};
  }
  for (const auto& entry : std::filesystem::directory_iterator(dir / "scans")) {
    if (entry.path().extension() == ".bin") seq.scans.push_back(entry.path());
  }
  std::sort(seq.scans.begin(), seq.scans.end());
  std::ifstream poses(dir / poses_file);
  if (!poses)
    return core::Error{"dataset.missing", (dir / poses_file).string() + ": cannot be read"};
  std::string line;
  int line_no = 0;
  while (std::getline(poses, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream in(line);
    Eigen::Matrix<double, 3, 4> m;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        if (!(in >> m(r, c)) || !std::isfinite(m(r, c))) {
          return core::Error{"dataset.pose", poses_file + ":" + std::to_string(line_no) +
                                                 ": needs 12 finite numbers"};
        }
      }
    }
    const Eigen::Matrix3d R = m.leftCols<3>();
    if ((R * R.transpose() - Eigen::Matrix3d::Identity()).norm() > 1e-3 || R.determinant() < 0.0) {
      return core::Error{"dataset.pose", poses_file + ":" + std::to_string(line_no) +
                                             ": rotation is not orthonormal"};
    }
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = R;
    T.translation() = m.col(3);
    seq.T_W_S.push_back(T);
  }
  if (seq.T_W_S.size() != seq.scans.size()) {
    return core::Error{"dataset.size", std::to_string(seq.scans.size()) + " scans but " +
                                           std::to_string(seq.T_W_S.size()) + " poses in " +
                                           poses_file};
  }
  std::ifstream times(dir / "times.txt");
  double t = 0.0;
  while (times && times >> t) seq.times_s.push_back(t);
  if (seq.times_s.size() != seq.scans.size()) {
    seq.times_s.clear();
    for (std::size_t i = 0; i < seq.scans.size(); ++i)
      seq.times_s.push_back(0.1 * static_cast<double>(i));
  }
  return seq;
}

core::Status read_kitti_scan(const std::filesystem::path& file, core::PointCloud& cloud) {
  cloud.clear();
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) return core::Error{"dataset.scan", file.string() + ": cannot be read"};
  const auto bytes = static_cast<std::size_t>(in.tellg());
  if (bytes % 16 != 0)
    return core::Error{"dataset.scan", file.string() + ": size is not a multiple of 16"};
  std::vector<float> raw(bytes / 4);
  in.seekg(0);
  in.read(reinterpret_cast<char*>(raw.data()), static_cast<std::streamsize>(bytes));
  const std::size_t n = bytes / 16;
  cloud.points_S.reserve(n);
  cloud.intensity.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    cloud.points_S.emplace_back(raw[4 * i], raw[4 * i + 1], raw[4 * i + 2]);
    cloud.intensity.push_back(raw[4 * i + 3]);
  }
  return core::Ok{};
}

}  // namespace tarmac::tools
