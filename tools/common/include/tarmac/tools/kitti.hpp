#pragma once
/// @file Reading a sequence in KITTI layout: scans/NNNNNN.bin (float32 x, y, z, intensity, sensor
/// frame), poses.txt (row-major 3×4 T_world_sensor per scan), optional times.txt (s).

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/organised_scan.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/pose_correction.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::tools {

struct KittiSequence {
  std::filesystem::path dir;
  std::vector<std::filesystem::path> scans;  ///< sorted by name
  std::vector<Eigen::Isometry3d> T_W_S;      ///< one per scan
  std::vector<double> times_s;               ///< one per scan (10 Hz assumed when absent)
  /// The sweeps organised (tarmac-sim's organised/NNNNNN.bin: rows × cols cells, row-major,
  /// float32 x, y, z, intensity, NaN where a beam returned nothing; organised/shape.txt gives
  /// "rows cols"), one per scan, or empty when the sequence has none.
  std::vector<std::filesystem::path> organised;
  std::size_t rows = 0, cols = 0;
};

/// Opens a sequence; `poses_file` overrides poses.txt (e.g. poses_leveled.txt). Checks that
/// there is one pose per scan and that every rotation is orthonormal.
core::Result<KittiSequence> open_kitti(const std::filesystem::path& dir,
                                       const std::string& poses_file = "poses.txt");

/// Reads one scan into `cloud` (points in the sensor frame, intensity). Rejects files whose size
/// is not a multiple of 16 bytes.
core::Status read_kitti_scan(const std::filesystem::path& file, core::PointCloud& cloud);

/// Reads one organised sweep (rows × cols cells) into `cloud` as organised_scan.hpp splits it:
/// the returns as points, the beams without return as directions (cloud.no_return_S).
/// Rejects files of another size ("dataset.scan").
core::Status read_organised_scan(const std::filesystem::path& file, std::size_t rows,
                                 std::size_t cols, core::PointCloud& cloud,
                                 core::OrganisedScratch& scratch);

/// Reads scan k of `seq` as the mapper should see it: the organised sweep when the sequence has
/// them (read_organised_scan), else scans/NNNNNN.bin (read_kitti_scan).
core::Status read_sequence_scan(const KittiSequence& seq, std::size_t k, core::PointCloud& cloud,
                                core::OrganisedScratch& scratch);

/// One corrected trajectory of a corrections file (tarmac-sim --correct-at writes
/// corrections.txt), applied after scan `after_scan`.
struct Correction {
  std::size_t after_scan = 0;
  std::vector<core::StampedPose> trajectory_W_S;  ///< T_world_sensor, as poses.txt; stamps in s·1e9
};

/// Reads a corrections file: lines "K stamp_s r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz";
/// consecutive lines with the same K form one correction, stamps increasing within it.
/// Errors: "corrections.open", "corrections.format" (with the line number).
core::Result<std::vector<Correction>> read_corrections(const std::filesystem::path& path);

}  // namespace tarmac::tools
