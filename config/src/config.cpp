#include "tarmac/config/config.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <span>
#include <sstream>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "tarmac/config/schema.hpp"
#include "yaml_values.hpp"

namespace tarmac::config {

namespace {

using namespace detail;  // yaml_values.hpp

std::string choice_list(const Key& key) {
  std::string list;
  for (const auto& c : key.choices) list += (list.empty() ? "" : ", ") + std::string(c);
  return list;
}

/// Reads a YAML document into a Config by the schema: the keys of each map in schema order,
/// then the map's unknown keys refused (with the nearest known key suggested).
/// check_structure() has run on the whole document first: no duplicate or non-scalar keys.
class SchemaReader {
 public:
  SchemaReader(Config& config, std::string base_dir)
      : config_(config), base_dir_(std::move(base_dir)) {}

  /// Reads `keys` (all in the map `prefix`, schema form: "dds.qos.lidar.") from `node`, the
  /// map at `path` ("" for the root).
  void read_map(const YAML::Node& node, const std::string& path, const std::string& prefix,
                std::span<const Key> keys) {
    if (node && !node.IsNull() && !node.IsMap()) {
      fail("type", path_or_root(path), "expected a map, got " + describe(node));
    }
    std::vector<std::string> known;
    for (std::size_t i = 0; i < keys.size();) {
      const std::string name = next_segment(keys[i], prefix);
      std::size_t end = i + 1;
      while (end < keys.size() && next_segment(keys[end], prefix) == name) ++end;
      const bool is_list = name.ends_with("[]");
      const std::string key = is_list ? name.substr(0, name.size() - 2) : name;
      known.push_back(key);
      const YAML::Node child = take(node, path, key);
      if (child) {
        const std::string child_path = join_path(path, key);
        present_.insert(child_path);
        const auto group = keys.subspan(i, end - i);
        if (is_list) {
          read_sensors(child, child_path, group);
        } else if (keys[i].path.size() == prefix.size() + name.size()) {
          read_leaf(keys[i], child, child_path);
        } else {
          read_map(child, child_path, prefix + name + ".", group);
        }
      }
      i = end;
    }
    if (!node || !node.IsMap()) return;
    for (const auto& kv : node) {
      const std::string& key = kv.first.Scalar();
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        fail("unknown_key", join_path(path, key), "unknown key" + did_you_mean(key, known));
      }
    }
  }

  /// True when the file gives the key or map at `path` ("dds.domain_id").
  [[nodiscard]] bool present(const std::string& path) const { return present_.count(path) > 0; }

 private:
  /// The key or map name that follows `prefix` in `key`'s path ("sensors[]", "rate_hz").
  static std::string next_segment(const Key& key, const std::string& prefix) {
    const std::string rest = key.path.substr(prefix.size());
    return rest.substr(0, rest.find('.'));
  }

  static YAML::Node take(const YAML::Node& map, const std::string& path, const std::string& key) {
    if (!map || !map.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    YAML::Node child = map[key];
    if (child && child.IsNull()) fail("type", join_path(path, key), "has no value");
    return child;
  }

  /// `sensors`: a list of 1..16 maps, each read by the `sensors[].` keys.
  void read_sensors(const YAML::Node& node, const std::string& path, std::span<const Key> keys) {
    if (!node.IsSequence()) fail("type", path, "expected a list of maps, got " + describe(node));
    config_.sensors.clear();
    for (std::size_t i = 0; i < node.size(); ++i) {
      const std::string at = path + "[" + std::to_string(i) + "]";
      if (!node[i].IsMap()) fail("type", at, "expected a map, got " + describe(node[i]));
      SensorEntry entry;
      entry.sensor.id.clear();
      sensor_ = &entry;
      // The id first: the topic's and frame's defaults are made from it.
      if (const YAML::Node id = take(node[i], at, "id")) read_leaf(keys.front(), id, at + ".id");
      const std::string& id = entry.sensor.id;
      if (id.empty()) fail("value", at + ".id", "is required and must not be empty");
      entry.sensor.topic = "rt/tarmac/lidar/" + id + "/points";
      entry.sensor.frame_id = "lidar_" + id;
      read_map(node[i], at, "sensors[].", keys);
      sensor_ = nullptr;
      // A default topic is checked as a given one is: an id that makes it one ROS 2 cannot see
      // is refused here, not at the first reload of the written config (found by fuzzing).
      if (!present(at + ".topic")) {
        if (const auto why = ros_topic_problem(entry.sensor.topic); !why.empty()) {
          fail("value", at + ".id",
               "'" + id + "' makes the default topic '" + entry.sensor.topic + "', which " + why +
                   " (give " + at + ".topic, or an id of letters, digits and '_')");
        }
      }
      entry.sensor.q_base_sensor = rotation(entry, at + ".extrinsic");
      entry.sensor.T_base_sensor = Eigen::Isometry3d::Identity();
      entry.sensor.T_base_sensor.linear() = entry.sensor.q_base_sensor.toRotationMatrix();
      entry.sensor.T_base_sensor.translation() = entry.translation_m;
      for (const auto& other : config_.sensors) {
        if (other.id == id) fail("value", at + ".id", "duplicate id '" + id + "'");
        if (other.topic == entry.sensor.topic) {
          fail("value", at + ".topic", "duplicate topic '" + entry.sensor.topic + "'");
        }
      }
      config_.sensors.push_back(std::move(entry.sensor));
    }
    if (config_.sensors.empty()) fail("value", "sensors", "needs at least one sensor");
    if (config_.sensors.size() > 16) fail("range", "sensors", "at most 16 sensors");
  }

  /// T_base_sensor's rotation as a unit quaternion, given as one or as roll-pitch-yaw (ROS
  /// convention: R = Rz(yaw) · Ry(pitch) · Rx(roll)); identity if neither. A quaternion already
  /// of unit norm to 1e-12 is kept as given (normalising it again may move its last bits: a
  /// printed config must reload to the same values).
  Eigen::Quaterniond rotation(const SensorEntry& e, const std::string& path) const {
    constexpr double kDegToRad = 3.14159265358979323846 / 180.0;
    const bool has_rpy = present(path + ".rpy_deg");
    const bool has_quat = present(path + ".quaternion");
    if (has_rpy && has_quat) {
      fail("value", path + ".quaternion", "give either rpy_deg or quaternion, not both");
    }
    if (has_rpy) {
      return Eigen::AngleAxisd(e.yaw_deg * kDegToRad, Eigen::Vector3d::UnitZ()) *
             Eigen::AngleAxisd(e.pitch_deg * kDegToRad, Eigen::Vector3d::UnitY()) *
             Eigen::AngleAxisd(e.roll_deg * kDegToRad, Eigen::Vector3d::UnitX());
    }
    if (!has_quat) return Eigen::Quaterniond::Identity();
    const double norm = e.quaternion.norm();
    if (std::abs(norm - 1.0) > 1e-3) {
      fail("range", path + ".quaternion",
           "must be a unit quaternion (norm " + std::to_string(norm) + ")");
    }
    return std::abs(norm - 1.0) > 1e-12 ? e.quaternion.normalized() : e.quaternion;
  }

  /// One leaf: parsed and checked by its key's type and range, stored in its field.
  void read_leaf(const Key& key, const YAML::Node& node, const std::string& path) {
    const Field field = field_of(key, config_, sensor_);
    std::visit(
        [&](auto target) {
          using T = std::remove_pointer_t<decltype(target)>;
          if constexpr (std::is_same_v<T, bool>) {
            *target = parse_bool(node, path);
          } else if constexpr (std::is_integral_v<T>) {
            *target =
                parse_integer<T>(node, path, static_cast<T>(key.min), static_cast<T>(key.max));
          } else if constexpr (std::is_floating_point_v<T>) {
            *target = parse_real<T>(node, path, static_cast<T>(key.min), static_cast<T>(key.max));
          } else if constexpr (std::is_same_v<T, std::string>) {
            read_string(key, node, path, *target);
          } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
            read_string_list(node, path, *target);
          } else if constexpr (std::is_same_v<T, std::vector<int>>) {
            read_integer_list(key, node, path, *target);
          } else {
            static_assert(std::is_same_v<decltype(target), ChoiceField>);
            target.set(target.field, read_choice(key, node, path));
          }
        },
        field);
  }

  void read_string(const Key& key, const YAML::Node& node, const std::string& path,
                   std::string& value) const {
    if (!node.IsScalar()) fail("type", path, "expected a string, got " + describe(node));
    if (key.type == KeyType::kTopic) return read_topic(node, path, value);
    value = node.Scalar();
    // A relative file is taken relative to the config file's folder (when read from a file),
    // so a config and its security material can move together.
    if (key.type == KeyType::kPath && !value.empty() && !base_dir_.empty() &&
        std::filesystem::path(value).is_relative()) {
      value = (std::filesystem::path(base_dir_) / value).lexically_normal().string();
    }
  }

  static void read_string_list(const YAML::Node& node, const std::string& path,
                               std::vector<std::string>& value) {
    if (!node.IsSequence()) fail("type", path, "expected a list of strings, got " + describe(node));
    value.clear();
    for (std::size_t i = 0; i < node.size(); ++i) {
      const std::string at = path + "[" + std::to_string(i) + "]";
      if (!node[i].IsScalar()) fail("type", at, "expected a string, got " + describe(node[i]));
      value.push_back(node[i].Scalar());
    }
  }

  static void read_integer_list(const Key& key, const YAML::Node& node, const std::string& path,
                                std::vector<int>& value) {
    if (!node.IsSequence()) {
      fail("type", path, "expected a list of integers, got " + describe(node));
    }
    value.clear();
    for (std::size_t i = 0; i < node.size(); ++i) {
      value.push_back(parse_integer<int>(node[i], path + "[" + std::to_string(i) + "]",
                                         static_cast<int>(key.min), static_cast<int>(key.max)));
    }
  }

  /// The index of the choice named by `node`.
  static int read_choice(const Key& key, const YAML::Node& node, const std::string& path) {
    if (!node.IsScalar()) {
      fail("type", path,
           "expected a string (one of {" + choice_list(key) + "}), got " + describe(node));
    }
    for (std::size_t i = 0; i < key.choices.size(); ++i) {
      if (key.choices[i] == node.Scalar()) return static_cast<int>(i);
    }
    fail("value", path, "must be one of {" + choice_list(key) + "}, got '" + node.Scalar() + "'");
  }

  Config& config_;
  std::string base_dir_;
  SensorEntry* sensor_ = nullptr;  ///< the sensor being read, for the `sensors[].` keys
  std::set<std::string> present_;
};

/// ROS 2's convention: the domain comes from ROS_DOMAIN_ID when the config names none.
void domain_from_environment(std::uint32_t& domain_id) {
  const char* env = std::getenv("ROS_DOMAIN_ID");
  if (env == nullptr || *env == '\0') return;
  char* end = nullptr;
  errno = 0;
  const long value = std::strtol(env, &end, 10);
  const Key& key = schema_key("dds.domain_id");
  if (errno != 0 || *end != '\0' || value < key.min || value > key.max) {
    fail("value", key.path,
         std::string("not set in the file, and ROS_DOMAIN_ID='") + env +
             "' in the environment is not a domain " + std::to_string(std::lround(key.min)) + ".." +
             std::to_string(std::lround(key.max)));
  }
  domain_id = static_cast<std::uint32_t>(value);
}

core::Status validate_daemon(const Config& c) {
  const auto err = [](const std::string& path, const std::string& why) {
    return core::Error{"config.value", path + ": " + why};
  };
  if (c.pose.topic.empty()) return err("pose.topic", "must not be empty");
  if (c.mapping.corrections.enabled && c.pose.correction_topic.empty()) {
    return err("pose.correction_topic", "must not be empty when corrections.enabled is true");
  }
  for (const auto& s : c.sensors) {
    if (s.topic == c.pose.topic) return err("pose.topic", "same topic as sensor " + s.id);
  }
  if (c.outputs.frame_id.empty()) return err("outputs.frame_id", "must not be empty");
  if (c.fleet.enabled) {
    const std::string& id = c.fleet.vehicle_id;
    const bool id_ok =
        !id.empty() && id.size() <= 64 && std::all_of(id.begin(), id.end(), [](char ch) {
          return std::isalnum(static_cast<unsigned char>(ch)) != 0 || ch == '_' || ch == '-';
        });
    if (!id_ok) {
      return err("fleet.vehicle_id", "must be 1..64 of [A-Za-z0-9_-] when fleet.enabled is true");
    }
    if (c.fleet.topic.empty()) return err("fleet.topic", "must not be empty");
    // A peer's cells would expire before its next summary: the costmap would flicker.
    if (c.fleet.max_age_s < c.fleet.publish_period_s) {
      return err("fleet.max_age_s", "must be at least fleet.publish_period_s");
    }
  }
  for (const auto& [key, topic] :
       {std::pair{"outputs.costmap_topic", &c.outputs.costmap_topic},
        std::pair{"outputs.esdf_slice_topic", &c.outputs.esdf_slice_topic},
        std::pair{"outputs.cycle_report_topic", &c.outputs.cycle_report_topic},
        std::pair{"outputs.diagnostic_array_topic", &c.outputs.diagnostic_array_topic},
        std::pair{"outputs.virtual_obstacles_topic", &c.outputs.virtual_obstacles_topic}}) {
    if (topic->empty()) return err(key, "must not be empty");
  }
  if (c.outputs.obstacle_grid_topic == c.outputs.costmap_topic) {
    return err("outputs.obstacle_grid_topic", "must differ from outputs.costmap_topic");
  }
  if (!c.outputs.esdf_slice_grid_topic.empty() &&
      (c.outputs.esdf_slice_grid_topic == c.outputs.costmap_topic ||
       c.outputs.esdf_slice_grid_topic == c.outputs.obstacle_grid_topic)) {
    return err("outputs.esdf_slice_grid_topic", "must differ from the other grid topics");
  }
  if (c.mapping.esdf_band.enabled && c.outputs.esdf_band_topic.empty()) {
    return err("outputs.esdf_band_topic", "must not be empty when esdf_band.enabled is true");
  }
  if (c.budgets.cycle_ms > 1000.0 / c.executor.rate_hz) {
    return err("budgets.cycle_ms", "exceeds the period of executor.rate_hz (" +
                                       std::to_string(1000.0 / c.executor.rate_hz) + " ms)");
  }
  if (c.executor.sensor_phase_ms >= 1000.0 / c.executor.rate_hz) {
    return err("executor.sensor_phase_ms", "must be below the period of executor.rate_hz");
  }
  if (c.quotas.points_per_scan > c.quotas.points_per_cycle) {
    return err("quotas.points_per_scan", "must be <= quotas.points_per_cycle");
  }
  if (c.state.save_on_exit && c.state.map_file.empty()) {
    return err("state.map_file", "must not be empty when state.save_on_exit is true");
  }
  if (c.mapping.tsdf.enabled && c.state.tsdf_file.empty() &&
      (c.state.save_on_exit || c.state.load_on_start || c.state.save_period_s > 0.0)) {
    return err("state.tsdf_file", "must not be empty when the TSDF is saved or loaded");
  }
  if (c.state.save_period_s > 0.0 && c.state.save_period_s * c.executor.rate_hz < 1.0) {
    return err("state.save_period_s", "shorter than one executor period");
  }
  return core::Ok{};
}

/// One leaf's value, as its field's type writes it (a float with float precision).
void emit_value(YAML::Emitter& out, const Key& key, const Field& field) {
  std::visit(
      [&](auto value) {
        using T = std::remove_pointer_t<decltype(value)>;
        if constexpr (std::is_same_v<T, std::vector<std::string>> ||
                      std::is_same_v<T, std::vector<int>>) {
          out << YAML::Flow << *value;
        } else if constexpr (std::is_same_v<decltype(value), ChoiceField>) {
          out << std::string(key.choices[value.get(value.field)]);
        } else {
          out << *value;
        }
      },
      field);
}

/// Writes `keys` (all in the map `prefix`, schema form) as entries of the map open in `out`.
void emit_map(YAML::Emitter& out, const std::string& prefix, std::span<const Key> keys,
              Config& config, SensorEntry* sensor) {
  for (std::size_t i = 0; i < keys.size();) {
    const std::string rest = keys[i].path.substr(prefix.size());
    const std::string name = rest.substr(0, rest.find('.'));
    std::size_t end = i + 1;
    while (end < keys.size() &&
           keys[end].path.compare(prefix.size(), name.size() + 1, name + ".") == 0) {
      ++end;
    }
    const auto group = keys.subspan(i, end - i);
    i = end;
    if (std::none_of(group.begin(), group.end(), [](const Key& k) { return k.written; })) continue;
    if (name.ends_with("[]")) {  // sensors
      out << YAML::Key << name.substr(0, name.size() - 2) << YAML::Value << YAML::BeginSeq;
      for (const auto& s : config.sensors) {
        SensorEntry entry = sensor_entry(s);
        out << YAML::BeginMap;
        emit_map(out, prefix + name + ".", group, config, &entry);
        out << YAML::EndMap;
      }
      out << YAML::EndSeq;
    } else if (rest == name) {
      out << YAML::Key << name << YAML::Value;
      emit_value(out, group.front(), field_of(group.front(), config, sensor));
    } else {
      out << YAML::Key << name << YAML::Value;
      if (is_flow_map(prefix + name)) out << YAML::Flow;
      out << YAML::BeginMap;
      emit_map(out, prefix + name + ".", group, config, sensor);
      out << YAML::EndMap;
    }
  }
}

core::Result<Config> load_config(const std::string& yaml_text, const std::string& base_dir) {
  Config config;
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root || root.IsNull()) return core::Error{"config.empty", "<root>: the file is empty"};
    std::size_t nodes = 0;
    check_structure(root, "", 0, nodes);
    if (!root.IsMap()) fail("type", "<root>", "expected a map, got " + describe(root));
    // The version first: a file of another version is reported as such, not by its keys.
    const Key& version = schema_key("version");
    if (root["version"] && root["version"].IsNull()) fail("type", version.path, "has no value");
    const int given = root["version"] ? parse_integer<int>(root["version"], version.path,
                                                           std::numeric_limits<int>::min(),
                                                           std::numeric_limits<int>::max())
                                      : 0;
    if (given < version.min || given > version.max) {
      return core::Error{"config.version",
                         "version: this build reads version " + std::to_string(kConfigVersion) +
                             ", the file says " +
                             (root["version"] ? root["version"].as<std::string>() : "nothing")};
    }
    SchemaReader reader(config, base_dir);
    reader.read_map(root, "", "", schema());
    if (!reader.present("dds.domain_id")) {
      domain_from_environment(config.dds.participant.domain_id);
    }
  } catch (const ConfigError& e) {
    return core::Error{"config." + e.reason, e.message};
  } catch (const YAML::Exception& e) {
    return core::Error{"config.syntax", std::string("<yaml>: ") + e.what()};
  }
  if (auto valid = config.dds.participant.validate(); !valid) return valid.error();
  if (auto valid = config.mapping.validate(); !valid) return valid.error();
  if (auto valid = validate_daemon(config); !valid) return valid.error();
  return config;
}

}  // namespace

core::Result<Config> load_config_string(const std::string& yaml_text) {
  return load_config(yaml_text, "");
}

core::Result<Config> load_config_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return core::Error{"config.io", path + ": cannot be read"};
  std::ostringstream text;
  text << in.rdbuf();
  std::string base_dir = std::filesystem::path(path).parent_path().string();
  if (base_dir.empty()) base_dir = ".";
  auto result = load_config(text.str(), base_dir);
  if (!result) return core::Error{result.error().code, path + ": " + result.error().message};
  return result;
}

std::string to_yaml(const Config& config) {
  Config copy = config;  // the schema's fields are reached through a mutable Config
  YAML::Emitter out;
  out << YAML::BeginMap;
  emit_map(out, "", schema(), copy, nullptr);
  out << YAML::EndMap;
  return out.c_str();
}

std::string config_hash(const Config& config) {
  std::uint64_t h = 1469598103934665603ull;
  for (const char c : to_yaml(config)) {
    h ^= static_cast<unsigned char>(c);
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

int load_tool_config(const std::string& program, const std::string& path, Config& cfg) {
  if (path.empty()) return 0;
  auto loaded = load_config_file(path);
  if (!loaded) {
    std::fprintf(stderr, "%s: invalid config: %s\n", program.c_str(),
                 loaded.error().message.c_str());
    return 78;
  }
  cfg = std::move(loaded).value();
  return 0;
}

}  // namespace tarmac::config
