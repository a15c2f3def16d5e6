#include "tarmac/sim/lidar.hpp"

#include "small_objects.hpp"
#include "text_number.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <numbers>
#include <system_error>

namespace tarmac::sim {
namespace {

double radians(double deg) {
  return deg * std::numbers::pi / 180.0;
}

void append_le(std::string& bytes, float value) {
  const auto bits = std::bit_cast<std::uint32_t>(value);
  for (int i = 0; i < 4; ++i) bytes += static_cast<char>((bits >> (8 * i)) & 0xffu);
}

bool write_file(const std::filesystem::path& file, const std::string& bytes, std::string& error) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) {
    error = file.string() + ": cannot be written";
    return false;
  }
  return true;
}

/// scans/NNNNNN.bin, the names this writer produces.
bool is_scan_name(const std::string& name) {
  return name.size() == 10 && name.ends_with(".bin") &&
         std::all_of(name.begin(), name.begin() + 6, [](char c) { return c >= '0' && c <= '9'; });
}

std::string scan_name(int i) {
  std::string digits = std::to_string(i);
  if (digits.size() < 6) digits.insert(0, 6 - digits.size(), '0');
  return digits + ".bin";
}

std::string pose_line(const Eigen::Isometry3d& T) {
  std::string line;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (!line.empty()) line += ' ';
      line += number(T.matrix()(r, c));
    }
  }
  return line + "\n";
}

std::string readme(const SequenceParams& p) {
  const LidarParams& l = p.lidar;
  std::string s;
  s += "tarmac-sim: a synthetic airside sequence in KITTI layout with analytic ground truth.\n\n";
  if (p.path.terrain.flat()) {
    s += "A simulated spinning multi-beam LiDAR on a vehicle driving through an airside apron\n";
    s += "made of exact primitives (scene.json: parked aircraft with a wing over the path, jet\n";
    s += "bridge, traffic cones, 10 cm debris, a tug crossing the path).\n\n";
  } else {
    s += "A simulated spinning multi-beam LiDAR on a vehicle driving over airside terrain\n";
    s += "made of exact primitives (scene.json: ramps, a crowned road or a lower level, with\n";
    s += "cones, crates, curbs and walls), pitched and rolled with the ground under its\n";
    s += "wheels.\n\n";
  }
  s += "Files:\n";
  s += "  scans/NNNNNN.bin  float32 little-endian x, y, z, intensity per point, sensor frame S\n";
  s += "  organised/NNNNNN.bin  the same sweep as a grid of beams (rows, lowest first) by azimuth\n"
       "                    steps (columns), row-major, float32 x, y, z, intensity; NaN x, y, z\n"
       "                    where the beam returned nothing (organised/shape.txt: rows cols)\n";
  s += "                    (x forward, y left, z up, m); intensity " + number(kGroundIntensity) +
       " ground, " + number(kObjectIntensity) + " other objects\n";
  s += "  poses.txt         per scan, row-major 3x4 T_world_sensor (12 numbers)\n";
  s += "  times.txt         per scan, stamp in s (scan i at i / rate)\n";
  s += "  scene.json        the scene in the scene frame (x along the apron, y left, z up, m,\n";
  s += p.path.terrain.flat()
           ? "                    ground z = 0) and T_world_scene (rotation about x by the tilt)\n"
           : "                    ground: the objects of kind ground) and T_world_scene (rotation\n"
             "                    about x by the tilt)\n";
  s += "  obstacle_columns.txt  the costmap's ground truth: cells (lattice ix iy) whose span\n";
  s += "                    " + number(p.envelope_low_m) + ".." + number(p.envelope_high_m) +
       (p.path.terrain.flat() ? " m up" : " m above the ground") +
       " meets a static object, with the first scan that returned a point from it\n";
  s += "  dynamic_boxes.txt moving objects' ground truth: a '# T_world_scene' line (12 numbers,\n";
  s += "                    row-major 3x4), then per scan and moving object 'scan id min_x min_y\n";
  s += "                    min_z max_x max_y max_z': its axis-aligned box in the scene frame at\n";
  s += "                    the scan's stamp, m\n";
  s += "  small_objects.txt when the scene has any: its cones, debris, poles (at most 1 m\n";
  s += "                    across) with their boxes, and the returns each gave per scan\n";
  if (!p.path.terrain.flat()) {
    s += "  ground_cells.txt  the ground the vehicle may drive on: cells (lattice ix iy) within\n";
    s += "                    " + number(p.ground_truth_margin_m) +
         " m of the drive whose ground rises less than " + number(p.envelope_low_m) + " m\n";
    s += "                    across the cell, with the ground's height at its centre (scene\n";
    s += "                    frame, m); obstacle_columns.txt's span is taken above it\n";
    s += "  curb_columns.txt  when the scene has curbs: the obstacle columns of the curbs, with\n";
    s += "                    the first scan that returned a point of a curb from their span\n";
  }
  s += "\n";
  s += "Each scan is one revolution taken at its stamp (no motion distortion). Beams that hit\n";
  s += "nothing within the maximum range give no point.\n\n";
  s += "Parameters:\n";
  if (p.path.waypoints_W.size() >= 2) {
    s += "  path              ";
    for (std::size_t i = 0; i < p.path.waypoints_W.size(); ++i) {
      s += (i == 0 ? "(" : " -> (") + number(p.path.waypoints_W[i].x()) + ", " +
           number(p.path.waypoints_W[i].y()) + ")";
    }
    s += " m, turns of " + number(p.path.corner_radius_m) + " m radius, at " +
         number(p.path.speed_mps) + " m/s, sensor " + number(p.path.sensor_height_m) +
         " m above the base\n";
  } else {
    s += "  path              (" + number(p.path.start_W.x()) + ", " + number(p.path.start_W.y()) +
         ") -> (" + number(p.path.end_W.x()) + ", " + number(p.path.end_W.y()) + ") m at " +
         number(p.path.speed_mps) + " m/s, sensor " + number(p.path.sensor_height_m) +
         " m above the base\n";
  }
  if (!p.path.terrain.flat()) {
    s += "  terrain           wheels on the objects of kind ground, wheelbase " +
         number(p.path.wheelbase_m) + " m, track " + number(p.path.track_m) + " m\n";
  }
  s += "  beams             " + std::to_string(l.beams) + ", elevation " +
       number(l.min_elevation_deg) + " .. " + number(l.max_elevation_deg) + " deg\n";
  s += "  azimuth steps     " + std::to_string(l.azimuth_steps) + "\n";
  s += "  max range         " + number(l.max_range_m) + " m\n";
  s += "  range noise       " + number(l.range_noise_m) + " m (1 sigma), seed " +
       std::to_string(p.seed) + "\n";
  if (l.dropout > 0.0) {
    s += "  dropout           " + number(100.0 * l.dropout) +
         " % of returns lost at random, seed " + std::to_string(l.dropout_seed) + "\n";
  }
  s += "  rate              " + number(p.rate_hz) + " Hz, " + std::to_string(p.scan_count()) +
       " scans\n";
  s += "  tilt              " + number(p.tilt_deg) + " deg about x (world = Rx(tilt) * scene)\n";
  if (p.drift_m != 0.0) {
    s += "  pose drift        " + number(p.drift_m) + " m along scene y, reached after " +
         number(p.drift_ramp_s) + " s; " +
         (p.correct_at_scan > 0 ? "true poses from scan " + std::to_string(p.correct_at_scan) +
                                      " on (corrections.txt: the corrected trajectory)"
                                : std::string("never corrected")) +
         "\n";
  }
  if (p.drift_z_m != 0.0) {
    const std::string end =
        p.correct_at_scan > 0 ? "true poses from scan " + std::to_string(p.correct_at_scan) + " on"
                              : "never corrected";
    s += "  height drift      " + number(p.drift_z_m) +
         " m along scene z, growing evenly over the drive; " + end + "\n";
  }
  return s;
}

}  // namespace

double GaussianNoise::uniform() {
  return static_cast<double>(engine_() >> 11) * 0x1.0p-53;
}

double GaussianNoise::sample() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  double u = 0.0, v = 0.0, s = 0.0;
  do {
    u = 2.0 * uniform() - 1.0;
    v = 2.0 * uniform() - 1.0;
    s = u * u + v * v;
  } while (s >= 1.0 || s == 0.0);
  const double m = std::sqrt(-2.0 * std::log(s) / s);
  spare_ = v * m;
  has_spare_ = true;
  return u * m;
}

std::string LidarParams::validate() const {
  if (beams < 1 || beams > 1024) return "beams must be in [1, 1024]";
  if (azimuth_steps < 1 || azimuth_steps > 65536) return "azimuth steps must be in [1, 65536]";
  if (!std::isfinite(min_elevation_deg) || !std::isfinite(max_elevation_deg) ||
      min_elevation_deg > max_elevation_deg || min_elevation_deg < -90.0 ||
      max_elevation_deg > 90.0) {
    return "elevations must satisfy -90 <= min <= max <= 90 deg";
  }
  if (!(max_range_m > 0.0) || !std::isfinite(max_range_m)) return "max range must be > 0 m";
  if (!(range_noise_m >= 0.0) || !std::isfinite(range_noise_m)) return "noise must be >= 0 m";
  if (!(dropout >= 0.0 && dropout <= 1.0)) return "dropout must be in [0, 1]";
  return {};
}

Lidar::Lidar(const LidarParams& params) : params_(params) {
  directions_S_.reserve(static_cast<std::size_t>(params_.beams) *
                        static_cast<std::size_t>(params_.azimuth_steps));
  for (int j = 0; j < params_.azimuth_steps; ++j) {
    const double azimuth = 2.0 * std::numbers::pi * j / params_.azimuth_steps;
    for (int b = 0; b < params_.beams; ++b) {
      const double elevation_deg =
          params_.beams == 1 ? 0.5 * (params_.min_elevation_deg + params_.max_elevation_deg)
                             : params_.min_elevation_deg +
                                   b * (params_.max_elevation_deg - params_.min_elevation_deg) /
                                       (params_.beams - 1);
      const double elevation = radians(elevation_deg);
      directions_S_.emplace_back(std::cos(elevation) * std::cos(azimuth),
                                 std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
    }
  }
}

namespace {

/// A uniform number in [0, 1) from (seed, beam, step, time): splitmix64 over the four.
double dropped(std::uint64_t seed, int beam, int step, double t_s) {
  std::uint64_t t_bits = 0;
  std::memcpy(&t_bits, &t_s, sizeof t_bits);
  std::uint64_t x = seed;
  for (const std::uint64_t v :
       {static_cast<std::uint64_t>(beam), static_cast<std::uint64_t>(step), t_bits}) {
    x += 0x9e3779b97f4a7c15ULL ^ v;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    x ^= x >> 31;
  }
  return static_cast<double>(x >> 11) * 0x1.0p-53;
}

}  // namespace

void Lidar::scan(const Scene& scene, const Eigen::Isometry3d& T_W_S, double t_s,
                 GaussianNoise* noise, std::vector<LidarReturn>& returns) const {
  returns.clear();
  const Eigen::Vector3d origin_W = T_W_S.translation();
  const Eigen::Matrix3d R_W_S = T_W_S.linear();
  const std::vector<int> candidates = scene.near(origin_W, params_.max_range_m, t_s);
  for (int j = 0; j < params_.azimuth_steps; ++j) {
    for (int b = 0; b < params_.beams; ++b) {
      const Eigen::Vector3d& dir_S = direction_S(b, j);
      const std::optional<Hit> hit =
          scene.raycast(origin_W, R_W_S * dir_S, params_.max_range_m, t_s, &candidates);
      if (!hit) continue;
      if (params_.dropout > 0.0 && dropped(params_.dropout_seed, b, j, t_s) < params_.dropout) {
        continue;  // the return was lost (a dark or specular spot): the beam reports none
      }
      LidarReturn r;
      r.true_range_m = hit->range_m;
      r.range_m = hit->range_m;
      if (params_.range_noise_m > 0.0) r.range_m += params_.range_noise_m * noise->sample();
      if (r.range_m <= 0.0) continue;  // noise cannot put a point behind the sensor
      r.point_S = r.range_m * dir_S;
      r.intensity = scene.objects()[static_cast<std::size_t>(hit->object_id)].kind == "ground"
                        ? kGroundIntensity
                        : kObjectIntensity;
      r.beam = b;
      r.azimuth_step = j;
      r.object_id = hit->object_id;
      returns.push_back(r);
    }
  }
}

DrivePath DrivePath::loop(const Eigen::Vector2d& min_W, const Eigen::Vector2d& max_W,
                          double speed_mps, double corner_radius_m) {
  DrivePath p;
  p.speed_mps = speed_mps;
  p.corner_radius_m = corner_radius_m;
  const Eigen::Vector2d start(0.5 * (min_W.x() + max_W.x()), min_W.y());
  p.waypoints_W = {start, {max_W.x(), min_W.y()}, max_W, {min_W.x(), max_W.y()}, min_W, start};
  return p;
}

namespace {

/// One piece of a drive path: a straight segment (radius 0) or a circular arc.
struct PathPiece {
  Eigen::Vector2d from;    ///< start point
  double heading = 0.0;    ///< heading at the start, rad
  double length = 0.0;     ///< m
  double curvature = 0.0;  ///< 1/m, signed (left positive); 0: straight
};

double heading_of(const Eigen::Vector2d& d) {
  return std::atan2(d.y(), d.x());
}

/// The path's pieces: straight segments between the vertices, each inner vertex replaced by an
/// arc of radius r tangent to both segments (shrunk where a segment is too short for it).
std::vector<PathPiece> path_pieces(const std::vector<Eigen::Vector2d>& points, double r) {
  std::vector<PathPiece> pieces;
  const std::size_t n = points.size();
  Eigen::Vector2d from = points[0];
  for (std::size_t i = 1; i < n; ++i) {
    const Eigen::Vector2d in = points[i] - points[i - 1];
    Eigen::Vector2d to = points[i];
    double tangent = 0.0, turn = 0.0, radius = 0.0;
    if (i + 1 < n && r > 0.0) {
      const Eigen::Vector2d out = points[i + 1] - points[i];
      turn = std::remainder(heading_of(out) - heading_of(in), 2.0 * std::numbers::pi);
      const double half = std::tan(0.5 * std::abs(turn));
      // A segment between two turns gives each half of it; the first and the last all of it.
      const double in_share = i == 1 ? in.norm() : 0.5 * in.norm();
      const double out_share = i + 2 == n ? out.norm() : 0.5 * out.norm();
      tangent = std::min({r * half, in_share, out_share});
      radius = half > 0.0 ? tangent / half : 0.0;
      to = points[i] - tangent * in.normalized();
    }
    if ((to - from).norm() > 0.0) {
      pieces.push_back({from, heading_of(in), (to - from).norm(), 0.0});
    }
    if (radius > 0.0) {
      const double k = (turn > 0.0 ? 1.0 : -1.0) / radius;
      pieces.push_back({to, heading_of(in), std::abs(turn) * radius, k});
      const Eigen::Vector2d out = points[i + 1] - points[i];
      from = points[i] + tangent * out.normalized();
    } else {
      from = points[i];
    }
  }
  return pieces;
}

}  // namespace

namespace {

/// The base at xy_W heading `heading` with its wheels on `terrain` (DrivePath): the contacts'
/// mean height, x along the rear-to-front line, z normal to it and to the right-to-left line.
Eigen::Isometry3d on_terrain(const Terrain& terrain, const Eigen::Vector2d& xy_W, double heading,
                             double wheelbase_m, double track_m) {
  const Eigen::Vector2d forward(std::cos(heading), std::sin(heading));
  const Eigen::Vector2d left(-forward.y(), forward.x());
  // Off the terrain a wheel is taken at z = 0: write_sequence refuses such a drive.
  const auto z = [&](const Eigen::Vector2d& xy) { return terrain.height_m(xy).value_or(0.0); };
  const double front = z(xy_W + 0.5 * wheelbase_m * forward);
  const double rear = z(xy_W - 0.5 * wheelbase_m * forward);
  const double left_z = z(xy_W + 0.5 * track_m * left);
  const double right_z = z(xy_W - 0.5 * track_m * left);
  const Eigen::Vector3d x_axis =
      Eigen::Vector3d(wheelbase_m * forward.x(), wheelbase_m * forward.y(), front - rear)
          .normalized();
  const Eigen::Vector3d across(track_m * left.x(), track_m * left.y(), left_z - right_z);
  const Eigen::Vector3d z_axis = x_axis.cross(across).normalized();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear().col(0) = x_axis;
  T.linear().col(1) = z_axis.cross(x_axis);
  T.linear().col(2) = z_axis;
  T.translation() = Eigen::Vector3d(xy_W.x(), xy_W.y(), 0.25 * (front + rear + left_z + right_z));
  return T;
}

}  // namespace

double DrivePath::length_m() const {
  if (waypoints_W.size() < 2) return (end_W - start_W).norm();
  double length = 0.0;
  for (const PathPiece& piece : path_pieces(waypoints_W, corner_radius_m)) length += piece.length;
  return length;
}

Eigen::Isometry3d DrivePath::T_W_base(double t_s) const {
  const double length = length_m();
  double travelled_m = std::clamp(speed_mps * t_s, 0.0, length);
  const std::vector<PathPiece> pieces =
      waypoints_W.size() < 2
          ? std::vector<PathPiece>{{start_W, heading_of(end_W - start_W), length, 0.0}}
          : path_pieces(waypoints_W, corner_radius_m);
  std::size_t i = 0;
  while (i + 1 < pieces.size() && travelled_m > pieces[i].length) travelled_m -= pieces[i++].length;
  const PathPiece& piece = pieces[i];
  const double s = std::min(travelled_m, piece.length);
  double heading = piece.heading;
  Eigen::Vector2d p;
  if (piece.curvature == 0.0) {
    p = piece.from + s * Eigen::Vector2d(std::cos(heading), std::sin(heading));
  } else {
    // On the circle through `from` whose centre lies 1/k to the left of the heading.
    const double k = piece.curvature;
    const Eigen::Vector2d centre =
        piece.from + Eigen::Vector2d(-std::sin(heading), std::cos(heading)) / k;
    heading += k * s;
    p = centre + Eigen::Vector2d(std::sin(heading), -std::cos(heading)) / k;
  }
  if (!terrain.flat()) return on_terrain(terrain, p, heading, wheelbase_m, track_m);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.x(), p.y(), 0.0);
  return T;
}

Eigen::Isometry3d DrivePath::T_W_S(double t_s) const {
  Eigen::Isometry3d T_base_S = Eigen::Isometry3d::Identity();
  T_base_S.translation() = Eigen::Vector3d(0.0, 0.0, sensor_height_m);
  return T_W_base(t_s) * T_base_S;
}

int SequenceParams::scan_count() const {
  if (scans > 0) return scans;
  // The small margin keeps an exact multiple (60 m / 3 m/s · 10 Hz = 200) from rounding down.
  return static_cast<int>(std::floor(path.duration_s() * rate_hz + 1e-9)) + 1;
}

Eigen::Isometry3d SequenceParams::true_T_O_S(int i) const {
  return T_O_W() * path.T_W_S(stamp_s(i));
}

Eigen::Isometry3d SequenceParams::written_T_O_S(int i) const {
  const double t_s = stamp_s(i);
  if ((drift_m == 0.0 && drift_z_m == 0.0) || (correct_at_scan > 0 && i >= correct_at_scan)) {
    return true_T_O_S(i);
  }
  Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
  D.translation().y() = drift_m * std::min(t_s / drift_ramp_s, 1.0);
  if (drift_z_m != 0.0) {
    const double last_s = stamp_s(scan_count() - 1);
    D.translation().z() = last_s > 0.0 ? drift_z_m * t_s / last_s : 0.0;
  }
  return T_O_W() * D * path.T_W_S(t_s);
}

Eigen::Isometry3d SequenceParams::T_O_W() const {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  if (tilt_deg != 0.0) {
    T.linear() = Eigen::AngleAxisd(radians(tilt_deg), Eigen::Vector3d::UnitX()).toRotationMatrix();
  }
  return T;
}

std::string SequenceParams::validate() const {
  if (std::string e = lidar.validate(); !e.empty()) return e;
  if (!(path.speed_mps > 0.0) || !std::isfinite(path.speed_mps)) return "speed must be > 0 m/s";
  if (!(path.length_m() > 0.0)) return "the drive path must have a length";
  if (!std::isfinite(path.sensor_height_m)) return "sensor height must be finite";
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) return "rate must be > 0 Hz";
  if (scans < 0) return "scans must be >= 0 (0: drive the whole path)";
  if (!std::isfinite(tilt_deg) || std::abs(tilt_deg) > 180.0) {
    return "tilt must be in [-180, 180] deg";
  }
  if (!std::isfinite(drift_m) || std::abs(drift_m) > 100.0) return "drift must be in [-100, 100] m";
  if (!std::isfinite(drift_z_m) || std::abs(drift_z_m) > 100.0) {
    return "height drift must be in [-100, 100] m";
  }
  if (!path.terrain.flat() && (!(path.wheelbase_m > 0.0) || !(path.track_m > 0.0) ||
                               !std::isfinite(path.wheelbase_m) || !std::isfinite(path.track_m))) {
    return "wheelbase and track must be > 0 m";
  }
  if (!(ground_truth_margin_m >= 0.0) || !std::isfinite(ground_truth_margin_m)) {
    return "ground truth margin must be >= 0 m";
  }
  if (!(drift_ramp_s > 0.0) || !std::isfinite(drift_ramp_s)) return "drift ramp must be > 0 s";
  if (correct_at_scan < 0) return "correct-at must be >= 0 (0: never)";
  if (scans > 1000000 || (scans == 0 && !(path.duration_s() * rate_hz < 1e6))) {
    return "too many scans (more than 1000000)";
  }
  return {};
}

namespace {

/// ground_cells.txt (write_sequence): the cells within ground_truth_margin_m of the drive's
/// bounding box whose ground is there and rises less than envelope_low_m across the cell (a
/// rise the costmap must block is no ground), with the ground's height at their centres.
std::string ground_cells(const SequenceParams& params, const Eigen::Isometry3d& T_O_W) {
  const Terrain& terrain = params.path.terrain;
  const double cell = params.truth_cell_m;
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (int i = 0; i < params.scan_count(); ++i) {
    const Eigen::Vector2d xy = params.path.T_W_base(params.stamp_s(i)).translation().head<2>();
    lo = lo.cwiseMin(xy);
    hi = hi.cwiseMax(xy);
  }
  lo.array() -= params.ground_truth_margin_m;
  hi.array() += params.ground_truth_margin_m;
  std::string out = "# ground cells: cell_m " + number(cell) + " rise_below_m " +
                    number(params.envelope_low_m) + "\n# T_world_scene " + pose_line(T_O_W) +
                    "# ix iy ground_z_m (at the cell's centre)\n";
  char line[80];
  for (long iy = static_cast<long>(std::floor(lo.y() / cell));
       iy <= static_cast<long>(std::floor(hi.y() / cell)); ++iy) {
    for (long ix = static_cast<long>(std::floor(lo.x() / cell));
         ix <= static_cast<long>(std::floor(hi.x() / cell)); ++ix) {
      // The same 3 x 3 points of the cell's square as the obstacle columns.
      double low = std::numeric_limits<double>::infinity(), high = -low;
      bool covered = true;
      for (int sx = 0; sx < 3 && covered; ++sx) {
        for (int sy = 0; sy < 3 && covered; ++sy) {
          const std::optional<double> z =
              terrain.height_m({(static_cast<double>(ix) + 0.1 + 0.4 * sx) * cell,
                                (static_cast<double>(iy) + 0.1 + 0.4 * sy) * cell});
          covered = z.has_value();
          if (covered) {
            low = std::min(low, *z);
            high = std::max(high, *z);
          }
        }
      }
      if (!covered || high - low >= params.envelope_low_m) continue;
      const double centre_z = *terrain.height_m(
          {(static_cast<double>(ix) + 0.5) * cell, (static_cast<double>(iy) + 0.5) * cell});
      std::snprintf(line, sizeof line, "%ld %ld %.3f\n", ix, iy, centre_z);
      out += line;
    }
  }
  return out;
}

}  // namespace

namespace {

/// The columns (truth_cell_m on the world lattice) whose envelope span meets a static object,
/// each with the first scan that returned a point from that span (−1: none yet); the curbs'
/// apart (a costmap that blocks cones may still drive over a curb).
struct ColumnTruth {
  std::map<std::pair<long, long>, int> columns, curbs;
};

/// out_dir/scans and out_dir/organised, made and cleared of earlier scans. An error, or "".
std::string prepare_scan_dirs(const std::filesystem::path& out_dir) {
  std::error_code ec;
  for (const auto& dir : {out_dir / "scans", out_dir / "organised"}) {
    std::filesystem::create_directories(dir, ec);
    if (ec) return dir.string() + ": " + ec.message();
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      if (entry.is_regular_file() && is_scan_name(entry.path().filename().string())) {
        std::filesystem::remove(entry.path(), ec);
        if (ec) return entry.path().string() + ": " + ec.message();
      }
    }
    if (ec) return dir.string() + ": " + ec.message();
  }
  return {};
}

/// Ground truth for the costmap: every column whose envelope span (above the terrain) meets a
/// static object, none seen yet.
ColumnTruth envelope_columns(const Scene& scene, const SequenceParams& params) {
  const double cell = params.truth_cell_m;
  const Terrain& terrain = params.path.terrain;
  ColumnTruth truth;
  auto& columns = truth.columns;
  auto& curb_columns = truth.curbs;
  for (const Object& o : scene.objects()) {
    if (o.dynamic() || o.kind == "ground") continue;
    const Aabb b = scene.bounds_at(o.id, 0.0);
    // On flat ground the envelope is one z range; on terrain it follows the ground.
    if (terrain.flat() &&
        (b.max_W.z() < params.envelope_low_m || b.min_W.z() > params.envelope_high_m)) {
      continue;
    }
    for (long ix = static_cast<long>(std::floor(b.min_W.x() / cell));
         ix <= static_cast<long>(std::floor(b.max_W.x() / cell)); ++ix) {
      for (long iy = static_cast<long>(std::floor(b.min_W.y() / cell));
           iy <= static_cast<long>(std::floor(b.max_W.y() / cell)); ++iy) {
        // 3 x 3 points of the cell's square, every 2 cm up the envelope above their ground.
        bool hit = false;
        for (int sx = 0; sx < 3 && !hit; ++sx) {
          for (int sy = 0; sy < 3 && !hit; ++sy) {
            const double x = (static_cast<double>(ix) + 0.1 + 0.4 * sx) * cell;
            const double y = (static_cast<double>(iy) + 0.1 + 0.4 * sy) * cell;
            const std::optional<double> ground_z = terrain.height_m({x, y});
            if (!ground_z) continue;
            for (double z = params.envelope_low_m; z <= params.envelope_high_m && !hit; z += 0.02) {
              hit = contains(o.shape_W, Eigen::Vector3d(x, y, *ground_z + z));
            }
          }
        }
        if (hit) columns.emplace(std::make_pair(ix, iy), -1);
        if (hit && o.kind == "curb") curb_columns.emplace(std::make_pair(ix, iy), -1);
      }
    }
  }
  return truth;
}

/// A sweep's returns as scans/NNNNNN.bin holds them: float32 x, y, z, intensity.
std::string list_bytes(const std::vector<LidarReturn>& returns) {
  std::string bytes;
  bytes.reserve(returns.size() * 16);
  for (const LidarReturn& r : returns) {
    append_le(bytes, static_cast<float>(r.point_S.x()));
    append_le(bytes, static_cast<float>(r.point_S.y()));
    append_le(bytes, static_cast<float>(r.point_S.z()));
    append_le(bytes, r.intensity);
  }
  return bytes;
}

/// The same sweep organised, beams by azimuth steps (row-major), NaN where a beam returned
/// nothing: what a spinning LiDAR's driver publishes, beams without return included.
std::string organised_bytes(const std::vector<LidarReturn>& returns, int rows, int cols,
                            std::vector<float>& organised) {
  organised.assign(static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols) * 4,
                   std::numeric_limits<float>::quiet_NaN());
  for (const LidarReturn& r : returns) {
    float* cell = &organised[(static_cast<std::size_t>(r.beam) * static_cast<std::size_t>(cols) +
                              static_cast<std::size_t>(r.azimuth_step)) *
                             4];
    cell[0] = static_cast<float>(r.point_S.x());
    cell[1] = static_cast<float>(r.point_S.y());
    cell[2] = static_cast<float>(r.point_S.z());
    cell[3] = r.intensity;
  }
  std::string bytes;
  for (const float f : organised) append_le(bytes, f);
  return bytes;
}

/// Scan i's returns from the envelope span of a static object mark their columns seen.
void mark_seen(const Scene& scene, const SequenceParams& params,
               const std::vector<LidarReturn>& returns, const Eigen::Isometry3d& T_W_S, int i,
               ColumnTruth& truth) {
  const double cell = params.truth_cell_m;
  const Terrain& terrain = params.path.terrain;
  auto& columns = truth.columns;
  auto& curb_columns = truth.curbs;
  for (const LidarReturn& r : returns) {
    if (r.object_id < 0 || r.range_m <= 0.0) continue;
    const Object& o = scene.objects()[static_cast<std::size_t>(r.object_id)];
    if (o.dynamic() || o.kind == "ground") continue;
    const Eigen::Vector3d p_W = T_W_S * (r.point_S * (r.true_range_m / r.range_m));
    const std::optional<double> ground_z = terrain.height_m(p_W.head<2>());
    if (!ground_z) continue;
    const double above_ground_m = p_W.z() - *ground_z;
    if (above_ground_m < params.envelope_low_m || above_ground_m > params.envelope_high_m) {
      continue;
    }
    const auto key = std::make_pair(static_cast<long>(std::floor(p_W.x() / cell)),
                                    static_cast<long>(std::floor(p_W.y() / cell)));
    // A return on the object's surface lies in one of its columns (or on the edge of one).
    if (auto it = columns.find(key); it != columns.end() && it->second < 0) it->second = i;
    if (o.kind != "curb") continue;
    if (auto it = curb_columns.find(key); it != curb_columns.end() && it->second < 0) {
      it->second = i;
    }
  }
}

/// obstacle_columns.txt's or curb_columns.txt's text.
std::string column_file(const std::string& what, const SequenceParams& params,
                        const Eigen::Isometry3d& T_O_W,
                        const std::map<std::pair<long, long>, int>& first_seen) {
  std::string text = "# " + what + " columns: cell_m " + number(params.truth_cell_m) +
                     " envelope_z_m " + number(params.envelope_low_m) + " " +
                     number(params.envelope_high_m) + "\n# T_world_scene " + pose_line(T_O_W) +
                     "# ix iy first_seen_scan (-1: no return from its envelope span)\n";
  for (const auto& [key, first] : first_seen) {
    text += std::to_string(key.first) + ' ' + std::to_string(key.second) + ' ' +
            std::to_string(first) + '\n';
  }
  return text;
}

}  // namespace

SequenceResult write_sequence(const Scene& scene, const SequenceParams& params,
                              const std::filesystem::path& out_dir) {
  SequenceResult result;
  if (std::string e = params.validate(); !e.empty()) {
    result.error = e;
    return result;
  }
  if (params.path.terrain != scene.terrain()) {
    result.error = "the drive path's terrain is not the scene's (path.terrain = scene.terrain())";
    return result;
  }
  for (int i = 0; i < params.scan_count() && !params.path.terrain.flat(); ++i) {
    const Eigen::Vector2d xy = params.path.T_W_base(params.stamp_s(i)).translation().head<2>();
    if (!params.path.terrain.height_m(xy)) {
      result.error = "the drive leaves the terrain at scan " + std::to_string(i);
      return result;
    }
  }
  const std::filesystem::path scans_dir = out_dir / "scans";
  const std::filesystem::path organised_dir = out_dir / "organised";
  std::error_code ec;
  if (result.error = prepare_scan_dirs(out_dir); !result.error.empty()) return result;
  const int rows = params.lidar.beams;
  const int cols = params.lidar.azimuth_steps;
  if (!write_file(organised_dir / "shape.txt",
                  std::to_string(rows) + " " + std::to_string(cols) + "\n", result.error)) {
    return result;
  }

  const Eigen::Isometry3d T_O_W = params.T_O_W();
  if (!write_file(out_dir / "scene.json", scene.to_json(T_O_W), result.error) ||
      !write_file(out_dir / "README.txt", readme(params), result.error)) {
    return result;
  }

  const Terrain& terrain = params.path.terrain;
  ColumnTruth truth = envelope_columns(scene, params);

  const Lidar lidar(params.lidar);
  GaussianNoise noise(params.seed);
  std::vector<LidarReturn> returns;
  std::vector<float> organised;
  std::vector<std::size_t> points_per_scan;
  std::string poses, times;
  std::string boxes = "# T_world_scene " + pose_line(T_O_W);
  std::map<std::pair<int, int>, int> small_returns;  // (scan, object id) -> returns
  const int n = params.scan_count();
  for (int i = 0; i < n; ++i) {
    const double t_s = params.stamp_s(i);
    const Eigen::Isometry3d T_W_S = params.path.T_W_S(t_s);
    lidar.scan(scene, T_W_S, t_s, &noise, returns);
    if (!write_file(scans_dir / scan_name(i), list_bytes(returns), result.error) ||
        !write_file(organised_dir / scan_name(i), organised_bytes(returns, rows, cols, organised),
                    result.error)) {
      return result;
    }
    mark_seen(scene, params, returns, T_W_S, i, truth);
    for (const LidarReturn& r : returns) {
      if (r.object_id >= 0 && r.range_m > 0.0 &&
          small_object(scene.objects()[static_cast<std::size_t>(r.object_id)])) {
        ++small_returns[{i, r.object_id}];
      }
    }
    poses += pose_line(params.written_T_O_S(i));
    times += number(t_s) + "\n";
    for (const Object& o : scene.objects()) {
      if (!o.dynamic()) continue;
      const Aabb b = scene.bounds_at(o.id, t_s);
      boxes += std::to_string(i) + ' ' + std::to_string(o.id);
      for (const Eigen::Vector3d* c : {&b.min_W, &b.max_W}) {
        for (int a = 0; a < 3; ++a) boxes += ' ' + number((*c)[a]);
      }
      boxes += '\n';
    }
    points_per_scan.push_back(returns.size());
  }
  if ((params.drift_m != 0.0 || params.drift_z_m != 0.0) && params.correct_at_scan > 0 &&
      params.correct_at_scan <= n) {
    std::string corrections;
    const std::string after = std::to_string(params.correct_at_scan - 1) + " ";
    for (int i = 0; i < params.correct_at_scan; ++i) {
      corrections += after + number(params.stamp_s(i)) + " " + pose_line(params.true_T_O_S(i));
    }
    if (!write_file(out_dir / "corrections.txt", corrections, result.error)) return result;
  } else {
    std::filesystem::remove(out_dir / "corrections.txt", ec);  // none stale from an earlier run
  }
  if (!write_file(out_dir / "poses.txt", poses, result.error) ||
      !write_file(out_dir / "times.txt", times, result.error) ||
      !write_file(out_dir / "dynamic_boxes.txt", boxes, result.error)) {
    return result;
  }
  if (!write_file(out_dir / "obstacle_columns.txt",
                  column_file("obstacle", params, T_O_W, truth.columns), result.error)) {
    return result;
  }
  if (const std::string small = small_objects_file(scene, T_O_W, small_returns); !small.empty()) {
    if (!write_file(out_dir / "small_objects.txt", small, result.error)) return result;
  } else {
    std::filesystem::remove(out_dir / "small_objects.txt", ec);  // none stale from an earlier run
  }
  if (!truth.curbs.empty()) {
    if (!write_file(out_dir / "curb_columns.txt", column_file("curb", params, T_O_W, truth.curbs),
                    result.error)) {
      return result;
    }
  } else {
    std::filesystem::remove(out_dir / "curb_columns.txt", ec);  // none stale from an earlier run
  }
  if (!terrain.flat()) {
    std::string ground = ground_cells(params, T_O_W);
    if (!write_file(out_dir / "ground_cells.txt", ground, result.error)) return result;
  } else {
    std::filesystem::remove(out_dir / "ground_cells.txt", ec);  // none stale from an earlier run
  }

  std::sort(points_per_scan.begin(), points_per_scan.end());
  result.summary.scans = n;
  result.summary.min_points = points_per_scan.front();
  result.summary.median_points = points_per_scan[points_per_scan.size() / 2];
  result.summary.max_points = points_per_scan.back();
  return result;
}

}  // namespace tarmac::sim
