// The config schema is the one definition of every key: the loader, to_yaml, the shipped
// config/tarmac.yaml and the reference table in docs/configuration.md all agree with it.

#include "tarmac/config/schema.hpp"

#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "load_error.hpp"
#include "tarmac/config/config.hpp"
#include "test_env.hpp"

namespace tarmac::config {
namespace {

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

/// The map that holds `path`'s leaf ("executor.rate_hz" -> "executor"; "version" -> "").
std::string parent_of(const std::string& path) {
  const auto dot = path.rfind('.');
  return dot == std::string::npos ? "" : path.substr(0, dot);
}

TEST(ConfigSchema, KeysAreUniqueAndEachMapIsContiguous) {
  // The loader and to_yaml walk the table map by map, so a map's keys must not be split.
  std::set<std::string> paths;
  std::set<std::string> closed_maps;
  std::string open_map;
  for (const Key& key : schema()) {
    EXPECT_TRUE(paths.insert(key.path).second) << key.path << " is defined twice";
    // Every map from the root down to the key's own must still be open.
    for (std::string map = parent_of(key.path); !map.empty(); map = parent_of(map)) {
      EXPECT_EQ(closed_maps.count(map), 0u) << key.path << ": map " << map << " was split";
    }
    const std::string map = parent_of(key.path);
    for (std::string m = open_map; !m.empty() && map.rfind(m, 0) != 0; m = parent_of(m)) {
      closed_maps.insert(m);
    }
    open_map = map;
  }
}

TEST(ConfigSchema, EachKeysFieldHasTheKeysType) {
  Config config;
  SensorEntry sensor = sensor_entry(config.sensors.front());
  for (const Key& key : schema()) {
    const Field field = field_of(key, config, &sensor);
    switch (key.type) {
      case KeyType::kBool: EXPECT_TRUE(std::holds_alternative<bool*>(field)) << key.path; break;
      case KeyType::kInteger:
        EXPECT_TRUE(std::holds_alternative<int*>(field) ||
                    std::holds_alternative<std::uint32_t*>(field) ||
                    std::holds_alternative<std::uint64_t*>(field))
            << key.path;
        break;
      case KeyType::kReal:
        EXPECT_TRUE(std::holds_alternative<float*>(field) || std::holds_alternative<double*>(field))
            << key.path;
        break;
      case KeyType::kString:
      case KeyType::kTopic:
      case KeyType::kPath:
        EXPECT_TRUE(std::holds_alternative<std::string*>(field)) << key.path;
        break;
      case KeyType::kChoice:
        EXPECT_TRUE(std::holds_alternative<ChoiceField>(field)) << key.path;
        break;
      case KeyType::kStringList:
        EXPECT_TRUE(std::holds_alternative<std::vector<std::string>*>(field)) << key.path;
        break;
      case KeyType::kIntegerList:
        EXPECT_TRUE(std::holds_alternative<std::vector<int>*>(field)) << key.path;
        break;
    }
    EXPECT_FALSE(key.doc.empty()) << key.path;
  }
}

TEST(ConfigSchema, EveryDefaultIsInItsRange) {
  Config config;
  SensorEntry sensor = sensor_entry(config.sensors.front());
  for (const Key& key : schema()) {
    const Field field = field_of(key, config, &sensor);
    std::visit(
        [&](auto value) {
          using T = std::remove_pointer_t<decltype(value)>;
          if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
            EXPECT_GE(*value, static_cast<T>(key.min)) << key.path;
            EXPECT_LE(*value, static_cast<T>(key.max)) << key.path;
          } else if constexpr (std::is_same_v<decltype(value), ChoiceField>) {
            EXPECT_LT(static_cast<std::size_t>(value.get(value.field)), key.choices.size())
                << key.path;
          }
        },
        field);
  }
}

/// A config file that sets `key` to `value` and leaves every other key at its default: the path
/// "a.b.c" as flow maps around the value, {a: {b: {c: V}}}, a sensor's key in a sensor with an id.
std::string yaml_setting(const Key& key, double value) {
  std::string open;
  std::string close;
  std::string rest = key.path;
  for (auto dot = rest.find('.'); dot != std::string::npos; dot = rest.find('.')) {
    std::string map = rest.substr(0, dot);
    if (map == "sensors[]") {
      open += "sensors: [{id: a, ";
      close = "}]" + close;
    } else {
      open += map + ": {";
      close = "}" + close;
    }
    rest = rest.substr(dot + 1);
  }
  std::ostringstream text;
  text.precision(17);
  text << value;
  return "version: 1\n" + open + rest + ": " + text.str() + close + "\n";
}

TEST(ConfigSchema, EveryNumericKey_RefusesAValueBeyondItsRangeWithItsPath) {
  // The reader takes each key's range from the table: one past the top is refused, naming
  // the key (sensor keys as sensors[0].…).
  for (const Key& key : schema()) {
    if (key.type != KeyType::kInteger && key.type != KeyType::kReal) continue;
    if (key.path == "version") continue;  // another version is config.version, not a range
    std::string path = key.path;
    if (path.rfind("sensors[].", 0) == 0) path = "sensors[0]." + path.substr(10);
    const std::string yaml = yaml_setting(key, key.max + 1.0);
    const auto result = load_config_string(yaml);
    ASSERT_FALSE(result.ok()) << yaml;
    EXPECT_EQ(result.error().code, "config.range") << yaml << result.error().message;
    EXPECT_EQ(result.error().message.rfind(path + ": must be in [", 0), 0u)
        << yaml << result.error().message;
  }
}

TEST(ConfigSchema, EveryNumericKey_AtEitherEndOfItsRange_PassesTheLibrariesValidation) {
  // The table's ranges are what a user reads; the core and transport libraries validate their
  // parameters again (for callers without a config file). A value the table accepts must not be
  // refused there, except by a rule between keys, listed here with the reason.
  // "<key> min|max" -> the start of the message of the rule between keys that refuses it (the
  // other keys at their defaults). Exact: each entry must be refused so, and nothing else.
  const std::string ego = "filters.ego_box: min must be < max on every axis";
  const std::string unit_q = "sensors[0].extrinsic.quaternion: must be a unit quaternion";
  const std::string below = "occupancy.window_below_m: must be within the window height";
  const std::string trunc = "tsdf.truncation_m: must be in [voxel_size_m, 32 * voxel_size_m]";
  const std::string shm = "dds.shm_segment_bytes: must be >= dds.shm_max_message_bytes";
  const std::string inflation = "costmap.inflation_radius_m: must be >= inscribed_radius_m";
  const std::string points = "quotas.points_per_scan: must be <= quotas.points_per_cycle";
  const std::map<std::string, std::string> cross_key = {
      {"dds.shm_segment_bytes min", shm},
      {"dds.shm_max_message_bytes max", shm},
      // One component at ±1 beside the default w = 1: norm √2.
      {"sensors[].extrinsic.quaternion.x min", unit_q},
      {"sensors[].extrinsic.quaternion.x max", unit_q},
      {"sensors[].extrinsic.quaternion.y min", unit_q},
      {"sensors[].extrinsic.quaternion.y max", unit_q},
      {"sensors[].extrinsic.quaternion.z min", unit_q},
      {"sensors[].extrinsic.quaternion.z max", unit_q},
      {"executor.rate_hz max", "budgets.cycle_ms: exceeds the period of executor.rate_hz"},
      {"executor.sensor_phase_ms max",
       "executor.sensor_phase_ms: must be below the period of executor.rate_hz"},
      {"budgets.cycle_ms max", "budgets.cycle_ms: exceeds the period of executor.rate_hz"},
      {"quotas.points_per_cycle min", points},
      {"quotas.points_per_scan max", points},
      {"filters.ego_box_min_m.x max", ego},
      {"filters.ego_box_min_m.y max", ego},
      {"filters.ego_box_min_m.z max", ego},
      {"filters.ego_box_max_m.x min", ego},
      {"filters.ego_box_max_m.y min", ego},
      {"filters.ego_box_max_m.z min", ego},
      {"occupancy.voxel_size_m min", below},  // 40 voxels of 2 cm: lower than the 3 m below
      {"occupancy.window_z_vox min", below},
      {"occupancy.window_below_m max", below},
      {"occupancy.window_z_vox max", "occupancy.window_*_vox: window larger than 512 M voxels"},
      {"occupancy.low_object_lethal_returns max",
       "low_objects.lethal_returns: must be in [1, confirm_returns]"},
      {"costmap.min_obstacle_height_m max",
       "costmap.vehicle_height_m: must be > min_obstacle_height_m"},
      {"costmap.inscribed_radius_m max", inflation},
      {"costmap.inflation_radius_m min", inflation},
      {"tsdf.voxel_size_m max", trunc},
      {"tsdf.truncation_m min", trunc},
      {"tsdf.truncation_m max", trunc},
  };
  std::size_t refused = 0;
  for (const Key& key : schema()) {
    if (key.type != KeyType::kInteger && key.type != KeyType::kReal) continue;
    if (key.path == "version") continue;
    for (const double value : {key.min, key.max}) {
      const std::string yaml = yaml_setting(key, value);
      const auto result = load_config_string(yaml);
      const auto rule = cross_key.find(key.path + (value == key.min ? " min" : " max"));
      if (rule == cross_key.end()) {
        EXPECT_TRUE(result.ok()) << yaml << result.error().code << ": " << result.error().message;
        continue;
      }
      ++refused;
      ASSERT_FALSE(result.ok()) << yaml << "is no longer refused: update the list";
      EXPECT_EQ(result.error().message.rfind(rule->second, 0), 0u)
          << yaml << result.error().message;
    }
  }
  EXPECT_EQ(refused, cross_key.size()) << "an entry names no key of the schema";
}

TEST(ConfigSchema, UnknownKeys_SuggestTheNearestKnownKey) {
  EXPECT_EQ(error_of("version: 1\ncostmap: {inflation_radius: 2}\n"),
            "costmap.inflation_radius: unknown key (did you mean 'inflation_radius_m'?)");
  EXPECT_EQ(error_of("version: 1\ndds: {qos: {costmap: {depht: 3}}}\n"),
            "dds.qos.costmap.depht: unknown key (did you mean 'depth'?)");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, extrinsic: {rpy: {yaw: 3}}}\n"),
            "sensors[0].extrinsic.rpy: unknown key");
  EXPECT_EQ(error_of("version: 1\nexecuter: {rate_hz: 10}\n"),
            "executer: unknown key (did you mean 'executor'?)");
  // Nothing near enough to be a typo: no suggestion.
  EXPECT_EQ(error_of("version: 1\nmapp: {}\n"), "mapp: unknown key");
  const auto code = load_config_string("version: 1\ntsdf: {enable: true}\n");
  ASSERT_FALSE(code.ok());
  EXPECT_EQ(code.error().code, "config.unknown_key");
}

/// Leaf paths of a YAML document in schema form: sensors' keys as `sensors[].…`, a list of
/// scalars as one leaf.
void leaf_paths(const YAML::Node& node, const std::string& path, std::set<std::string>& out) {
  if (node.IsMap()) {
    for (const auto& kv : node) {
      leaf_paths(kv.second, path.empty() ? kv.first.Scalar() : path + "." + kv.first.Scalar(), out);
    }
  } else if (node.IsSequence() && node.size() > 0 && node[0].IsMap()) {
    for (const auto& item : node) leaf_paths(item, path + "[]", out);
  } else {
    out.insert(path);
  }
}

TEST(ConfigSchema, ShippedFileListsEveryKeyAndOnlySchemaKeys) {
  // config/tarmac.yaml is the documented default config: every key the schema writes, and no
  // other. Its values are the defaults (Config.ShippedFileIsValidAndEqualsDefaults).
  std::set<std::string> in_file;
  leaf_paths(YAML::LoadFile((test::source_dir() / "config/tarmac.yaml").string()), "", in_file);
  std::set<std::string> in_schema;
  for (const Key& key : schema()) {
    // dds.domain_id is left unset (commented out) so that ROS_DOMAIN_ID applies; rpy_deg is
    // the alternative to the quaternion, shown in a comment.
    if (key.written && key.path != "dds.domain_id") in_schema.insert(key.path);
  }
  for (const auto& path : in_file) EXPECT_EQ(in_schema.count(path), 1u) << path << ": not a key";
  for (const auto& path : in_schema) {
    EXPECT_EQ(in_file.count(path), 1u) << path << ": missing from config/tarmac.yaml";
  }
}

TEST(ConfigSchema, ReferenceInTheDocsIsTheGeneratedTable) {
  const std::string begin = "<!-- BEGIN tarmacd --print-config-reference -->\n";
  const std::string end = "<!-- END tarmacd --print-config-reference -->";
  const std::string doc = read_text(test::source_dir() / "docs/configuration.md");
  const auto from = doc.find(begin);
  const auto to = doc.find(end);
  ASSERT_NE(from, std::string::npos) << "docs/configuration.md has no " << begin;
  ASSERT_NE(to, std::string::npos) << "docs/configuration.md has no " << end;
  EXPECT_EQ(doc.substr(from + begin.size(), to - from - begin.size()), reference_markdown())
      << "regenerate the table with build/bin/tarmacd --print-config-reference";
}

TEST(ConfigSchema, ReferenceHasOneRowPerKey) {
  const std::string table = reference_markdown();
  std::size_t rows = 0;
  for (const char c : table) rows += c == '\n' ? 1 : 0;
  EXPECT_EQ(rows, schema().size() + 2);  // + header and separator
  EXPECT_NE(table.find("| `executor.rate_hz` | real | `10` | 0.1..1000 | Hz | ticks per second |"),
            std::string::npos)
      << table;
}

}  // namespace
}  // namespace tarmac::config
