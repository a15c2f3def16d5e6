#include "conversions.hpp"

#include <chrono>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac_msgsPubSubTypes.h"

namespace tarmac::transport {
namespace {

namespace pf = sensor_msgs::msg::PointField_Constants;

core::PointCloud sample_cloud(bool optional_channels) {
  core::PointCloud cloud;
  cloud.frame_id = "lidar_front";
  cloud.stamp_ns = 1'700'000'000'123'456'789;
  for (int i = 0; i < 100; ++i) {
    cloud.points_S.emplace_back(0.5f * i, -0.25f * i, 0.01f * i - 1.0f);
    if (optional_channels) {
      cloud.intensity.push_back(3.0f * i);
      cloud.ring.push_back(static_cast<std::uint16_t>(i % 64));
      cloud.time_offset_s.push_back(1e-4f * i);
    }
  }
  return cloud;
}

void add_field(PointCloud2Msg& msg, const char* name, std::uint32_t offset, std::uint8_t type,
               std::uint32_t count = 1) {
  sensor_msgs::msg::dds_::PointField_ f;
  f.name(name);
  f.offset(offset);
  f.datatype(type);
  f.count(count);
  msg.fields().push_back(f);
}

template <typename T>
void put_be(std::vector<std::uint8_t>& data, std::size_t at, T value) {
  std::uint8_t raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T); ++i) data[at + i] = raw[sizeof(T) - 1 - i];
}

TEST(TimeMsg, RoundTripsIncludingBeforeTheEpoch) {
  for (const std::int64_t ns :
       {0LL, 1LL, 999'999'999LL, 1'700'000'000'123'456'789LL, -1LL, -1'500'000'000LL}) {
    const auto t = to_time_msg(ns);
    EXPECT_LT(t.nanosec(), 1'000'000'000u);
    EXPECT_EQ(from_time_msg(t), ns);
  }
  EXPECT_EQ(to_time_msg(-1).sec(), -1);
  EXPECT_EQ(to_time_msg(-1).nanosec(), 999'999'999u);
}

TEST(PointCloud2, RoundTripKeepsEveryChannel) {
  for (const bool optional : {false, true}) {
    const auto cloud = sample_cloud(optional);
    core::PointCloud back;
    ASSERT_TRUE(from_point_cloud2(to_point_cloud2(cloud), back).ok());
    EXPECT_EQ(back.frame_id, cloud.frame_id);
    EXPECT_EQ(back.stamp_ns, cloud.stamp_ns);
    EXPECT_EQ(back.points_S, cloud.points_S);
    EXPECT_EQ(back.intensity, cloud.intensity);
    EXPECT_EQ(back.ring, cloud.ring);
    EXPECT_EQ(back.time_offset_s, cloud.time_offset_s);
    EXPECT_TRUE(back.consistent());
  }
}

// A big-endian cloud with float64 coordinates, int16 intensity, padding between points and at
// the end of each row, and an unrelated field: parsed by name, offset and datatype alone.
TEST(PointCloud2, ParsesForeignLayoutBigEndianWithPadding) {
  PointCloud2Msg msg;
  msg.header().frame_id("lidar_rear");
  add_field(msg, "reflectivity", 0, pf::UINT8);
  add_field(msg, "z", 2, pf::FLOAT64);
  add_field(msg, "x", 10, pf::FLOAT64);
  add_field(msg, "y", 18, pf::FLOAT64);
  add_field(msg, "intensity", 26, pf::INT16);
  add_field(msg, "timestamp", 28, pf::FLOAT64);
  msg.is_bigendian(true);
  msg.height(2);
  msg.width(3);
  msg.point_step(40);
  msg.row_step(3 * 40 + 5);
  msg.data().assign(msg.row_step() * msg.height(), 0xAB);
  for (std::uint32_t r = 0; r < 2; ++r) {
    for (std::uint32_t c = 0; c < 3; ++c) {
      const std::size_t at = r * msg.row_step() + c * msg.point_step();
      const double i = r * 3 + c;
      put_be(msg.data(), at + 10, 1.5 * i);
      put_be(msg.data(), at + 18, -2.25 * i);
      put_be(msg.data(), at + 2, 0.125 * i);
      put_be(msg.data(), at + 26, static_cast<std::int16_t>(-100 * i));
      put_be(msg.data(), at + 28, 1e-3 * i);
    }
  }
  core::PointCloud cloud;
  ASSERT_TRUE(from_point_cloud2(msg, cloud).ok());
  ASSERT_EQ(cloud.size(), 6u);
  EXPECT_FALSE(cloud.has_ring());
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(cloud.points_S[i], Eigen::Vector3f(1.5f * i, -2.25f * i, 0.125f * i)) << i;
    EXPECT_EQ(cloud.intensity[i], -100.0f * i);
    EXPECT_FLOAT_EQ(cloud.time_offset_s[i], 1e-3f * i);
  }
  EXPECT_EQ(cloud.frame_id, "lidar_rear");
}

/// Four points x = 1..4 stamped `stamp_ns`, little endian, with one more field `name` of
/// `type` holding `times[i]` (written as that type), at offset 12 (packed, unaligned after it:
/// point_step 12 + size).
template <typename T>
PointCloud2Msg timed_msg(const char* name, std::uint8_t type, std::int64_t stamp_ns,
                         const std::vector<T>& times) {
  PointCloud2Msg msg;
  msg.header().frame_id("lidar");
  msg.header().stamp(to_time_msg(stamp_ns));
  add_field(msg, "x", 0, pf::FLOAT32);
  add_field(msg, "y", 4, pf::FLOAT32);
  add_field(msg, "z", 8, pf::FLOAT32);
  add_field(msg, name, 12, type);
  msg.height(1);
  msg.width(static_cast<std::uint32_t>(times.size()));
  msg.point_step(12 + sizeof(T));
  msg.row_step(msg.point_step() * msg.width());
  msg.data().assign(msg.row_step(), 0);
  for (std::size_t i = 0; i < times.size(); ++i) {
    const float x = 1.0f + i;
    std::memcpy(msg.data().data() + i * msg.point_step(), &x, 4);
    std::memcpy(msg.data().data() + i * msg.point_step() + 12, &times[i], sizeof(T));
  }
  return msg;
}

constexpr std::int64_t kStampNs = 1'767'225'600'123'456'789;  // 2026-01-01, ns since the epoch

// Each driver's per-point time, from the field table and its first value: docs/ros2.md.
TEST(PointCloud2, PointTimes_EachDriversUnitAndOrigin_SecondsFromTheStamp) {
  const std::vector<float> want = {0.0f, 0.025f, 0.05f, 0.0999f};
  const auto expect_times = [&](const PointCloud2Msg& msg, const std::vector<float>& expected,
                                float tolerance) {
    core::PointCloud cloud;
    CloudNotes notes;
    ASSERT_TRUE(from_point_cloud2(msg, cloud, &notes).ok());
    EXPECT_FALSE(notes.time_unrelated);
    ASSERT_EQ(cloud.time_offset_s.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
      EXPECT_NEAR(cloud.time_offset_s[i], expected[i], tolerance) << i;
    }
  };
  // ouster-ros `t`, Autoware `time_stamp`: uint32 ns from the stamp.
  const std::vector<std::uint32_t> ns = {0, 25'000'000, 50'000'000, 99'900'000};
  expect_times(timed_msg("t", pf::UINT32, kStampNs, ns), want, 1e-9f);
  expect_times(timed_msg("time_stamp", pf::UINT32, kStampNs, ns), want, 1e-9f);
  // velodyne `time`: float32 s from the stamp, which is the last packet's: negative.
  const std::vector<float> velodyne = {-0.0999f, -0.05f, -0.025f, 0.0f};
  expect_times(timed_msg("time", pf::FLOAT32, kStampNs, velodyne), velodyne, 0.0f);
  // rslidar_sdk / HesaiLidar_ROS_2.0 `timestamp`: float64 absolute s.
  const double stamp_s = static_cast<double>(kStampNs) * 1e-9;
  std::vector<double> absolute_s, absolute_ns;
  for (const float t : want) {
    absolute_s.push_back(stamp_s + t);
    absolute_ns.push_back(static_cast<double>(kStampNs) + t * 1e9);
  }
  expect_times(timed_msg("timestamp", pf::FLOAT64, kStampNs, absolute_s), want, 1e-6f);
  // livox_ros_driver2 `timestamp`: float64 absolute ns (not seconds since 1e9 epoch-seconds).
  expect_times(timed_msg("timestamp", pf::FLOAT64, kStampNs, absolute_ns), want, 1e-6f);
}

TEST(PointCloud2, PointTimesThatCannotBeRelatedToTheStamp_DroppedAndNoted) {
  // A sensor clock not synchronised (seconds since power-on) reads neither relative nor absolute:
  // no deskew rather than a wrong one, and the caller counts it.
  core::PointCloud cloud;
  CloudNotes notes;
  const std::vector<double> since_boot = {3600.0, 3600.05};
  ASSERT_TRUE(
      from_point_cloud2(timed_msg("timestamp", pf::FLOAT64, kStampNs, since_boot), cloud, &notes)
          .ok());
  EXPECT_TRUE(notes.time_unrelated);
  EXPECT_FALSE(cloud.has_time());
  EXPECT_EQ(cloud.size(), 2u);
  // One broken point among good ones reads NaN (taken as the stamp), the others keep theirs.
  const std::vector<float> one_broken = {0.01f, 1e6f, 0.02f};
  ASSERT_TRUE(
      from_point_cloud2(timed_msg("time", pf::FLOAT32, kStampNs, one_broken), cloud, &notes).ok());
  EXPECT_FALSE(notes.time_unrelated);
  EXPECT_EQ(cloud.time_offset_s[0], 0.01f);
  EXPECT_TRUE(std::isnan(cloud.time_offset_s[1]));
  EXPECT_EQ(cloud.time_offset_s[2], 0.02f);
}

TEST(PointCloud2, PointTimes_AJunkFirstCellDecidesNothing) {
  // Absolute seconds (rslidar_sdk) with a zero-filled first cell: the median decides, the junk
  // cell reads NaN (taken as the stamp), the others keep their times.
  const double stamp_s = static_cast<double>(kStampNs) * 1e-9;
  const std::vector<double> times = {0.0, stamp_s + 0.01, stamp_s + 0.02, stamp_s + 0.03};
  core::PointCloud cloud;
  CloudNotes notes;
  ASSERT_TRUE(
      from_point_cloud2(timed_msg("timestamp", pf::FLOAT64, kStampNs, times), cloud, &notes).ok());
  EXPECT_FALSE(notes.time_unrelated);
  ASSERT_EQ(cloud.time_offset_s.size(), 4u);
  EXPECT_TRUE(std::isnan(cloud.time_offset_s[0]));
  for (std::size_t i = 1; i < 4; ++i) {
    EXPECT_NEAR(cloud.time_offset_s[i], 0.01f * static_cast<float>(i), 1e-6f) << i;
  }
}

TEST(PointCloud2, AutowareChannelIsTheRing_LivoxLineIsNot) {
  core::PointCloud cloud;
  const std::vector<std::uint16_t> channels = {3, 7};
  ASSERT_TRUE(from_point_cloud2(timed_msg("channel", pf::UINT16, kStampNs, channels), cloud).ok());
  EXPECT_EQ(cloud.ring, channels);
  // Livox's `line` is the point's index in its packet modulo 4 or 6, not a beam.
  const std::vector<std::uint8_t> lines = {0, 1};
  ASSERT_TRUE(from_point_cloud2(timed_msg("line", pf::UINT8, kStampNs, lines), cloud).ok());
  EXPECT_FALSE(cloud.has_ring());
}

PointCloud2Msg valid_xyz_msg() {
  return to_point_cloud2(sample_cloud(false));
}

void expect_rejected(const PointCloud2Msg& msg, const std::string& code) {
  core::PointCloud cloud;
  const auto status = from_point_cloud2(msg, cloud);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().code, code) << status.error().message;
}

TEST(PointCloud2, RejectsMissingCoordinate) {
  auto msg = valid_xyz_msg();
  msg.fields().erase(msg.fields().begin() + 2);  // z
  expect_rejected(msg, "pointcloud.missing_xyz");
}

TEST(PointCloud2, RejectsFieldOutsidePoint) {
  auto msg = valid_xyz_msg();
  msg.fields()[2].offset(10);  // z would read bytes 10..13 of a 12-byte point
  expect_rejected(msg, "pointcloud.field_outside_point");
}

TEST(PointCloud2, RejectsDataSizeMismatch) {
  auto msg = valid_xyz_msg();
  msg.data().pop_back();
  expect_rejected(msg, "pointcloud.bad_size");
  msg = valid_xyz_msg();
  msg.width(msg.width() + 1);  // claims more points than the data holds
  expect_rejected(msg, "pointcloud.bad_row_step");
}

TEST(PointCloud2, RejectsUnknownDatatypeAndArrays) {
  auto msg = valid_xyz_msg();
  msg.fields()[0].datatype(9);
  expect_rejected(msg, "pointcloud.bad_datatype");
  msg = valid_xyz_msg();
  msg.fields()[1].count(3);
  expect_rejected(msg, "pointcloud.bad_count");
}

TEST(PointCloud2, KeepsNonFinitePointsForTheFilters) {
  auto cloud = sample_cloud(false);
  cloud.points_S[3].x() = std::nanf("");
  core::PointCloud back;
  ASSERT_TRUE(from_point_cloud2(to_point_cloud2(cloud), back).ok());
  EXPECT_TRUE(std::isnan(back.points_S[3].x()));
  EXPECT_EQ(back.size(), cloud.size());
}

// Found by tools/fuzz.sh point_cloud2: width 0 and a height of ~2e9 with no data passed the size
// checks and the parser walked 2e9 empty rows (seconds at -O2, inside the cycle).
TEST(PointCloud2, EmptyCloudOfHugeHeightParsesAtOnce) {
  for (const auto& [width, height] : {std::pair{0u, 0xFFFFFFFFu}, std::pair{0xFFFFFFFFu, 0u}}) {
    PointCloud2Msg msg;
    msg.header().frame_id("lidar_front");
    add_field(msg, "x", 0, pf::FLOAT32);
    add_field(msg, "y", 4, pf::FLOAT32);
    add_field(msg, "z", 8, pf::FLOAT32);
    msg.point_step(12);
    msg.width(width);
    msg.height(height);
    msg.row_step(width == 0 ? 0 : 0xFFFFFFFFu);
    core::PointCloud cloud;
    const auto t0 = std::chrono::steady_clock::now();
    const auto parsed = from_point_cloud2(msg, cloud);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_TRUE(parsed.ok() || parsed.error().code == "pointcloud.bad_row_step");
    EXPECT_EQ(cloud.size(), 0u);
    EXPECT_EQ(cloud.frame_id, "lidar_front");
    EXPECT_LT(s, 0.5) << "parsing an empty " << width << " x " << height << " cloud";
  }
}

TEST(OccupancyGrid, RoundTripAndSizeCheck) {
  core::Costmap costmap(core::GridGeometry2D{-40.0, -20.0, 0.2, 17, 9}, core::kCostUnknown);
  for (std::size_t i = 0; i < costmap.cells().size(); ++i) {
    costmap.cells()[i] = static_cast<std::int8_t>(static_cast<int>(i % 102) - 1);
  }
  auto msg = to_occupancy_grid(costmap, 42'000'000'001, "map");
  EXPECT_EQ(msg.header().frame_id(), "map");
  EXPECT_EQ(msg.header().stamp().sec(), 42);
  EXPECT_EQ(msg.header().stamp().nanosec(), 1u);
  EXPECT_EQ(msg.info().origin().orientation().w(), 1.0);
  auto back = from_occupancy_grid(msg);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back.value().cells(), costmap.cells());
  EXPECT_EQ(back.value().width(), 17u);
  EXPECT_DOUBLE_EQ(back.value().geometry().origin_x_m, -40.0);
  EXPECT_FLOAT_EQ(static_cast<float>(back.value().geometry().resolution_m), 0.2f);

  msg.data().pop_back();
  auto bad = from_occupancy_grid(msg);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, "occupancy_grid.size");
}

PathMsg path(const std::string& frame, std::int64_t made_ns,
             const std::vector<std::int64_t>& stamps_ns) {
  PathMsg msg;
  msg.header().frame_id(frame);
  msg.header().stamp(to_time_msg(made_ns));
  for (const std::int64_t ns : stamps_ns) {
    geometry_msgs::msg::dds_::PoseStamped_ p;
    p.header().stamp(to_time_msg(ns));
    p.pose().orientation().w(1.0);
    p.pose().position().x(static_cast<double>(ns) * 1e-9);
    msg.poses().push_back(p);
  }
  return msg;
}

TEST(Path, AcceptsSortedPosesAndTakesTheHeaderStamp) {
  std::vector<PoseSample> poses;
  const auto made = from_path_msg(path("map", 50, {10, 20, 30}), "map", poses);
  ASSERT_TRUE(made.ok()) << made.error().message;
  EXPECT_EQ(made.value(), 50);
  ASSERT_EQ(poses.size(), 3u);
  EXPECT_EQ(poses[2].stamp_ns, 30);
  EXPECT_DOUBLE_EQ(poses[2].T_W_B.translation().x(), 30e-9);
}

TEST(Path, ZeroHeaderStampMeansTheNewestPose) {
  std::vector<PoseSample> poses;
  const auto made = from_path_msg(path("map", 0, {10, 20}), "map", poses);
  ASSERT_TRUE(made.ok());
  EXPECT_EQ(made.value(), 20);
}

TEST(Path, RejectsEachMalformedPathWithItsCode) {
  std::vector<PoseSample> poses;
  EXPECT_EQ(from_path_msg(path("odom", 0, {10}), "map", poses).error().code,
            "correction.unknown_frame");
  EXPECT_EQ(from_path_msg(path("map", 0, {}), "map", poses).error().code, "correction.empty");
  EXPECT_EQ(from_path_msg(path("map", 0, {10, 10}), "map", poses).error().code,
            "correction.unsorted");
  PathMsg other_pose_frame = path("map", 0, {10, 20});
  other_pose_frame.poses()[1].header().frame_id("odom");
  EXPECT_EQ(from_path_msg(other_pose_frame, "map", poses).error().code, "correction.unknown_frame");
  PathMsg bad_quaternion = path("map", 0, {10});
  bad_quaternion.poses()[0].pose().orientation().w(2.0);
  EXPECT_EQ(from_path_msg(bad_quaternion, "map", poses).error().code, "pose.bad_quaternion");
  PathMsg nan_position = path("map", 0, {10});
  nan_position.poses()[0].pose().position().y(std::nan(""));
  EXPECT_EQ(from_path_msg(nan_position, "map", poses).error().code, "pose.non_finite");
}

TEST(FleetBev, RoundTripsEveryField_RefusesAnotherFrameAndABadResolution) {
  core::BevMessage m;
  m.vehicle_id = "tug-7";
  m.stamp_ns = -1'500'000'001;  // before the epoch too
  m.sequence = 4'000'000'000u;
  m.keyframe = true;
  m.resolution_m = 0.2;  // exact on the wire: float64
  m.tiles = {core::BevTile{-3, 7, {0x7f, 0x40, 0x12, 0x34}},
             core::BevTile{1 << 20, -(1 << 20), {}}};
  const FleetBevMsg msg = to_fleet_bev(m, "map");
  EXPECT_EQ(msg.header().frame_id(), "map");
  const auto back = from_fleet_bev(msg, "map");
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back.value().vehicle_id, m.vehicle_id);
  EXPECT_EQ(back.value().stamp_ns, m.stamp_ns);
  EXPECT_EQ(back.value().sequence, m.sequence);
  EXPECT_EQ(back.value().keyframe, m.keyframe);
  EXPECT_EQ(back.value().resolution_m, m.resolution_m);
  EXPECT_EQ(back.value().tiles, m.tiles);
  // The core's wire size (for traffic figures) is Fast DDS's CDR size plus the encapsulation.
  EXPECT_EQ(core::bev_wire_bytes(m, 3), 4 + FleetBevMsg::getCdrSerializedSize(msg));
  core::BevMessage odd = m;
  odd.vehicle_id = "t";
  odd.tiles[0].runs.assign(5, 1);
  EXPECT_EQ(core::bev_wire_bytes(odd, 7),
            4 + FleetBevMsg::getCdrSerializedSize(to_fleet_bev(odd, "map_xyz")));
  EXPECT_EQ(from_fleet_bev(msg, "odom").error().code, "fleet.frame");
  FleetBevMsg bad = msg;
  bad.resolution(std::nan(""));
  EXPECT_EQ(from_fleet_bev(bad, "map").error().code, "fleet.resolution");
  bad.resolution(0.0);
  EXPECT_EQ(from_fleet_bev(bad, "map").error().code, "fleet.resolution");
  bad = msg;
  bad.vehicle_id("");
  EXPECT_EQ(from_fleet_bev(bad, "map").error().code, "fleet.malformed");
}

TEST(DebrisArray, RoundTripsEveryFieldThroughCdr) {
  core::Debris a;
  a.id = 7;
  a.xy_W = Eigen::Vector2d(12.25, -3.5);
  a.ground_z_m = 0.125;
  a.height_m = 0.25;      // exact in float32
  a.footprint_m = 0.375;  // exact in float32
  a.first_seen_ns = -1'500'000'001;
  a.last_confirmed_ns = 1'700'000'000'123'456'789;
  a.returns = 4'000'000'000u;
  core::Debris b;
  b.id = 9;
  b.returns = 2;
  const std::vector<core::Debris> debris{a, b};
  DebrisArrayMsg msg;
  fill_debris_array(debris, 1'700'000'000'000'000'001, "map", msg);
  // Through Fast DDS's own serialisation: what a subscriber decodes.
  tarmac_msgs::msg::dds_::DebrisArray_PubSubType type;
  eprosima::fastrtps::rtps::SerializedPayload_t payload(type.getSerializedSizeProvider(&msg)());
  ASSERT_TRUE(type.serialize(&msg, &payload));
  DebrisArrayMsg received;
  ASSERT_TRUE(type.deserialize(&payload, &received));
  EXPECT_EQ(from_time_msg(received.header().stamp()), 1'700'000'000'000'000'001);
  EXPECT_EQ(received.header().frame_id(), "map");
  const auto back = from_debris_array(received);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].id, a.id);
  EXPECT_EQ(back[0].xy_W, a.xy_W);
  EXPECT_EQ(back[0].ground_z_m, a.ground_z_m);
  EXPECT_EQ(back[0].height_m, a.height_m);
  EXPECT_EQ(back[0].footprint_m, a.footprint_m);
  EXPECT_EQ(back[0].first_seen_ns, a.first_seen_ns);
  EXPECT_EQ(back[0].last_confirmed_ns, a.last_confirmed_ns);
  EXPECT_EQ(back[0].returns, a.returns);
  EXPECT_EQ(back[1].id, b.id);
  EXPECT_EQ(back[1].returns, b.returns);
  // Refilled with fewer: the message holds only those.
  fill_debris_array(std::span<const core::Debris>(debris).first(1), 0, "map", msg);
  EXPECT_EQ(msg.objects().size(), 1u);
  fill_debris_array({}, 0, "map", msg);
  EXPECT_TRUE(msg.objects().empty());
}

TEST(CycleReport, CarriesTheDebrisCount) {
  CycleReport r;
  r.debris = 3;
  CycleReportMsg msg;
  fill_cycle_report(r, msg);
  EXPECT_EQ(msg.debris(), 3u);
  EXPECT_EQ(from_cycle_report(msg).debris, 3u);
}

TEST(CycleReport, CarriesTheColumnsChanged) {
  CycleReport r;
  r.columns_changed = 160'000;
  CycleReportMsg msg;
  fill_cycle_report(r, msg);
  EXPECT_EQ(msg.columns_changed(), 160'000u);
  EXPECT_EQ(from_cycle_report(msg).columns_changed, 160'000u);
}

}  // namespace
}  // namespace tarmac::transport
