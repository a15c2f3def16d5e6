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
    r.finish();
  } catch (const ConfigError& e) {
    return core::Error{"config." + e.reason, e.message};
  } catch (const YAML::Exception& e) {
    return core::Error{"config.syntax", std::string("<yaml>: ") + e.what()};
  }
  if (auto valid = config.dds.participant.validate(); !valid) return valid.error();
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
  out << YAML::EndMap << YAML::EndMap << YAML::EndMap;
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
