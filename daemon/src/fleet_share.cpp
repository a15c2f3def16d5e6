#include "fleet_share.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

namespace tarmac::daemon {

namespace {

std::int64_t seconds_to_ns(double s) {
  return std::llround(s * 1e9);
}

std::uint64_t total_gaps(const core::BevPeers& peers) {
  std::uint64_t n = 0;
  for (const auto& [id, st] : peers.stats()) n += st.gaps;
  return n;
}

}  // namespace

core::Result<std::unique_ptr<FleetShare>> FleetShare::create(
    const transport::Participant& participant, const config::Config& config, double resolution_m,
    ReasonCounters& drops, ReasonCounters& rejections) {
  transport::FleetLinkOptions options;
  options.topic = config.fleet.topic;
  options.frame_id = config.outputs.frame_id;
  options.vehicle_id = config.fleet.vehicle_id;
  options.queue_depth = kMaxPending;
  auto link = transport::FleetLink::create(participant, options);
  if (!link) return link.error();
  for (const char* r : {"queue.fleet_overflow", "transport.fleet_lost", "fleet.gap"}) {
    drops.declare(r);
  }
  for (const char* r : {"fleet.frame", "fleet.resolution", "fleet.malformed", "fleet.impersonation",
                        "fleet.own_id", "fleet.future", "fleet.stale", "fleet.order",
                        "fleet.too_large", "fleet.too_many_peers", "fleet.localisation"}) {
    rejections.declare(r);
  }
  return std::unique_ptr<FleetShare>(new FleetShare(config, resolution_m, std::move(link).value()));
}

FleetShare::FleetShare(const config::Config& config, double resolution_m,
                       std::unique_ptr<transport::FleetLink> link)
    : link_(std::move(link)),
      peers_(config.fleet.vehicle_id, resolution_m, seconds_to_ns(config.fleet.max_age_s),
             std::llround(config.executor.max_future_ms * 1e6), position_bound_m(config)),
      encoder_(config.fleet.vehicle_id, resolution_m),
      period_ns_(seconds_to_ns(config.fleet.publish_period_s)),
      max_age_ns_(seconds_to_ns(config.fleet.max_age_s)),
      input_delay_ns_(std::llround(config.executor.input_delay_ms * 1e6)),
      max_future_ns_(std::llround(config.executor.max_future_ms * 1e6)) {
  pending_.reserve(2 * kMaxPending);
}

double FleetShare::position_bound_m(const config::Config& config) {
  const auto& c = config.mapping.costmap;
  return std::max(c.inflation_radius_m - c.inscribed_radius_m, 0.0) / 3.0;
}

void FleetShare::summary(core::BevMessage&& message) {
  if (pending_.size() >= kMaxPending) {
    pending_.erase(pending_.begin());  // the oldest received
    drops_->add("queue.fleet_overflow");
  }
  pending_.push_back(std::move(message));
}

void FleetShare::reject(std::string_view reason) {
  rejections_->add(reason);
}

bool FleetShare::take(std::int64_t tick_ns, ReasonCounters& drops, ReasonCounters& rejections) {
  drops_ = &drops;
  rejections_ = &rejections;
  link_->drain(*this);
  const std::uint64_t overflow = link_->overflow_drops(), lost = link_->transport_lost();
  drops.add("queue.fleet_overflow", overflow - overflow_seen_);
  drops.add("transport.fleet_lost", lost - lost_seen_);
  overflow_seen_ = overflow;
  lost_seen_ = lost;
  if (pending_.empty()) return false;

  core::sort_in_apply_order(pending_);
  // Due: stamped at least the input delay before the tick. One from beyond the future tolerance
  // is handed over now, to be refused and counted, not held.
  const std::int64_t horizon = tick_ns - input_delay_ns_;
  const std::uint64_t gaps_before = total_gaps(peers_);
  bool changed = false;
  std::size_t kept = 0;
  for (auto& m : pending_) {
    if (m.stamp_ns > horizon && m.stamp_ns <= tick_ns + max_future_ns_) {
      pending_[kept++] = std::move(m);
      continue;
    }
    const auto applied = peers_.apply(m, tick_ns);
    if (!applied) {
      rejections.add(applied.error().code);
    } else {
      changed = true;
    }
  }
  pending_.resize(kept);
  drops.add("fleet.gap", total_gaps(peers_) - gaps_before);
  return changed;
}

std::size_t FleetShare::publish_if_due(std::int64_t tick_ns, core::Mapper& mapper) {
  if (tick_ns < next_publish_ns_) return 0;
  // The next on the period's grid: a late tick does not shift every later summary.
  next_publish_ns_ = (tick_ns / period_ns_ + 1) * period_ns_;
  const core::BevSnapshot snapshot = mapper.fleet_snapshot();
  const bool keyframe = encoder_.next_sequence() % kKeyframeEvery == 0;
  core::BevMessage message = encoder_.encode(snapshot, tick_ns, keyframe, max_age_ns_);
  if (pose_since_summary_) pose_std_sent_m_ = pose_std_max_m_;
  message.position_std_m = pose_std_sent_m_;
  pose_std_max_m_ = 0.0;
  pose_since_summary_ = false;
  if (!link_->publish(message)) return 0;
  bytes_published_ += link_->last_bytes();
  ++messages_published_;
  return link_->last_bytes();
}

void FleetShare::fill_report(std::int64_t tick_ns, const core::BevFusionCounts& counts,
                             transport::CycleReport& report) const {
  const auto& stats = peers_.stats();
  report.fleet_peers.resize(stats.size());
  std::size_t i = 0;
  for (const auto& [id, st] : stats) {
    auto& p = report.fleet_peers[i++];
    p.vehicle_id = id;
    const auto cells = counts.cells_by_peer.find(id);
    p.cells = cells == counts.cells_by_peer.end() ? 0 : cells->second;
    p.age_ms =
        st.newest_stamp_ns == 0 ? -1.0 : static_cast<double>(tick_ns - st.newest_stamp_ns) / 1e6;
    p.messages = st.messages;
    p.rejected = st.rejected;
    p.gaps = st.gaps;
  }
  report.fleet_newest_age_ms =
      counts.newest_observed_ns == 0
          ? -1.0
          : std::max(0.0, static_cast<double>(tick_ns - counts.newest_observed_ns) / 1e6);
}

}  // namespace tarmac::daemon
