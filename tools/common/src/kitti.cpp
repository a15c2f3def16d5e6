#include "tarmac/tools/kitti.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

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
  if (std::ifstream shape(dir / "organised" / "shape.txt"); shape) {
    if (!(shape >> seq.rows >> seq.cols) || seq.rows == 0 || seq.cols == 0 ||
        seq.rows * seq.cols > (std::size_t{1} << 24)) {
      return core::Error{"dataset.organised", "organised/shape.txt: needs \"rows cols\""};
    }
    for (const auto& scan : seq.scans) {
      seq.organised.push_back(dir / "organised" / scan.filename());
      if (!std::filesystem::is_regular_file(seq.organised.back(), ec)) {
        return core::Error{"dataset.organised",
                           seq.organised.back().string() + ": missing (one per scan)"};
      }
    }
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

core::Status read_organised_scan(const std::filesystem::path& file, std::size_t rows,
                                 std::size_t cols, core::PointCloud& cloud,
                                 core::OrganisedScratch& scratch) {
  if (auto s = read_kitti_scan(file, cloud); !s) return s;
  if (cloud.size() != rows * cols) {
    return core::Error{"dataset.scan", file.string() + ": " + std::to_string(cloud.size()) +
                                           " cells, organised/shape.txt says " +
                                           std::to_string(rows) + " x " + std::to_string(cols)};
  }
  cloud.grid_rows = static_cast<std::uint32_t>(rows);
  core::organise(cloud, scratch);
  return core::Ok{};
}

core::Status read_sequence_scan(const KittiSequence& seq, std::size_t k, core::PointCloud& cloud,
                                core::OrganisedScratch& scratch) {
  return seq.organised.empty()
             ? read_kitti_scan(seq.scans[k], cloud)
             : read_organised_scan(seq.organised[k], seq.rows, seq.cols, cloud, scratch);
}

core::Result<std::vector<Correction>> read_corrections(const std::filesystem::path& file) {
  std::ifstream in(file);
  const std::string path = file.string();
  if (!in) return core::Error{"corrections.open", path + ": cannot be read"};
  std::vector<Correction> out;
  std::string line;
  for (std::size_t n = 1; std::getline(in, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    long long k = -1;
    double stamp_s = 0.0;
    double m[12];
    ls >> k >> stamp_s;
    for (double& x : m) ls >> x;
    std::string rest;
    if (!ls || k < 0 || !std::isfinite(stamp_s) || (ls >> rest)) {
      return core::Error{"corrections.format",
                         path + ":" + std::to_string(n) + ": expected 'K stamp_s' and 12 numbers"};
    }
    core::StampedPose p;
    p.stamp_ns = std::llround(stamp_s * 1e9);
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    for (int i = 0; i < 12; ++i) T(i / 4, i % 4) = m[i];
    p.T_W_B.matrix() = T;
    const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
    if (!T.allFinite() || !(R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-6)) {
      return core::Error{"corrections.format",
                         path + ":" + std::to_string(n) + ": not a rigid transform"};
    }
    if (out.empty() || out.back().after_scan != static_cast<std::size_t>(k)) {
      out.push_back({static_cast<std::size_t>(k), {}});
    } else if (p.stamp_ns <= out.back().trajectory_W_S.back().stamp_ns) {
      return core::Error{"corrections.format",
                         path + ":" + std::to_string(n) + ": stamps must increase"};
    }
    out.back().trajectory_W_S.push_back(p);
  }
  return out;
}

}  // namespace tarmac::tools
