#pragma once
/// @file Internal: IDL <-> core conversion. The only place where ROS message layouts meet core
/// types. PointCloud2 parsing follows the message's own field table (name, offset, datatype,
/// endianness); nothing about the layout is assumed.

#include <cstdint>
#include <string>

#include "builtin_interfaces.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"
#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::transport {

using TimeMsg = builtin_interfaces::msg::dds_::Time_;
using PointCloud2Msg = sensor_msgs::msg::dds_::PointCloud2_;
using OccupancyGridMsg = nav_msgs::msg::dds_::OccupancyGrid_;

/// ns since the epoch <-> builtin_interfaces/Time (sec may be negative; nanosec in [0, 1e9)).
TimeMsg to_time_msg(std::int64_t stamp_ns);
std::int64_t from_time_msg(const TimeMsg& time);

/// Costmap -> nav_msgs/OccupancyGrid in `frame_id`, origin at the grid corner, identity rotation.
OccupancyGridMsg to_occupancy_grid(const core::Costmap& costmap, std::int64_t stamp_ns,
                                   const std::string& frame_id);
/// nav_msgs/OccupancyGrid -> Costmap. Rejects sizes that do not match and rotated origins.
core::Result<core::Costmap> from_occupancy_grid(const OccupancyGridMsg& msg);

/// PointCloud -> PointCloud2, little endian, fields x y z (float32) then intensity (float32),
/// ring (uint16) and time (float32, s relative to the stamp) when present. Dense, height 1.
PointCloud2Msg to_point_cloud2(const core::PointCloud& cloud);

/// Parses a PointCloud2 into `out` (cleared first, capacity kept). x, y, z are required and may
/// be any numeric datatype; `intensity`, `ring` and `time`/`t`/`timestamp` are optional. Either
/// endianness, any offsets and padding, row padding honoured. Points whose x, y or z is not
/// finite are kept (filters count them); the caller decides. Rejections carry a code
/// "pointcloud.<reason>" and a message naming the offending field or size.
core::Status from_point_cloud2(const PointCloud2Msg& msg, core::PointCloud& out);

}  // namespace tarmac::transport
