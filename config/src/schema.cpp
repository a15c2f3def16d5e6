// The config schema (schema.hpp): every key once, with its type, bounds, default, unit and doc.
// Over 600 lines because make_schema() is that table, one entry per key; reading, validation,
// --print-config, the documented config/tarmac.yaml and docs/configuration.md all derive from it.

#include "tarmac/config/schema.hpp"

#include <algorithm>
#include <iomanip>
#include <limits>
#include <sstream>

#include "tarmac/core/assert.hpp"

namespace tarmac::config {

namespace {

/// An enum field as a ChoiceField: its value is the index of its name in the key's choices.
template <typename Enum>
ChoiceField choice_field(Enum& value) {
  return {&value, [](const void* f) { return static_cast<int>(*static_cast<const Enum*>(f)); },
          [](void* f, int i) { *static_cast<Enum*>(f) = static_cast<Enum>(i); }};
}

Key boolean(std::string path, std::string_view doc, Access access) {
  return Key{std::move(path), KeyType::kBool, 0, 1, {}, "", doc, access};
}
Key integer(std::string path, double min, double max, std::string_view unit, std::string_view doc,
            Access access) {
  return Key{std::move(path), KeyType::kInteger, min, max, {}, unit, doc, access};
}
Key real(std::string path, double min, double max, std::string_view unit, std::string_view doc,
         Access access) {
  return Key{std::move(path), KeyType::kReal, min, max, {}, unit, doc, access};
}
Key string(std::string path, std::string_view doc, Access access) {
  return Key{std::move(path), KeyType::kString, 0, 0, {}, "", doc, access};
}
Key topic(std::string path, std::string_view doc, Access access) {
  return Key{std::move(path), KeyType::kTopic, 0, 0, {}, "", doc, access};
}
Key file(std::string path, std::string_view doc, Access access) {
  return Key{std::move(path), KeyType::kPath, 0, 0, {}, "", doc, access};
}
Key choice(std::string path, std::vector<std::string_view> choices, std::string_view doc,
           Access access) {
  return Key{std::move(path), KeyType::kChoice, 0, 0, std::move(choices), "", doc, access};
}
/// `key`, shown in the reference with `text` as its default (a derived default).
Key derived_default(Key key, std::string_view text) {
  key.default_text = text;
  return key;
}
/// `key`, read but not written by to_yaml.
Key read_only(Key key) {
  key.written = false;
  return key;
}

// Enum names, in each enum's declaration order.
const std::vector<std::string_view> kTransports = {"localhost", "shm", "network"};
const std::vector<std::string_view> kReliability = {"best_effort", "reliable"};
const std::vector<std::string_view> kDurability = {"volatile", "transient_local"};
const std::vector<std::string_view> kPoseTypes = {"PoseWithCovarianceStamped", "Odometry"};
const std::vector<std::string_view> kLidarDrivers = {"auto",  "ouster", "velodyne", "rslidar",
                                                     "hesai", "livox",  "autoware"};
const std::vector<std::string_view> kUnknownCost = {"unknown", "lethal", "free"};
const std::vector<std::string_view> kFreeRule = {"whole_envelope", "any_voxel"};
const std::vector<std::string_view> kUnknownPolicy = {"report", "occupied"};

constexpr double kBufferMin = 1u << 16;  // socket buffers and shared memory, bytes
constexpr double kBufferMax = 1u << 30;
constexpr double kBudgetMin = 0.001;  // budgets, ms
constexpr double kBudgetMax = 10000.0;
constexpr double kVectorMax = 1e3;  // vectors of the base frame, m

/// Appends the keys of one QoS profile, `dds.qos.<role>`.
template <transport::QosSpec QosConfig::*kRole>
void add_qos_keys(std::vector<Key>& keys, const std::string& role) {
  const std::string at = "dds.qos." + role + ".";
  keys.push_back(
      choice(at + "reliability", kReliability, "best_effort: the newest sample wins",
             [](Config& c) -> Field { return choice_field((c.dds.qos.*kRole).reliability); }));
  keys.push_back(choice(
      at + "durability", kDurability, "transient_local: a late subscriber gets the last samples",
      [](Config& c) -> Field { return choice_field((c.dds.qos.*kRole).durability); }));
  keys.push_back(integer(at + "depth", 1, 10000, "samples", "history: keep the last N",
                         [](Config& c) -> Field { return &(c.dds.qos.*kRole).history_depth; }));
}

std::vector<Key> make_schema() {
  std::vector<Key> keys = {
      integer("version", kConfigVersion, kConfigVersion, "",
              "config schema version; required, this build reads 1",
              [](Config& c) -> Field { return &c.version; }),
      // dds
      derived_default(integer("dds.domain_id", 0, 232, "", "DDS domain",
                              [](Config& c) -> Field { return &c.dds.participant.domain_id; }),
                      "`ROS_DOMAIN_ID`, else `0`"),
      string("dds.participant_name", "participant name shown by discovery tools",
             [](Config& c) -> Field { return &c.dds.participant.name; }),
      choice("dds.transport", kTransports,
             "localhost: nothing leaves the machine; shm: shared memory only; network: UDP on "
             "network_interfaces",
             [](Config& c) -> Field { return choice_field(c.dds.participant.transport); }),
      Key{"dds.network_interfaces",
          KeyType::kStringList,
          0,
          0,
          {},
          "",
          "IPv4 addresses of the interfaces to use; only with transport network",
          [](Config& c) -> Field { return &c.dds.participant.network_interfaces; }},
      Key{"dds.initial_peers",
          KeyType::kStringList,
          0,
          0,
          {},
          "",
          "IPv4 unicast discovery peers; only with transport network",
          [](Config& c) -> Field { return &c.dds.participant.initial_peers; }},
      Key{"dds.discovery_servers",
          KeyType::kStringList,
          0,
          0,
          {},
          "",
          "Fast DDS discovery servers IPv4:port, entry N = server id N; empty: no server",
          [](Config& c) -> Field { return &c.dds.participant.discovery_servers; }},
      integer("dds.shm_segment_bytes", kBufferMin, kBufferMax, "bytes",
              "shared-memory segment per participant",
              [](Config& c) -> Field { return &c.dds.participant.shm_segment_bytes; }),
      integer("dds.shm_max_message_bytes", kBufferMin, kBufferMax, "bytes",
              "largest shared-memory message, at most the segment",
              [](Config& c) -> Field { return &c.dds.participant.shm_max_message_bytes; }),
      integer("dds.udp_receive_buffer_bytes", kBufferMin, kBufferMax, "bytes",
              "UDP socket receive buffer (capped by net.core.rmem_max, warned at start)",
              [](Config& c) -> Field { return &c.dds.participant.udp_receive_buffer_bytes; }),
      integer("dds.udp_send_buffer_bytes", kBufferMin, kBufferMax, "bytes",
              "UDP socket send buffer (capped by net.core.wmem_max)",
              [](Config& c) -> Field { return &c.dds.participant.udp_send_buffer_bytes; }),
      boolean("dds.security.enabled", "DDS Security: join the domain only with the identity below",
              [](Config& c) -> Field { return &c.dds.participant.security.enabled; }),
      file("dds.security.identity_ca", "PEM: CA that signs participant identities",
           [](Config& c) -> Field { return &c.dds.participant.security.identity_ca; }),
      file("dds.security.identity_certificate", "PEM: this process's certificate",
           [](Config& c) -> Field { return &c.dds.participant.security.identity_certificate; }),
      file("dds.security.private_key", "PEM: its private key (keep it mode 0600)",
           [](Config& c) -> Field { return &c.dds.participant.security.private_key; }),
      file("dds.security.permissions_ca", "PEM: CA that signs governance and permissions",
           [](Config& c) -> Field { return &c.dds.participant.security.permissions_ca; }),
      file("dds.security.governance", "S/MIME-signed governance XML: domain rules",
           [](Config& c) -> Field { return &c.dds.participant.security.governance; }),
      file("dds.security.permissions", "S/MIME-signed permissions XML: who may publish what",
           [](Config& c) -> Field { return &c.dds.participant.security.permissions; }),
  };
  add_qos_keys<&QosConfig::lidar>(keys, "lidar");
  add_qos_keys<&QosConfig::pose>(keys, "pose");
  add_qos_keys<&QosConfig::virtual_obstacles>(keys, "virtual_obstacles");
  add_qos_keys<&QosConfig::costmap>(keys, "costmap");
  add_qos_keys<&QosConfig::esdf_slice>(keys, "esdf_slice");
  add_qos_keys<&QosConfig::esdf_band>(keys, "esdf_band");
  add_qos_keys<&QosConfig::debris>(keys, "debris");
  add_qos_keys<&QosConfig::diagnostics>(keys, "diagnostics");
  keys.insert(
      keys.end(),
      {
          // sensors: a list of 1..16; giving it replaces the default one-sensor list
          derived_default(
              string("sensors[].id", "short unique name; orders scans with equal stamps",
                     [](SensorEntry& s) -> Field { return &s.sensor.id; }),
              "*required*"),
          derived_default(topic("sensors[].topic", "sensor_msgs/PointCloud2 input",
                                [](SensorEntry& s) -> Field { return &s.sensor.topic; }),
                          "`rt/tarmac/lidar/<id>/points`"),
          derived_default(string("sensors[].frame_id", "the only header.frame_id accepted on topic",
                                 [](SensorEntry& s) -> Field { return &s.sensor.frame_id; }),
                          "`lidar_<id>`"),
          real("sensors[].extrinsic.translation_m.x", -kVectorMax, kVectorMax, "m",
               "sensor origin in the vehicle base frame",
               [](SensorEntry& s) -> Field { return &s.translation_m.x(); }),
          real("sensors[].extrinsic.translation_m.y", -kVectorMax, kVectorMax, "m",
               "sensor origin in the vehicle base frame",
               [](SensorEntry& s) -> Field { return &s.translation_m.y(); }),
          real("sensors[].extrinsic.translation_m.z", -kVectorMax, kVectorMax, "m",
               "sensor origin in the vehicle base frame",
               [](SensorEntry& s) -> Field { return &s.translation_m.z(); }),
          real("sensors[].extrinsic.quaternion.x", -1.0, 1.0, "",
               "rotation sensor to base, unit quaternion (norm within 1e-3)",
               [](SensorEntry& s) -> Field { return &s.quaternion.x(); }),
          real("sensors[].extrinsic.quaternion.y", -1.0, 1.0, "",
               "rotation sensor to base, unit quaternion (norm within 1e-3)",
               [](SensorEntry& s) -> Field { return &s.quaternion.y(); }),
          real("sensors[].extrinsic.quaternion.z", -1.0, 1.0, "",
               "rotation sensor to base, unit quaternion (norm within 1e-3)",
               [](SensorEntry& s) -> Field { return &s.quaternion.z(); }),
          real("sensors[].extrinsic.quaternion.w", -1.0, 1.0, "",
               "rotation sensor to base, unit quaternion (norm within 1e-3)",
               [](SensorEntry& s) -> Field { return &s.quaternion.w(); }),
          read_only(real("sensors[].extrinsic.rpy_deg.roll", -180.0, 180.0, "deg",
                         "instead of quaternion: R = Rz(yaw) Ry(pitch) Rx(roll)",
                         [](SensorEntry& s) -> Field { return &s.roll_deg; })),
          read_only(real("sensors[].extrinsic.rpy_deg.pitch", -90.0, 90.0, "deg",
                         "instead of quaternion: R = Rz(yaw) Ry(pitch) Rx(roll)",
                         [](SensorEntry& s) -> Field { return &s.pitch_deg; })),
          read_only(real("sensors[].extrinsic.rpy_deg.yaw", -180.0, 180.0, "deg",
                         "instead of quaternion: R = Rz(yaw) Ry(pitch) Rx(roll)",
                         [](SensorEntry& s) -> Field { return &s.yaw_deg; })),
          real("sensors[].max_age_ms", 1.0, 60000.0, "ms",
               "a scan older than this at tick time is rejected as stale",
               [](SensorEntry& s) -> Field { return &s.sensor.max_age_ms; }),
          boolean("sensors[].deskew",
                  "motion-compensate scans that carry per-point times (they wait for those poses)",
                  [](SensorEntry& s) -> Field { return &s.sensor.deskew; }),
          choice("sensors[].driver", kLidarDrivers,
                 "auto: fields and time unit told from each message; else the ROS 2 driver "
                 "whose default message to expect (its ring and time fields fixed; one that "
                 "does not match is rejected: pointcloud.driver_mismatch)",
                 [](SensorEntry& s) -> Field { return choice_field(s.sensor.driver); }),
          // pose
          topic("pose.topic", "vehicle base pose T_map_base",
                [](Config& c) -> Field { return &c.pose.topic; }),
          choice("pose.type", kPoseTypes, "message type of pose.topic",
                 [](Config& c) -> Field { return choice_field(c.pose.type); }),
          string("pose.frame_id", "the only header.frame_id accepted",
                 [](Config& c) -> Field { return &c.pose.frame_id; }),
          integer("pose.buffer_size", 2, 100000, "poses", "poses kept for interpolation",
                  [](Config& c) -> Field { return &c.pose.buffer_size; }),
          real("pose.max_gap_ms", 1.0, 10000.0, "ms", "never interpolate across a larger gap",
               [](Config& c) -> Field { return &c.pose.max_gap_ms; }),
          real("pose.max_age_ms", 1.0, 60000.0, "ms",
               "the pose input is reported stale beyond this",
               [](Config& c) -> Field { return &c.pose.max_age_ms; }),
          topic("pose.correction_topic",
                "nav_msgs/Path of revised past poses (corrections.enabled)",
                [](Config& c) -> Field { return &c.pose.correction_topic; }),
          // executor
          real("executor.rate_hz", kMinRateHz, kMaxRateHz, "Hz", "ticks per second",
               [](Config& c) -> Field { return &c.executor.rate_hz; }),
          real("executor.input_delay_ms", 0.0, 5000.0, "ms",
               "a tick takes scans stamped <= tick - this (arrival jitter margin)",
               [](Config& c) -> Field { return &c.executor.input_delay_ms; }),
          real("executor.pose_wait_ms", 0.0, 10000.0, "ms",
               "an eligible scan waits at most this for its pose, then is dropped",
               [](Config& c) -> Field { return &c.executor.pose_wait_ms; }),
          real("executor.max_future_ms", 0.0, 60000.0, "ms",
               "scans stamped later than tick + this are rejected",
               [](Config& c) -> Field { return &c.executor.max_future_ms; }),
          real("executor.sensor_phase_ms", 0.0, 10000.0, "ms",
               "phase of the LiDARs' stamps on the period grid, below the period",
               [](Config& c) -> Field { return &c.executor.sensor_phase_ms; }),
          integer("executor.workers", 1, 64, "threads", "threads running stages, executor included",
                  [](Config& c) -> Field { return &c.executor.workers; }),
          Key{"executor.cpus",
              KeyType::kIntegerList,
              0,
              1023,
              {},
              "",
              "executor on cpus[0], worker i on cpus[(i+1) % n]; empty: no pinning",
              [](Config& c) -> Field { return &c.executor.cpus; }},
          integer("executor.realtime_priority", 0, 99, "",
                  "SCHED_FIFO priority of executor and workers; 0: off",
                  [](Config& c) -> Field { return &c.executor.realtime_priority; }),
          boolean("executor.lock_memory", "mlockall(MCL_CURRENT | MCL_FUTURE)",
                  [](Config& c) -> Field { return &c.executor.lock_memory; }),
          integer("executor.queue_depth", 1, 1000, "samples",
                  "samples held per input between ticks, oldest dropped",
                  [](Config& c) -> Field { return &c.executor.queue_depth; }),
          // budgets
          real("budgets.drain_ms", kBudgetMin, kBudgetMax, "ms",
               "take queues, parse clouds, select by stamp, look up poses",
               [](Config& c) -> Field { return &c.budgets.drain_ms; }),
          real("budgets.ingest_ms", kBudgetMin, kBudgetMax, "ms", "filters, every scan of the tick",
               [](Config& c) -> Field { return &c.budgets.ingest_ms; }),
          real("budgets.integrate_ms", kBudgetMin, kBudgetMax, "ms",
               "occupancy raycasting, every scan of the tick",
               [](Config& c) -> Field { return &c.budgets.integrate_ms; }),
          real("budgets.tsdf_ms", kBudgetMin, kBudgetMax, "ms",
               "TSDF integration, every scan of the tick that runs it",
               [](Config& c) -> Field { return &c.budgets.tsdf_ms; }),
          real("budgets.rebuild_ms", kBudgetMin, kBudgetMax, "ms",
               "pose-correction rebuild work of the tick",
               [](Config& c) -> Field { return &c.budgets.rebuild_ms; }),
          real("budgets.costmap_ms", kBudgetMin, kBudgetMax, "ms",
               "costmap + 2D ESDF, once per tick",
               [](Config& c) -> Field { return &c.budgets.costmap_ms; }),
          real("budgets.esdf_band_ms", kBudgetMin, kBudgetMax, "ms", "3D ESDF band, once per tick",
               [](Config& c) -> Field { return &c.budgets.esdf_band_ms; }),
          real("budgets.publish_ms", kBudgetMin, kBudgetMax, "ms",
               "costmap, ESDF slice and band, CycleReport, DiagnosticArray",
               [](Config& c) -> Field { return &c.budgets.publish_ms; }),
          real("budgets.cycle_ms", kBudgetMin, kBudgetMax, "ms",
               "the whole tick; at most the period",
               [](Config& c) -> Field { return &c.budgets.cycle_ms; }),
          // quotas
          integer("quotas.points_per_cycle", 1, 100'000'000, "points",
                  "rays integrated per tick; later scans wait (one scan per tick always runs)",
                  [](Config& c) -> Field { return &c.quotas.points_per_cycle; }),
          integer("quotas.points_per_scan", 1, 100'000'000, "points",
                  "larger scans are decimated to this many (every k-th point)",
                  [](Config& c) -> Field { return &c.quotas.points_per_scan; }),
          integer("quotas.max_pending_scans", 1, 1000, "scans",
                  "scans waiting (tick, pose, quota); beyond, the oldest is shed",
                  [](Config& c) -> Field { return &c.quotas.max_pending_scans; }),
          integer("quotas.reserve_points_per_scan", 0, 4'000'000, "points",
                  "reserved at start in each scan buffer, so the cycle does not allocate",
                  [](Config& c) -> Field { return &c.quotas.reserve_points_per_scan; }),
          integer("quotas.tsdf_points_per_cycle", 0, 100'000'000, "points",
                  "points integrated into the TSDF per tick; a scan beyond skips the TSDF only",
                  [](Config& c) -> Field { return &c.quotas.tsdf_points_per_cycle; }),
          // outputs
          string("outputs.frame_id", "frame of the costmap and the ESDF slice (the pose frame)",
                 [](Config& c) -> Field { return &c.outputs.frame_id; }),
          topic("outputs.costmap_topic", "nav_msgs/OccupancyGrid, the inflated costmap",
                [](Config& c) -> Field { return &c.outputs.costmap_topic; }),
          topic("outputs.obstacle_grid_topic",
                "nav_msgs/OccupancyGrid without inflation (Nav2 StaticLayer); empty: not published",
                [](Config& c) -> Field { return &c.outputs.obstacle_grid_topic; }),
          topic("outputs.esdf_slice_grid_topic",
                "nav_msgs/OccupancyGrid, the 2D ESDF shaded for rviz2; empty: not published",
                [](Config& c) -> Field { return &c.outputs.esdf_slice_grid_topic; }),
          real("outputs.esdf_slice_grid_range_m", 0.1, 1000.0, "m",
               "distance shown as 0 on esdf_slice_grid_topic",
               [](Config& c) -> Field { return &c.outputs.esdf_slice_grid_range_m; }),
          topic("outputs.esdf_slice_topic", "tarmac_msgs/DistanceMapSlice",
                [](Config& c) -> Field { return &c.outputs.esdf_slice_topic; }),
          topic("outputs.esdf_band_topic", "tarmac_msgs/DistanceMapVolume (esdf_band.enabled)",
                [](Config& c) -> Field { return &c.outputs.esdf_band_topic; }),
          topic("outputs.debris_topic",
                "tarmac_msgs/DebrisArray, the debris for the ground crew; empty: not published",
                [](Config& c) -> Field { return &c.outputs.debris_topic; }),
          topic("outputs.cycle_report_topic", "tarmac_msgs/CycleReport, one per tick",
                [](Config& c) -> Field { return &c.outputs.cycle_report_topic; }),
          topic("outputs.diagnostic_array_topic", "diagnostic_msgs/DiagnosticArray",
                [](Config& c) -> Field { return &c.outputs.diagnostic_array_topic; }),
          topic("outputs.virtual_obstacles_topic", "input: tarmac_msgs/VirtualObstacleArray",
                [](Config& c) -> Field { return &c.outputs.virtual_obstacles_topic; }),
          integer("outputs.diagnostic_array_every", 1, 100000, "ticks",
                  "ticks between DiagnosticArray messages",
                  [](Config& c) -> Field { return &c.outputs.diagnostic_array_every; }),
          real("outputs.costmap_max_age_ms", 1.0, 3.6e6, "ms",
               "the costmap is reported stale when its newest scan is older",
               [](Config& c) -> Field { return &c.outputs.costmap_max_age_ms; }),
          // state
          string("state.dir", "state directory (systemd StateDirectory=tarmac); created if missing",
                 [](Config& c) -> Field { return &c.state.dir; }),
          string("state.map_file", "occupancy window file in dir, written on exit",
                 [](Config& c) -> Field { return &c.state.map_file; }),
          boolean("state.save_on_exit", "on SIGTERM/SIGINT write map_file and tsdf_file",
                  [](Config& c) -> Field { return &c.state.save_on_exit; }),
          string("state.tsdf_file", "the static map (TSDF .vdb) in dir, when tsdf.enabled",
                 [](Config& c) -> Field { return &c.state.tsdf_file; }),
          boolean("state.load_on_start",
                  "load tsdf_file at start when present (refused: moved aside)",
                  [](Config& c) -> Field { return &c.state.load_on_start; }),
          real("state.save_period_s", 0.0, 86400.0, "s",
               "periodic TSDF save; 0: only on exit, else at least one tick",
               [](Config& c) -> Field { return &c.state.save_period_s; }),
          // filters
          real("filters.min_range_m", 0.0, 100.0, "m",
               "drop returns closer than this to the sensor",
               [](Config& c) -> Field { return &c.mapping.filters.min_range_m; }),
          boolean("filters.ego_box_enabled", "drop returns inside the vehicle's own box",
                  [](Config& c) -> Field { return &c.mapping.filters.ego_box_enabled; }),
          real("filters.ego_box_min_m.x", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_min_B.x(); }),
          real("filters.ego_box_min_m.y", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_min_B.y(); }),
          real("filters.ego_box_min_m.z", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_min_B.z(); }),
          real("filters.ego_box_max_m.x", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_max_B.x(); }),
          real("filters.ego_box_max_m.y", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_max_B.y(); }),
          real("filters.ego_box_max_m.z", -kVectorMax, kVectorMax, "m",
               "ego box corner, base frame",
               [](Config& c) -> Field { return &c.mapping.filters.ego_box_max_B.z(); }),
          integer("filters.outlier_min_neighbors", 0, 26, "points",
                  "returns with fewer neighbours in their 27 cells are dropped; 0: off",
                  [](Config& c) -> Field { return &c.mapping.filters.outlier_min_neighbors; }),
          real("filters.outlier_cell_m", 0.05, 5.0, "m", "cell size of that neighbourhood",
               [](Config& c) -> Field { return &c.mapping.filters.outlier_cell_m; }),
          real("filters.outlier_max_range_m", 0.0, 1000.0, "m", "only nearer points are tested",
               [](Config& c) -> Field { return &c.mapping.filters.outlier_max_range_m; }),
          // occupancy
          real("occupancy.voxel_size_m", 0.02, 2.0, "m", "voxel edge of the rolling window",
               [](Config& c) -> Field { return &c.mapping.occupancy.voxel_size_m; }),
          integer("occupancy.window_x_vox", 4, 4096, "voxels", "window size along x",
                  [](Config& c) -> Field { return &c.mapping.occupancy.window_x_vox; }),
          integer("occupancy.window_y_vox", 4, 4096, "voxels", "window size along y",
                  [](Config& c) -> Field { return &c.mapping.occupancy.window_y_vox; }),
          integer("occupancy.window_z_vox", 4, 4096, "voxels", "window size along z",
                  [](Config& c) -> Field { return &c.mapping.occupancy.window_z_vox; }),
          real("occupancy.window_below_m", 0.0, 100.0, "m", "window bottom below the vehicle base",
               [](Config& c) -> Field { return &c.mapping.occupancy.window_below_m; }),
          real("occupancy.prob_hit", 0.5001, 0.9999, "", "P(occupied | return in voxel)",
               [](Config& c) -> Field { return &c.mapping.occupancy.prob_hit; }),
          real("occupancy.prob_miss", 0.0001, 0.4999, "", "P(occupied | ray passed through)",
               [](Config& c) -> Field { return &c.mapping.occupancy.prob_miss; }),
          real("occupancy.clamp_min", 0.0001, 0.4999, "", "lower probability clamp",
               [](Config& c) -> Field { return &c.mapping.occupancy.clamp_min; }),
          real("occupancy.clamp_max", 0.5001, 0.9999, "",
               "upper probability clamp of the dynamic layer (how fast a left voxel reads free)",
               [](Config& c) -> Field { return &c.mapping.occupancy.clamp_max; }),
          real("occupancy.max_range_m", 0.1, 1000.0, "m", "returns beyond this do not mark",
               [](Config& c) -> Field { return &c.mapping.occupancy.max_range_m; }),
          real("occupancy.clearing_range_m", 0.0, 1000.0, "m",
               "beams beyond max range or without return clear this far",
               [](Config& c) -> Field { return &c.mapping.occupancy.clearing_range_m; }),
          real("occupancy.ground_radius_m", 0.0, 10.0, "m",
               "heights above ground are taken against the second-lowest return of the scan "
               "within this radius",
               [](Config& c) -> Field { return &c.mapping.occupancy.ground_radius_m; }),
          integer("occupancy.static_promote_scans", 0, 127, "scans",
                  "consecutive hits that make a voxel static; 0: no static layer",
                  [](Config& c) -> Field { return &c.mapping.occupancy.static_promote_scans; }),
          integer("occupancy.static_demote_scans", 1, 127, "scans",
                  "consecutive scans seeing a static voxel free that clear it",
                  [](Config& c) -> Field { return &c.mapping.occupancy.static_demote_scans; }),
          real("occupancy.low_object_max_rise_m", 0.1, 2.55, "m",
               "returns rising up to this above their scan's ground are low objects' evidence "
               "(from costmap.min_obstacle_height_m up)",
               [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.max_rise_m; }),
          integer(
              "occupancy.low_object_lethal_returns", 1, 1000, "returns",
              "rising returns (one scan or several) that make a low object lethal; at most "
              "low_object_confirm_returns",
              [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.lethal_returns; }),
          integer(
              "occupancy.low_object_confirm_returns", 1, 1000, "returns",
              "rising returns (one scan or several) that confirm a low object: kept until its "
              "spot is seen empty, and debris",
              [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.confirm_returns; }),
          integer("occupancy.low_object_clear_scans", 1, 100, "scans",
                  "scans in a row with a ray past a low object under its top, or the ground "
                  "found at its top, that remove it",
                  [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.clear_scans; }),
          integer(
              "occupancy.low_object_candidate_scans", 1, 1000, "scans",
              "scans a single rising return waits for a second before it is dropped",
              [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.candidate_scans; }),
          integer("occupancy.low_object_capacity", 0, 1000000, "objects",
                  "low objects and candidates kept at most (fixed memory; more are counted)",
                  [](Config& c) -> Field { return &c.mapping.occupancy.low_objects.capacity; }),
          // costmap
          real("costmap.min_obstacle_height_m", 0.0, 10.0, "m",
               "returns this far above the local ground block",
               [](Config& c) -> Field { return &c.mapping.costmap.min_obstacle_height_m; }),
          real("costmap.vehicle_height_m", 0.1, 20.0, "m", "vehicle top above ground",
               [](Config& c) -> Field { return &c.mapping.costmap.vehicle_height_m; }),
          real("costmap.clearance_m", 0.0, 10.0, "m",
               "headroom above the vehicle; higher structures do not block",
               [](Config& c) -> Field { return &c.mapping.costmap.clearance_m; }),
          real("costmap.inscribed_radius_m", 0.0, 20.0, "m",
               "cells this close to an obstacle cost 99",
               [](Config& c) -> Field { return &c.mapping.costmap.inscribed_radius_m; }),
          real("costmap.inflation_radius_m", 0.0, 50.0, "m", "cost decays to 0 beyond this",
               [](Config& c) -> Field { return &c.mapping.costmap.inflation_radius_m; }),
          real("costmap.cost_scaling_factor", 0.01, 100.0, "1/m",
               "exponential decay rate (Nav2 convention)",
               [](Config& c) -> Field { return &c.mapping.costmap.cost_scaling_factor; }),
          real("costmap.ground_cell_m", 0.05, 20.0, "m", "local ground estimate cell",
               [](Config& c) -> Field { return &c.mapping.costmap.ground_cell_m; }),
          real("costmap.max_ground_step_m", 0.01, 10.0, "m",
               "ground spreads from cell to neighbouring cell (`ground_cell_m`) only across steps "
               "up or down of at most this; a higher step (a dock, a truck roof, a wing with "
               "nothing seen under it) is not ground, and a column observed more than this below "
               "its ground (a dock edge falling away, a pit) is lethal",
               [](Config& c) -> Field { return &c.mapping.costmap.max_ground_step_m; }),
          real("costmap.max_ground_slope", 0.0, 1.0, "",
               "the seed cells of the ground (within 4 m of the vehicle) lie within "
               "`ground_tolerance_m` + this x distance of the wheels' plane",
               [](Config& c) -> Field { return &c.mapping.costmap.max_ground_slope; }),
          real("costmap.ground_tolerance_m", 0.0, 10.0, "m",
               "the seed cells lie within this (+ slope x distance) of the wheels' plane",
               [](Config& c) -> Field { return &c.mapping.costmap.ground_tolerance_m; }),
          choice("costmap.unknown_cost", kUnknownCost, "value of cells never observed",
                 [](Config& c) -> Field { return choice_field(c.mapping.costmap.unknown_cost); }),
          choice("costmap.free_rule", kFreeRule,
                 "whole_envelope: free only when the whole column up to the vehicle was observed",
                 [](Config& c) -> Field { return choice_field(c.mapping.costmap.free_rule); }),
          real("costmap.debris_max_height_m", 0.01, 2.55, "m",
               "a low object (or a cluster of them) this high above the ground at most is debris",
               [](Config& c) -> Field { return &c.mapping.debris.max_height_m; }),
          real("costmap.debris_max_footprint_m", 0.01, 10.0, "m",
               "debris's obstacle columns span at most this along x and along y",
               [](Config& c) -> Field { return &c.mapping.debris.max_footprint_m; }),
          real("costmap.debris_clearance_m", 0.0, 10.0, "m",
               "no other obstacle column this close to debris (a kerb, a wall foot, a wheel)",
               [](Config& c) -> Field { return &c.mapping.debris.clearance_m; }),
          integer("costmap.debris_min_scans", 1, 1000, "scans",
                  "debris is listed once some object of it rose in this many scans (lethal "
                  "in the costmap from its first)",
                  [](Config& c) -> Field { return &c.mapping.debris.min_scans; }),
          // esdf_band
          boolean("esdf_band.enabled", "compute the 3D ESDF band every tick and publish it",
                  [](Config& c) -> Field { return &c.mapping.esdf_band.enabled; }),
          real("esdf_band.below_m", 0.0, 1000.0, "m", "band bottom below the vehicle base",
               [](Config& c) -> Field { return &c.mapping.esdf_band.below_m; }),
          real("esdf_band.above_m", 0.001, 1000.0, "m", "band top above the vehicle base",
               [](Config& c) -> Field { return &c.mapping.esdf_band.above_m; }),
          choice("esdf_band.unknown", kUnknownPolicy,
                 "report: unknown voxels are not obstacles (distance NaN); occupied: they are",
                 [](Config& c) -> Field { return choice_field(c.mapping.esdf_band.unknown); }),
          real("esdf_band.publish_radius_m", 0.0, 10000.0, "m",
               "publish the band's voxels within this of the vehicle; 0: the whole band",
               [](Config& c) -> Field { return &c.mapping.esdf_band.publish_radius_m; }),
          // tsdf
          boolean("tsdf.enabled", "false: the TSDF stage is skipped",
                  [](Config& c) -> Field { return &c.mapping.tsdf.enabled; }),
          real("tsdf.voxel_size_m", 0.01, 2.0, "m", "voxel edge",
               [](Config& c) -> Field { return &c.mapping.tsdf.voxel_size_m; }),
          real("tsdf.truncation_m", 0.01, 64.0, "m",
               "band half-width around each return, voxel_size_m..32 x voxel_size_m",
               [](Config& c) -> Field { return &c.mapping.tsdf.truncation_m; }),
          real("tsdf.max_weight", 1.0, 1e6, "scans", "weight cap; lower: surfaces re-learnt faster",
               [](Config& c) -> Field { return &c.mapping.tsdf.max_weight; }),
          real("tsdf.max_range_m", 0.1, 1000.0, "m", "returns farther than this are not integrated",
               [](Config& c) -> Field { return &c.mapping.tsdf.max_range_m; }),
          boolean("tsdf.space_carving", "also write free space from the sensor to the band; costly",
                  [](Config& c) -> Field { return &c.mapping.tsdf.space_carving; }),
          integer("tsdf.reserve_blocks", 0, 10'000'000, "blocks",
                  "blocks (4 KB each) built at start so new blocks cost no page faults",
                  [](Config& c) -> Field { return &c.mapping.tsdf.reserve_blocks; }),
          integer("tsdf.resident_limit_mb", 0, 1'000'000, "MiB",
                  "tiles beyond this are paged to state.dir/tsdf_tiles, far ones first; 0: none",
                  [](Config& c) -> Field { return &c.mapping.tsdf.resident_limit_mb; }),
          // corrections
          boolean("corrections.enabled",
                  "retain scans and rebuild the maps when poses are corrected",
                  [](Config& c) -> Field { return &c.mapping.corrections.enabled; }),
          integer("corrections.retain_scans", 1, 10000, "scans",
                  "filtered scans kept for a rebuild",
                  [](Config& c) -> Field { return &c.mapping.corrections.retain_scans; }),
          real("corrections.jump_threshold_m", 0.01, 1000.0, "m",
               "a live pose this far from its prediction is a correction",
               [](Config& c) -> Field { return &c.mapping.corrections.jump_threshold_m; }),
          real("corrections.jump_threshold_deg", 0.01, 180.0, "deg",
               "... or rotated more than this from it",
               [](Config& c) -> Field { return &c.mapping.corrections.jump_threshold_deg; }),
          real("corrections.max_prediction_gap_s", 0.001, 60.0, "s",
               "no prediction (no jump detected) across longer pose gaps",
               [](Config& c) -> Field { return &c.mapping.corrections.max_prediction_gap_s; }),
          integer(
              "corrections.rebuild_points_per_cycle", 0, 100'000'000, "points",
              "points re-integrated per integrated scan while rebuilding; 0: all at once",
              [](Config& c) -> Field { return &c.mapping.corrections.rebuild_points_per_cycle; }),
          // fleet
          boolean("fleet.enabled", "share bird's-eye summaries with the fleet and fuse theirs",
                  [](Config& c) -> Field { return &c.fleet.enabled; }),
          string("fleet.vehicle_id",
                 "this vehicle's id, unique in the fleet: 1..64 of [A-Za-z0-9_-]",
                 [](Config& c) -> Field { return &c.fleet.vehicle_id; }),
          topic("fleet.topic", "tarmac_msgs/FleetBev, every vehicle's summaries",
                [](Config& c) -> Field { return &c.fleet.topic; }),
          real("fleet.publish_period_s", 0.1, 60.0, "s", "a summary this often",
               [](Config& c) -> Field { return &c.fleet.publish_period_s; }),
          real("fleet.max_age_s", 0.5, 600.0, "s", "peers' observations older than this expire",
               [](Config& c) -> Field { return &c.fleet.max_age_s; }),
      });
  return keys;
}

}  // namespace

const std::vector<Key>& schema() {
  static const std::vector<Key> keys = make_schema();
  return keys;
}

SensorEntry sensor_entry(const SensorConfig& sensor) {
  SensorEntry entry;
  entry.sensor = sensor;
  entry.translation_m = sensor.T_base_sensor.translation();
  const Eigen::Matrix3d R = sensor.T_base_sensor.linear();
  entry.quaternion =
      sensor.q_base_sensor.toRotationMatrix() == R ? sensor.q_base_sensor : Eigen::Quaterniond(R);
  return entry;
}

const Key& schema_key(std::string_view path) {
  const auto& keys = schema();
  const auto it =
      std::find_if(keys.begin(), keys.end(), [&](const Key& key) { return key.path == path; });
  TARMAC_ASSERT(it != keys.end(), "no such key in the config schema");
  return *it;
}

Field field_of(const Key& key, Config& config, SensorEntry* sensor) {
  if (key.access.of_config != nullptr) return key.access.of_config(config);
  TARMAC_ASSERT(sensor != nullptr, "a sensors[] key needs the sensor it is read into");
  return key.access.of_sensor(*sensor);
}

bool is_flow_map(std::string_view map_path) {
  const auto under = [&](std::string_view parent) {
    return map_path.size() > parent.size() && map_path.substr(0, parent.size()) == parent &&
           map_path.find('.', parent.size()) == std::string_view::npos;
  };
  return under("dds.qos.") || under("sensors[].extrinsic.") ||
         map_path == "filters.ego_box_min_m" || map_path == "filters.ego_box_max_m";
}

namespace {

/// A number as the reference shows it: a float to float precision (0.7f as 0.7, not as the
/// 0.699999988 to_yaml writes), a double to 12 digits.
std::string number_text(double value, int digits) {
  std::ostringstream os;
  os << std::setprecision(digits) << value;
  return os.str();
}

/// The default of a key as the reference shows it.
std::string default_text(const Key& key, Config& config, SensorEntry& sensor) {
  if (!key.default_text.empty()) return std::string(key.default_text);
  const auto list = [](const auto& items) {
    std::ostringstream os;
    os << '[';
    for (std::size_t i = 0; i < items.size(); ++i) os << (i > 0 ? ", " : "") << items[i];
    os << ']';
    return os.str();
  };
  const Field field = field_of(key, config, &sensor);
  std::string text;
  if (const auto* b = std::get_if<bool*>(&field)) text = **b ? "true" : "false";
  if (const auto* i = std::get_if<int*>(&field)) text = std::to_string(**i);
  if (const auto* u = std::get_if<std::uint32_t*>(&field)) text = std::to_string(**u);
  if (const auto* u = std::get_if<std::uint64_t*>(&field)) text = std::to_string(**u);
  if (const auto* f = std::get_if<float*>(&field)) text = number_text(**f, 7);
  if (const auto* d = std::get_if<double*>(&field)) text = number_text(**d, 12);
  if (const auto* s = std::get_if<std::string*>(&field)) text = (*s)->empty() ? "\"\"" : **s;
  if (const auto* l = std::get_if<std::vector<std::string>*>(&field)) text = list(**l);
  if (const auto* l = std::get_if<std::vector<int>*>(&field)) text = list(**l);
  if (const auto* c = std::get_if<ChoiceField>(&field)) text = key.choices[c->get(c->field)];
  return "`" + text + "`";
}

std::string range_text(const Key& key) {
  const auto bound = [&](double v) {
    return key.type == KeyType::kReal ? number_text(v, 12)
                                      : std::to_string(static_cast<long long>(v));
  };
  const std::string range =
      key.min == key.max ? bound(key.min) : bound(key.min) + ".." + bound(key.max);
  switch (key.type) {
    case KeyType::kInteger:
    case KeyType::kReal: return range;
    case KeyType::kIntegerList: return "each " + range;
    case KeyType::kChoice: {
      std::string names;
      for (const auto& c : key.choices) names += (names.empty() ? "" : ", ") + std::string(c);
      return names;
    }
    default: return "";
  }
}

const char* type_name(KeyType type) {
  switch (type) {
    case KeyType::kBool: return "bool";
    case KeyType::kInteger: return "integer";
    case KeyType::kReal: return "real";
    case KeyType::kString: return "string";
    case KeyType::kTopic: return "topic";
    case KeyType::kPath: return "path";
    case KeyType::kChoice: return "choice";
    case KeyType::kStringList: return "list of strings";
    case KeyType::kIntegerList: return "list of integers";
  }
  return "";
}

/// `text` safe inside a Markdown table cell.
std::string cell(std::string_view text) {
  std::string out;
  for (const char ch : text) {
    if (ch == '|') out += '\\';
    out += ch;
  }
  return out;
}

}  // namespace

std::string reference_markdown() {
  Config config;
  SensorEntry sensor = sensor_entry(config.sensors.front());
  std::string out =
      "| key | type | default | range | unit | doc |\n| --- | --- | --- | --- | --- | --- |\n";
  for (const Key& key : schema()) {
    out += "| `" + key.path + "` | " + type_name(key.type) + " | " +
           cell(default_text(key, config, sensor)) + " | " + cell(range_text(key)) + " | " +
           cell(key.unit) + " | " + cell(key.doc) + " |\n";
  }
  return out;
}

}  // namespace tarmac::config
