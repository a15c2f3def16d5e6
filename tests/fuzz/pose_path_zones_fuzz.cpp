// libFuzzer target: the conversions of tarmacd's other inputs. The first byte picks the message;
// the rest describes it field by field:
//   0 geometry_msgs/Pose (from_pose_msg) and builtin_interfaces/Time (from_time_msg),
//   1 nav_msgs/Path as a corrected trajectory (from_path_msg, TrajectoryInput's conversion),
//   2 tarmac_msgs/VirtualObstacleArray (from_virtual_obstacles),
//   3 nav_msgs/OccupancyGrid (from_occupancy_grid).
// Flags can normalise quaternions, make stamps increase and size the grid data, so the accepting
// paths are reached as well as each rejection. Properties: what is accepted is what the contract
// promises (a proper rotation, sorted stamps, finite closed polygons, matching cells).

#include <cmath>

#include "conversions.hpp"
#include "fuzz_bytes.hpp"

namespace tarmac::fuzz {
namespace {

using transport::PathMsg;
using transport::PoseMsg;
using transport::TimeMsg;

enum Kind : std::uint8_t { kPose = 0, kPath = 1, kZones = 2, kGrid = 3, kKinds = 4 };
enum PoseFlags : std::uint8_t { kNormalise = 1 };
enum PathFlags : std::uint8_t { kIncreasing = 1 };
enum GridFlags : std::uint8_t { kIdentity = 1, kSized = 2 };
constexpr std::size_t kMaxPoses = 64, kMaxZones = 16, kMaxVertices = 64;
constexpr std::size_t kMaxCells = std::size_t{1} << 22;
const std::string kFrame = "map";

/// Frame codes: 0 the expected frame, 1 empty, 2 another, else a literal string.
std::string frame(ByteReader& in) {
  switch (const auto code = in.get<std::uint8_t>(); code) {
    case 0: return kFrame;
    case 1: return "";
    case 2: return "odom";
    default: return in.string();
  }
}

TimeMsg time_msg(ByteReader& in) {
  TimeMsg t;
  t.sec(in.get<std::int32_t>());
  t.nanosec(in.get<std::uint32_t>());
  return t;
}

PoseMsg pose_msg(ByteReader& in) {
  PoseMsg p;
  const auto flags = in.get<std::uint8_t>();
  p.position().x(in.get<double>());
  p.position().y(in.get<double>());
  p.position().z(in.get<double>());
  double q[4] = {in.get<double>(), in.get<double>(), in.get<double>(), in.get<double>()};
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if ((flags & kNormalise) != 0 && std::isfinite(norm) && norm > 0.0) {
    for (double& c : q) c /= norm;
  }
  p.orientation().x(q[0]);
  p.orientation().y(q[1]);
  p.orientation().z(q[2]);
  p.orientation().w(q[3]);
  return p;
}

void check_pose(const PoseMsg& msg) {
  const auto T = transport::from_pose_msg(msg);
  if (!T) {
    TARMAC_FUZZ_CHECK(T.error().code == "pose.non_finite" ||
                      T.error().code == "pose.bad_quaternion");
    return;
  }
  const Eigen::Matrix3d R = T.value().linear();
  TARMAC_FUZZ_CHECK((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-9);
  TARMAC_FUZZ_CHECK(std::abs(R.determinant() - 1.0) < 1e-9);
  TARMAC_FUZZ_CHECK(T.value().translation().x() == msg.position().x());
  TARMAC_FUZZ_CHECK(T.value().translation().y() == msg.position().y());
  TARMAC_FUZZ_CHECK(T.value().translation().z() == msg.position().z());
  // Our own output must come back as the same pose.
  const auto again = transport::from_pose_msg(transport::to_pose_msg(T.value()));
  TARMAC_FUZZ_CHECK(again.ok());
  TARMAC_FUZZ_CHECK((again.value().linear() - R).norm() < 1e-9);
}

void check_time(const TimeMsg& t) {
  const std::int64_t ns = transport::from_time_msg(t);
  if (t.nanosec() >= 1'000'000'000u) return;  // not a normalised Time: no round trip promised
  const TimeMsg back = transport::to_time_msg(ns);
  TARMAC_FUZZ_CHECK(back.sec() == t.sec() && back.nanosec() == t.nanosec());
}

void check_path(ByteReader& in) {
  PathMsg msg;
  const auto flags = in.get<std::uint8_t>();
  msg.header().stamp(time_msg(in));
  msg.header().frame_id(frame(in));
  const std::size_t n = in.get<std::uint8_t>() % (kMaxPoses + 1);
  std::int64_t stamp_ns = 0;
  for (std::size_t i = 0; i < n; ++i) {
    geometry_msgs::msg::dds_::PoseStamped_ p;
    p.header().frame_id(frame(in));
    if ((flags & kIncreasing) != 0) {
      stamp_ns += in.get<std::uint16_t>() * std::int64_t{1'000'000};  // ms steps, maybe 0
      p.header().stamp(transport::to_time_msg(stamp_ns));
    } else {
      p.header().stamp(time_msg(in));
    }
    p.pose(pose_msg(in));
    msg.poses().push_back(p);
  }
  std::vector<transport::PoseSample> poses;
  const auto made_ns = transport::from_path_msg(msg, kFrame, poses);
  if (!made_ns) {
    const std::string& code = made_ns.error().code;
    TARMAC_FUZZ_CHECK(code.rfind("correction.", 0) == 0 || code.rfind("pose.", 0) == 0);
    return;
  }
  TARMAC_FUZZ_CHECK(poses.size() == msg.poses().size() && !poses.empty());
  for (std::size_t i = 1; i < poses.size(); ++i) {
    TARMAC_FUZZ_CHECK(poses[i].stamp_ns > poses[i - 1].stamp_ns);
  }
  const std::int64_t header_ns = transport::from_time_msg(msg.header().stamp());
  TARMAC_FUZZ_CHECK(made_ns.value() == (header_ns != 0 ? header_ns : poses.back().stamp_ns));
  for (const auto& p : poses) TARMAC_FUZZ_CHECK(p.T_W_B.matrix().allFinite());
}

void check_zones(ByteReader& in) {
  transport::VirtualObstacleArrayMsg msg;
  const std::size_t n = in.get<std::uint8_t>() % (kMaxZones + 1);
  for (std::size_t i = 0; i < n; ++i) {
    tarmac_msgs::msg::dds_::VirtualObstacle_ o;
    o.id(in.string());
    o.kind(in.get<std::uint8_t>());
    const std::size_t vertices = in.get<std::uint8_t>() % (kMaxVertices + 1);
    for (std::size_t v = 0; v < vertices; ++v) {
      geometry_msgs::msg::dds_::Point_ p;
      p.x(in.get<double>());
      p.y(in.get<double>());
      p.z(in.get<double>());
      o.polygon().push_back(p);
    }
    o.min_z(in.get<double>());
    o.max_z(in.get<double>());
    o.expiry(time_msg(in));
    msg.obstacles().push_back(o);
  }
  const auto zones = transport::from_virtual_obstacles(msg);
  if (!zones) {
    TARMAC_FUZZ_CHECK(zones.error().code.rfind("zones.", 0) == 0);
    return;
  }
  TARMAC_FUZZ_CHECK(zones.value().size() == msg.obstacles().size());
  for (std::size_t i = 0; i < zones.value().size(); ++i) {
    const core::VirtualZone& z = zones.value()[i];
    TARMAC_FUZZ_CHECK(z.id == msg.obstacles()[i].id());
    TARMAC_FUZZ_CHECK(z.polygon_W.size() >= 3 &&
                      z.polygon_W.size() == msg.obstacles()[i].polygon().size());
    for (const auto& v : z.polygon_W) TARMAC_FUZZ_CHECK(v.allFinite());
    TARMAC_FUZZ_CHECK(z.min_z_m <= z.max_z_m);
    TARMAC_FUZZ_CHECK(z.restricted ==
                      (msg.obstacles()[i].kind() ==
                       tarmac_msgs::msg::VirtualObstacle_Constants::KIND_RESTRICTED));
  }
}

void check_grid(ByteReader& in) {
  transport::OccupancyGridMsg msg;
  const auto flags = in.get<std::uint8_t>();
  msg.header().stamp(time_msg(in));
  msg.header().frame_id(frame(in));
  msg.info().resolution(in.get<float>());
  msg.info().width(in.get<std::uint32_t>());
  msg.info().height(in.get<std::uint32_t>());
  msg.info().origin(pose_msg(in));
  if ((flags & kIdentity) != 0) {
    msg.info().origin().orientation().x(0.0);
    msg.info().origin().orientation().y(0.0);
    msg.info().origin().orientation().z(0.0);
    msg.info().origin().orientation().w(1.0);
  }
  const auto rest = in.rest();
  msg.data().assign(rest.begin(), rest.end());
  const std::uint64_t cells = std::uint64_t{msg.info().width()} * msg.info().height();
  if ((flags & kSized) != 0 && cells <= kMaxCells) msg.data().resize(cells);
  const auto grid = transport::from_occupancy_grid(msg);
  if (!grid) {
    TARMAC_FUZZ_CHECK(grid.error().code.rfind("occupancy_grid.", 0) == 0);
    return;
  }
  TARMAC_FUZZ_CHECK(grid.value().cells() == msg.data());
  TARMAC_FUZZ_CHECK(grid.value().geometry().width == msg.info().width());
  TARMAC_FUZZ_CHECK(grid.value().geometry().height == msg.info().height());
}

// ---- seeds: one or more valid messages of each kind, and a rejection of each kind ----

void put_pose(ByteWriter& out, bool normalise, double x, double y, double yaw) {
  out.put<std::uint8_t>(normalise ? kNormalise : 0);
  out.put(x);
  out.put(y);
  out.put(0.5);
  out.put(0.0);
  out.put(0.0);
  out.put(std::sin(yaw / 2));
  out.put(std::cos(yaw / 2));
}

void put_time(ByteWriter& out, std::int32_t sec, std::uint32_t nanosec) {
  out.put(sec);
  out.put(nanosec);
}

Bytes pose_seed(bool normalise, double scale) {
  ByteWriter out;
  out.put<std::uint8_t>(kPose);
  put_time(out, 1767225600, 5);
  put_pose(out, normalise, 12.5 * scale, -3.0, 0.7 * scale);
  return out.take();
}

Bytes path_seed(bool increasing, std::uint8_t poses, std::uint8_t pose_frame) {
  ByteWriter out;
  out.put<std::uint8_t>(kPath);
  out.put<std::uint8_t>(increasing ? kIncreasing : 0);
  put_time(out, 0, 0);
  out.put<std::uint8_t>(0);  // header frame "map"
  out.put(poses);
  for (std::uint8_t i = 0; i < poses; ++i) {
    out.put(pose_frame);
    if (increasing) {
      out.put<std::uint16_t>(100);
    } else {
      put_time(out, 1767225600 + (i == 2 ? 0 : i), 0);  // the third repeats the first
    }
    put_pose(out, true, 0.5 * i, 0.1 * i, 0.05 * i);
  }
  return out.take();
}

Bytes zones_seed(std::uint8_t vertices, double max_z) {
  ByteWriter out;
  out.put<std::uint8_t>(kZones);
  out.put<std::uint8_t>(2);
  for (std::uint8_t z = 0; z < 2; ++z) {
    out.string(z == 0 ? "stand_12_jet_blast" : "fuel_spill");
    out.put<std::uint8_t>(z == 0 ? 1 : 4);
    out.put(vertices);
    for (std::uint8_t v = 0; v < vertices; ++v) {
      out.put(10.0 * std::cos(v));
      out.put(10.0 * std::sin(v));
      out.put(0.0);
    }
    out.put(-1.0);
    out.put(max_z);
    put_time(out, z == 0 ? 0 : 1767225700, 0);
  }
  return out.take();
}

Bytes grid_seed(std::uint8_t flags, std::uint32_t width, std::uint32_t height) {
  ByteWriter out;
  out.put<std::uint8_t>(kGrid);
  out.put(flags);
  put_time(out, 1767225600, 0);
  out.put<std::uint8_t>(0);
  out.put(0.1f);
  out.put(width);
  out.put(height);
  put_pose(out, true, -5.0, -5.0, 0.0);
  for (std::uint32_t i = 0; i < width * height; ++i) out.put(static_cast<std::int8_t>(i % 102 - 1));
  return out.take();
}

const std::vector<Bytes>& seeds() {
  static const std::vector<Bytes> all = {
      pose_seed(true, 1.0),  pose_seed(false, 1.0),      pose_seed(true, 1e300),
      path_seed(true, 5, 0), path_seed(true, 3, 1),      path_seed(false, 4, 0),
      path_seed(true, 2, 2), zones_seed(5, 3.0),         zones_seed(2, 3.0),
      zones_seed(4, -2.0),   grid_seed(kIdentity, 8, 6), grid_seed(kIdentity | kSized, 4, 4),
      grid_seed(0, 3, 3),
  };
  return all;
}

}  // namespace
}  // namespace tarmac::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  tarmac::fuzz::handle_make_seeds(argc, argv, &tarmac::fuzz::seeds, {"map", "odom"});
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tarmac::fuzz;
  ByteReader in(data, size);
  switch (in.get<std::uint8_t>() % kKinds) {
    case kPose: {
      const TimeMsg t = time_msg(in);
      check_time(t);
      check_pose(pose_msg(in));
      break;
    }
    case kPath: check_path(in); break;
    case kZones: check_zones(in); break;
    default: check_grid(in); break;
  }
  return 0;
}
