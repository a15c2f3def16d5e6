#pragma once
/// @file How a LiDAR's PointCloud2 is read (`sensors[].driver`): told from each message
/// (`auto`), or as the named ROS 2 driver publishes it in its default configuration, its ring
/// and time fields, their datatypes and time origin fixed (docs/ros2.md, "LiDAR drivers"). No
/// Fast DDS here: the config includes it.

#include <cstdint>

namespace tarmac::transport {

enum class LidarDriver : std::uint8_t {
  kAuto,      ///< fields and time unit told from each message
  kOuster,    ///< ouster-ros `original`: ring u16, t u32 ns from the stamp
  kVelodyne,  ///< velodyne_pointcloud: ring u16, time f32 s from the stamp
  kRslidar,   ///< rslidar_sdk XYZIRT: ring u16, timestamp f64 absolute s
  kHesai,     ///< HesaiLidar_ROS_2.0: ring u16, timestamp f64 absolute s (per packet)
  kLivox,  ///< livox_ros_driver2 (PointCloud2): no ring (`line` is not one), timestamp f64 absolute
           ///< ns
  kAutoware,  ///< Autoware / Nebula PointXYZIRCAEDT: channel u16, time_stamp u32 ns from the stamp
};

}  // namespace tarmac::transport
