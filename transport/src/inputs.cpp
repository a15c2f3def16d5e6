#include "tarmac/transport/inputs.hpp"

#include <array>
#include <cmath>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "geometry_msgsPubSubTypes.h"
#include "nav_msgsPubSubTypes.h"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac_msgsPubSubTypes.h"

namespace tarmac::transport {

namespace {

/// Moves every queued message of `reader` into `batch` (capacity kept across drains), hands each
/// to `handle`, oldest first, and empties the batch. Returns the number taken.
template <typename ReaderT, typename Message, typename Handle>
std::size_t drain_batch(ReaderT& reader, std::vector<Message>& batch, Handle&& handle) {
  batch.clear();
  const std::size_t n = reader.take_all(batch);
  for (auto& message : batch) handle(message);
  batch.clear();
  return n;
}

}  // namespace

// ---- scans ----

class ScanInput::Impl {
 public:
  using Reader = transport::Reader<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
  std::unique_ptr<Reader> reader;
  std::string frame_id;
  LidarDriver driver = LidarDriver::kAuto;
  std::vector<PointCloud2Msg> batch;  // capacity kept across drains
};

core::Result<std::unique_ptr<ScanInput>> ScanInput::create(
    const Participant& participant, const std::string& topic, const std::string& frame_id,
    const QosSpec& qos, std::size_t queue_depth, LidarDriver driver) {
  auto reader = Impl::Reader::create(participant, topic, qos, queue_depth);
  if (!reader) return reader.error();
  auto impl = std::make_unique<Impl>();
  impl->reader = std::move(reader).value();
  impl->frame_id = frame_id;
  impl->driver = driver;
  impl->batch.reserve(queue_depth);
  return std::unique_ptr<ScanInput>(new ScanInput(std::move(impl)));
}

ScanInput::ScanInput(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ScanInput::~ScanInput() = default;

std::size_t ScanInput::drain(ScanSink& sink) {
  return drain_batch(*impl_->reader, impl_->batch, [&](const PointCloud2Msg& msg) {
    if (msg.header().frame_id() != impl_->frame_id) {
      sink.reject("scan.unknown_frame");
      return;
    }
    core::PointCloud& cloud = sink.slot();
    CloudNotes notes;
    if (auto parsed = from_point_cloud2(msg, cloud, &notes, impl_->driver); !parsed) {
      sink.reject(parsed.error().code);
      return;
    }
    if (notes.time_unrelated) sink.count("scan.time_unrelated");
    // Converted only: the mapper organises the sweep (core::organise, from grid_rows and ring).
    sink.commit();
  });
}

std::uint64_t ScanInput::overflow_drops() const {
  return impl_->reader->dropped();
}
std::uint64_t ScanInput::transport_lost() const {
  return impl_->reader->lost();
}
std::uint64_t ScanInput::transport_rejected() const {
  return impl_->reader->rejected();
}
std::size_t ScanInput::matched_writers() const {
  return impl_->reader->matched_writers();
}

// ---- poses ----

class PoseInput::Impl {
 public:
  using StampedReader =
      transport::Reader<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;
  using OdometryReader = transport::Reader<nav_msgs::msg::dds_::Odometry_PubSubType>;
  std::unique_ptr<StampedReader> stamped;
  std::unique_ptr<OdometryReader> odometry;
  std::string frame_id;
  std::vector<PoseStampedMsg> stamped_batch;
  std::vector<OdometryMsg> odometry_batch;

  void convert(const std_msgs::msg::dds_::Header_& header, const PoseMsg& pose,
               const std::array<double, 36>& covariance, PoseSink& sink) {
    if (header.frame_id() != frame_id) {
      sink.reject("pose.unknown_frame");
      return;
    }
    auto T = from_pose_msg(pose);
    if (!T) {
      sink.reject(T.error().code);
      return;
    }
    const double var = std::max(covariance[0], covariance[7]);
    const double std_m = std::isfinite(var) && var > 0.0 ? std::sqrt(var) : 0.0;
    sink.pose(PoseSample{from_time_msg(header.stamp()), T.value(), std_m});
  }
};

core::Result<std::unique_ptr<PoseInput>> PoseInput::create(
    const Participant& participant, const std::string& topic, PoseMessage type,
    const std::string& frame_id, const QosSpec& qos, std::size_t queue_depth) {
  auto impl = std::make_unique<Impl>();
  impl->frame_id = frame_id;
  if (type == PoseMessage::kPoseWithCovarianceStamped) {
    auto reader = Impl::StampedReader::create(participant, topic, qos, queue_depth);
    if (!reader) return reader.error();
    impl->stamped = std::move(reader).value();
    impl->stamped_batch.reserve(queue_depth);
  } else {
    auto reader = Impl::OdometryReader::create(participant, topic, qos, queue_depth);
    if (!reader) return reader.error();
    impl->odometry = std::move(reader).value();
    impl->odometry_batch.reserve(queue_depth);
  }
  return std::unique_ptr<PoseInput>(new PoseInput(std::move(impl)));
}

PoseInput::PoseInput(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PoseInput::~PoseInput() = default;

std::size_t PoseInput::drain(PoseSink& sink) {
  const auto convert = [&](const auto& m) {
    impl_->convert(m.header(), m.pose().pose(), m.pose().covariance(), sink);
  };
  return impl_->stamped ? drain_batch(*impl_->stamped, impl_->stamped_batch, convert)
                        : drain_batch(*impl_->odometry, impl_->odometry_batch, convert);
}

std::uint64_t PoseInput::overflow_drops() const {
  return impl_->stamped ? impl_->stamped->dropped() : impl_->odometry->dropped();
}
std::uint64_t PoseInput::transport_lost() const {
  return impl_->stamped ? impl_->stamped->lost() + impl_->stamped->rejected()
                        : impl_->odometry->lost() + impl_->odometry->rejected();
}
std::size_t PoseInput::matched_writers() const {
  return impl_->stamped ? impl_->stamped->matched_writers() : impl_->odometry->matched_writers();
}

// ---- corrected trajectories ----

class TrajectoryInput::Impl {
 public:
  using Reader = transport::Reader<nav_msgs::msg::dds_::Path_PubSubType>;
  std::unique_ptr<Reader> reader;
  std::string frame_id;
  std::vector<PathMsg> batch;
  std::vector<PoseSample> poses;  // capacity kept across drains

  void convert(const PathMsg& msg, TrajectorySink& sink) {
    const auto made_ns = from_path_msg(msg, frame_id, poses);
    if (!made_ns) {
      sink.reject(made_ns.error().code);
      return;
    }
    sink.trajectory(made_ns.value(), poses);
  }
};

core::Result<std::unique_ptr<TrajectoryInput>> TrajectoryInput::create(
    const Participant& participant, const std::string& topic, const std::string& frame_id,
    const QosSpec& qos, std::size_t queue_depth) {
  auto reader = Impl::Reader::create(participant, topic, qos, queue_depth);
  if (!reader) return reader.error();
  auto impl = std::make_unique<Impl>();
  impl->reader = std::move(reader).value();
  impl->frame_id = frame_id;
  impl->batch.reserve(queue_depth);
  impl->poses.reserve(1024);
  return std::unique_ptr<TrajectoryInput>(new TrajectoryInput(std::move(impl)));
}

TrajectoryInput::TrajectoryInput(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
TrajectoryInput::~TrajectoryInput() = default;

std::size_t TrajectoryInput::drain(TrajectorySink& sink) {
  return drain_batch(*impl_->reader, impl_->batch,
                     [&](const PathMsg& m) { impl_->convert(m, sink); });
}

std::uint64_t TrajectoryInput::overflow_drops() const {
  return impl_->reader->dropped();
}
std::size_t TrajectoryInput::matched_writers() const {
  return impl_->reader->matched_writers();
}

// ---- virtual obstacles ----

class ZoneInput::Impl {
 public:
  using Reader = transport::Reader<tarmac_msgs::msg::dds_::VirtualObstacleArray_PubSubType>;
  std::unique_ptr<Reader> reader;
  std::vector<VirtualObstacleArrayMsg> batch;
};

core::Result<std::unique_ptr<ZoneInput>> ZoneInput::create(const Participant& participant,
                                                           const std::string& topic,
                                                           const QosSpec& qos) {
  auto reader = Impl::Reader::create(participant, topic, qos, 4);
  if (!reader) return reader.error();
  auto impl = std::make_unique<Impl>();
  impl->reader = std::move(reader).value();
  return std::unique_ptr<ZoneInput>(new ZoneInput(std::move(impl)));
}

ZoneInput::ZoneInput(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ZoneInput::~ZoneInput() = default;

bool ZoneInput::take_latest(std::vector<core::VirtualZone>& zones, std::string& rejected) {
  auto& batch = impl_->batch;
  batch.clear();
  if (impl_->reader->take_all(batch) == 0) return false;
  auto converted = from_virtual_obstacles(batch.back());
  batch.clear();
  if (!converted) {
    rejected = converted.error().code;
    return false;
  }
  zones = std::move(converted).value();
  return true;
}

}  // namespace tarmac::transport
