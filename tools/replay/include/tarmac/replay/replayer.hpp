#pragma once
/// @file Replays a KITTI-layout sequence over DDS as a ROS 2-style publisher would:
/// sensor_msgs/PointCloud2 (points in the sensor frame) and geometry_msgs/PoseWithCovarianceStamped
/// (T_map_base) on tarmac's default topics, each scan's pose stamped exactly like the scan.
///
/// The sequence's poses.txt holds T_world_sensor; the pose published is
/// T_world_base = T_world_sensor · T_base_sensor⁻¹ with the extrinsic given in the options (the
/// daemon's config), so the daemon recovers T_world_sensor. Stamps are re-based on this
/// machine's clock: stamp_k = start + (t_k − t_0) / rate_scale, and scan k is published at its
/// stamp (plus an optional random jitter, for determinism tests; minus clock_offset_ns).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/result.hpp"
#include "tarmac/sim/driver_cloud.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::tools {

struct ReplayOptions {
  std::string lidar_topic = "rt/tarmac/lidar/front/points";
  std::string frame_id = "lidar_front";
  std::string pose_topic = "rt/tarmac/pose";
  std::string pose_frame_id = "map";
  Eigen::Isometry3d T_base_sensor = Eigen::Isometry3d::Identity();
  double rate_scale = 1.0;    ///< > 1 replays faster
  std::int64_t start_ns = 0;  ///< stamp of the first scan; 0: now + lead_ms
  double lead_ms = 300.0;     ///< with start_ns == 0
  /// With start_ns == 0 and > 0: the first stamp is put on a multiple of this (ms since the
  /// epoch), as a LiDAR phase-locked to PTP would stamp its scans.
  double align_ms = 0.0;
  double jitter_ms = 0.0;            ///< each message published up to this late (uniform)
  std::uint64_t seed = 1;            ///< jitter seed
  std::size_t max_scans = 0;         ///< 0: all
  std::size_t loops = 1;             ///< replay the sequence this many times, stamps continuing
  double wait_for_readers_s = 10.0;  ///< wait this long for a matched reader on both topics
  /// Readers the pose topic must have matched before the first message (tarmacd, and e.g.
  /// tarmac-audit --score, which must not miss the first poses: their QoS is volatile).
  std::size_t pose_readers = 1;
  /// Poses are published for the first `pose_count` scans only (0: all); tests use it to starve
  /// the daemon of poses.
  std::size_t pose_count = 0;
  /// No poses for the `pose_gap_count` scans from scan `pose_gap_first` on (counted over all
  /// loops): the localiser drops out for a while, then comes back.
  std::size_t pose_gap_first = 0;
  std::size_t pose_gap_count = 0;
  /// The sender's clock reads CLOCK_REALTIME + this: messages are stamped by it (start_ns too)
  /// but sent on CLOCK_REALTIME. Tests play a sensor whose wall clock stepped (or has not yet).
  std::int64_t clock_offset_ns = 0;
  /// false: scans only (another process publishes the poses, e.g. one replay per LiDAR).
  bool publish_poses = true;
  /// QoS of the scan writer; must be compatible with the daemon's `dds.qos.lidar`.
  transport::QosSpec lidar_qos = transport::qos::kLidar;
  /// Corrected trajectories (read_corrections(), e.g. tarmac-sim's corrections.txt), each
  /// published once as a nav_msgs/Path on `correction_topic` right after scan `after_scan` of
  /// the first loop, its header stamped like that scan (the correction applies after it), its
  /// poses as T_world_base, stamped like the scans they belong to.
  std::vector<Correction> corrections;
  std::string correction_topic = "rt/tarmac/pose_correction";
  /// Each correction is sent this long before its scan instead (its stamp unchanged): tests
  /// that tarmacd applies it by stamp, not on arrival.
  double correction_lead_s = 0.0;
  /// How an organised sequence (tarmac-sim's organised/ sweeps, beams × azimuths) goes out, as
  /// the drivers publish theirs (docs/ros2.md, "LiDAR drivers"): rows = beams (ouster-ros), or
  /// rows = firings with one column per laser (velodyne's organize_cloud, rslidar_sdk), or a
  /// list of the returns in firing order, the beams without return left out (HesaiLidar_ROS_2.0,
  /// velodyne without organize_cloud; with ring_field, as they carry the ring).
  enum class Layout : std::uint8_t { kRowsAreBeams, kRowsAreFirings, kUnorganised };
  Layout layout = Layout::kRowsAreBeams;
  /// With an organised sequence: a `ring` field (uint16, the beam's index, 0 = lowest) too.
  bool ring_field = false;
  /// With an organised sequence: each sweep as this driver publishes it instead (field table,
  /// padding, layout, ring order, no-return marker, point times: sim/driver_cloud.hpp), every
  /// point timed at the stamp (the simulator's sweeps are instantaneous); `layout` and
  /// `ring_field` are then not used.
  std::optional<sim::Driver> driver;
  /// Called after each scan is published (index, count); e.g. a progress bar.
  std::function<void(std::size_t, std::size_t)> progress;
  /// Empty: the schedule alone sets the pace. Otherwise called before the first message (pose
  /// or scan) of scan `k` (0-based, counted over loops; `stamp_ns` its stamp; called for every
  /// k in order) and must return once the consumer can take it — e.g. when it has taken scan
  /// k − 4 — or false when it gave up waiting (the replay then fails with "replay.pace"). A
  /// message is never sent before its scheduled time; a consumer slower than the schedule makes
  /// later messages leave late, stamps unchanged. Tests feed a daemon this way at the pace it
  /// acknowledges, whatever else loads the machine.
  std::function<bool(std::size_t k, std::int64_t stamp_ns)> pace;
};

struct ReplayStats {
  std::size_t scans = 0;
  std::int64_t first_stamp_ns = 0;
  std::int64_t last_stamp_ns = 0;
  double max_late_ms = 0.0;     ///< worst publish time behind schedule (excluding jitter)
  std::size_t corrections = 0;  ///< corrected trajectories published
};

/// T_world_base for a scan whose sensor pose is T_W_S.
Eigen::Isometry3d base_pose(const Eigen::Isometry3d& T_W_S, const Eigen::Isometry3d& T_B_S);

/// A ReplayOptions::pace for a daemon in another process: scan k goes once a costmap stamped
/// at or after scan k − `ahead` has arrived on `costmap_topic` (tarmacd stamps its costmap with
/// the newest scan it integrated), so at most `ahead` scans are on their way to it. Gives up
/// when no newer costmap came for `patience`, or at once when `stop` becomes true. The reader
/// is created here, with `costmap_qos` (the daemon's dds.qos.costmap).
core::Result<std::function<bool(std::size_t, std::int64_t)>> pace_by_costmap(
    const transport::Participant& participant, const std::string& costmap_topic,
    const transport::QosSpec& costmap_qos, std::size_t ahead, std::chrono::milliseconds patience,
    const std::atomic<bool>* stop = nullptr);

/// Publishes `seq` and returns when the last message is out (or `stop` became true).
core::Result<ReplayStats> replay(const transport::Participant& participant,
                                 const KittiSequence& seq, const ReplayOptions& options,
                                 const std::atomic<bool>* stop = nullptr);

}  // namespace tarmac::tools
