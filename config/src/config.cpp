#include "tarmac/config/config.hpp"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <type_traits>
#include <utility>
#include <vector>

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

/// Why a DDS topic name is not the wire form of a ROS 2 topic (`rt/` + a fully qualified ROS
/// name: tokens of [A-Za-z0-9_] not starting with a digit, separated by single '/'), or "".
std::string ros_topic_problem(const std::string& name) {
  if (name.rfind("rt/", 0) != 0) return "is not a ROS 2 topic: ROS 2 nodes could not see it";
  const std::string ros = name.substr(2);  // "/ns/name"
  if (ros.size() < 2) return "has no name after the namespace";
  if (ros.back() == '/') return "ends with '/'";
  bool token_start = false;
  for (const char c : ros) {
    if (c == '/') {
      if (token_start) return "has an empty token ('//')";
      token_start = true;
      continue;
    }
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    if (!alnum && c != '_') return std::string("has a character ROS 2 names refuse: '") + c + "'";
    if (token_start && c >= '0' && c <= '9') return "has a token starting with a digit";
    token_start = false;
  }
  return {};
}

/// `key` appended to `path` ("executor" + "rate_hz" -> "executor.rate_hz").
std::string join_path(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

std::string path_or_root(const std::string& path) {
  return path.empty() ? "<root>" : path;
}

/// The YAML line and column of a node, 1-based, for messages.
std::string where(const YAML::Mark& mark, bool with_column) {
  std::string s = "line " + std::to_string(mark.line + 1);
  if (with_column) s += " column " + std::to_string(mark.column + 1);
  return s;
}

bool decodes_as_number(const YAML::Node& node) {
  double d = 0.0;
  return YAML::convert<double>::decode(node, d);
}

/// What a node holds, for type errors: "a map", "a list", "a bool 'yes'", "a number '2.5'",
/// "a string 'abc'" (a quoted scalar is always a string).
std::string describe(const YAML::Node& node) {
  if (node.IsMap()) return "a map";
  if (node.IsSequence()) return "a list";
  if (!node.IsScalar()) return "nothing";
  const std::string quoted = "'" + node.Scalar() + "'";
  if (node.Tag() == "!") return "a string " + quoted;
  bool b = false;
  if (YAML::convert<bool>::decode(node, b)) return "a bool " + quoted;
  if (decodes_as_number(node)) return "a number " + quoted;
  return "a string " + quoted;
}

/// A YAML nesting deeper than this, or with more nodes than that, is refused: no config comes
/// near either, and aliases can make a node contain itself (`a: &x [*x]`) or expand
/// exponentially (each level a list of two aliases of the one before), which a walk would
/// follow forever.
constexpr int kMaxDepth = 32;
constexpr std::size_t kMaxNodes = 100000;

/// Refuses what yaml-cpp accepts silently, at every depth (maps inside lists included): a key
/// given twice in one map (yaml-cpp would keep the first and drop the other), a key that is
/// not a plain scalar, and nesting beyond kMaxDepth or kMaxNodes. `nodes` counts the visits.
void check_structure(const YAML::Node& node, const std::string& path, int depth,
                     std::size_t& nodes) {
  if (depth > kMaxDepth || ++nodes > kMaxNodes) {
    fail("structure", path_or_root(path),
         depth > kMaxDepth
             ? "nested deeper than " + std::to_string(kMaxDepth) +
                   " levels (an alias that contains itself?)"
             : "more than " + std::to_string(kMaxNodes) + " nodes (aliases that expand?)");
  }
  if (node.IsMap()) {
    std::vector<std::pair<std::string, YAML::Mark>> seen;
    for (const auto& kv : node) {
      if (!kv.first.IsScalar()) {
        fail("type", path_or_root(path),
             "keys must be strings, got " + describe(kv.first) + " at " +
                 where(kv.first.Mark(), true));
      }
      const std::string& key = kv.first.Scalar();
      const std::string key_path = join_path(path, key);
      for (const auto& [other, mark] : seen) {
        if (other != key) continue;
        const YAML::Mark again = kv.first.Mark();
        const bool same_line = mark.line == again.line;
        fail("duplicate_key", key_path,
             "duplicate key (" + where(mark, same_line) + " and " + where(again, same_line) + ")");
      }
      seen.emplace_back(key, kv.first.Mark());
      check_structure(kv.second, key_path, depth + 1, nodes);
    }
  } else if (node.IsSequence()) {
    std::size_t i = 0;
    for (const auto& item : node) {
      check_structure(item, path + "[" + std::to_string(i++) + "]", depth + 1, nodes);
    }
  }
}

/// A YAML bool (true/false, yes/no, on/off).
bool parse_bool(const YAML::Node& node, const std::string& path) {
  bool value = false;
  if (!node.IsScalar() || !YAML::convert<bool>::decode(node, value)) {
    fail("type", path, "expected a bool (true or false), got " + describe(node));
  }
  return value;
}

template <typename T>
[[noreturn]] void fail_range(const std::string& path, T min, T max, const std::string& got) {
  std::ostringstream os;
  os << "must be in [" << min << ", " << max << "], got " << got;
  fail("range", path, os.str());
}

/// A decimal integer within [min, max]. "2.5", "1e3", "0x10" are type errors (an integer key
/// takes an integer written as one); `.nan` and `.inf` are refused as not finite, as for reals.
template <typename T>
T parse_integer(const YAML::Node& node, const std::string& path, T min, T max) {
  static_assert(std::is_integral_v<T> && !std::is_same_v<T, bool>);
  if (!node.IsScalar()) fail("type", path, "expected an integer, got " + describe(node));
  const std::string& text = node.Scalar();
  const char* first = text.data();
  const char* last = text.data() + text.size();
  if (first != last && *first == '+') ++first;
  long long parsed = 0;
  const auto [end, ec] = std::from_chars(first, last, parsed, 10);
  if (ec == std::errc::result_out_of_range) fail_range(path, min, max, text);
  if (ec != std::errc() || end != last || first == last) {
    double real = 0.0;
    if (YAML::convert<double>::decode(node, real) && !std::isfinite(real)) {
      fail("not_finite", path, "must be a finite number, got " + text);
    }
    fail("type", path, "expected an integer, got " + describe(node));
  }
  if (std::cmp_less(parsed, min) || std::cmp_greater(parsed, max)) {
    fail_range(path, min, max, std::to_string(parsed));
  }
  return static_cast<T>(parsed);
}

/// A finite real number within [min, max] (compared in T, so a float key's bounds mean what
/// they say in float). `.nan`, `.inf`, `-.inf` and numbers beyond the range of a double (1e400)
/// are refused as not finite.
template <typename T>
T parse_real(const YAML::Node& node, const std::string& path, T min, T max) {
  static_assert(std::is_floating_point_v<T>);
  if (!node.IsScalar()) fail("type", path, "expected a number, got " + describe(node));
  const std::string& text = node.Scalar();
  double parsed = 0.0;
  if (!YAML::convert<double>::decode(node, parsed)) {
    // yaml-cpp refuses a number that overflows a double; say why instead of "not a number".
    errno = 0;
    char* end = nullptr;
    const double huge = std::strtod(text.c_str(), &end);
    if (!text.empty() && end == text.c_str() + text.size() && errno == ERANGE && std::isinf(huge)) {
      fail("not_finite", path, "must be a finite number, got " + text);
    }
    fail("type", path, "expected a number, got " + describe(node));
  }
  if (!std::isfinite(parsed)) fail("not_finite", path, "must be a finite number, got " + text);
  if (std::abs(parsed) > static_cast<double>(std::numeric_limits<T>::max())) {
    fail_range(path, min, max, text);
  }
  const auto value = static_cast<T>(parsed);
  if (value < min || value > max) {
    std::ostringstream got;
    got << value;
    fail_range(path, min, max, got.str());
  }
  return value;
}

/// One scalar of type T: bool, an integer type or a floating-point type.
template <typename T>
T parse_scalar(const YAML::Node& node, const std::string& path, T min, T max) {
  if constexpr (std::is_same_v<T, bool>) {
    (void)min;
    (void)max;
    return parse_bool(node, path);
  } else if constexpr (std::is_integral_v<T>) {
    return parse_integer(node, path, min, max);
  } else {
    return parse_real(node, path, min, max);
  }
}

/// Reads the keys of one YAML map and, at the end, rejects any key nobody asked for.
/// check_structure() has run on the whole document first: no duplicate or non-scalar keys.
class MapReader {
 public:
  MapReader(const YAML::Node& node, std::string path) : node_(node), path_(std::move(path)) {
    if (node_ && !node_.IsNull() && !node_.IsMap()) {
      fail("type", path_or_root(path_), "expected a map, got " + describe(node_));
    }
  }

  /// A number (finite, in [min, max]), an integer (in [min, max]) or a bool, by T.
  template <typename T>
  void scalar(const std::string& key, T& value, T min, T max) {
    const YAML::Node child = take(key);
    if (!child) return;
    value = parse_scalar<T>(child, join(key), min, max);
  }

  void string(const std::string& key, std::string& value) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsScalar()) fail("type", join(key), "expected a string, got " + describe(child));
    value = child.Scalar();
  }

  /// A DDS topic name that ROS 2 nodes can see: its wire form `rt/ns/name` as is, a ROS 2 name
  /// `/ns/name` mapped to `rt/ns/name`; anything else is refused (ROS could not see it). Empty
  /// stays empty (an output switched off, where the key allows it).
  void topic(const std::string& key, std::string& value) {
    string(key, value);
    if (value.empty()) return;
    const std::string given = value;
    if (value.front() == '/') value = "rt" + value;
    const auto why = ros_topic_problem(value);
    if (!why.empty()) {
      fail("value", join(key),
           "'" + given + "' " + why + " (give a ROS 2 name such as /tarmac/costmap, or its DDS " +
               "form rt/tarmac/costmap)");
    }
  }

  /// A string that must be one of `choices`; returns the index chosen, or -1 if absent.
  int choice(const std::string& key, const std::vector<std::string>& choices) {
    const YAML::Node child = take(key);
    if (!child) return -1;
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
    if (!child.IsScalar()) {
      fail("type", join(key), "expected a string (one of {" + list + "}), got " + describe(child));
    }
    const std::string& text = child.Scalar();
    for (std::size_t i = 0; i < choices.size(); ++i) {
      if (choices[i] == text) return static_cast<int>(i);
    }
    fail("value", join(key), "must be one of {" + list + "}, got '" + text + "'");
  }

  void string_list(const std::string& key, std::vector<std::string>& value) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsSequence()) {
      fail("type", join(key), "expected a list of strings, got " + describe(child));
    }
    value.clear();
    for (std::size_t i = 0; i < child.size(); ++i) {
      if (!child[i].IsScalar()) {
        fail("type", item(key, i), "expected a string, got " + describe(child[i]));
      }
      value.push_back(child[i].Scalar());
    }
  }

  void int_list(const std::string& key, std::vector<int>& value, int min, int max) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsSequence()) {
      fail("type", join(key), "expected a list of integers, got " + describe(child));
    }
    value.clear();
    for (std::size_t i = 0; i < child.size(); ++i) {
      value.push_back(parse_integer<int>(child[i], item(key, i), min, max));
    }
  }

  /// True when `key` is present (and marks it as known).
  bool has(const std::string& key) {
    const YAML::Node child = take(key);
    return static_cast<bool>(child);
  }

  /// A list of maps, each read by `read(MapReader&, index)`; paths are `key[i].sub`.
  template <typename Fn>
  void map_list(const std::string& key, Fn read) {
    const YAML::Node child = take(key);
    if (!child) return;
    if (!child.IsSequence()) {
      fail("type", join(key), "expected a list of maps, got " + describe(child));
    }
    for (std::size_t i = 0; i < child.size(); ++i) {
      if (!child[i].IsMap())
        fail("type", item(key, i), "expected a map, got " + describe(child[i]));
      MapReader nested(child[i], item(key, i));
      read(nested, i);
      nested.finish();
    }
  }

  [[nodiscard]] const std::string& path() const { return path_; }

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
      const std::string& key = kv.first.Scalar();
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
  [[nodiscard]] std::string join(const std::string& key) const { return join_path(path_, key); }
  [[nodiscard]] std::string item(const std::string& key, std::size_t i) const {
    return join(key) + "[" + std::to_string(i) + "]";
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

/// `dds.security`. Relative paths are taken relative to `base_dir` (the config file's folder)
/// when one is given, so a config and its security material can move together.
void read_security(MapReader& r, transport::SecurityConfig& s, const std::string& base_dir) {
  r.scalar<bool>("enabled", s.enabled, false, true);
  const auto path = [&](const char* key, std::string& value) {
    r.string(key, value);
    if (!value.empty() && !base_dir.empty() && std::filesystem::path(value).is_relative()) {
      value = (std::filesystem::path(base_dir) / value).lexically_normal().string();
    }
  };
  path("identity_ca", s.identity_ca);
  path("identity_certificate", s.identity_certificate);
  path("private_key", s.private_key);
  path("permissions_ca", s.permissions_ca);
  path("governance", s.governance);
  path("permissions", s.permissions);
}

/// ROS 2's convention: the domain comes from ROS_DOMAIN_ID when the config names none.
void domain_from_environment(std::uint32_t& domain_id) {
  const char* env = std::getenv("ROS_DOMAIN_ID");
  if (env == nullptr || *env == '\0') return;
  char* end = nullptr;
  errno = 0;
  const long value = std::strtol(env, &end, 10);
  if (errno != 0 || *end != '\0' || value < 0 || value > 232) {
    fail("value", "dds.domain_id",
         std::string("not set in the file, and ROS_DOMAIN_ID='") + env +
             "' in the environment is not a domain 0..232");
  }
  domain_id = static_cast<std::uint32_t>(value);
}

void read_dds(MapReader& r, DdsConfig& dds, const std::string& base_dir) {
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
  r.scalar<std::uint32_t>("udp_receive_buffer_bytes", p.udp_receive_buffer_bytes, 1u << 16,
                          1u << 30);
  r.scalar<std::uint32_t>("udp_send_buffer_bytes", p.udp_send_buffer_bytes, 1u << 16, 1u << 30);
  r.map("security", [&](MapReader& m) { read_security(m, p.security, base_dir); });
  r.map("qos", [&](MapReader& q) {
    q.map("lidar", [&](MapReader& m) { read_qos(m, dds.qos.lidar); });
    q.map("pose", [&](MapReader& m) { read_qos(m, dds.qos.pose); });
    q.map("virtual_obstacles", [&](MapReader& m) { read_qos(m, dds.qos.virtual_obstacles); });
    q.map("costmap", [&](MapReader& m) { read_qos(m, dds.qos.costmap); });
    q.map("esdf_slice", [&](MapReader& m) { read_qos(m, dds.qos.esdf_slice); });
    q.map("esdf_band", [&](MapReader& m) { read_qos(m, dds.qos.esdf_band); });
    q.map("diagnostics", [&](MapReader& m) { read_qos(m, dds.qos.diagnostics); });
  });
}

const std::vector<std::string> kUnknownCost = {"unknown", "lethal", "free"};
const std::vector<std::string> kFreeRule = {"whole_envelope", "any_voxel"};
/// core::UnknownPolicy, in its order.
const std::vector<std::string> kUnknownPolicy = {"report", "occupied"};

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
    r.scalar<int>("static_promote_scans", o.static_promote_scans, 0, 127);
    r.scalar<int>("static_demote_scans", o.static_demote_scans, 1, 127);
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
    if (const int i = r.choice("free_rule", kFreeRule); i >= 0) {
      c.free_rule = static_cast<core::FreeRule>(i);
    }
  });
  root.map("esdf_band", [&](MapReader& r) {
    auto& e = p.esdf_band;
    r.scalar<bool>("enabled", e.enabled, false, true);
    r.scalar<double>("below_m", e.below_m, 0.0, 1000.0);
    r.scalar<double>("above_m", e.above_m, 0.001, 1000.0);
    if (const int i = r.choice("unknown", kUnknownPolicy); i >= 0) {
      e.unknown = static_cast<core::UnknownPolicy>(i);
    }
    r.scalar<double>("publish_radius_m", e.publish_radius_m, 0.0, 10000.0);
  });
  root.map("tsdf", [&](MapReader& r) {
    auto& t = p.tsdf;
    r.scalar<bool>("enabled", t.enabled, false, true);
    r.scalar<float>("voxel_size_m", t.voxel_size_m, 0.01f, 2.0f);
    r.scalar<float>("truncation_m", t.truncation_m, 0.01f, 64.0f);
    r.scalar<float>("max_weight", t.max_weight, 1.0f, 1e6f);
    r.scalar<float>("max_range_m", t.max_range_m, 0.1f, 1000.0f);
    r.scalar<bool>("space_carving", t.space_carving, false, true);
    r.scalar<std::uint32_t>("reserve_blocks", t.reserve_blocks, 0, 10'000'000);
  });
  root.map("corrections", [&](MapReader& r) {
    auto& k = p.corrections;
    r.scalar<bool>("enabled", k.enabled, false, true);
    r.scalar<int>("retain_scans", k.retain_scans, 1, 10000);
    r.scalar<double>("jump_threshold_m", k.jump_threshold_m, 0.01, 1000.0);
    r.scalar<double>("jump_threshold_deg", k.jump_threshold_deg, 0.01, 180.0);
    r.scalar<double>("max_prediction_gap_s", k.max_prediction_gap_s, 0.001, 60.0);
    r.scalar<std::uint64_t>("rebuild_points_per_cycle", k.rebuild_points_per_cycle, 0, 100'000'000);
  });
}

const std::vector<std::string> kPoseTypes = {"PoseWithCovarianceStamped", "Odometry"};

constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

void read_extrinsic(MapReader& r, Eigen::Isometry3d& T) {
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  read_vector3(r, "translation_m", t);
  const bool has_rpy = r.has("rpy_deg");
  const bool has_quat = r.has("quaternion");
  if (has_rpy && has_quat) {
    fail("value", r.path() + ".quaternion", "give either rpy_deg or quaternion, not both");
  }
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  if (has_rpy) {
    double roll = 0, pitch = 0, yaw = 0;
    r.map("rpy_deg", [&](MapReader& m) {
      m.scalar<double>("roll", roll, -180.0, 180.0);
      m.scalar<double>("pitch", pitch, -90.0, 90.0);
      m.scalar<double>("yaw", yaw, -180.0, 180.0);
    });
    // ROS convention: R = Rz(yaw) · Ry(pitch) · Rx(roll).
    R = (Eigen::AngleAxisd(yaw * kDegToRad, Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(pitch * kDegToRad, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(roll * kDegToRad, Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
  }
  if (has_quat) {
    Eigen::Quaterniond q(1, 0, 0, 0);
    r.map("quaternion", [&](MapReader& m) {
      m.scalar<double>("x", q.x(), -1.0, 1.0);
      m.scalar<double>("y", q.y(), -1.0, 1.0);
      m.scalar<double>("z", q.z(), -1.0, 1.0);
      m.scalar<double>("w", q.w(), -1.0, 1.0);
    });
    if (std::abs(q.norm() - 1.0) > 1e-3) {
      fail("range", r.path() + ".quaternion",
           "must be a unit quaternion (norm " + std::to_string(q.norm()) + ")");
    }
    R = q.normalized().toRotationMatrix();
  }
  T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
}

void read_sensors(MapReader& root, std::vector<SensorConfig>& sensors) {
  if (!root.has("sensors")) return;
  sensors.clear();
  root.map_list("sensors", [&](MapReader& r, std::size_t i) {
    SensorConfig s;
    s.id.clear();
    s.topic.clear();
    s.frame_id.clear();
    r.string("id", s.id);
    if (s.id.empty()) fail("value", r.path() + ".id", "is required and must not be empty");
    s.topic = "rt/tarmac/lidar/" + s.id + "/points";
    s.frame_id = "lidar_" + s.id;
    r.topic("topic", s.topic);
    r.string("frame_id", s.frame_id);
    r.map("extrinsic", [&](MapReader& m) { read_extrinsic(m, s.T_base_sensor); });
    r.scalar<double>("max_age_ms", s.max_age_ms, 1.0, 60000.0);
    r.scalar<bool>("deskew", s.deskew, false, true);
    for (std::size_t j = 0; j < sensors.size(); ++j) {
      const std::string at = "sensors[" + std::to_string(i) + "]";
      if (sensors[j].id == s.id) fail("value", at + ".id", "duplicate id '" + s.id + "'");
      if (sensors[j].topic == s.topic) {
        fail("value", at + ".topic", "duplicate topic '" + s.topic + "'");
      }
    }
    sensors.push_back(std::move(s));
  });
  if (sensors.empty()) fail("value", "sensors", "needs at least one sensor");
  if (sensors.size() > 16) fail("range", "sensors", "at most 16 sensors");
}

void read_daemon(MapReader& root, Config& c) {
  read_sensors(root, c.sensors);
  root.map("pose", [&](MapReader& r) {
    r.topic("topic", c.pose.topic);
    if (const int i = r.choice("type", kPoseTypes); i >= 0) {
      c.pose.type = static_cast<PoseType>(i);
    }
    r.string("frame_id", c.pose.frame_id);
    r.scalar<std::uint32_t>("buffer_size", c.pose.buffer_size, 2, 100000);
    r.scalar<double>("max_gap_ms", c.pose.max_gap_ms, 1.0, 10000.0);
    r.scalar<double>("max_age_ms", c.pose.max_age_ms, 1.0, 60000.0);
    r.topic("correction_topic", c.pose.correction_topic);
  });
  root.map("executor", [&](MapReader& r) {
    auto& e = c.executor;
    r.scalar<double>("rate_hz", e.rate_hz, kMinRateHz, kMaxRateHz);
    r.scalar<double>("input_delay_ms", e.input_delay_ms, 0.0, 5000.0);
    r.scalar<double>("pose_wait_ms", e.pose_wait_ms, 0.0, 10000.0);
    r.scalar<double>("max_future_ms", e.max_future_ms, 0.0, 60000.0);
    r.scalar<double>("sensor_phase_ms", e.sensor_phase_ms, 0.0, 10000.0);
    r.scalar<std::uint32_t>("workers", e.workers, 1, 64);
    r.int_list("cpus", e.cpus, 0, 1023);
    r.scalar<int>("realtime_priority", e.realtime_priority, 0, 99);
    r.scalar<bool>("lock_memory", e.lock_memory, false, true);
    r.scalar<std::uint32_t>("queue_depth", e.queue_depth, 1, 1000);
  });
  root.map("budgets", [&](MapReader& r) {
    auto& b = c.budgets;
    r.scalar<double>("drain_ms", b.drain_ms, 0.001, 10000.0);
    r.scalar<double>("ingest_ms", b.ingest_ms, 0.001, 10000.0);
    r.scalar<double>("integrate_ms", b.integrate_ms, 0.001, 10000.0);
    r.scalar<double>("tsdf_ms", b.tsdf_ms, 0.001, 10000.0);
    r.scalar<double>("rebuild_ms", b.rebuild_ms, 0.001, 10000.0);
    r.scalar<double>("costmap_ms", b.costmap_ms, 0.001, 10000.0);
    r.scalar<double>("esdf_band_ms", b.esdf_band_ms, 0.001, 10000.0);
    r.scalar<double>("publish_ms", b.publish_ms, 0.001, 10000.0);
    r.scalar<double>("cycle_ms", b.cycle_ms, 0.001, 10000.0);
  });
  root.map("quotas", [&](MapReader& r) {
    auto& q = c.quotas;
    r.scalar<std::uint64_t>("points_per_cycle", q.points_per_cycle, 1, 100'000'000);
    r.scalar<std::uint64_t>("points_per_scan", q.points_per_scan, 1, 100'000'000);
    r.scalar<std::uint32_t>("max_pending_scans", q.max_pending_scans, 1, 1000);
    r.scalar<std::uint64_t>("reserve_points_per_scan", q.reserve_points_per_scan, 0, 4'000'000);
    r.scalar<std::uint64_t>("tsdf_points_per_cycle", q.tsdf_points_per_cycle, 0, 100'000'000);
  });
  root.map("outputs", [&](MapReader& r) {
    auto& o = c.outputs;
    r.string("frame_id", o.frame_id);
    r.topic("costmap_topic", o.costmap_topic);
    r.topic("esdf_slice_topic", o.esdf_slice_topic);
    r.topic("esdf_band_topic", o.esdf_band_topic);
    r.topic("cycle_report_topic", o.cycle_report_topic);
    r.topic("diagnostic_array_topic", o.diagnostic_array_topic);
    r.topic("virtual_obstacles_topic", o.virtual_obstacles_topic);
    r.topic("obstacle_grid_topic", o.obstacle_grid_topic);
    r.topic("esdf_slice_grid_topic", o.esdf_slice_grid_topic);
    r.scalar<double>("esdf_slice_grid_range_m", o.esdf_slice_grid_range_m, 0.1, 1000.0);
    r.scalar<std::uint32_t>("diagnostic_array_every", o.diagnostic_array_every, 1, 100000);
    r.scalar<double>("costmap_max_age_ms", o.costmap_max_age_ms, 1.0, 3.6e6);
  });
  root.map("state", [&](MapReader& r) {
    r.string("dir", c.state.dir);
    r.string("map_file", c.state.map_file);
    r.scalar<bool>("save_on_exit", c.state.save_on_exit, false, true);
    r.string("tsdf_file", c.state.tsdf_file);
    r.scalar<bool>("load_on_start", c.state.load_on_start, false, true);
    r.scalar<double>("save_period_s", c.state.save_period_s, 0.0, 86400.0);
  });
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

void emit_qos(YAML::Emitter& out, const char* name, const transport::QosSpec& q) {
  out << YAML::Key << name << YAML::Value << YAML::Flow << YAML::BeginMap;
  out << YAML::Key << "reliability" << YAML::Value << kReliability[static_cast<int>(q.reliability)];
  out << YAML::Key << "durability" << YAML::Value << kDurability[static_cast<int>(q.durability)];
  out << YAML::Key << "depth" << YAML::Value << q.history_depth;
  out << YAML::EndMap;
}

}  // namespace

namespace {
core::Result<Config> load_config(const std::string& yaml_text, const std::string& base_dir) {
  Config config;
  try {
    const YAML::Node root = YAML::Load(yaml_text);
    if (!root || root.IsNull()) return core::Error{"config.empty", "<root>: the file is empty"};
    std::size_t nodes = 0;
    check_structure(root, "", 0, nodes);
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
    bool domain_given = false;
    r.map("dds", [&](MapReader& m) {
      domain_given = m.has("domain_id");
      read_dds(m, config.dds, base_dir);
    });
    if (!domain_given) domain_from_environment(config.dds.participant.domain_id);
    read_daemon(r, config);
    read_mapping(r, config.mapping);
    r.finish();
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
  out << YAML::Key << "udp_receive_buffer_bytes" << YAML::Value << p.udp_receive_buffer_bytes;
  out << YAML::Key << "udp_send_buffer_bytes" << YAML::Value << p.udp_send_buffer_bytes;
  const auto& sec = p.security;
  out << YAML::Key << "security" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << sec.enabled;
  out << YAML::Key << "identity_ca" << YAML::Value << sec.identity_ca;
  out << YAML::Key << "identity_certificate" << YAML::Value << sec.identity_certificate;
  out << YAML::Key << "private_key" << YAML::Value << sec.private_key;
  out << YAML::Key << "permissions_ca" << YAML::Value << sec.permissions_ca;
  out << YAML::Key << "governance" << YAML::Value << sec.governance;
  out << YAML::Key << "permissions" << YAML::Value << sec.permissions;
  out << YAML::EndMap;
  out << YAML::Key << "qos" << YAML::Value << YAML::BeginMap;
  emit_qos(out, "lidar", config.dds.qos.lidar);
  emit_qos(out, "pose", config.dds.qos.pose);
  emit_qos(out, "virtual_obstacles", config.dds.qos.virtual_obstacles);
  emit_qos(out, "costmap", config.dds.qos.costmap);
  emit_qos(out, "esdf_slice", config.dds.qos.esdf_slice);
  emit_qos(out, "esdf_band", config.dds.qos.esdf_band);
  emit_qos(out, "diagnostics", config.dds.qos.diagnostics);
  out << YAML::EndMap << YAML::EndMap;
  out << YAML::Key << "sensors" << YAML::Value << YAML::BeginSeq;
  for (const auto& s : config.sensors) {
    const Eigen::Quaterniond q(s.T_base_sensor.linear());
    const Eigen::Vector3d t = s.T_base_sensor.translation();
    out << YAML::BeginMap;
    out << YAML::Key << "id" << YAML::Value << s.id;
    out << YAML::Key << "topic" << YAML::Value << s.topic;
    out << YAML::Key << "frame_id" << YAML::Value << s.frame_id;
    out << YAML::Key << "extrinsic" << YAML::Value << YAML::BeginMap;
    out << YAML::Key << "translation_m" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key
        << "x" << YAML::Value << t.x() << YAML::Key << "y" << YAML::Value << t.y() << YAML::Key
        << "z" << YAML::Value << t.z() << YAML::EndMap;
    out << YAML::Key << "quaternion" << YAML::Value << YAML::Flow << YAML::BeginMap << YAML::Key
        << "x" << YAML::Value << q.x() << YAML::Key << "y" << YAML::Value << q.y() << YAML::Key
        << "z" << YAML::Value << q.z() << YAML::Key << "w" << YAML::Value << q.w() << YAML::EndMap;
    out << YAML::EndMap;
    out << YAML::Key << "max_age_ms" << YAML::Value << s.max_age_ms;
    out << YAML::Key << "deskew" << YAML::Value << s.deskew;
    out << YAML::EndMap;
  }
  out << YAML::EndSeq;
  const auto& pi = config.pose;
  out << YAML::Key << "pose" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "topic" << YAML::Value << pi.topic;
  out << YAML::Key << "type" << YAML::Value << kPoseTypes[static_cast<int>(pi.type)];
  out << YAML::Key << "frame_id" << YAML::Value << pi.frame_id;
  out << YAML::Key << "buffer_size" << YAML::Value << pi.buffer_size;
  out << YAML::Key << "max_gap_ms" << YAML::Value << pi.max_gap_ms;
  out << YAML::Key << "max_age_ms" << YAML::Value << pi.max_age_ms;
  out << YAML::Key << "correction_topic" << YAML::Value << pi.correction_topic;
  out << YAML::EndMap;
  const auto& e = config.executor;
  out << YAML::Key << "executor" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "rate_hz" << YAML::Value << e.rate_hz;
  out << YAML::Key << "input_delay_ms" << YAML::Value << e.input_delay_ms;
  out << YAML::Key << "pose_wait_ms" << YAML::Value << e.pose_wait_ms;
  out << YAML::Key << "max_future_ms" << YAML::Value << e.max_future_ms;
  out << YAML::Key << "sensor_phase_ms" << YAML::Value << e.sensor_phase_ms;
  out << YAML::Key << "workers" << YAML::Value << e.workers;
  out << YAML::Key << "cpus" << YAML::Value << YAML::Flow << e.cpus;
  out << YAML::Key << "realtime_priority" << YAML::Value << e.realtime_priority;
  out << YAML::Key << "lock_memory" << YAML::Value << e.lock_memory;
  out << YAML::Key << "queue_depth" << YAML::Value << e.queue_depth;
  out << YAML::EndMap;
  const auto& b = config.budgets;
  out << YAML::Key << "budgets" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "drain_ms" << YAML::Value << b.drain_ms;
  out << YAML::Key << "ingest_ms" << YAML::Value << b.ingest_ms;
  out << YAML::Key << "integrate_ms" << YAML::Value << b.integrate_ms;
  out << YAML::Key << "tsdf_ms" << YAML::Value << b.tsdf_ms;
  out << YAML::Key << "rebuild_ms" << YAML::Value << b.rebuild_ms;
  out << YAML::Key << "costmap_ms" << YAML::Value << b.costmap_ms;
  out << YAML::Key << "esdf_band_ms" << YAML::Value << b.esdf_band_ms;
  out << YAML::Key << "publish_ms" << YAML::Value << b.publish_ms;
  out << YAML::Key << "cycle_ms" << YAML::Value << b.cycle_ms;
  out << YAML::EndMap;
  const auto& qu = config.quotas;
  out << YAML::Key << "quotas" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "points_per_cycle" << YAML::Value << qu.points_per_cycle;
  out << YAML::Key << "points_per_scan" << YAML::Value << qu.points_per_scan;
  out << YAML::Key << "max_pending_scans" << YAML::Value << qu.max_pending_scans;
  out << YAML::Key << "reserve_points_per_scan" << YAML::Value << qu.reserve_points_per_scan;
  out << YAML::Key << "tsdf_points_per_cycle" << YAML::Value << qu.tsdf_points_per_cycle;
  out << YAML::EndMap;
  const auto& ou = config.outputs;
  out << YAML::Key << "outputs" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "frame_id" << YAML::Value << ou.frame_id;
  out << YAML::Key << "costmap_topic" << YAML::Value << ou.costmap_topic;
  out << YAML::Key << "obstacle_grid_topic" << YAML::Value << ou.obstacle_grid_topic;
  out << YAML::Key << "esdf_slice_grid_topic" << YAML::Value << ou.esdf_slice_grid_topic;
  out << YAML::Key << "esdf_slice_grid_range_m" << YAML::Value << ou.esdf_slice_grid_range_m;
  out << YAML::Key << "esdf_slice_topic" << YAML::Value << ou.esdf_slice_topic;
  out << YAML::Key << "esdf_band_topic" << YAML::Value << ou.esdf_band_topic;
  out << YAML::Key << "cycle_report_topic" << YAML::Value << ou.cycle_report_topic;
  out << YAML::Key << "diagnostic_array_topic" << YAML::Value << ou.diagnostic_array_topic;
  out << YAML::Key << "virtual_obstacles_topic" << YAML::Value << ou.virtual_obstacles_topic;
  out << YAML::Key << "diagnostic_array_every" << YAML::Value << ou.diagnostic_array_every;
  out << YAML::Key << "costmap_max_age_ms" << YAML::Value << ou.costmap_max_age_ms;
  out << YAML::EndMap;
  out << YAML::Key << "state" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "dir" << YAML::Value << config.state.dir;
  out << YAML::Key << "map_file" << YAML::Value << config.state.map_file;
  out << YAML::Key << "save_on_exit" << YAML::Value << config.state.save_on_exit;
  out << YAML::Key << "tsdf_file" << YAML::Value << config.state.tsdf_file;
  out << YAML::Key << "load_on_start" << YAML::Value << config.state.load_on_start;
  out << YAML::Key << "save_period_s" << YAML::Value << config.state.save_period_s;
  out << YAML::EndMap;
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
  out << YAML::Key << "static_promote_scans" << YAML::Value << o.static_promote_scans;
  out << YAML::Key << "static_demote_scans" << YAML::Value << o.static_demote_scans;
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
  out << YAML::Key << "free_rule" << YAML::Value << kFreeRule[static_cast<int>(c.free_rule)];
  out << YAML::EndMap;
  const auto& band = m.esdf_band;
  out << YAML::Key << "esdf_band" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << band.enabled;
  out << YAML::Key << "below_m" << YAML::Value << band.below_m;
  out << YAML::Key << "above_m" << YAML::Value << band.above_m;
  out << YAML::Key << "unknown" << YAML::Value << kUnknownPolicy[static_cast<int>(band.unknown)];
  out << YAML::Key << "publish_radius_m" << YAML::Value << band.publish_radius_m;
  out << YAML::EndMap;
  const auto& t = m.tsdf;
  out << YAML::Key << "tsdf" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << t.enabled;
  out << YAML::Key << "voxel_size_m" << YAML::Value << t.voxel_size_m;
  out << YAML::Key << "truncation_m" << YAML::Value << t.truncation_m;
  out << YAML::Key << "max_weight" << YAML::Value << t.max_weight;
  out << YAML::Key << "max_range_m" << YAML::Value << t.max_range_m;
  out << YAML::Key << "space_carving" << YAML::Value << t.space_carving;
  out << YAML::Key << "reserve_blocks" << YAML::Value << t.reserve_blocks;
  out << YAML::EndMap;
  const auto& k = m.corrections;
  out << YAML::Key << "corrections" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "enabled" << YAML::Value << k.enabled;
  out << YAML::Key << "retain_scans" << YAML::Value << k.retain_scans;
  out << YAML::Key << "jump_threshold_m" << YAML::Value << k.jump_threshold_m;
  out << YAML::Key << "jump_threshold_deg" << YAML::Value << k.jump_threshold_deg;
  out << YAML::Key << "max_prediction_gap_s" << YAML::Value << k.max_prediction_gap_s;
  out << YAML::Key << "rebuild_points_per_cycle" << YAML::Value << k.rebuild_points_per_cycle;
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
