#pragma once
/// @file One simulated sweep as a ROS 2 LiDAR driver publishes it: the PointCloud2 field table,
/// datatypes, point_step with the driver's padding, layout, ring order, no-return marker and
/// point times, each as that driver's source builds them (docs/lidar-drivers.md names the
/// source and commit of every rule used here). Independent of DDS: the caller copies the result
/// into its message type.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "tarmac/sim/lidar.hpp"

namespace tarmac::sim {

/// The drivers modelled, each in its default configuration unless named.
enum class Driver : std::uint8_t {
  kOuster,             ///< ouster-ros `point_type: original`, organized: rows = beams
  kVelodyne,           ///< velodyne_pointcloud, organize_cloud: true: rows = firings
  kVelodyneList,       ///< velodyne_pointcloud, organize_cloud: false: a list
  kRslidarXYZIRT,      ///< rslidar_sdk POINT_TYPE XYZIRT, dense_points: false: rows = firings
  kHesai,              ///< HesaiLidar_ROS_2.0: a list, (0, 0, 0) kept for no return
  kAutowareXYZIRCAEDT  ///< Autoware / Nebula PointXYZIRCAEDT: a list
};

/// Every modelled driver, and its name for command lines ("ouster", "velodyne", ...).
const std::vector<Driver>& all_drivers();
std::string_view driver_name(Driver d);
/// The driver named `name`; false when there is none.
bool driver_from_name(std::string_view name, Driver& out);

/// A PointCloud2 field (sensor_msgs/PointField: datatype 2 UINT8, 4 UINT16, 6 UINT32,
/// 7 FLOAT32, 8 FLOAT64).
struct DriverField {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
};

/// A PointCloud2's contents (little-endian, as every modelled driver on x86 and ARM).
struct DriverCloud {
  std::int64_t stamp_ns = 0;  ///< header.stamp as the driver sets it
  std::uint32_t height = 0, width = 0, point_step = 0;
  std::vector<DriverField> fields;
  std::vector<std::uint8_t> data;  ///< height · width · point_step bytes
  bool is_dense = false;
};

/// The sweep taken at `sweep_start_ns`: `returns` as Lidar::scan gives them (one revolution of
/// `lidar`), fired over `sweep_period_s`. The driver's firing order runs clockwise from +x
/// (azimuth step j fired at k = (steps − j) % steps, at time k / steps · period), as the
/// modelled sensors turn; the points themselves are the sim's instantaneous ones.
DriverCloud encode_sweep(Driver driver, const LidarParams& lidar,
                         const std::vector<LidarReturn>& returns, std::int64_t sweep_start_ns,
                         double sweep_period_s);

/// The time (ns from `sweep_start_ns`) at which the driver says azimuth step j was fired, and
/// the offset of its point times from the cloud's stamp (what a reader must recover): for the
/// checks of a reader.
std::int64_t firing_time_ns(const LidarParams& lidar, int azimuth_step, double sweep_period_s);

}  // namespace tarmac::sim
