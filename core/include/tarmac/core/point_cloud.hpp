#pragma once
/// @file One LiDAR scan as the core sees it: points in the sensor frame, structure of arrays.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace tarmac::core {

/// One scan of one LiDAR. Coordinates are metres in the sensor frame (`frame_id`).
/// Optional channels are either empty or exactly as long as `points_S`.
struct PointCloud {
  std::string frame_id;                   ///< sensor frame, e.g. "lidar_front"
  std::int64_t stamp_ns = 0;              ///< acquisition time of the scan, ns since the epoch
  std::vector<Eigen::Vector3f> points_S;  ///< x, y, z in the sensor frame, m
  std::vector<float> intensity;           ///< optional, sensor units
  std::vector<std::uint16_t> ring;        ///< optional, beam index
  std::vector<float> time_offset_s;       ///< optional, per-point time relative to stamp_ns, s
  /// Optional: unit directions (sensor frame) of the beams that returned nothing within the
  /// sensor's range. They clear free space like returns beyond range (OccupancyParams::
  /// clearing_range_m); organised_scan.hpp rebuilds them from an organised scan. Any length.
  std::vector<Eigen::Vector3f> no_return_S;
  /// As the source sent it: > 0, an organised sweep of `grid_rows` rows × size() / grid_rows
  /// columns, row-major, its cells without a return kept (NaN or 0,0,0), as a PointCloud2 with
  /// height > 1; 0, a list of points. core::organise (organised_scan.hpp), which Mapper::ingest
  /// runs, turns either into returns plus `no_return_S` and sets `organised`.
  std::uint32_t grid_rows = 0;
  bool organised = false;  ///< core::organise has run: `no_return_S` says all there is

  [[nodiscard]] std::size_t size() const { return points_S.size(); }
  [[nodiscard]] bool has_intensity() const { return !intensity.empty(); }
  [[nodiscard]] bool has_ring() const { return !ring.empty(); }
  [[nodiscard]] bool has_time() const { return !time_offset_s.empty(); }

  /// True when every optional channel is empty or matches the point count.
  [[nodiscard]] bool consistent() const;

  /// Empties every channel, keeping capacity (RT-safe after warm-up).
  void clear();
};

}  // namespace tarmac::core
