#pragma once
/// @file The config schema: one entry per leaf key of tarmacd's YAML file, with its type, range,
/// unit, one-line doc and where its value lives in `Config`. The default of a key is its value in
/// a default-constructed `Config`. The loader, to_yaml, `tarmacd --print-config-reference` and
/// the tests of config/tarmac.yaml and docs/configuration.md all walk this one table, so a key is
/// defined here and nowhere else (cross-key rules stay code: validate_daemon in config.cpp).

#include <cstdint>
#include <string>
#include <string_view>
#include <type_traits>
#include <variant>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/config/config.hpp"

namespace tarmac::config {

/// One `sensors[i]` map as written in YAML: the sensor, with its extrinsic as the file gives it
/// (a translation, and a rotation as a quaternion or as roll-pitch-yaw), not yet composed into
/// `SensorConfig::T_base_sensor`.
struct SensorEntry {
  SensorConfig sensor;
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  Eigen::Quaterniond quaternion = Eigen::Quaterniond::Identity();
  double roll_deg = 0.0;
  double pitch_deg = 0.0;
  double yaw_deg = 0.0;
};

/// A field holding an enum, read and written as the index of its name in `Key::choices` (the
/// enum's values in declaration order).
struct ChoiceField {
  void* field = nullptr;
  int (*get)(const void* field) = nullptr;
  void (*set)(void* field, int index) = nullptr;
};

/// Where a key's value lives: a pointer to the field, of the field's own C++ type.
using Field = std::variant<bool*, int*, std::uint32_t*, std::uint64_t*, float*, double*,
                           std::string*, std::vector<std::string>*, std::vector<int>*, ChoiceField>;

/// What a key holds, as the file spells it.
enum class KeyType {
  kBool,
  kInteger,
  kReal,
  kString,
  kTopic,  ///< a ROS 2 topic: `/ns/name` is mapped to its DDS form `rt/ns/name`; "" allowed
  kPath,   ///< a file; a relative path is taken relative to the config file's folder
  kChoice,
  kStringList,
  kIntegerList,  ///< each element in [min, max]
};

/// Where a key's value lives, for a key of the whole config or (path `sensors[].…`) of one sensor.
struct Access {
  using OfConfig = Field (*)(Config&);
  using OfSensor = Field (*)(SensorEntry&);
  /// From a captureless lambda taking `Config&` or `SensorEntry&` and returning a Field.
  template <typename Fn>
  Access(Fn fn) {  // NOLINT(google-explicit-constructor): the table reads better without a cast
    if constexpr (std::is_convertible_v<Fn, OfConfig>) {
      of_config = fn;
    } else {
      of_sensor = fn;
    }
  }
  OfConfig of_config = nullptr;
  OfSensor of_sensor = nullptr;
};

/// One leaf key.
struct Key {
  std::string path;  ///< "executor.rate_hz"; a sensor's keys are "sensors[].max_age_ms"
  KeyType type;
  double min = 0.0;  ///< kInteger, kReal, kIntegerList: the accepted range, inclusive
  double max = 0.0;
  std::vector<std::string_view> choices;  ///< kChoice: the names, in the enum's order
  std::string_view unit;                  ///< "ms", "m", "Hz"; "" when none
  std::string_view doc;                   ///< one line, for the reference
  Access access;
  /// Shown as the default in the reference instead of the default Config's value, for a
  /// default that is derived (a sensor's topic from its id) or taken from the environment.
  std::string_view default_text = {};
  /// false: read but never written by to_yaml (rpy_deg: the rotation is written as a
  /// quaternion); such a key is an alternative spelling of keys that are written.
  bool written = true;
};

/// Every key, in the order to_yaml writes them. Keys of one map are contiguous.
const std::vector<Key>& schema();

/// A sensor as to_yaml writes it: the extrinsic as translation and quaternion.
SensorEntry sensor_entry(const SensorConfig& sensor);

/// The key at `path` ("executor.rate_hz"); the path must be in the schema.
const Key& schema_key(std::string_view path);

/// Where `key`'s value lives in `config`, or (a `sensors[]` key) in `*sensor`.
Field field_of(const Key& key, Config& config, SensorEntry* sensor);

/// True when to_yaml writes the map at `map_path` on one line ({x: 0, y: 0, z: 0}): vectors,
/// rotations and QoS profiles. `map_path` is in schema form ("sensors[].extrinsic.quaternion").
bool is_flow_map(std::string_view map_path);

/// The reference of every key as a Markdown table (key, type, default, range, unit, doc), the
/// output of `tarmacd --print-config-reference` and the table in docs/configuration.md.
std::string reference_markdown();

}  // namespace tarmac::config
