#pragma once
/// @file One vehicle's link to the fleet's bird's-eye summaries (docs/fleet.md): its own writer,
/// in the DDS partition named after its vehicle id (fleet_partition()), and a reader of every
/// vehicle's partition. With DDS Security the permissions file grants each vehicle publication in
/// its own partition only, and the link refuses a summary whose vehicle id is not its writer's
/// partition: a vehicle cannot speak for another.

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::transport {

/// The DDS partition a vehicle's summaries are written in: "tarmac_fleet_<vehicle id>".
std::string fleet_partition(std::string_view vehicle_id);

/// Receives the summaries of other vehicles, converted.
class FleetSink {
 public:
  virtual ~FleetSink() = default;
  virtual void summary(core::BevMessage&& message) = 0;
  /// A summary refused before it reached the core: `reason` is a stable code ("fleet.frame",
  /// "fleet.resolution", "fleet.malformed", "fleet.impersonation").
  virtual void reject(std::string_view reason) = 0;
};

struct FleetLinkOptions {
  std::string topic = "rt/tarmac/fleet/bev";
  std::string frame_id = "map";  ///< the shared map frame: summaries in another are refused
  /// This vehicle's id: its summaries are written in its partition, and its own are not handed
  /// to the sink. Empty: a listener only (the site view), no writer.
  std::string vehicle_id;
  QosSpec qos = qos::kFleet;
  std::size_t queue_depth = 64;  ///< summaries kept between drains (oldest dropped, counted)
};

class FleetLink {
 public:
  static core::Result<std::unique_ptr<FleetLink>> create(const Participant& participant,
                                                         const FleetLinkOptions& options);
  ~FleetLink();
  FleetLink(const FleetLink&) = delete;
  FleetLink& operator=(const FleetLink&) = delete;

  /// Writes one of this vehicle's summaries; false when Fast DDS refused it or there is no writer.
  bool publish(const core::BevMessage& message);
  /// The serialized size of the last summary published (bytes), for the traffic figures.
  [[nodiscard]] std::size_t last_bytes() const;

  /// Converts every queued summary of another vehicle into the sink, oldest first. Returns the
  /// number taken (own summaries included).
  std::size_t drain(FleetSink& sink);
  /// Summaries dropped by queue overflow, and lost or refused in transport, since creation.
  [[nodiscard]] std::uint64_t overflow_drops() const;
  [[nodiscard]] std::uint64_t transport_lost() const;
  [[nodiscard]] std::size_t matched_writers() const;
  [[nodiscard]] std::size_t matched_readers() const;

  class Impl;

 private:
  explicit FleetLink(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tarmac::transport
