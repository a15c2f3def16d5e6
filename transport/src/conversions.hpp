#pragma once
/// @file Internal: IDL <-> core conversion. The only place where ROS message layouts meet core
/// types. PointCloud2 parsing follows the message's own field table (name, offset, datatype,
/// endianness); nothing about the layout is assumed.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "builtin_interfaces.h"
#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"
#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/debris.hpp"
#include "tarmac/core/distance_field.hpp"
#include "tarmac/core/esdf_band.hpp"
#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/core/grid2d.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/cycle_report.hpp"
#include "tarmac/transport/inputs.hpp"
#include "tarmac/transport/lidar_driver.hpp"
#include "tarmac_msgs.h"

namespace tarmac::transport {

using TimeMsg = builtin_interfaces::msg::dds_::Time_;
using PointCloud2Msg = sensor_msgs::msg::dds_::PointCloud2_;
using OccupancyGridMsg = nav_msgs::msg::dds_::OccupancyGrid_;
using PoseMsg = geometry_msgs::msg::dds_::Pose_;
using PoseStampedMsg = geometry_msgs::msg::dds_::PoseWithCovarianceStamped_;
using OdometryMsg = nav_msgs::msg::dds_::Odometry_;
using PathMsg = nav_msgs::msg::dds_::Path_;
using DistanceMapSliceMsg = tarmac_msgs::msg::dds_::DistanceMapSlice_;
using DistanceMapVolumeMsg = tarmac_msgs::msg::dds_::DistanceMapVolume_;
using CycleReportMsg = tarmac_msgs::msg::dds_::CycleReport_;
using VirtualObstacleArrayMsg = tarmac_msgs::msg::dds_::VirtualObstacleArray_;
using DiagnosticArrayMsg = diagnostic_msgs::msg::dds_::DiagnosticArray_;
using FleetBevMsg = tarmac_msgs::msg::dds_::FleetBev_;
using DebrisArrayMsg = tarmac_msgs::msg::dds_::DebrisArray_;

/// ns since the epoch <-> builtin_interfaces/Time (sec may be negative; nanosec in [0, 1e9)).
TimeMsg to_time_msg(std::int64_t stamp_ns);
std::int64_t from_time_msg(const TimeMsg& time);

/// Costmap -> nav_msgs/OccupancyGrid in `frame_id`, origin at the grid corner, identity rotation.
OccupancyGridMsg to_occupancy_grid(const core::Costmap& costmap, std::int64_t stamp_ns,
                                   const std::string& frame_id);
/// Same, into an existing message (its buffers are reused: no allocation once sized).
void fill_occupancy_grid(const core::Costmap& costmap, std::int64_t stamp_ns,
                         const std::string& frame_id, OccupancyGridMsg& msg);
/// nav_msgs/OccupancyGrid -> Costmap. Rejects sizes that do not match and rotated origins.
core::Result<core::Costmap> from_occupancy_grid(const OccupancyGridMsg& msg);

/// PointCloud -> PointCloud2, little endian, fields x y z (float32) then intensity (float32),
/// ring (uint16) and time (float32, s relative to the stamp) when present. Dense, height 1.
PointCloud2Msg to_point_cloud2(const core::PointCloud& cloud);

/// What from_point_cloud2 took from a cloud without rejecting it, worth counting.
struct CloudNotes {
  /// The per-point time field could not be related to the stamp (its values' median is more
  /// than 10 s from it in every unit and origin drivers use): dropped, no deskew.
  bool time_unrelated = false;
};

/// Parses a PointCloud2 into `out` (cleared first, capacity kept). x, y, z are required and may
/// be any numeric datatype; `intensity`, the ring (`ring`, or Autoware's `channel`) and the
/// point time (`t`, `time`, `timestamp` or `time_stamp`) are optional. The time's unit and
/// origin are told from its datatype and the median of a sample of its finite values: integer
/// nanoseconds or floating seconds from the stamp, or floating absolute seconds or nanoseconds
/// (docs/ros2.md, "LiDAR drivers"); a point time more than 10 s from the stamp reads NaN (taken as
/// the stamp). Either endianness, any offsets and padding, row padding honoured. Points whose x, y
/// or z is not finite are kept (filters count them); the caller decides. Rejections carry a code
/// "pointcloud.<reason>" and a message naming the offending field or size.
/// With a `driver` other than kAuto, the ring and time fields are that driver's (by name and
/// datatype, the time's origin and unit fixed, nothing told from the values); a message without
/// them is rejected: "pointcloud.driver_mismatch".
core::Status from_point_cloud2(const PointCloud2Msg& msg, core::PointCloud& out,
                               CloudNotes* notes = nullptr,
                               LidarDriver driver = LidarDriver::kAuto);

/// Isometry -> geometry_msgs/Pose (unit quaternion from the rotation).
PoseMsg to_pose_msg(const Eigen::Isometry3d& T);
/// geometry_msgs/Pose -> isometry. Rejects non-finite values ("pose.non_finite") and quaternions
/// whose norm is off by more than 1e-3 ("pose.bad_quaternion"); the quaternion is normalised.
core::Result<Eigen::Isometry3d> from_pose_msg(const PoseMsg& msg);

/// nav_msgs/Path -> a corrected trajectory in `frame_id` (TrajectoryInput's rules). `poses` is
/// cleared (capacity kept) and receives every pose, stamps strictly increasing. Returns when the
/// correction was made: the header stamp, or the newest pose's when that is zero. Rejections:
/// "correction.unknown_frame" (the header, or a pose whose frame_id is neither empty nor
/// `frame_id`), "correction.empty", "correction.unsorted" and the from_pose_msg codes.
/// Allocates only for paths longer than any before, and for the error text.
core::Result<std::int64_t> from_path_msg(const PathMsg& msg, const std::string& frame_id,
                                         std::vector<PoseSample>& poses);

/// 2D distance field on `geometry` -> DistanceMapSlice (NaN where unknown, the sentinel says so;
/// +inf where no obstacle is in the window). Reuses the message's buffers.
void fill_distance_slice(const core::DistanceField& field, const core::GridGeometry2D& geometry,
                         std::int64_t stamp_ns, const std::string& frame_id,
                         DistanceMapSliceMsg& msg);

/// The 3D ESDF band -> DistanceMapVolume: the box of the band's voxels whose x and y lie within
/// `radius_m` (rounded out to whole voxels) of `centre_W` (the vehicle), clipped to the band;
/// radius_m 0 takes the whole band. NaN where unknown (the sentinel says so), +inf where no
/// obstacle is in the window. Reuses the message's buffers.
void fill_distance_volume(const core::EsdfBand& band, const Eigen::Vector2d& centre_W,
                          double radius_m, std::int64_t stamp_ns, const std::string& frame_id,
                          DistanceMapVolumeMsg& msg);

/// CycleReport -> tarmac_msgs/CycleReport, reusing the message's buffers.
void fill_cycle_report(const CycleReport& report, CycleReportMsg& msg);
/// tarmac_msgs/CycleReport -> CycleReport (tools and tests).
CycleReport from_cycle_report(const CycleReportMsg& msg);
void fill_diagnostic_array(const DiagnosticReport& report, DiagnosticArrayMsg& msg);

/// Debris -> tarmac_msgs/DebrisArray in `frame_id` (position z: the ground under it), reusing
/// the message's buffers (debris_conversions.cpp).
void fill_debris_array(std::span<const core::Debris> debris, std::int64_t stamp_ns,
                       const std::string& frame_id, DebrisArrayMsg& msg);
/// tarmac_msgs/DebrisArray -> debris (tools and tests; `objects` is not carried: 0).
std::vector<core::Debris> from_debris_array(const DebrisArrayMsg& msg);

/// VirtualObstacleArray -> zones (KIND_RESTRICTED -> restricted, every other kind -> no-go).
/// Rejects polygons with fewer than 3 vertices or non-finite coordinates ("zones.*").
core::Result<std::vector<core::VirtualZone>> from_virtual_obstacles(
    const VirtualObstacleArrayMsg& msg);

/// A fleet summary -> tarmac_msgs/FleetBev in `frame_id`.
FleetBevMsg to_fleet_bev(const core::BevMessage& message, const std::string& frame_id);
/// The same into `msg`, whose buffers are reused.
void fill_fleet_bev(const core::BevMessage& message, const std::string& frame_id, FleetBevMsg& msg);
/// tarmac_msgs/FleetBev -> a fleet summary. Rejects a frame other than `frame_id` (the summaries
/// are in the shared map frame), a non-finite or non-positive resolution and an empty vehicle id
/// ("fleet.*"); the tiles' contents are checked where they are applied (BevPeers::apply).
core::Result<core::BevMessage> from_fleet_bev(const FleetBevMsg& msg, const std::string& frame_id);

}  // namespace tarmac::transport
