#pragma once
/// @file A simulated spinning multi-beam LiDAR on a vehicle driving through a Scene, and the
/// writer of the resulting sequence in KITTI layout.
///
/// Frames: W is the scene frame (scene.hpp); S the sensor (x forward, y left, z up); base the
/// vehicle base on the ground (x along the heading). O is the world frame of poses.txt: W
/// rotated about x by the tilt, T_O_W = Rx(tilt_deg), so that a non-zero tilt gives poses in a
/// frame that is not gravity-aligned while the scans (frame S) stay the same.

#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "tarmac/sim/scene.hpp"

namespace tarmac::sim {

/// Intensity written for returns from the ground plane.
inline constexpr float kGroundIntensity = 10.0f;
/// Intensity written for returns from every other object.
inline constexpr float kObjectIntensity = 100.0f;

/// Gaussian samples from a seeded std::mt19937_64 (whose output sequence the C++ standard fixes)
/// by Marsaglia's polar method, so the stream depends only on the seed: no
/// std::normal_distribution, whose algorithm differs between standard libraries.
class GaussianNoise {
 public:
  explicit GaussianNoise(std::uint64_t seed) : engine_(seed) {}

  /// Next sample of N(0, 1).
  double sample();

 private:
  /// Uniform in [0, 1) with 53 random bits.
  double uniform();

  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

/// The sensor model. Beam b has elevation min + b·(max − min)/(beams − 1) (0 for one beam);
/// azimuth step j has azimuth 2π·j/azimuth_steps, counter-clockwise from +x of frame S.
struct LidarParams {
  int beams = 32;                    ///< number of beams (rings), >= 1
  double min_elevation_deg = -22.5;  ///< lowest beam, degrees above the sensor's xy plane
  double max_elevation_deg = 22.5;   ///< highest beam
  int azimuth_steps = 1024;          ///< firings per revolution, >= 1
  double max_range_m = 100.0;        ///< returns beyond this are dropped (> 0)
  double range_noise_m = 0.0;        ///< standard deviation of Gaussian range noise (>= 0)
  /// Share of returns lost at random (0..1), as real sensors lose them on dark, wet or specular
  /// surfaces and at grazing angles: the beam then reports no return (NaN in an organised
  /// sweep). Decided per (beam, azimuth step, scan time) by a hash of `dropout_seed`, so a
  /// sequence is the same whatever else is simulated.
  double dropout = 0.0;
  std::uint64_t dropout_seed = 1;

  /// Empty when valid, else what is wrong.
  std::string validate() const;
};

/// One return of one beam.
struct LidarReturn {
  Eigen::Vector3d point_S;    ///< measured point, frame S (m): range_m · direction
  double range_m = 0.0;       ///< measured range (true range plus noise), m
  double true_range_m = 0.0;  ///< exact range to the surface hit, m
  float intensity = 0.0f;     ///< kGroundIntensity or kObjectIntensity
  int beam = 0;               ///< 0 = lowest
  int azimuth_step = 0;       ///< 0 .. azimuth_steps − 1
  int object_id = -1;         ///< Object::id of the surface hit
};

/// A spinning multi-beam LiDAR. One scan is one revolution taken at a single instant (no motion
/// distortion).
class Lidar {
 public:
  /// Precondition: params.validate() is empty.
  explicit Lidar(const LidarParams& params);

  const LidarParams& params() const { return params_; }

  /// Unit direction of (beam, azimuth_step) in frame S.
  const Eigen::Vector3d& direction_S(int beam, int azimuth_step) const {
    return directions_S_[static_cast<std::size_t>(azimuth_step * params_.beams + beam)];
  }

  /// Casts every beam of one revolution from the sensor pose T_W_S into `scene` at time t_s.
  /// Fills `returns` (cleared first) in firing order: azimuth step by azimuth step, beams low to
  /// high within a step. Beams that hit nothing within max_range_m are omitted. When
  /// range_noise_m > 0, each return draws one sample from `noise` (must then be non-null).
  void scan(const Scene& scene, const Eigen::Isometry3d& T_W_S, double t_s, GaussianNoise* noise,
            std::vector<LidarReturn>& returns) const;

 private:
  LidarParams params_;
  std::vector<Eigen::Vector3d> directions_S_;  // [azimuth_step * beams + beam]
};

/// The vehicle drives in a straight line from start_W to end_W at constant speed, heading along
/// the line, and stops at end_W — or, when `waypoints_W` holds two or more points, along that
/// polyline (start_W and end_W unused), heading along each segment in turn, its inner vertices
/// rounded into circular arcs of corner_radius_m (tangent to both segments, shrunk where a
/// segment is too short). The sensor sits sensor_height_m above the base (T_base_S =
/// translation (0, 0, sensor_height_m), no rotation).
///
/// On flat terrain the base is on the plane z = 0, level. Otherwise the vehicle drives on the
/// terrain: its four wheels touch the surface (front and rear on the centre line, wheelbase_m
/// apart; left and right across the middle, track_m apart), the base's x axis runs from the
/// rear contact to the front one, its y axis lies in the plane of that line and the left-right
/// one, and the base sits at the mean height of the four contacts. On a plane that is the
/// surface under the base, pitched and rolled with it (a 10 % ramp pitches it by atan(0.1));
/// over a kink the wheels even it out as a vehicle's axles do.
struct DrivePath {
  Eigen::Vector2d start_W{0.0, 0.0};         ///< m, on the ground
  Eigen::Vector2d end_W{60.0, 0.0};          ///< m, != start_W
  std::vector<Eigen::Vector2d> waypoints_W;  ///< m; 2+ points: a polyline instead of the line
  /// Radius of the polyline's turns, m; 0: the heading jumps at each vertex (a vehicle cannot
  /// drive that at speed, and a localiser's pose stream would not show it).
  double corner_radius_m = 0.0;
  double speed_mps = 3.0;  ///< > 0
  double sensor_height_m = 2.0;
  /// The surface the wheels run on: the scene's (Scene::terrain()).
  Terrain terrain;
  double wheelbase_m = 3.0;  ///< > 0; on terrain only
  double track_m = 2.0;      ///< > 0; on terrain only

  /// A loop round the rectangle [min_W, max_W], counter-clockwise from the middle of its lower
  /// side back to it, at `speed_mps`, its corners turned on arcs of `corner_radius_m`.
  static DrivePath loop(const Eigen::Vector2d& min_W, const Eigen::Vector2d& max_W,
                        double speed_mps, double corner_radius_m);

  /// Length of the path (m).
  double length_m() const;
  /// Time to drive the whole path (s).
  double duration_s() const { return length_m() / speed_mps; }
  /// Pose of the vehicle base at time t_s (clamped to [0, duration_s()]).
  Eigen::Isometry3d T_W_base(double t_s) const;
  /// Pose of the sensor at time t_s.
  Eigen::Isometry3d T_W_S(double t_s) const;
};

/// Everything that defines a generated sequence; equal parameters give byte-identical output.
struct SequenceParams {
  LidarParams lidar;
  DrivePath path;
  double rate_hz = 10.0;   ///< scans per second, > 0; scan i is taken at i / rate_hz
  int scans = 0;           ///< 0: enough to drive the whole path, floor(duration·rate) + 1
  double tilt_deg = 0.0;   ///< rotation of the poses' world frame O about x (T_O_W)
  std::uint64_t seed = 1;  ///< seed of the range noise
  /// Pose drift (a localiser's growing error) written into poses.txt: the written pose of scan
  /// i is T_O_W · D(t) · T_W_S(t), D(t) a translation along the scene's +y of
  /// drift_m · min(t / drift_ramp_s, 1), until scan correct_at_scan (0: never) from which the
  /// true poses are written again (the jump a GPS fix or loop closure makes). The scans are
  /// always taken from the true poses.
  double drift_m = 0.0;
  /// Height drift written into poses.txt (a localiser's height wandering): the translation D(t)
  /// above also rises along the scene's +z by drift_z_m · t / t_last, t_last the last scan's
  /// stamp, so the written poses reach drift_z_m above the true ones at the end of the drive.
  /// correct_at_scan ends it as it ends drift_m.
  double drift_z_m = 0.0;
  /// Ground truth for the costmap (obstacle_columns.txt): columns of truth_cell_m on the world
  /// lattice whose vertical span [envelope_low_m, envelope_high_m] above the ground meets a static
  /// object, i.e. what the costmap must show lethal (the shipped config's min_obstacle_height_m and
  /// vehicle_height_m + clearance_m, its voxel size).
  double truth_cell_m = 0.2;
  double envelope_low_m = 0.08;
  double envelope_high_m = 2.8;
  /// On terrain, ground_cells.txt lists the ground cells within this of the drive's bounding
  /// box (the scored radius round the vehicle, and a pose drift, inside it), m.
  double ground_truth_margin_m = 35.0;
  double drift_ramp_s = 2.0;  ///< > 0
  int correct_at_scan = 0;
  /// The written pose of scan i (with the drift, if any).
  Eigen::Isometry3d written_T_O_S(int i) const;
  /// The true pose of scan i (no drift).
  Eigen::Isometry3d true_T_O_S(int i) const;

  /// The number of scans to write (resolves scans == 0).
  int scan_count() const;
  /// Stamp of scan i (s).
  double stamp_s(int i) const { return static_cast<double>(i) / rate_hz; }
  /// The rotation from the scene frame W to the poses' world frame O.
  Eigen::Isometry3d T_O_W() const;
  /// Empty when valid, else what is wrong.
  std::string validate() const;
};

/// Counts of a written sequence.
struct SequenceSummary {
  int scans = 0;
  std::size_t min_points = 0;     ///< points in the emptiest scan
  std::size_t median_points = 0;  ///< the upper median over scans
  std::size_t max_points = 0;
};

/// Result of write_sequence: `error` is empty on success.
struct SequenceResult {
  std::string error;
  SequenceSummary summary;

  bool ok() const { return error.empty(); }
};

/// Simulates the sequence and writes it to `out_dir` in KITTI layout: scans/NNNNNN.bin
/// (float32 little-endian x, y, z, intensity per point, frame S), poses.txt (row-major 3×4
/// T_O_S per scan, shortest round-trip decimal), times.txt (stamp per scan, s), scene.json and
/// README.txt. Creates the directories; removes stale scans/NNNNNN.bin files first. With a
/// drift and correct_at_scan = K > 0 it also writes corrections.txt: the corrected trajectory
/// the pose source publishes with its jump, one line per scan 0 .. K − 1:
/// `K−1 stamp_s` then the 12 numbers of the true T_O_S (row-major 3×4) — read by
/// `tarmac-map --corrections` (applied after scan K − 1 is integrated).
///
/// The costmap's ground truth: obstacle_columns.txt (SequenceParams::truth_cell_m), the
/// envelope span taken above the ground under each point; on terrain also ground_cells.txt,
/// the cells of the lattice within ground_truth_margin_m of the drive's bounding box whose
/// ground rises less than envelope_low_m across the cell, each with the ground's height at its
/// centre (`ix iy z_m`, mm precision); with objects of kind "curb", curb_columns.txt, their
/// columns as obstacle_columns.txt lists them, first seen by a return from a curb. Errors: the
/// path's terrain is not the scene's, or the drive leaves the terrain.
SequenceResult write_sequence(const Scene& scene, const SequenceParams& params,
                              const std::filesystem::path& out_dir);

}  // namespace tarmac::sim
