#pragma once
/// @file tarmacd's configuration: plain structs with defaults, loaded from one YAML file
/// (config/tarmac.yaml documents every key). Unknown keys and out-of-range values are errors that
/// name the key path, e.g. "dds.qos.costmap.depht: unknown key".

#include <cstdint>
#include <string>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/transport/participant.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::config {

/// The only config schema version this build reads.
inline constexpr int kConfigVersion = 1;

/// QoS per DDS topic role (DESIGN.md §5 defaults).
struct QosConfig {
  transport::QosSpec lidar = transport::qos::kLidar;
  transport::QosSpec pose = transport::qos::kPose;
  transport::QosSpec virtual_obstacles = transport::qos::kVirtualObstacles;
  transport::QosSpec costmap = transport::qos::kCostmap;
  transport::QosSpec esdf_slice = transport::qos::kEsdfSlice;
  transport::QosSpec diagnostics = transport::qos::kDiagnostics;
};

struct DdsConfig {
  transport::ParticipantConfig participant;  ///< localhost-only by default
  QosConfig qos;
};

struct Config {
  int version = kConfigVersion;
  DdsConfig dds;
  core::MapperParams mapping;  ///< YAML sections filters, occupancy, costmap, tsdf
};

/// Parses YAML text. Error code "config.<reason>", message "<key.path>: <why>".
core::Result<Config> load_config_string(const std::string& yaml_text);
/// Reads and parses a file; "config.io" when it cannot be read.
core::Result<Config> load_config_file(const std::string& path);

/// A stable hash (16 hex digits, FNV-1a 64) of the effective config, for logs and CycleReport.
std::string config_hash(const Config& config);
/// The effective config rendered as YAML (defaults filled in), for the start-up log.
std::string to_yaml(const Config& config);

}  // namespace tarmac::config
