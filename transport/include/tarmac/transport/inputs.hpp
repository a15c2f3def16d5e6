#pragma once
/// @file tarmacd's DDS inputs, in core types: LiDAR scans (sensor_msgs/PointCloud2), vehicle poses
/// (PoseWithCovarianceStamped or Odometry) and virtual obstacles. DDS listener threads only
/// enqueue into bounded queues (overflow drops the oldest, counted); `drain` runs in the cycle,
/// never blocks on DDS, converts and hands each sample to a sink owned by the caller.

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/lidar_driver.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

/// Receives parsed scans. The caller owns the storage so that nothing is allocated per scan.
class ScanSink {
 public:
  virtual ~ScanSink() = default;
  /// A cloud to parse the next scan into (its capacity is reused).
  virtual core::PointCloud& slot() = 0;
  /// The last slot() now holds a valid scan of the expected frame.
  virtual void commit() = 0;
  /// A scan was rejected; `reason` is a stable code, e.g. "pointcloud.bad_size".
  virtual void reject(std::string_view reason) = 0;
  /// The scan being parsed is taken, with something worth counting: `reason` is a stable code,
  /// e.g. "scan.time_unrelated" (point times that relate to no stamp, not used).
  virtual void count(std::string_view reason) = 0;
};

/// One LiDAR's PointCloud2 topic.
class ScanInput {
 public:
  /// @param frame_id the only header.frame_id accepted ("scan.unknown_frame" otherwise).
  /// @param driver how the clouds are read (lidar_driver.hpp; from_point_cloud2).
  static core::Result<std::unique_ptr<ScanInput>> create(
      const Participant& participant, const std::string& topic, const std::string& frame_id,
      const QosSpec& qos, std::size_t queue_depth, LidarDriver driver = LidarDriver::kAuto);
  ~ScanInput();
  ScanInput(const ScanInput&) = delete;
  ScanInput& operator=(const ScanInput&) = delete;

  /// Parses every queued scan into the sink, oldest first. Returns the number taken.
  /// RT-safe after warm-up except for the rejection path (error text).
  std::size_t drain(ScanSink& sink);
  /// Samples dropped by queue overflow since creation.
  [[nodiscard]] std::uint64_t overflow_drops() const;
  /// Scans lost in transport before the reader had them (DDS SAMPLE_LOST: e.g. fragments of a
  /// large cloud overflowing the UDP receive buffer), since creation.
  [[nodiscard]] std::uint64_t transport_lost() const;
  /// Scans DDS received but refused (SAMPLE_REJECTED: reader resource limits), since creation.
  [[nodiscard]] std::uint64_t transport_rejected() const;
  [[nodiscard]] std::size_t matched_writers() const;

  class Impl;

 private:
  explicit ScanInput(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// One stamped vehicle pose: T_map_base.
struct PoseSample {
  std::int64_t stamp_ns = 0;
  Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
  /// The localiser's horizontal position uncertainty, 1σ (m): √max(cov_xx, cov_yy) of the
  /// message's covariance; 0 when it states none (all zero, negative or not finite: ROS's
  /// "unknown" conventions). Fleet summaries carry it (docs/fleet.md).
  double position_std_m = 0.0;
};

class PoseSink {
 public:
  virtual ~PoseSink() = default;
  virtual void pose(const PoseSample& sample) = 0;
  virtual void reject(std::string_view reason) = 0;
};

enum class PoseMessage { kPoseWithCovarianceStamped, kOdometry };

class PoseInput {
 public:
  /// @param frame_id the only header.frame_id accepted ("pose.unknown_frame" otherwise).
  static core::Result<std::unique_ptr<PoseInput>> create(const Participant& participant,
                                                         const std::string& topic, PoseMessage type,
                                                         const std::string& frame_id,
                                                         const QosSpec& qos,
                                                         std::size_t queue_depth);
  ~PoseInput();
  PoseInput(const PoseInput&) = delete;
  PoseInput& operator=(const PoseInput&) = delete;

  /// Converts every queued pose into the sink, oldest first. Returns the number taken.
  std::size_t drain(PoseSink& sink);
  [[nodiscard]] std::uint64_t overflow_drops() const;
  /// Poses lost or refused in transport (SAMPLE_LOST + SAMPLE_REJECTED), since creation.
  [[nodiscard]] std::uint64_t transport_lost() const;
  [[nodiscard]] std::size_t matched_writers() const;

  class Impl;

 private:
  explicit PoseInput(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// A corrected trajectory (pose-graph correction): revised T_map_base for past stamps, sorted.
class TrajectorySink {
 public:
  virtual ~TrajectorySink() = default;
  /// `stamp_ns`: when the correction was made (the Path's header stamp; a zero stamp there
  /// means the newest pose's): it applies after every scan stamped up to it. `poses` is valid
  /// during the call only.
  virtual void trajectory(std::int64_t stamp_ns, std::span<const PoseSample> poses) = 0;
  virtual void reject(std::string_view reason) = 0;
};

/// nav_msgs/Path read as a corrected trajectory. Rejected whole, with a reason:
/// `correction.unknown_frame` (header or a pose in another frame than `frame_id`; a pose with an
/// empty frame_id takes the path's), `correction.empty`, `correction.unsorted` (stamps not
/// strictly increasing), and the pose codes (`pose.non_finite`, `pose.bad_quaternion`).
class TrajectoryInput {
 public:
  static core::Result<std::unique_ptr<TrajectoryInput>> create(const Participant& participant,
                                                               const std::string& topic,
                                                               const std::string& frame_id,
                                                               const QosSpec& qos,
                                                               std::size_t queue_depth);
  ~TrajectoryInput();
  TrajectoryInput(const TrajectoryInput&) = delete;
  TrajectoryInput& operator=(const TrajectoryInput&) = delete;

  /// Converts every queued path into the sink, oldest first. Returns the number taken.
  /// Allocates only for paths longer than any before (corrections are rare).
  std::size_t drain(TrajectorySink& sink);
  [[nodiscard]] std::uint64_t overflow_drops() const;
  [[nodiscard]] std::size_t matched_writers() const;

  class Impl;

 private:
  explicit TrajectoryInput(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// tarmac_msgs/VirtualObstacleArray: the newest array replaces every zone.
class ZoneInput {
 public:
  static core::Result<std::unique_ptr<ZoneInput>> create(const Participant& participant,
                                                         const std::string& topic,
                                                         const QosSpec& qos);
  ~ZoneInput();
  ZoneInput(const ZoneInput&) = delete;
  ZoneInput& operator=(const ZoneInput&) = delete;

  /// When a new array arrived, replaces `zones` with it and returns true (allocates: zones
  /// change rarely). A malformed array is rejected whole (`rejected` gets its code).
  bool take_latest(std::vector<core::VirtualZone>& zones, std::string& rejected);

  class Impl;

 private:
  explicit ZoneInput(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::transport
