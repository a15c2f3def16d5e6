#pragma once
/// @file Fleet sharing in the executor (docs/fleet.md): what this vehicle publishes of its own
/// cells, and what it keeps of its peers' summaries for the costmap. Created with the executor
/// when fleet.enabled; the tick calls take() in its drain stage, update_costmap() fuses
/// peers(), and publish_if_due() sends this vehicle's summary every fleet.publish_period_s.
///
/// Determinism: a summary is applied at the first tick whose time is at least its stamp plus
/// executor.input_delay_ms (as a scan is integrated), summaries of one tick in (stamp, vehicle
/// id, sequence) order, so the same summaries with the same stamps give the same peers' cells
/// whatever their arrival times within the delay.

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "tarmac/config/config.hpp"
#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/daemon/reason_counters.hpp"
#include "tarmac/transport/cycle_report.hpp"
#include "tarmac/transport/fleet.hpp"

namespace tarmac::daemon {

class FleetShare final : private transport::FleetSink {
 public:
  /// Summaries held between arrival and their tick; beyond, the oldest is dropped (counted).
  static constexpr std::size_t kMaxPending = 64;
  /// Every this many messages is a keyframe (every known tile): a late joiner or a receiver
  /// that lost a message converges within this many periods.
  static constexpr std::uint64_t kKeyframeEvery = 10;

  /// The link on `participant` (fleet.topic, in this vehicle's partition), the peers at the
  /// costmap's resolution `resolution_m`; declares the fleet's reasons in `drops` and
  /// `rejections`.
  static core::Result<std::unique_ptr<FleetShare>> create(const transport::Participant& participant,
                                                          const config::Config& config,
                                                          double resolution_m,
                                                          ReasonCounters& drops,
                                                          ReasonCounters& rejections);

  /// Drain stage: takes the summaries received since the last tick and applies those due at
  /// `tick_ns` to the peers (refusals counted in `rejections` as "fleet.<reason>", transport
  /// losses and ignored change messages in `drops`). Returns true when a peer's cells changed.
  bool take(std::int64_t tick_ns, ReasonCounters& drops, ReasonCounters& rejections);

  /// Forgets peers' observations older than fleet.max_age_s before `now_ns`.
  void expire(std::int64_t now_ns) { peers_.expire(now_ns); }

  [[nodiscard]] const core::BevPeers& peers() const { return peers_; }

  /// A pose of this vehicle was taken, with its localiser's position uncertainty (1σ, m; 0: not
  /// stated): the next summary states the largest since the last one.
  void note_pose(double position_std_m) {
    pose_std_max_m_ = std::max(pose_std_max_m_, position_std_m);
    pose_since_summary_ = true;
  }

  /// The bound on a peer's stated position uncertainty (1σ) this vehicle accepts: a third of its
  /// inflation margin (costmap.inflation_radius_m − inscribed_radius_m), so that a peer's cells
  /// sit within that margin of where they are at 3σ (docs/fleet.md).
  static double position_bound_m(const config::Config& config);

  /// After the costmap: when a period has passed since the last, encodes `mapper`'s own cells
  /// (Mapper::fleet_snapshot) stamped `tick_ns` and publishes them. Returns the bytes written
  /// (0: not due, or refused by DDS).
  std::size_t publish_if_due(std::int64_t tick_ns, core::Mapper& mapper);

  /// The report's fleet fields: per peer what it gave (`counts`, from this tick's costmap) and
  /// how old its newest summary is at `tick_ns`.
  void fill_report(std::int64_t tick_ns, const core::BevFusionCounts& counts,
                   transport::CycleReport& report) const;

  /// Bytes published since start, and messages.
  [[nodiscard]] std::uint64_t bytes_published() const { return bytes_published_; }
  [[nodiscard]] std::uint64_t messages_published() const { return messages_published_; }

 private:
  FleetShare(const config::Config& config, double resolution_m,
             std::unique_ptr<transport::FleetLink> link);
  void summary(core::BevMessage&& message) override;
  void reject(std::string_view reason) override;

  std::unique_ptr<transport::FleetLink> link_;
  core::BevPeers peers_;
  core::BevEncoder encoder_;
  std::int64_t period_ns_;
  std::int64_t max_age_ns_;
  std::int64_t input_delay_ns_;
  std::int64_t max_future_ns_;
  std::int64_t next_publish_ns_ = 0;
  std::vector<core::BevMessage> pending_;
  ReasonCounters* rejections_ = nullptr;  // during take(): where the link's refusals go
  ReasonCounters* drops_ = nullptr;
  std::uint64_t overflow_seen_ = 0, lost_seen_ = 0;
  std::uint64_t bytes_published_ = 0, messages_published_ = 0;
  double pose_std_max_m_ = 0.0;   // since the last summary
  double pose_std_sent_m_ = 0.0;  // in the last summary: kept when no pose came since
  bool pose_since_summary_ = false;
};

}  // namespace tarmac::daemon
