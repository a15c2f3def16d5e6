#include "tarmac/sim/driver_cloud.hpp"

#include <cmath>
#include <cstring>
#include <limits>

namespace tarmac::sim {

namespace {

constexpr std::uint8_t kU8 = 2, kU16 = 4, kU32 = 6, kF32 = 7, kF64 = 8;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// The sweep as a grid: cell (beam, step) → the return there, or null.
struct Grid {
  int beams = 0, steps = 0;
  std::vector<const LidarReturn*> cell;
  const LidarReturn* at(int beam, int step) const {
    return cell[static_cast<std::size_t>(beam) * static_cast<std::size_t>(steps) +
                static_cast<std::size_t>(step)];
  }
};

Grid grid_of(const LidarParams& lidar, const std::vector<LidarReturn>& returns) {
  Grid g;
  g.beams = lidar.beams;
  g.steps = lidar.azimuth_steps;
  g.cell.assign(static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps), nullptr);
  for (const auto& r : returns) {
    g.cell[static_cast<std::size_t>(r.beam) * static_cast<std::size_t>(g.steps) +
           static_cast<std::size_t>(r.azimuth_step)] = &r;
  }
  return g;
}

/// The azimuth step fired k-th: clockwise from +x, as the modelled sensors turn.
int step_fired(int k, int steps) {
  return (steps - k) % steps;
}

/// Raw channel c's beam for drivers that list channels in the sensor's raw order: interleaved
/// elevations, as the VLP-16's and HDL-32E's laser ids (low, middle, low + 1, middle + 1, ...).
int interleaved_beam(int c, int beams) {
  return c % 2 == 0 ? c / 2 : (beams + 1) / 2 + c / 2;
}

/// Writes points one after the other into a cloud's data.
class Writer {
 public:
  Writer(DriverCloud& cloud, std::size_t points) : cloud_(cloud) {
    cloud_.data.assign(points * cloud_.point_step, 0);
  }
  template <typename T>
  void put(std::uint32_t offset, T value) {
    std::memcpy(cloud_.data.data() + at_ * cloud_.point_step + offset, &value, sizeof(T));
  }
  void xyz(const LidarReturn* r, float none) {
    put<float>(0, r != nullptr ? static_cast<float>(r->point_S.x()) : none);
    put<float>(4, r != nullptr ? static_cast<float>(r->point_S.y()) : none);
    put<float>(8, r != nullptr ? static_cast<float>(r->point_S.z()) : none);
  }
  void next() { ++at_; }
  std::size_t written() const { return at_; }

 private:
  DriverCloud& cloud_;
  std::size_t at_ = 0;
};

void set_fields(DriverCloud& c, std::uint32_t point_step, std::vector<DriverField> fields) {
  c.point_step = point_step;
  c.fields = std::move(fields);
}

/// XYZI, ring u16 and an f64 `timestamp`, by addPointField without padding (26 bytes): the
/// layout of rslidar_sdk's XYZIRT and of HesaiLidar_ROS_2.0.
void set_xyzirt26_fields(DriverCloud& c) {
  set_fields(c, 26,
             {{"x", 0, kF32},
              {"y", 4, kF32},
              {"z", 8, kF32},
              {"intensity", 12, kF32},
              {"ring", 16, kU16},
              {"timestamp", 18, kF64}});
}

/// One point of that layout.
void put_xyzirt26(Writer& w, const LidarReturn* r, float marker, std::uint16_t ring, double t_s) {
  w.xyz(r, marker);
  w.put<float>(12, r != nullptr ? r->intensity : 0.0f);
  w.put<std::uint16_t>(16, ring);
  w.put<double>(18, t_s);
  w.next();
}

/// ouster-ros `original`: ouster_ros::Point (PCL_ADD_POINT4D, 48 bytes), rows = beams top
/// first (ring 0 = top), columns in firing order, NaN x, y, z kept for no return, t u32 ns from
/// the stamp (the first column's time).
void ouster(const Grid& g, std::int64_t start_ns, double period_s, DriverCloud& c) {
  set_fields(c, 48,
             {{"x", 0, kF32},
              {"y", 4, kF32},
              {"z", 8, kF32},
              {"intensity", 16, kF32},
              {"t", 20, kU32},
              {"reflectivity", 24, kU16},
              {"ring", 26, kU16},
              {"ambient", 28, kU16},
              {"range", 32, kU32}});
  c.stamp_ns = start_ns;
  c.height = static_cast<std::uint32_t>(g.beams);
  c.width = static_cast<std::uint32_t>(g.steps);
  Writer w(c, static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps));
  for (int row = 0; row < g.beams; ++row) {
    const int beam = g.beams - 1 - row;
    for (int k = 0; k < g.steps; ++k) {
      const LidarReturn* r = g.at(beam, step_fired(k, g.steps));
      w.xyz(r, kNaN);
      w.put<float>(16, r != nullptr ? r->intensity : 0.0f);
      w.put<std::uint32_t>(20,
                           static_cast<std::uint32_t>(std::llround(k * period_s * 1e9 / g.steps)));
      w.put<std::uint16_t>(26, static_cast<std::uint16_t>(row));
      w.put<std::uint32_t>(32, r != nullptr ? static_cast<std::uint32_t>(r->range_m * 1000.0) : 0u);
      w.next();
    }
  }
}

/// velodyne_pointcloud's PointXYZIRT by addPointField (22 bytes, `time` f32 unaligned at 18),
/// ring = elevation rank (0 = lowest), `time` in s from the stamp, which is the last packet's:
/// negative. Organised: rows = firings, columns = lasers in ring order, NaN x, y, z and
/// intensity for no return. A list: the returns only, firing order, raw (interleaved) laser order.
void velodyne(const Grid& g, std::int64_t start_ns, double period_s, bool organised,
              DriverCloud& c) {
  set_fields(c, 22,
             {{"x", 0, kF32},
              {"y", 4, kF32},
              {"z", 8, kF32},
              {"intensity", 12, kF32},
              {"ring", 16, kU16},
              {"time", 18, kF32}});
  const double last_s = (g.steps - 1) * period_s / g.steps;
  c.stamp_ns = start_ns + std::llround(last_s * 1e9);
  Writer w(c, static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps));
  for (int k = 0; k < g.steps; ++k) {
    for (int laser = 0; laser < g.beams; ++laser) {
      const int beam = organised ? laser : interleaved_beam(laser, g.beams);
      const LidarReturn* r = g.at(beam, step_fired(k, g.steps));
      if (!organised && r == nullptr) continue;
      w.xyz(r, kNaN);
      w.put<float>(12, r != nullptr ? r->intensity : kNaN);
      w.put<std::uint16_t>(16, static_cast<std::uint16_t>(beam));
      w.put<float>(18, static_cast<float>(k * period_s / g.steps - last_s));
      w.next();
    }
  }
  c.data.resize(w.written() * c.point_step);
  c.height = organised ? static_cast<std::uint32_t>(g.steps) : 1u;
  c.width =
      organised ? static_cast<std::uint32_t>(g.beams) : static_cast<std::uint32_t>(w.written());
}

/// rslidar_sdk XYZIRT, ros_send_by_rows false (26 bytes, `timestamp` f64 absolute s unaligned
/// at 18): rows = firings, columns = channels in raw order, ring = elevation rank (0 = lowest),
/// NaN x, y, z with intensity 0 for no return; the stamp is the first point's time.
void rslidar(const Grid& g, std::int64_t start_ns, double period_s, DriverCloud& c) {
  set_xyzirt26_fields(c);
  c.stamp_ns = start_ns;
  c.height = static_cast<std::uint32_t>(g.steps);
  c.width = static_cast<std::uint32_t>(g.beams);
  Writer w(c, static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps));
  for (int k = 0; k < g.steps; ++k) {
    for (int channel = 0; channel < g.beams; ++channel) {
      const int beam = interleaved_beam(channel, g.beams);
      put_xyzirt26(w, g.at(beam, step_fired(k, g.steps)), kNaN, static_cast<std::uint16_t>(beam),
                   static_cast<double>(start_ns) / 1e9 + k * period_s / g.steps);
    }
  }
}

/// HesaiLidar_ROS_2.0 (26 bytes): a list in packet order (firing, then raw channel 0..N−1 with
/// channel 0 the top beam), (0, 0, 0) kept for no return, `timestamp` f64 absolute s of the
/// packet (6 firings each), the stamp the first packet's.
void hesai(const Grid& g, std::int64_t start_ns, double period_s, DriverCloud& c) {
  set_xyzirt26_fields(c);
  constexpr int kFiringsPerPacket = 6;
  c.stamp_ns = start_ns;
  c.height = 1;
  c.width = static_cast<std::uint32_t>(g.beams * g.steps);
  Writer w(c, static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps));
  for (int k = 0; k < g.steps; ++k) {
    const int packet_first = k - k % kFiringsPerPacket;
    for (int channel = 0; channel < g.beams; ++channel) {
      const int beam = g.beams - 1 - channel;
      put_xyzirt26(w, g.at(beam, step_fired(k, g.steps)), 0.0f, static_cast<std::uint16_t>(channel),
                   static_cast<double>(start_ns) / 1e9 + packet_first * period_s / g.steps);
    }
  }
}

/// Autoware's PointXYZIRCAEDT (32 bytes, plain struct): a list of the returns in firing order,
/// channel = elevation rank (a Velodyne behind Nebula), intensity u8, azimuth / elevation (rad)
/// and distance of the point, time_stamp u32 ns from the stamp (the earliest point's).
void autoware(const Grid& g, std::int64_t start_ns, double period_s, DriverCloud& c) {
  set_fields(c, 32,
             {{"x", 0, kF32},
              {"y", 4, kF32},
              {"z", 8, kF32},
              {"intensity", 12, kU8},
              {"return_type", 13, kU8},
              {"channel", 14, kU16},
              {"azimuth", 16, kF32},
              {"elevation", 20, kF32},
              {"distance", 24, kF32},
              {"time_stamp", 28, kU32}});
  c.stamp_ns = start_ns;
  Writer w(c, static_cast<std::size_t>(g.beams) * static_cast<std::size_t>(g.steps));
  for (int k = 0; k < g.steps; ++k) {
    for (int beam = 0; beam < g.beams; ++beam) {
      const LidarReturn* r = g.at(beam, step_fired(k, g.steps));
      if (r == nullptr) continue;
      const Eigen::Vector3d& p = r->point_S;
      w.xyz(r, 0.0f);
      w.put<std::uint8_t>(12, static_cast<std::uint8_t>(std::min(255.0f, r->intensity)));
      w.put<std::uint8_t>(13, 1);  // first return
      w.put<std::uint16_t>(14, static_cast<std::uint16_t>(beam));
      w.put<float>(16, static_cast<float>(std::atan2(p.y(), p.x())));
      w.put<float>(20, static_cast<float>(std::atan2(p.z(), std::hypot(p.x(), p.y()))));
      w.put<float>(24, static_cast<float>(r->range_m));
      w.put<std::uint32_t>(28,
                           static_cast<std::uint32_t>(std::llround(k * period_s * 1e9 / g.steps)));
      w.next();
    }
  }
  c.data.resize(w.written() * c.point_step);
  c.height = 1;
  c.width = static_cast<std::uint32_t>(w.written());
}

}  // namespace

const std::vector<Driver>& all_drivers() {
  static const std::vector<Driver> drivers = {Driver::kOuster,       Driver::kVelodyne,
                                              Driver::kVelodyneList, Driver::kRslidarXYZIRT,
                                              Driver::kHesai,        Driver::kAutowareXYZIRCAEDT};
  return drivers;
}

std::string_view driver_name(Driver d) {
  switch (d) {
    case Driver::kOuster: return "ouster";
    case Driver::kVelodyne: return "velodyne";
    case Driver::kVelodyneList: return "velodyne-list";
    case Driver::kRslidarXYZIRT: return "rslidar";
    case Driver::kHesai: return "hesai";
    case Driver::kAutowareXYZIRCAEDT: return "autoware";
  }
  return "?";
}

bool driver_from_name(std::string_view name, Driver& out) {
  for (const Driver d : all_drivers()) {
    if (driver_name(d) == name) {
      out = d;
      return true;
    }
  }
  return false;
}

std::int64_t firing_time_ns(const LidarParams& lidar, int azimuth_step, double sweep_period_s) {
  const int k = (lidar.azimuth_steps - azimuth_step) % lidar.azimuth_steps;
  return std::llround(k * sweep_period_s * 1e9 / lidar.azimuth_steps);
}

DriverCloud encode_sweep(Driver driver, const LidarParams& lidar,
                         const std::vector<LidarReturn>& returns, std::int64_t sweep_start_ns,
                         double sweep_period_s) {
  const Grid g = grid_of(lidar, returns);
  DriverCloud c;
  switch (driver) {
    case Driver::kOuster: ouster(g, sweep_start_ns, sweep_period_s, c); break;
    case Driver::kVelodyne:
    case Driver::kVelodyneList:
      velodyne(g, sweep_start_ns, sweep_period_s, driver == Driver::kVelodyne, c);
      break;
    case Driver::kRslidarXYZIRT: rslidar(g, sweep_start_ns, sweep_period_s, c); break;
    case Driver::kHesai: hesai(g, sweep_start_ns, sweep_period_s, c); break;
    case Driver::kAutowareXYZIRCAEDT: autoware(g, sweep_start_ns, sweep_period_s, c); break;
  }
  // Velodyne's containers and Hesai's say is_dense false; the lists without markers true.
  c.is_dense = driver == Driver::kVelodyneList || driver == Driver::kAutowareXYZIRCAEDT;
  return c;
}

}  // namespace tarmac::sim
