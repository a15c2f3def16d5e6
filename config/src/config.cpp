#include "tarmac/config/config.hpp"

#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include <yaml-cpp/yaml.h>

namespace tarmac::config {

namespace {

/// Signals a config error from deep inside the walk; caught once in load_config_string and
/// turned into a Result there (exceptions never leave this file).
struct ConfigError {
  std::string reason;
  std::string message;
};

[[noreturn]] void fail(const std::string& reason, const std::string& path, const std::string& why) {
  throw ConfigError{reason, path + ": " + why};
}

/// Reads the keys of one YAML map and, at the end, rejects any key nobody asked for.
class MapReader {
 public:
  MapReader(const YAML::Node& node, std::string path) : node_(node), path_(std::move(path)) {
    if (node_ && !node_.IsNull() && !node_.IsMap()) fail("type", path_or_root(), "must be a map");
  }

  template <typename T>
  void scalar(const std::string& key, T& value, T min, T max) {
    const YAML::Node child = take(key);
    if (!child) return;
    T parsed{};
    if (!child.IsScalar() || !YAML::convert<T>::decode(child, parsed)) {
      fail("type", join(key), "expected a number, got '" + dump(child) + "'");
    }
    if (parsed < min || parsed > max) {
      std::ostringstream os;
      os << "must be in [" << min << ", " << max << "], got " << parsed;
      fail("range", join(key), os.str());
    }
    value = parsed;
  }

  void string(const std::string& key, std::string& value) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsScalar()) fail("type", join(key), "expected a string");
    value = child.as<std::string>();
  }

  /// A string that must be one of `choices`; returns the index chosen, or -1 if absent.
  int choice(const std::string& key, const std::vector<std::string>& choices) {
    const YAML::Node child = take(key);
    if (!child) return -1;
    const std::string text = child.IsScalar() ? child.as<std::string>() : dump(child);
    for (std::size_t i = 0; i < choices.size(); ++i) {
      if (choices[i] == text) return static_cast<int>(i);
    }
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
    fail("value", join(key), "must be one of {" + list + "}, got '" + text + "'");
  }

  void string_list(const std::string& key, std::vector<std::string>& value) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsSequence()) fail("type", join(key), "expected a list of strings");
    value.clear();
    for (const auto& item : child) {
      if (!item.IsScalar()) fail("type", join(key), "expected a list of strings");
      value.push_back(item.as<std::string>());
    }
  }

  /// A nested map, read by `read(MapReader&)`.
  template <typename Fn>
  void map(const std::string& key, Fn read) {
    const YAML::Node child = take(key);
    if (!child) return;
    MapReader nested(child, join(key));
    read(nested);
    nested.finish();
  }

  /// Rejects keys that were never asked for.
  void finish() const {
    if (!node_ || !node_.IsMap()) return;
    for (const auto& kv : node_) {
      const auto key = kv.first.as<std::string>();
      if (seen_.count(key) == 0) fail("unknown_key", join(key), "unknown key");
    }
  }

 private:
  YAML::Node take(const std::string& key) {
    seen_.insert(key);
    if (!node_ || !node_.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    YAML::Node child = node_[key];
    if (child && child.IsNull()) fail("type", join(key), "has no value");
    return child;
  }
  [[nodiscard]] std::string join(const std::string& key) const {
    return path_.empty() ? key : path_ + "." + key;
  }
  [[nodiscard]] std::string path_or_root() const { return path_.empty() ? "<root>" : path_; }
  static std::string dump(const YAML::Node& node) {
    YAML::Emitter out;
    out << YAML::Flow << node;
    return out.c_str();
  }

  YAML::Node node_;
  std::string path_;
  std::set<std::string> seen_;
};

const std::vector<std::string> kTransports = {"localhost", "shm", "network"};
const std::vector<std::string> kReliability = {"best_effort", "reliable"};
const std::vector<std::string> kDurability = {"volatile", "transient_local"};

void read_qos(MapReader& r, transport::QosSpec& qos) {
  if (const int i = r.choice("reliability", kReliability); i >= 0) {
    qos.reliability = static_cast<transport::Reliability>(i);
  }
  if (const int i = r.choice("durability", kDurability); i >= 0) {
    qos.durability = static_cast<transport::Durability>(i);
  }
  r.scalar<std::uint32_t>("depth", qos.history_depth, 1, 10000);
}

void read_dds(MapReader& r, DdsConfig& dds) {
  auto& p = dds.participant;
  r.scalar<std::uint32_t>("domain_id", p.domain_id, 0, 232);
  r.string("participant_name", p.name);
  if (const int i = r.choice("transport", kTransports); i >= 0) {
    p.transport = static_cast<transport::TransportMode>(i);
  }
  r.string_list("network_interfaces", p.network_interfaces);
  r.string_list("initial_peers", p.initial_peers);
  r.scalar<std::uint32_t>("shm_segment_bytes", p.shm_segment_bytes, 1u << 16, 1u << 30);
  r.scalar<std::uint32_t>("shm_max_message_bytes", p.shm_max_message_bytes, 1u << 16, 1u << 30);
  r.map("qos", [&](MapReader& q) {
    q.map("lidar", [&](MapReader& m) { read_qos(m, dds.qos.lidar); });
    q.map("pose", [&](MapReader& m) { read_qos(m, dds.qos.pose); });
    q.map("virtual_obstacles", [&](MapReader& m) { read_qos(m, dds.qos.virtual_obstacles); });
    q.map("costmap", [&](MapReader& m) { read_qos(m, dds.qos.costmap); });
    q.map("esdf_slice", [&](MapReader& m) { read_qos(m, dds.qos.esdf_slice); });
    q.map("diagnostics", [&](MapReader& m) { read_qos(m, dds.qos.diagnostics); });
  });
}

const std::vector<std::string> kUnknownCost = {"unknown", "lethal", "free"};

void read_vector3(MapReader& r, const std::string& key, Eigen::Vector3d& v) {
  r.map(key, [&](MapReader& m) {
    m.scalar<double>("x", v.x(), -1e3, 1e3);
    m.scalar<double>("y", v.y(), -1e3, 1e3);
    m.scalar<double>("z", v.z(), -1e3, 1e3);
  });
}

void read_mapping(MapReader& root, core::MapperParams& p) {
  root.map("filters", [&](MapReader& r) {
    r.scalar<double>("min_range_m", p.filters.min_range_m, 0.0, 100.0);
    r.scalar<bool>("ego_box_enabled", p.filters.ego_box_enabled, false, true);
    read_vector3(r, "ego_box_min_m", p.filters.ego_box_min_B);
    read_vector3(r, "ego_box_max_m", p.filters.ego_box_max_B);
    r.scalar<int>("outlier_min_neighbors", p.filters.outlier_min_neighbors, 0, 26);
    r.scalar<double>("outlier_cell_m", p.filters.outlier_cell_m, 0.05, 5.0);
    r.scalar<double>("outlier_max_range_m", p.filters.outlier_max_range_m, 0.0, 1000.0);
  });
  root.map("occupancy", [&](MapReader& r) {
    auto& o = p.occupancy;
    r.scalar<double>("voxel_size_m", o.voxel_size_m, 0.02, 2.0);
    r.scalar<int>("window_x_vox", o.window_x_vox, 4, 4096);
    r.scalar<int>("window_y_vox", o.window_y_vox, 4, 4096);
    r.scalar<int>("window_z_vox", o.window_z_vox, 4, 4096);
    r.scalar<double>("window_below_m", o.window_below_m, 0.0, 100.0);
    r.scalar<float>("prob_hit", o.prob_hit, 0.5001f, 0.9999f);
    r.scalar<float>("prob_miss", o.prob_miss, 0.0001f, 0.4999f);
    r.scalar<float>("clamp_min", o.clamp_min, 0.0001f, 0.4999f);
    r.scalar<float>("clamp_max", o.clamp_max, 0.5001f, 0.9999f);
    r.scalar<double>("max_range_m", o.max_range_m, 0.1, 1000.0);
    r.scalar<double>("clearing_range_m", o.clearing_range_m, 0.0, 1000.0);
    r.scalar<double>("ground_radius_m", o.ground_radius_m, 0.0, 10.0);
  });
  root.map("costmap", [&](MapReader& r) {
    auto& c = p.costmap;
    r.scalar<double>("min_obstacle_height_m", c.min_obstacle_height_m, 0.0, 10.0);
    r.scalar<double>("vehicle_height_m", c.vehicle_height_m, 0.1, 20.0);
    r.scalar<double>("clearance_m", c.clearance_m, 0.0, 10.0);
    r.scalar<double>("inscribed_radius_m", c.inscribed_radius_m, 0.0, 20.0);
    r.scalar<double>("inflation_radius_m", c.inflation_radius_m, 0.0, 50.0);
    r.scalar<double>("cost_scaling_factor", c.cost_scaling_factor, 0.01, 100.0);
    r.scalar<double>("ground_cell_m", c.ground_cell_m, 0.05, 20.0);
    r.scalar<double>("max_ground_step_m", c.max_ground_step_m, 0.01, 10.0);
    r.scalar<double>("max_ground_slope", c.max_ground_slope, 0.0, 1.0);
    r.scalar<double>("ground_tolerance_m", c.ground_tolerance_m, 0.0, 10.0);
    if (const int i = r.choice("unknown_cost", kUnknownCost); i >= 0) {
      c.unknown_cost = static_cast<core::UnknownCost>(i);
    }
  });
  root.map("tsdf", [&](MapReader& r) {
    auto& t = p.tsdf;
    r.scalar<bool>("enabled", t.enabled, false, true);
    r.scalar<float>("voxel_size_m", t.voxel_size_m, 0.01f, 2.0f);
    r.scalar<float>("truncation_m", t.truncation_m, 0.01f, 64.0f);
    r.scalar<float>("max_weight", t.max_weight, 1.0f, 1e6f);
    r.scalar<float>("max_range_m", t.max_range_m, 0.1f, 1000.0f);
    r.scalar<bool>("space_carving", t.space_carving, false, true);
  });
}

void emit_qos(YAML::Emitter& out, const char* name, const transport::QosSpec& q) {
  out << YAML::Key << name << YAML::Value << YAML::Flow << YAML::BeginMap;
  out << YAML::Key << "reliability" << YAML::Value << kReliability[static_cast<int>(q.reliability)];
  out << YAML::Key << "durability" << YAML::Value << kDurability[static_cast<int>(q.durability)];
  out << YAML::Key << "depth" << YAML::Value << q.history_depth;
  out << YAML::EndMap;
}

}  // namespace

core::Result<Config> load_config_string(const std::string& yaml_text) {
  Config config;
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root || root.IsNull()) return core::Error{"config.empty", "<root>: the file is empty"};
    MapReader r(root, "");
    int version = 0;
    r.scalar<int>("version", version, std::numeric_limits<int>::min(),
                  std::numeric_limits<int>::max());
    if (version != kConfigVersion) {
      return core::Error{"config.version",
                         "version: this build reads version " + std::to_string(kConfigVersion) +
                             ", the file says " +
                             (root["version"] ? root["version"].as<std::string>() : "nothing")};
    }
    r.map("dds", [&](MapReader& m) { read_dds(m, config.dds); });
    read_mapping(r, config.mapping);
    r.finish();
  } catch (const ConfigError& e) {
    return core::Error{"config." + e.reason, e.message};
  } catch (const YAML::Exception& e) {
    return core::Error{"config.syntax", std::string("<yaml>: ") + e.what()};
  }
  if (auto valid = config.dds.participant.validate(); !valid) return valid.error();
  if (auto valid = config.mapping.validate(); !valid) return valid.error();
  return config;
}

core::Result<Config> load_config_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) return core::Error{"config.io", path + ": cannot be read"};
  std::ostringstream text;
  text << in.rdbuf();
  auto result = load_config_string(text.str());
  if (!result) return core::Error{result.error().code, path + ": " + result.error().message};
  return result;
}

std::string to_yaml(const Config& config) {
  const auto& p = config.dds.participant;
  YAML::Emitter out;
  out << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << config.version;
  out << YAML::Key << "dds" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "domain_id" << YAML::Value << p.domain_id;
  out << YAML::Key << "participant_name" << YAML::Value << p.name;
  out << YAML::Key << "transport" << YAML::Value << transport::to_string(p.transport);
  out << YAML::Key << "network_interfaces" << YAML::Value << YAML::Flow << p.network_interfaces;
  out << YAML::Key << "initial_peers" << YAML::Value << YAML::Flow << p.initial_peers;
  out << YAML::Key << "shm_segment_bytes" << YAML::Value << p.shm_segment_bytes;
  out << YAML::Key << "shm_max_message_bytes" << YAML::Value << p.shm_max_message_bytes;
  out << YAML::Key << "qos" << YAML::Value << YAML::BeginMap;
  emit_qos(out, "lidar", config.dds.qos.lidar);
  emit_qos(out, "pose", config.dds.qos.pose);
  emit_qos(out, "virtual_obstacles", config.dds.qos.virtual_obstacles);
  emit_qos(out, "costmap", config.dds.qos.costmap);
  emit_qos(out, "esdf_slice", config.dds.qos.esdf_slice);
  emit_qos(out, "diagnostics", config.dds.qos.diagnostics);
  out << YAML::EndMap << YAML::EndMap;
  const auto& m = config.mapping;
  const auto vec = [&](const char* key, const Eigen::Vector3d& v) {
    out << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key << "x"
        << YAML::Value << v.x() << YAML::Key << "y" << YAML::Value << v.y() << YAML::Key << "z"
        << YAML::Value << v.z() << YAML::EndMap;
  };
  out << YAML::Key << "filters" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "min_range_m" << YAML::Value << m.filters.min_range_m;
  out << YAML::Key << "ego_box_enabled" << YAML::Value << m.filters.ego_box_enabled;
  vec("ego_box_min_m", m.filters.ego_box_min_B);
  vec("ego_box_max_m", m.filters.ego_box_max_B);
  out << YAML::Key << "outlier_min_neighbors" << YAML::Value << m.filters.outlier_min_neighbors;
  out << YAML::Key << "outlier_cell_m" << YAML::Value << m.filters.outlier_cell_m;
  out << YAML::Key << "outlier_max_range_m" << YAML::Value << m.filters.outlier_max_range_m;
  out << YAML::EndMap;
  const auto& o = m.occupancy;
  out << YAML::Key << "occupancy" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "voxel_size_m" << YAML::Value << o.voxel_size_m;
  out << YAML::Key << "window_x_vox" << YAML::Value << o.window_x_vox;
  out << YAML::Key << "window_y_vox" << YAML::Value << o.window_y_vox;
  out << YAML::Key << "window_z_vox" << YAML::Value << o.window_z_vox;
  out << YAML::Key << "window_below_m" << YAML::Value << o.window_below_m;
  out << YAML::Key << "prob_hit" << YAML::Value << o.prob_hit;
  out << YAML::Key << "prob_miss" << YAML::Value << o.prob_miss;
  out << YAML::Key << "clamp_min" << YAML::Value << o.clamp_min;
  out << YAML::Key << "clamp_max" << YAML::Value << o.clamp_max;
  out << YAML::Key << "max_range_m" << YAML::Value << o.max_range_m;
  out << YAML::Key << "clearing_range_m" << YAML::Value << o.clearing_range_m;
  out << YAML::Key << "ground_radius_m" << YAML::Value << o.ground_radius_m;
  out << YAML::EndMap;
  const auto& c = m.costmap;
  out << YAML::Key << "costmap" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "min_obstacle_height_m" << YAML::Value << c.min_obstacle_height_m;
  out << YAML::Key << "vehicle_height_m" << YAML::Value << c.vehicle_height_m;
  out << YAML::Key << "clearance_m" << YAML::Value << c.clearance_m;
  out << YAML::Key << "inscribed_radius_m" << YAML::Value << c.inscribed_radius_m;
  out << YAML::Key << "inflation_radius_m" << YAML::Value << c.inflation_radius_m;
  out << YAML::Key << "cost_scaling_factor" << YAML::Value << c.cost_scaling_factor;
  out << YAML::Key << "ground_cell_m" << YAML::Value << c.ground_cell_m;
  out << YAML::Key << "max_ground_step_m" << YAML::Value << c.max_ground_step_m;
  out << YAML::Key << "max_ground_slope" << YAML::Value << c.max_ground_slope;
  out << YAML::Key << "ground_tolerance_m" << YAML::Value << c.ground_tolerance_m;
  out << YAML::Key << "unknown_cost" << YAML::Value
      << kUnknownCost[static_cast<int>(c.unknown_cost)];
  out << YAML::EndMap;
  const auto& t = m.tsdf;
  out << YAML::Key << "tsdf" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << t.enabled;
  out << YAML::Key << "voxel_size_m" << YAML::Value << t.voxel_size_m;
  out << YAML::Key << "truncation_m" << YAML::Value << t.truncation_m;
  out << YAML::Key << "max_weight" << YAML::Value << t.max_weight;
  out << YAML::Key << "max_range_m" << YAML::Value << t.max_range_m;
  out << YAML::Key << "space_carving" << YAML::Value << t.space_carving;
  out << YAML::EndMap << YAML::EndMap;
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

}  // namespace tarmac::config
