#include "tick_inputs.hpp"

#include <algorithm>
#include <utility>

#include <spdlog/spdlog.h>

namespace tarmac::daemon {

core::Result<std::unique_ptr<TickInputs>> TickInputs::create(
    const transport::Participant& participant, const config::Config& cfg, Sinks sinks,
    ReasonCounters& drops) {
  std::unique_ptr<TickInputs> in(new TickInputs(std::move(sinks)));
  const auto& q = cfg.dds.qos;
  for (const auto& s : cfg.sensors) {
    auto input = transport::ScanInput::create(participant, s.topic, s.frame_id, q.lidar,
                                              cfg.executor.queue_depth, s.driver);
    if (!input) return input.error();
    Sensor sensor;
    sensor.input = std::move(input).value();
    sensor.id = s.id;
    sensor.lost_reason = "transport.scan_lost." + s.id;
    sensor.rejected_reason = "transport.scan_rejected." + s.id;
    drops.declare(sensor.lost_reason);
    drops.declare(sensor.rejected_reason);
    in->sensors_.push_back(std::move(sensor));
  }
  auto pose = transport::PoseInput::create(participant, cfg.pose.topic,
                                           cfg.pose.type == config::PoseType::kOdometry
                                               ? transport::PoseMessage::kOdometry
                                               : transport::PoseMessage::kPoseWithCovarianceStamped,
                                           cfg.pose.frame_id, q.pose,
                                           std::max<std::size_t>(cfg.executor.queue_depth, 64));
  if (!pose) return pose.error();
  in->pose_ = std::move(pose).value();
  if (cfg.mapping.corrections.enabled) {
    auto trajectory = transport::TrajectoryInput::create(participant, cfg.pose.correction_topic,
                                                         cfg.pose.frame_id, q.pose, 4);
    if (!trajectory) return trajectory.error();
    in->trajectory_ = std::move(trajectory).value();
  }
  auto zones = transport::ZoneInput::create(participant, cfg.outputs.virtual_obstacles_topic,
                                            q.virtual_obstacles);
  if (!zones) return zones.error();
  in->zones_ = std::move(zones).value();
  return in;
}

bool TickInputs::drain(std::vector<core::VirtualZone>& zones, ReasonCounters& drops,
                       ReasonCounters& rejections, std::uint64_t cycle_index) {
  for (std::size_t i = 0; i < sensors_.size(); ++i) {
    Sensor& s = sensors_[i];
    s.input->drain(*sinks_.scans[i]);
    const std::uint64_t overflow = s.input->overflow_drops();
    drops.add("queue.scan_overflow", overflow - s.overflow);
    s.overflow = overflow;
    count_transport_losses(s, drops, cycle_index);
  }
  pose_->drain(*sinks_.pose);
  const std::uint64_t pose_overflow = pose_->overflow_drops();
  drops.add("queue.pose_overflow", pose_overflow - pose_overflow_);
  pose_overflow_ = pose_overflow;
  const std::uint64_t pose_lost = pose_->transport_lost();
  drops.add("transport.pose_lost", pose_lost - pose_lost_);
  pose_lost_ = pose_lost;
  if (trajectory_) trajectory_->drain(*sinks_.trajectory);
  zone_rejection_.clear();
  const bool zones_changed = zones_->take_latest(zones, zone_rejection_);
  if (!zone_rejection_.empty()) rejections.add(zone_rejection_);
  return zones_changed;
}

void TickInputs::count_transport_losses(Sensor& s, ReasonCounters& drops,
                                        std::uint64_t cycle_index) {
  const std::uint64_t lost = s.input->transport_lost();
  const std::uint64_t rejected = s.input->transport_rejected();
  if (lost == s.lost && rejected == s.rejected) return;
  drops.add(s.lost_reason, lost - s.lost);
  drops.add(s.rejected_reason, rejected - s.rejected);
  s.lost = lost;
  s.rejected = rejected;
  // At most one line per sensor per kLossLogTicks ticks: a lossy link must not flood the log.
  if (s.logged_tick != 0 && cycle_index < s.logged_tick + kLossLogTicks) return;
  s.logged_tick = std::max<std::uint64_t>(cycle_index, 1);
  spdlog::warn(
      "input {}: {} scan(s) lost and {} rejected in DDS transport so far (UDP receive buffer "
      "too small? see dds.udp_receive_buffer_bytes and net.core.rmem_max)",
      s.id, lost, rejected);
}

}  // namespace tarmac::daemon
