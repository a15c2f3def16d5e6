#pragma once
/// @file The executor's DDS inputs (each sensor's scans, the poses, corrected trajectories, the
/// virtual obstacles) and what DDS lost of them: created with the executor, emptied once per
/// tick (the drain stage) into the cycle's sinks, never blocking. DDS listener threads only
/// enqueue; an overflowing queue drops its oldest sample, counted here.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "tarmac/config/config.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/daemon/reason_counters.hpp"
#include "tarmac/transport/inputs.hpp"
#include "tarmac/transport/participant.hpp"

namespace tarmac::daemon {

class TickInputs {
 public:
  /// Where drained samples go; the sinks must outlive the inputs.
  struct Sinks {
    std::vector<transport::ScanSink*> scans;  ///< one per sensor, in config order
    transport::PoseSink* pose = nullptr;
    transport::TrajectorySink* trajectory = nullptr;
  };

  /// Creates the readers: each sensor's scans, the poses, the corrected trajectories (with
  /// mapping.corrections.enabled), the virtual obstacles; fails with the first DDS error. Declares
  /// each sensor's transport reasons in `drops`.
  static core::Result<std::unique_ptr<TickInputs>> create(const transport::Participant& participant,
                                                          const config::Config& cfg, Sinks sinks,
                                                          ReasonCounters& drops);

  /// Empties every queue into the sinks: the scans, then the poses, then the corrected
  /// trajectories (after the poses: a correction applies to the samples already in the buffer),
  /// then takes the newest zones into `zones` (true when they changed; a refused array counted in
  /// `rejections`). Queue overflows and transport losses since the last call are added to
  /// `drops`; a sensor's losses are logged at most once per kLossLogTicks ticks (`cycle_index`).
  /// RT-safe.
  bool drain(std::vector<core::VirtualZone>& zones, ReasonCounters& drops,
             ReasonCounters& rejections, std::uint64_t cycle_index);

 private:
  static constexpr std::uint64_t kLossLogTicks = 100;

  struct Sensor {
    std::unique_ptr<transport::ScanInput> input;
    std::string id;
    std::string lost_reason, rejected_reason;
    std::uint64_t overflow = 0, lost = 0, rejected = 0;  // seen at the last drain
    std::uint64_t logged_tick = 0;  // cycle index of the last log line (0: never)
  };

  explicit TickInputs(Sinks sinks) : sinks_(std::move(sinks)) {}
  /// Adds the scans `sensor` lost or had rejected in DDS transport since the last tick to the
  /// drops (`transport.scan_lost.<id>`, `transport.scan_rejected.<id>`), and logs them.
  void count_transport_losses(Sensor& sensor, ReasonCounters& drops, std::uint64_t cycle_index);

  Sinks sinks_;
  std::vector<Sensor> sensors_;
  std::unique_ptr<transport::PoseInput> pose_;
  std::unique_ptr<transport::TrajectoryInput> trajectory_;
  std::unique_ptr<transport::ZoneInput> zones_;
  std::uint64_t pose_overflow_ = 0, pose_lost_ = 0;  // seen at the last drain
  std::string zone_rejection_;
};

}  // namespace tarmac::daemon
