#pragma once
/// @file tarmacd's configuration: plain structs with defaults, loaded from one YAML file
/// (config/tarmac.yaml documents every key). Every error names the key path: an unknown key
/// ("dds.qos.costmap.depht: unknown key"), a key given twice in one map, with both lines
/// ("executor.rate_hz: duplicate key (line 3 and line 7)"), a wrong type, with the type expected
/// and what was found ("executor.workers: expected an integer, got a number '2.5'"), a number
/// that is not finite ("executor.rate_hz: must be a finite number, got .nan") and a value out of
/// range ("dds.domain_id: must be in [0, 232], got 300"). An unknown key near a known one says
/// which ("costmap.inflation_radius: unknown key (did you mean 'inflation_radius_m'?)").
/// Each key's type, range, unit and doc are in the schema (schema.hpp); its default is here.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/lidar_driver.hpp"
#include "tarmac/transport/participant_config.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::config {

/// The only config schema version this build reads.
inline constexpr int kConfigVersion = 1;

/// QoS per DDS topic role (DESIGN.md §5 defaults).
struct QosConfig {
  transport::QosSpec lidar = transport::qos::kLidar;
  transport::QosSpec pose = transport::qos::kPose;
  transport::QosSpec virtual_obstacles = transport::qos::kVirtualObstacles;
  transport::QosSpec costmap = transport::qos::kCostmap;
  transport::QosSpec esdf_slice = transport::qos::kEsdfSlice;
  transport::QosSpec esdf_band = transport::qos::kEsdfBand;
  transport::QosSpec debris = transport::qos::kDebris;
  transport::QosSpec diagnostics = transport::qos::kDiagnostics;
};

struct DdsConfig {
  transport::ParticipantConfig participant;  ///< localhost-only by default
  QosConfig qos;
};

/// One LiDAR input (YAML `sensors[i]`).
struct SensorConfig {
  std::string id = "front";                            ///< short name, unique; orders equal stamps
  std::string topic = "rt/tarmac/lidar/front/points";  ///< PointCloud2 topic, ROS 2 wire form
  std::string frame_id = "lidar_front";  ///< the only header.frame_id accepted on `topic`
  /// Extrinsic: maps sensor-frame points into the vehicle base frame.
  Eigen::Isometry3d T_base_sensor = Eigen::Isometry3d::Identity();
  /// T_base_sensor's rotation as the loader built it, and as to_yaml writes it: a matrix turned
  /// back into a quaternion can differ in the last digit, so a printed config would not reload
  /// to the same bits. to_yaml uses T_base_sensor's own rotation when the two disagree (code
  /// that set T_base_sensor alone).
  Eigen::Quaterniond q_base_sensor = Eigen::Quaterniond::Identity();
  double max_age_ms = 500.0;  ///< a scan older than this at tick time is rejected as stale
  /// Motion-compensate scans with per-point times (PointCloud2 field time / t / timestamp)
  /// using the poses at their first and last point; such scans also wait for those poses.
  bool deskew = true;
  /// How its PointCloud2 is read: told from each message, or as this driver publishes it (a
  /// message that does not match is rejected: pointcloud.driver_mismatch).
  transport::LidarDriver driver = transport::LidarDriver::kAuto;
};

/// Which message type carries the vehicle pose.
enum class PoseType { kPoseWithCovarianceStamped, kOdometry };

/// The pose input (YAML `pose`): T_map_base, stamped.
struct PoseInputConfig {
  std::string topic = transport::topics::kPose;
  PoseType type = PoseType::kPoseWithCovarianceStamped;
  std::string frame_id = "map";     ///< the only header.frame_id accepted
  std::uint32_t buffer_size = 500;  ///< poses kept for interpolation (5 s at 100 Hz)
  double max_gap_ms = 250.0;        ///< no interpolation across a larger gap between poses
  double max_age_ms = 1000.0;       ///< pose input reported stale when its newest is older
  /// nav_msgs/Path of revised past poses (a pose-graph correction), same frame_id; QoS of the
  /// pose input. Read when corrections.enabled.
  std::string correction_topic = "rt/tarmac/pose_correction";
};

/// The executor's rate bounds (YAML `executor.rate_hz`), also checked by the executor itself.
inline constexpr double kMinRateHz = 0.1;
inline constexpr double kMaxRateHz = 1000.0;

/// The fixed-rate executor (YAML `executor`).
struct ExecutorConfig {
  double rate_hz = 10.0;         ///< ticks per second
  double input_delay_ms = 20.0;  ///< a tick takes scans stamped <= tick − this (jitter margin)
  double pose_wait_ms = 100.0;   ///< a scan waits this long past its eligibility for its pose
  double max_future_ms = 200.0;  ///< scans stamped later than tick + this are rejected
  /// Phase of the LiDARs' stamps on the period grid (PTP phase lock), < period. Ticks sit at
  /// k·period + sensor_phase + input_delay, so such a scan waits exactly input_delay.
  double sensor_phase_ms = 0.0;
  std::uint32_t workers = 2;      ///< threads running stages, including the executor thread
  std::vector<int> cpus;          ///< executor on cpus[0], worker i on cpus[(i+1) % n]; empty: any
  int realtime_priority = 10;     ///< SCHED_FIFO priority 1..99; 0: do not ask for real time
  bool lock_memory = true;        ///< mlockall(MCL_CURRENT | MCL_FUTURE)
  std::uint32_t queue_depth = 8;  ///< per input: samples held between drains (oldest dropped)
};

/// Per-stage budgets (YAML `budgets`), ms of wall time per tick.
struct BudgetConfig {
  double drain_ms = 10.0;      ///< take queued samples, parse, select
  double ingest_ms = 15.0;     ///< filters, all scans of the tick
  double integrate_ms = 50.0;  ///< occupancy raycasting, all scans of the tick
  double tsdf_ms = 30.0;       ///< TSDF integration, all scans of the tick that run it
  double rebuild_ms = 50.0;    ///< pose-correction rebuild work of the tick (corrections.*)
  double costmap_ms = 35.0;    ///< costmap + 2D ESDF, once per tick
  double esdf_band_ms = 40.0;  ///< 3D ESDF band, once per tick (esdf_band.enabled)
  double publish_ms = 10.0;    ///< costmap, ESDF slice, reports
  double cycle_ms = 90.0;      ///< the whole tick
};

/// Deterministic work quotas (YAML `quotas`): decided from inputs, never from the clock.
struct QuotaConfig {
  /// Points integrated per tick at most. Scans are taken in (stamp, sensor) order while they
  /// fit; the rest wait for the next tick (at least one scan per tick is always taken).
  std::uint64_t points_per_cycle = 500000;
  /// A scan with more points is decimated to this many (every k-th point, deterministic).
  std::uint64_t points_per_scan = 262144;
  /// Scans held waiting (for their tick, pose or quota); beyond this the oldest is shed.
  std::uint32_t max_pending_scans = 8;
  /// Points (xyz + intensity) reserved in each of the max_pending_scans + 1 scan buffers at
  /// start, so the cycle does not allocate for scans up to this size.
  std::uint64_t reserve_points_per_scan = 65536;
  /// Filtered points integrated into the TSDF per tick at most (DESIGN.md §3: TSDF is shed
  /// before occupancy). Scans are taken in (stamp, sensor) order; a scan whose points would
  /// exceed the quota skips the TSDF stage (occupancy still integrates it), counted as
  /// "scan.tsdf_shed_quota". 0 sheds every scan's TSDF.
  std::uint64_t tsdf_points_per_cycle = 500000;
};

/// Output topics and frame (YAML `outputs`).
struct OutputConfig {
  std::string frame_id = "map";
  std::string costmap_topic = transport::topics::kCostmap;
  std::string esdf_slice_topic = transport::topics::kEsdfSlice;
  std::string esdf_band_topic = transport::topics::kEsdfBand;  ///< when esdf_band.enabled
  std::string cycle_report_topic = transport::topics::kDiagnostics;
  std::string diagnostic_array_topic = transport::topics::kDiagnosticArray;
  std::string virtual_obstacles_topic = transport::topics::kVirtualObstacles;  ///< input
  /// The costmap without inflation (lethal 100 / free 0 / unknown −1) for a planner that
  /// inflates by its own footprint (Nav2's StaticLayer + InflationLayer). Empty: not published.
  std::string obstacle_grid_topic;
  /// The 2D ESDF shaded as an OccupancyGrid for rviz2's Map display (100 on obstacles, 0 at
  /// esdf_slice_grid_range_m and beyond, −1 unknown). Empty: not published.
  std::string esdf_slice_grid_topic;
  double esdf_slice_grid_range_m = 5.0;
  /// The debris for the ground crew (tarmac_msgs/DebrisArray, core::Debris), each tick the
  /// costmap is updated. Empty: not published.
  std::string debris_topic = transport::topics::kDebris;
  std::uint32_t diagnostic_array_every = 10;  ///< ticks between DiagnosticArray messages
  /// The costmap is reported stale (DiagnosticArray level ERROR, `costmap_stale`) when the
  /// newest scan in it is older than this at tick time, e.g. while no pose arrives.
  double costmap_max_age_ms = 1000.0;
};

/// Persistent state (YAML `state`).
struct StateConfig {
  std::string dir = "/var/lib/tarmac";  ///< systemd StateDirectory=tarmac
  std::string map_file = "occupancy_window.bin";
  bool save_on_exit = true;
  std::string tsdf_file = "tsdf.vdb";  ///< the TSDF (tsdf_io .vdb) in dir, when tsdf.enabled
  bool load_on_start = true;           ///< load tsdf_file at start when present (else empty map)
  /// Seconds between periodic TSDF saves (0: only on exit). The executor copies the TSDF between
  /// ticks; a low-priority thread writes the copy.
  double save_period_s = 300.0;
};

/// Fleet sharing of bird's-eye occupancy between vehicles (YAML `fleet`; issue 21).
struct FleetConfig {
  bool enabled = false;
  /// This vehicle's id in the fleet: unique, 1..64 of [A-Za-z0-9_-] (it names the vehicle's DDS
  /// partition and its grant in the permissions file). Required when enabled.
  std::string vehicle_id;
  std::string topic = "rt/tarmac/fleet/bev";  ///< every vehicle's summaries, one topic
  double publish_period_s = 1.0;              ///< a summary this often
  double max_age_s = 10.0;                    ///< peers' observations older than this are forgotten
};

/// The core's defaults, except where the daemon wants otherwise: 8192 TSDF blocks reserved at
/// start (32 MB), so the first scans from an empty map cost no page faults (the core's own
/// default is 0, for tools and tests that build many mappers).
inline core::MapperParams daemon_mapping_defaults() {
  core::MapperParams p;
  p.tsdf.reserve_blocks = 8192;
  return p;
}

struct Config {
  int version = kConfigVersion;
  DdsConfig dds;
  std::vector<SensorConfig> sensors{SensorConfig{}};
  PoseInputConfig pose;
  ExecutorConfig executor;
  BudgetConfig budgets;
  QuotaConfig quotas;
  OutputConfig outputs;
  StateConfig state;
  FleetConfig fleet;
  core::MapperParams mapping = daemon_mapping_defaults();  ///< YAML filters, occupancy, costmap,
                                                           ///< esdf_band, tsdf, corrections
};

/// Parses YAML text. Error code "config.<reason>" (e.g. config.duplicate_key, config.type,
/// config.not_finite, config.range, config.unknown_key), message "<key.path>: <why>".
core::Result<Config> load_config_string(const std::string& yaml_text);
/// Reads and parses a file; "config.io" when it cannot be read.
core::Result<Config> load_config_file(const std::string& path);

/// For the tools' --config FILE: the file's config into `cfg` (an empty path keeps `cfg`, the
/// built-in defaults) and 0, or 78 (EX_CONFIG) after "<program>: invalid config: <why>" on stderr.
int load_tool_config(const std::string& program, const std::string& path, Config& cfg);

/// A stable hash (16 hex digits, FNV-1a 64) of the effective config, for logs and CycleReport.
std::string config_hash(const Config& config);
/// The effective config rendered as YAML (defaults filled in), for the start-up log.
std::string to_yaml(const Config& config);

}  // namespace tarmac::config
