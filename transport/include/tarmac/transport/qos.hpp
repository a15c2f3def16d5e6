#pragma once
/// @file DDS quality of service as plain config values (filled from YAML by config/), and the
/// defaults of DESIGN.md §5 per topic role. No Fast DDS here: the config includes it.

#include <cstdint>

#include "tarmac/core/result.hpp"

namespace tarmac::transport {

enum class Reliability { kBestEffort, kReliable };
enum class Durability { kVolatile, kTransientLocal };

/// The QoS a reader or writer is created with. History is always KEEP_LAST(depth).
struct QosSpec {
  Reliability reliability = Reliability::kReliable;
  Durability durability = Durability::kVolatile;
  std::uint32_t history_depth = 1;  ///< samples kept per instance, >= 1

  [[nodiscard]] core::Status validate() const;
  friend bool operator==(const QosSpec&, const QosSpec&) = default;
};

/// DESIGN.md §5 defaults.
namespace qos {
/// LiDAR scans in: best effort, keep last 2 (a late scan is worth less than the next one).
inline constexpr QosSpec kLidar{Reliability::kBestEffort, Durability::kVolatile, 2};
/// Poses in: reliable, keep last 50 (the pose buffer interpolates between them).
inline constexpr QosSpec kPose{Reliability::kReliable, Durability::kVolatile, 50};
/// Virtual obstacles in: reliable, transient local, so a late-joining tarmacd gets the zones.
inline constexpr QosSpec kVirtualObstacles{Reliability::kReliable, Durability::kTransientLocal, 1};
/// Costmap out: reliable, transient local, keep last 1 (Nav2 map convention).
inline constexpr QosSpec kCostmap{Reliability::kReliable, Durability::kTransientLocal, 1};
/// ESDF slices out: best effort, keep last 1 (the safety filter wants the newest only).
inline constexpr QosSpec kEsdfSlice{Reliability::kBestEffort, Durability::kVolatile, 1};
/// 3D ESDF band out: best effort, keep last 1 (megabytes per sample; the newest only).
inline constexpr QosSpec kEsdfBand{Reliability::kBestEffort, Durability::kVolatile, 1};
/// Debris out: reliable, transient local, keep last 1 (a ground-crew tablet that joins late gets
/// the current list at once).
inline constexpr QosSpec kDebris{Reliability::kReliable, Durability::kTransientLocal, 1};
/// Diagnostics out: reliable, keep last 20 (the auditor must not miss a cycle).
inline constexpr QosSpec kDiagnostics{Reliability::kReliable, Durability::kVolatile, 20};
/// Fleet summaries, in and out: reliable (a lost change message costs its receiver every change
/// up to the next keyframe), volatile (a late joiner waits for a keyframe: an older message is
/// of no use to it), keep last 16.
inline constexpr QosSpec kFleet{Reliability::kReliable, Durability::kVolatile, 16};
}  // namespace qos

/// Default topic names, ROS 2 wire form (rt/ prefix). DESIGN.md §5.
namespace topics {
inline constexpr const char* kPose = "rt/tarmac/pose";
inline constexpr const char* kVirtualObstacles = "rt/tarmac/virtual_obstacles";
inline constexpr const char* kCostmap = "rt/tarmac/costmap";
inline constexpr const char* kEsdfSlice = "rt/tarmac/esdf_slice";
inline constexpr const char* kEsdfBand = "rt/tarmac/esdf_band";
inline constexpr const char* kDebris = "rt/tarmac/debris";
inline constexpr const char* kDiagnostics = "rt/tarmac/diagnostics";
inline constexpr const char* kDiagnosticArray = "rt/diagnostics";
}  // namespace topics

}  // namespace tarmac::transport
