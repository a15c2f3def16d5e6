#include "conversions.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>

namespace tarmac::transport {

namespace {

constexpr std::int64_t kNsPerSec = 1'000'000'000;

namespace pf = sensor_msgs::msg::PointField_Constants;

std::size_t datatype_size(std::uint8_t datatype) {
  switch (datatype) {
    case pf::INT8:
    case pf::UINT8: return 1;
    case pf::INT16:
    case pf::UINT16: return 2;
    case pf::INT32:
    case pf::UINT32:
    case pf::FLOAT32: return 4;
    case pf::FLOAT64: return 8;
    default: return 0;
  }
}

/// Where one field lives inside a point record.
struct FieldSlot {
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
};

/// How a cloud's per-point time field relates to its stamp, decided once per cloud from the
/// median of a sample of its finite values (drivers differ: docs/ros2.md, "LiDAR drivers"):
/// Ouster's `t` and Autoware's `time_stamp` are integer nanoseconds from the stamp, Velodyne's
/// `time` float seconds from it (mostly negative: its stamp is the last packet's), RoboSense's and
/// Hesai's `timestamp` float64 absolute seconds, Livox's `timestamp` float64 absolute nanoseconds.
struct TimeBase {
  double origin = 0.0;  ///< subtracted from the value
  double scale = 0.0;   ///< then multiplied: seconds; 0: the field cannot be related (dropped)
};

/// A point's time is within this of the stamp for any sweep a mapper takes; further means the
/// guessed unit or origin is wrong.
constexpr double kNearStampS = 10.0;

TimeBase time_base(double first, std::uint8_t datatype, std::int64_t stamp_ns) {
  const double stamp_s = static_cast<double>(stamp_ns) * 1e-9;
  const auto near = [](double offset_s) { return std::abs(offset_s) <= kNearStampS; };
  const bool floating = datatype == pf::FLOAT32 || datatype == pf::FLOAT64;
  if (floating && near(first)) return {0.0, 1.0};                // seconds from the stamp
  if (!floating && near(first * 1e-9)) return {0.0, 1e-9};       // nanoseconds from it
  if (floating && near(first - stamp_s)) return {stamp_s, 1.0};  // absolute seconds
  const double stamp_as_ns = static_cast<double>(stamp_ns);
  if (near((first - stamp_as_ns) * 1e-9)) return {stamp_as_ns, 1e-9};  // absolute nanoseconds
  return {};
}
/// A driver's ring and time fields (LidarDriver): names, the time's datatype and base.
struct DriverFields {
  std::string_view ring;  ///< empty: none (Livox)
  std::string_view time;
  std::uint8_t time_datatype = 0;
  bool absolute = false;  ///< time from the epoch (origin the stamp), else from the stamp
  double scale = 1.0;     ///< to seconds
};

std::optional<DriverFields> driver_fields(LidarDriver driver) {
  switch (driver) {
    case LidarDriver::kAuto: return std::nullopt;
    case LidarDriver::kOuster: return DriverFields{"ring", "t", pf::UINT32, false, 1e-9};
    case LidarDriver::kVelodyne: return DriverFields{"ring", "time", pf::FLOAT32, false, 1.0};
    case LidarDriver::kRslidar:
    case LidarDriver::kHesai: return DriverFields{"ring", "timestamp", pf::FLOAT64, true, 1.0};
    case LidarDriver::kLivox: return DriverFields{"", "timestamp", pf::FLOAT64, true, 1e-9};
    case LidarDriver::kAutoware:
      return DriverFields{"channel", "time_stamp", pf::UINT32, false, 1e-9};
  }
  return std::nullopt;
}

/// Reads a numeric field of any datatype as double, honouring the message's endianness.
double read_as_double(const std::uint8_t* p, std::uint8_t datatype, bool swap) {
  std::uint8_t raw[8];
  const std::size_t n = datatype_size(datatype);
  std::memcpy(raw, p, n);
  if (swap) {
    for (std::size_t i = 0; i < n / 2; ++i) std::swap(raw[i], raw[n - 1 - i]);
  }
  switch (datatype) {
    case pf::INT8: return static_cast<std::int8_t>(raw[0]);
    case pf::UINT8: return raw[0];
    case pf::INT16: {
      std::int16_t v;
      std::memcpy(&v, raw, 2);
      return v;
    }
    case pf::UINT16: {
      std::uint16_t v;
      std::memcpy(&v, raw, 2);
      return v;
    }
    case pf::INT32: {
      std::int32_t v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case pf::UINT32: {
      std::uint32_t v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case pf::FLOAT32: {
      float v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case pf::FLOAT64: {
      double v;
      std::memcpy(&v, raw, 8);
      return v;
    }
    default: return std::nan("");
  }
}

core::Error reject(const std::string& reason, const std::string& message) {
  return core::Error{"pointcloud." + reason, message};
}

void put_field(PointCloud2Msg& msg, const char* name, std::uint32_t offset, std::uint8_t datatype) {
  sensor_msgs::msg::dds_::PointField_ field;
  field.name(name);
  field.offset(offset);
  field.datatype(datatype);
  field.count(1);
  msg.fields().push_back(field);
}

/// The fields from_point_cloud2 reads, where each lives in a point record (unset: absent).
struct CloudFields {
  std::optional<FieldSlot> x, y, z, intensity, ring, time;
};

/// Whether a field can be read: a datatype of known size, one value, inside the point record.
core::Status check_field(const sensor_msgs::msg::dds_::PointField_& f, std::uint32_t point_step) {
  const std::size_t size = datatype_size(f.datatype());
  const std::string& name = f.name();
  if (size == 0) {
    return reject("bad_datatype",
                  "field '" + name + "' has unknown datatype " + std::to_string(f.datatype()));
  }
  if (f.count() != 1) {
    return reject("bad_count", "field '" + name + "' has count " + std::to_string(f.count()));
  }
  if (std::size_t{f.offset()} + size > point_step) {
    return reject("field_outside_point", "field '" + name + "' at offset " +
                                             std::to_string(f.offset()) + " exceeds point_step " +
                                             std::to_string(point_step));
  }
  return core::Ok{};
}

/// The fields a cloud's points are read from: x, y and z (required), intensity, and the ring and
/// the time under the names drivers give them (with a driver's `preset`, its own names only,
/// and they must be there). An error when a field to read cannot be, x, y or z is missing, or
/// the fields are not the preset's.
core::Result<CloudFields> find_fields(const PointCloud2Msg& msg,
                                      const std::optional<DriverFields>& preset) {
  CloudFields found;
  for (const auto& f : msg.fields()) {
    const std::string& name = f.name();
    // The ring (beam index): `ring`, or Autoware's `channel`. Not Livox's `line`: the driver
    // makes it from the point's place in its packet, not from a beam.
    const bool is_ring = preset ? !preset->ring.empty() && name == preset->ring
                                : name == "ring" || name == "channel";
    const bool is_time =
        preset ? name == preset->time
               : name == "t" || name == "time" || name == "timestamp" || name == "time_stamp";
    const bool wanted =
        name == "x" || name == "y" || name == "z" || name == "intensity" || is_ring || is_time;
    if (!wanted) continue;  // other fields (normals, reflectivity, ...) are ignored
    const core::Status readable = check_field(f, msg.point_step());
    if (!readable) return readable.error();
    const FieldSlot slot{f.offset(), f.datatype()};
    if (name == "x")
      found.x = slot;
    else if (name == "y")
      found.y = slot;
    else if (name == "z")
      found.z = slot;
    else if (name == "intensity")
      found.intensity = slot;
    else if (is_ring && !found.ring)
      found.ring = slot;  // the first of ring / channel wins
    else if (is_time && !found.time)
      found.time = slot;  // the first of t / time / timestamp / time_stamp wins
  }
  if (!found.x || !found.y || !found.z) {
    return reject("missing_xyz", "fields x, y and z are required");
  }
  if (preset && (!found.time || found.time->datatype != preset->time_datatype ||
                 (!preset->ring.empty() && !found.ring))) {
    std::string want = "field '" + std::string(preset->time) + "' of datatype " +
                       std::to_string(preset->time_datatype);
    if (!preset->ring.empty()) want += " and field '" + std::string(preset->ring) + "'";
    return reject("driver_mismatch", "sensors[].driver expects " + want);
  }
  return found;
}

/// Where a cloud's point records lie in its data: `height` rows of `width` records,
/// `point_step` bytes apart, the rows `row_step` apart; `swap`: the values are not in this
/// machine's byte order.
struct CloudLayout {
  const std::uint8_t* base;
  std::size_t width, height, point_step, row_step;
  bool swap;

  [[nodiscard]] std::size_t size() const { return width * height; }
  [[nodiscard]] const std::uint8_t* record(std::size_t row, std::size_t col) const {
    return base + row * row_step + col * point_step;
  }
};

/// The cloud's layout; an error when a row cannot hold its points or the data is not the rows.
core::Result<CloudLayout> cloud_layout(const PointCloud2Msg& msg) {
  const CloudLayout layout{.base = msg.data().data(),
                           .width = msg.width(),
                           .height = msg.height(),
                           .point_step = msg.point_step(),
                           .row_step = msg.row_step(),
                           .swap = msg.is_bigendian() != (std::endian::native == std::endian::big)};
  if (layout.row_step < layout.width * layout.point_step) {
    return reject("bad_row_step", "row_step " + std::to_string(layout.row_step) +
                                      " < width*point_step " +
                                      std::to_string(layout.width * layout.point_step));
  }
  if (msg.data().size() != layout.row_step * layout.height) {
    return reject("bad_size", "data has " + std::to_string(msg.data().size()) +
                                  " bytes, row_step*height is " +
                                  std::to_string(layout.row_step * layout.height));
  }
  return layout;
}

/// The median of up to 31 finite values of a field, spread over the (non-empty) cloud: a few
/// junk cells (a driver's zero fill) cannot decide it. None when no value sampled is finite.
std::optional<double> sampled_median(const CloudLayout& layout, FieldSlot field) {
  std::array<double, 31> sample{};
  std::size_t taken = 0;
  const std::size_t n = layout.size();
  const std::size_t stride = std::max<std::size_t>(1, n / sample.size());
  for (std::size_t i = 0; i < n && taken < sample.size(); i += stride) {
    const std::uint8_t* p = layout.record(i / layout.width, i % layout.width);
    const double v = read_as_double(p + field.offset, field.datatype, layout.swap);
    if (std::isfinite(v)) sample[taken++] = v;
  }
  if (taken == 0) return std::nullopt;
  const auto mid = sample.begin() + static_cast<std::ptrdiff_t>(taken / 2);
  std::nth_element(sample.begin(), mid, sample.begin() + static_cast<std::ptrdiff_t>(taken));
  return *mid;
}

/// How the (non-empty) cloud's time values become seconds from its stamp: the driver's origin
/// and unit with a `preset`, whatever the values say; else guessed from the values (time_base);
/// {0, 1} without a time field, or when no value sampled is finite (nothing to relate: they
/// read NaN).
TimeBase cloud_time_base(const CloudLayout& layout, const std::optional<FieldSlot>& time,
                         const std::optional<DriverFields>& preset, std::int64_t stamp_ns) {
  if (preset) {
    const double stamp = static_cast<double>(stamp_ns);
    return {preset->absolute ? (preset->scale == 1.0 ? stamp * 1e-9 : stamp) : 0.0, preset->scale};
  }
  if (!time) return {0.0, 1.0};
  const std::optional<double> median = sampled_median(layout, *time);
  return median ? time_base(*median, time->datatype, stamp_ns) : TimeBase{0.0, 1.0};
}

/// The (non-empty) cloud's points into `out`, in record order: xyz, and intensity, ring and time
/// where the cloud has them (the time only where `times` relates it to the stamp). (By value:
/// the loop's constants are then locals, kept in registers across the vectors' growth.)
void read_points(CloudLayout layout, CloudFields fields, TimeBase times, core::PointCloud& out) {
  const std::size_t n = layout.size();
  // Grow geometrically: clouds are parsed into reused buffers, so a slowly growing scan size
  // costs a few reallocations, not one per scan.
  const auto grow = [n](auto& v) {
    if (v.capacity() < n) v.reserve(std::max(n, v.capacity() + v.capacity() / 2));
  };
  const FieldSlot x = *fields.x, y = *fields.y, z = *fields.z;
  const std::optional<FieldSlot>& intensity = fields.intensity;
  const std::optional<FieldSlot>& ring = fields.ring;
  const bool swap = layout.swap;
  grow(out.points_S);
  if (intensity) grow(out.intensity);
  if (ring) grow(out.ring);
  // The slot copied out of the optional, for the loop (GCC 12 warns on the optional there).
  const bool use_time = fields.time.has_value() && times.scale != 0.0;
  const FieldSlot time_at = fields.time.value_or(FieldSlot{});
  if (use_time) grow(out.time_offset_s);
  const bool native_float_xyz =
      !swap && x.datatype == pf::FLOAT32 && y.datatype == pf::FLOAT32 && z.datatype == pf::FLOAT32;
  const bool native_float_intensity = !swap && intensity && intensity->datatype == pf::FLOAT32;
  for (std::size_t row = 0; row < layout.height; ++row) {
    for (std::size_t col = 0; col < layout.width; ++col) {
      const std::uint8_t* p = layout.record(row, col);
      if (native_float_xyz) {
        // The common layout (float32 in this machine's byte order): plain loads, same values.
        float v[3];
        std::memcpy(&v[0], p + x.offset, 4);
        std::memcpy(&v[1], p + y.offset, 4);
        std::memcpy(&v[2], p + z.offset, 4);
        out.points_S.emplace_back(v[0], v[1], v[2]);
      } else {
        out.points_S.emplace_back(
            static_cast<float>(read_as_double(p + x.offset, x.datatype, swap)),
            static_cast<float>(read_as_double(p + y.offset, y.datatype, swap)),
            static_cast<float>(read_as_double(p + z.offset, z.datatype, swap)));
      }
      if (intensity && native_float_intensity) {
        float v;
        std::memcpy(&v, p + intensity->offset, 4);
        out.intensity.push_back(v);
      } else if (intensity) {
        out.intensity.push_back(
            static_cast<float>(read_as_double(p + intensity->offset, intensity->datatype, swap)));
      }
      if (ring) {
        const double r = read_as_double(p + ring->offset, ring->datatype, swap);
        out.ring.push_back(r >= 0.0 && r <= 65535.0 ? static_cast<std::uint16_t>(r) : 0);
      }
      if (use_time) {
        const double t_s =
            (read_as_double(p + time_at.offset, time_at.datatype, swap) - times.origin) *
            times.scale;
        // Far from the stamp: a broken point time, taken as the stamp (not deskewed).
        out.time_offset_s.push_back(std::abs(t_s) <= kNearStampS
                                        ? static_cast<float>(t_s)
                                        : std::numeric_limits<float>::quiet_NaN());
      }
    }
  }
}

}  // namespace

TimeMsg to_time_msg(std::int64_t stamp_ns) {
  // Floor division so nanosec stays in [0, 1e9) for stamps before the epoch too.
  std::int64_t sec = stamp_ns / kNsPerSec;
  std::int64_t nsec = stamp_ns % kNsPerSec;
  if (nsec < 0) {
    nsec += kNsPerSec;
    sec -= 1;
  }
  TimeMsg t;
  t.sec(static_cast<std::int32_t>(sec));
  t.nanosec(static_cast<std::uint32_t>(nsec));
  return t;
}

std::int64_t from_time_msg(const TimeMsg& time) {
  return static_cast<std::int64_t>(time.sec()) * kNsPerSec + time.nanosec();
}

OccupancyGridMsg to_occupancy_grid(const core::Costmap& costmap, std::int64_t stamp_ns,
                                   const std::string& frame_id) {
  OccupancyGridMsg msg;
  fill_occupancy_grid(costmap, stamp_ns, frame_id, msg);
  return msg;
}

void fill_occupancy_grid(const core::Costmap& costmap, std::int64_t stamp_ns,
                         const std::string& frame_id, OccupancyGridMsg& msg) {
  const auto& g = costmap.geometry();
  msg.header().stamp(to_time_msg(stamp_ns));
  msg.header().frame_id(frame_id);
  msg.info().map_load_time(to_time_msg(stamp_ns));
  msg.info().resolution(static_cast<float>(g.resolution_m));
  msg.info().width(g.width);
  msg.info().height(g.height);
  msg.info().origin().position().x(g.origin_x_m);
  msg.info().origin().position().y(g.origin_y_m);
  msg.info().origin().position().z(0.0);
  msg.info().origin().orientation().w(1.0);
  msg.data().assign(costmap.cells().begin(), costmap.cells().end());
}

core::Result<core::Costmap> from_occupancy_grid(const OccupancyGridMsg& msg) {
  const auto& info = msg.info();
  const auto& q = info.origin().orientation();
  if (q.x() != 0.0 || q.y() != 0.0 || q.z() != 0.0 || q.w() != 1.0) {
    return core::Error{"occupancy_grid.rotated", "origin orientation is not identity"};
  }
  if (!(info.resolution() > 0.0f)) {
    return core::Error{"occupancy_grid.resolution", "resolution must be > 0"};
  }
  if (msg.data().size() != std::size_t{info.width()} * info.height()) {
    return core::Error{"occupancy_grid.size",
                       "data has " + std::to_string(msg.data().size()) +
                           " cells, width*height is " +
                           std::to_string(std::size_t{info.width()} * info.height())};
  }
  core::GridGeometry2D geometry{info.origin().position().x(), info.origin().position().y(),
                                info.resolution(), info.width(), info.height()};
  core::Costmap costmap(geometry, core::kCostUnknown);
  costmap.cells() = msg.data();
  return costmap;
}

PointCloud2Msg to_point_cloud2(const core::PointCloud& cloud) {
  PointCloud2Msg msg;
  msg.header().stamp(to_time_msg(cloud.stamp_ns));
  msg.header().frame_id(cloud.frame_id);
  std::uint32_t step = 12;
  put_field(msg, "x", 0, pf::FLOAT32);
  put_field(msg, "y", 4, pf::FLOAT32);
  put_field(msg, "z", 8, pf::FLOAT32);
  std::optional<std::uint32_t> intensity_at, ring_at, time_at;
  if (cloud.has_intensity()) {
    intensity_at = step;
    put_field(msg, "intensity", step, pf::FLOAT32);
    step += 4;
  }
  if (cloud.has_time()) {
    time_at = step;
    put_field(msg, "time", step, pf::FLOAT32);
    step += 4;
  }
  if (cloud.has_ring()) {
    ring_at = step;
    put_field(msg, "ring", step, pf::UINT16);
    step += 2;
  }
  const auto n = static_cast<std::uint32_t>(cloud.size());
  msg.height(1);
  msg.width(n);
  msg.is_bigendian(std::endian::native == std::endian::big);
  msg.point_step(step);
  msg.row_step(step * n);
  msg.is_dense(true);
  auto& data = msg.data();
  data.resize(std::size_t{step} * n);
  for (std::uint32_t i = 0; i < n; ++i) {
    std::uint8_t* p = data.data() + std::size_t{i} * step;
    std::memcpy(p, cloud.points_S[i].data(), 12);
    if (intensity_at) std::memcpy(p + *intensity_at, &cloud.intensity[i], 4);
    if (time_at) std::memcpy(p + *time_at, &cloud.time_offset_s[i], 4);
    if (ring_at) std::memcpy(p + *ring_at, &cloud.ring[i], 2);
  }
  return msg;
}

core::Status from_point_cloud2(const PointCloud2Msg& msg, core::PointCloud& out, CloudNotes* notes,
                               LidarDriver driver) {
  const std::optional<DriverFields> preset = driver_fields(driver);
  out.clear();
  if (notes != nullptr) *notes = CloudNotes{};
  out.frame_id = msg.header().frame_id();
  out.stamp_ns = from_time_msg(msg.header().stamp());
  const core::Result<CloudFields> fields = find_fields(msg, preset);
  if (!fields) return fields.error();
  const core::Result<CloudLayout> layout = cloud_layout(msg);
  if (!layout) return layout.error();
  // A grid (height > 1) is a sweep to organise, its cells without a return kept: core's ingest
  // decides its layout (organised_scan.hpp).
  const std::size_t height = layout.value().height;
  out.grid_rows = height > 1 ? static_cast<std::uint32_t>(height) : 0;
  // An empty cloud is done: its other dimension is unbounded by the data (0 x 4e9 with no
  // bytes passes the size checks) and walking its rows would stall the cycle for seconds.
  if (layout.value().size() == 0) return core::Ok{};
  const TimeBase times = cloud_time_base(layout.value(), fields.value().time, preset, out.stamp_ns);
  // A time that cannot be related: no deskew for this cloud, counted.
  if (times.scale == 0.0 && notes != nullptr) notes->time_unrelated = true;
  read_points(layout.value(), fields.value(), times, out);
  return core::Ok{};
}

PoseMsg to_pose_msg(const Eigen::Isometry3d& T) {
  PoseMsg msg;
  const Eigen::Quaterniond q(T.linear());
  msg.position().x(T.translation().x());
  msg.position().y(T.translation().y());
  msg.position().z(T.translation().z());
  msg.orientation().x(q.x());
  msg.orientation().y(q.y());
  msg.orientation().z(q.z());
  msg.orientation().w(q.w());
  return msg;
}

core::Result<Eigen::Isometry3d> from_pose_msg(const PoseMsg& msg) {
  const auto& p = msg.position();
  const auto& o = msg.orientation();
  const Eigen::Vector3d t(p.x(), p.y(), p.z());
  Eigen::Quaterniond q(o.w(), o.x(), o.y(), o.z());
  if (!t.allFinite() || !q.coeffs().allFinite()) {
    return core::Error{"pose.non_finite", "position or orientation is not finite"};
  }
  if (std::abs(q.norm() - 1.0) > 1e-3) {
    return core::Error{"pose.bad_quaternion", "orientation is not a unit quaternion"};
  }
  q.normalize();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = t;
  return T;
}

core::Result<std::int64_t> from_path_msg(const PathMsg& msg, const std::string& frame_id,
                                         std::vector<PoseSample>& poses) {
  poses.clear();
  if (msg.header().frame_id() != frame_id) {
    return core::Error{"correction.unknown_frame", "path frame '" + msg.header().frame_id() + "'"};
  }
  if (msg.poses().empty()) return core::Error{"correction.empty", "path has no poses"};
  for (const auto& p : msg.poses()) {
    if (!p.header().frame_id().empty() && p.header().frame_id() != frame_id) {
      return core::Error{"correction.unknown_frame", "pose frame '" + p.header().frame_id() + "'"};
    }
    auto T = from_pose_msg(p.pose());
    if (!T) return T.error();
    const std::int64_t stamp = from_time_msg(p.header().stamp());
    if (!poses.empty() && stamp <= poses.back().stamp_ns) {
      return core::Error{"correction.unsorted", "pose stamps are not strictly increasing"};
    }
    poses.push_back(PoseSample{stamp, T.value()});
  }
  const std::int64_t made_ns = from_time_msg(msg.header().stamp());
  return made_ns != 0 ? made_ns : poses.back().stamp_ns;
}

void fill_distance_slice(const core::DistanceField& field, const core::GridGeometry2D& geometry,
                         std::int64_t stamp_ns, const std::string& frame_id,
                         DistanceMapSliceMsg& msg) {
  msg.header().stamp(to_time_msg(stamp_ns));
  msg.header().frame_id(frame_id);
  msg.resolution(static_cast<float>(geometry.resolution_m));
  msg.width(geometry.width);
  msg.height(geometry.height);
  msg.origin().position().x(geometry.origin_x_m);
  msg.origin().position().y(geometry.origin_y_m);
  msg.origin().position().z(0.0);
  msg.origin().orientation().w(1.0);
  msg.unknown_value(std::numeric_limits<float>::quiet_NaN());
  msg.distance().assign(field.distance_m.begin(), field.distance_m.end());
  msg.gradient_x().assign(field.gradient_x.begin(), field.gradient_x.end());
  msg.gradient_y().assign(field.gradient_y.begin(), field.gradient_y.end());
}

void fill_distance_volume(const core::EsdfBand& band, const Eigen::Vector2d& centre_W,
                          double radius_m, std::int64_t stamp_ns, const std::string& frame_id,
                          DistanceMapVolumeMsg& msg) {
  const core::DistanceField& f = band.field;
  const int nx = f.dims.x(), ny = f.dims.y(), nz = f.dims.z();
  const double v = f.cell_size_m;
  int x0 = 0, x1 = nx, y0 = 0, y1 = ny;
  if (radius_m > 0.0) {
    const int half = static_cast<int>(std::ceil(radius_m / v - 1e-9));
    const int cx = static_cast<int>(std::floor(centre_W.x() / v)) - band.min.x();
    const int cy = static_cast<int>(std::floor(centre_W.y() / v)) - band.min.y();
    x0 = std::clamp(cx - half, 0, nx);
    x1 = std::clamp(cx + half + 1, x0, nx);
    y0 = std::clamp(cy - half, 0, ny);
    y1 = std::clamp(cy + half + 1, y0, ny);
  }
  const int w = x1 - x0, h = y1 - y0;
  msg.header().stamp(to_time_msg(stamp_ns));
  msg.header().frame_id(frame_id);
  msg.resolution(static_cast<float>(v));
  msg.width(static_cast<std::uint32_t>(w));
  msg.height(static_cast<std::uint32_t>(h));
  msg.depth(static_cast<std::uint32_t>(nz));
  msg.origin().position().x((band.min.x() + x0) * v);
  msg.origin().position().y((band.min.y() + y0) * v);
  msg.origin().position().z(band.min.z() * v);
  msg.origin().orientation().w(1.0);
  msg.unknown_value(std::numeric_limits<float>::quiet_NaN());
  const std::size_t n = static_cast<std::size_t>(w) * h * nz;
  const auto copy = [&](const std::vector<float>& in, std::vector<float>& out) {
    out.resize(n);
    float* o = out.data();
    for (int z = 0; z < nz; ++z) {
      for (int y = y0; y < y1; ++y) {
        const float* row = in.data() + (static_cast<std::size_t>(z) * ny + y) * nx;
        o = std::copy(row + x0, row + x1, o);
      }
    }
  };
  copy(f.distance_m, msg.distance());
  copy(f.gradient_x, msg.gradient_x());
  copy(f.gradient_y, msg.gradient_y());
  copy(f.gradient_z, msg.gradient_z());
}

namespace {
void fill_reasons(const std::vector<ReasonReport>& in,
                  std::vector<tarmac_msgs::msg::dds_::ReasonCount_>& out) {
  out.resize(in.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    out[i].reason() = in[i].reason;
    out[i].count(in[i].count);
    out[i].total(in[i].total);
  }
}
std::vector<ReasonReport> from_reasons(
    const std::vector<tarmac_msgs::msg::dds_::ReasonCount_>& in) {
  std::vector<ReasonReport> out;
  for (const auto& r : in) out.push_back(ReasonReport{r.reason(), r.count(), r.total()});
  return out;
}
}  // namespace

void fill_cycle_report(const CycleReport& r, CycleReportMsg& msg) {
  msg.header().stamp(to_time_msg(r.stamp_ns));
  msg.header().frame_id() = r.frame_id;
  msg.cycle_index(r.cycle_index);
  msg.tick_time(to_time_msg(r.tick_ns));
  msg.wake_jitter_ms(static_cast<float>(r.wake_jitter_ms));
  msg.skipped_ticks(r.skipped_ticks);
  msg.stages().resize(r.stages.size());
  for (std::size_t i = 0; i < r.stages.size(); ++i) {
    auto& s = msg.stages()[i];
    s.name() = r.stages[i].name;
    s.duration_ms(static_cast<float>(r.stages[i].duration_ms));
    s.budget_ms(static_cast<float>(r.stages[i].budget_ms));
    s.overrun(r.stages[i].overrun);
    s.shed_items(r.stages[i].shed_items);
  }
  msg.cycle_duration_ms(static_cast<float>(r.cycle_duration_ms));
  msg.cycle_budget_ms(static_cast<float>(r.cycle_budget_ms));
  msg.overrun(r.overrun);
  fill_reasons(r.drops, msg.drops());
  fill_reasons(r.rejections, msg.rejections());
  msg.input_ages().resize(r.input_ages.size());
  for (std::size_t i = 0; i < r.input_ages.size(); ++i) {
    auto& a = msg.input_ages()[i];
    a.input() = r.input_ages[i].input;
    a.age_ms(static_cast<float>(r.input_ages[i].age_ms));
    a.stale(r.input_ages[i].stale);
  }
  msg.points_in(r.points_in);
  msg.points_used(r.points_used);
  msg.map_memory_bytes(r.map_memory_bytes);
  msg.config_hash() = r.config_hash;
  msg.fleet_peers().resize(r.fleet_peers.size());
  for (std::size_t i = 0; i < r.fleet_peers.size(); ++i) {
    const auto& p = r.fleet_peers[i];
    auto& m = msg.fleet_peers()[i];
    m.vehicle_id() = p.vehicle_id;
    m.cells(p.cells);
    m.age_ms(static_cast<float>(p.age_ms));
    m.messages(p.messages);
    m.rejected(p.rejected);
    m.gaps(p.gaps);
  }
  msg.fleet_newest_age_ms(static_cast<float>(r.fleet_newest_age_ms));
  msg.debris(r.debris);
  msg.columns_changed(r.columns_changed);
}

CycleReport from_cycle_report(const CycleReportMsg& msg) {
  CycleReport r;
  r.stamp_ns = from_time_msg(msg.header().stamp());
  r.frame_id = msg.header().frame_id();
  r.cycle_index = msg.cycle_index();
  r.tick_ns = from_time_msg(msg.tick_time());
  r.wake_jitter_ms = msg.wake_jitter_ms();
  r.skipped_ticks = msg.skipped_ticks();
  for (const auto& s : msg.stages()) {
    r.stages.push_back(
        StageReport{s.name(), s.duration_ms(), s.budget_ms(), s.overrun(), s.shed_items()});
  }
  r.cycle_duration_ms = msg.cycle_duration_ms();
  r.cycle_budget_ms = msg.cycle_budget_ms();
  r.overrun = msg.overrun();
  r.drops = from_reasons(msg.drops());
  r.rejections = from_reasons(msg.rejections());
  for (const auto& a : msg.input_ages()) {
    r.input_ages.push_back(InputAgeReport{a.input(), a.age_ms(), a.stale()});
  }
  r.points_in = msg.points_in();
  r.points_used = msg.points_used();
  r.map_memory_bytes = msg.map_memory_bytes();
  r.config_hash = msg.config_hash();
  for (const auto& p : msg.fleet_peers()) {
    r.fleet_peers.push_back(FleetPeerReport{p.vehicle_id(), p.cells(), p.age_ms(), p.messages(),
                                            p.rejected(), p.gaps()});
  }
  r.fleet_newest_age_ms = msg.fleet_newest_age_ms();
  r.debris = msg.debris();
  r.columns_changed = msg.columns_changed();
  return r;
}

void fill_diagnostic_array(const DiagnosticReport& report, DiagnosticArrayMsg& msg) {
  msg.header().stamp(to_time_msg(report.stamp_ns));
  msg.status().resize(1);
  auto& s = msg.status()[0];
  s.level(report.level);
  s.name() = report.name;
  s.message() = report.message;
  s.hardware_id() = report.hardware_id;
  s.values().resize(report.values.size());
  for (std::size_t i = 0; i < report.values.size(); ++i) {
    s.values()[i].key() = report.values[i].first;
    s.values()[i].value() = report.values[i].second;
  }
}

core::Result<std::vector<core::VirtualZone>> from_virtual_obstacles(
    const VirtualObstacleArrayMsg& msg) {
  namespace vo = tarmac_msgs::msg::VirtualObstacle_Constants;
  std::vector<core::VirtualZone> zones;
  for (const auto& o : msg.obstacles()) {
    core::VirtualZone z;
    z.id = o.id();
    if (o.polygon().size() < 3) {
      return core::Error{"zones.polygon", "zone '" + o.id() + "' has fewer than 3 vertices"};
    }
    for (const auto& p : o.polygon()) {
      if (!std::isfinite(p.x()) || !std::isfinite(p.y())) {
        return core::Error{"zones.non_finite", "zone '" + o.id() + "' has a non-finite vertex"};
      }
      z.polygon_W.emplace_back(p.x(), p.y());
    }
    if (std::isnan(o.min_z()) || std::isnan(o.max_z()) || o.min_z() > o.max_z()) {
      return core::Error{"zones.z_range", "zone '" + o.id() + "' has an empty z range"};
    }
    z.min_z_m = o.min_z();
    z.max_z_m = o.max_z();
    z.expiry_ns = from_time_msg(o.expiry());
    z.restricted = o.kind() == vo::KIND_RESTRICTED;
    zones.push_back(std::move(z));
  }
  return zones;
}

FleetBevMsg to_fleet_bev(const core::BevMessage& message, const std::string& frame_id) {
  FleetBevMsg msg;
  fill_fleet_bev(message, frame_id, msg);
  return msg;
}

void fill_fleet_bev(const core::BevMessage& message, const std::string& frame_id,
                    FleetBevMsg& msg) {
  msg.header().stamp(to_time_msg(message.stamp_ns));
  msg.header().frame_id(frame_id);
  msg.vehicle_id(message.vehicle_id);
  msg.sequence_number(message.sequence);
  msg.keyframe(message.keyframe);
  msg.resolution(message.resolution_m);
  msg.position_std_m(static_cast<float>(message.position_std_m));
  msg.tiles().resize(message.tiles.size());
  for (std::size_t t = 0; t < message.tiles.size(); ++t) {
    msg.tiles()[t].x(message.tiles[t].x);
    msg.tiles()[t].y(message.tiles[t].y);
    msg.tiles()[t].runs(message.tiles[t].runs);
  }
}

core::Result<core::BevMessage> from_fleet_bev(const FleetBevMsg& msg, const std::string& frame_id) {
  if (msg.vehicle_id().empty()) return core::Error{"fleet.malformed", "no vehicle id"};
  if (msg.header().frame_id() != frame_id) {
    return core::Error{"fleet.frame", msg.vehicle_id() + ": frame '" + msg.header().frame_id() +
                                          "', not the shared '" + frame_id + "'"};
  }
  if (!std::isfinite(msg.resolution()) || msg.resolution() <= 0.0) {
    return core::Error{"fleet.resolution", msg.vehicle_id() + ": resolution not a positive number"};
  }
  core::BevMessage m;
  m.vehicle_id = msg.vehicle_id();
  m.stamp_ns = from_time_msg(msg.header().stamp());
  m.sequence = msg.sequence_number();
  m.keyframe = msg.keyframe();
  m.resolution_m = msg.resolution();
  if (!std::isfinite(msg.position_std_m()) || msg.position_std_m() < 0.0f) {
    return core::Error{"fleet.malformed", msg.vehicle_id() + ": position_std_m not a number >= 0"};
  }
  m.position_std_m = msg.position_std_m();
  m.tiles.resize(msg.tiles().size());
  for (std::size_t t = 0; t < msg.tiles().size(); ++t) {
    m.tiles[t] = core::BevTile{msg.tiles()[t].x(), msg.tiles()[t].y(), msg.tiles()[t].runs()};
  }
  return m;
}

}  // namespace tarmac::transport
