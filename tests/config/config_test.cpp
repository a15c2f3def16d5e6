#include "tarmac/config/config.hpp"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <vector>

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "load_error.hpp"
#include "test_env.hpp"

namespace tarmac::config {
namespace {

std::string code_of(const std::string& yaml) {
  auto result = load_config_string(yaml);
  EXPECT_FALSE(result.ok()) << yaml;
  return result.ok() ? "" : result.error().code;
}

/// Paths of the scalar leaves of `node` that hold a number ("executor.rate_hz",
/// "sensors[0].extrinsic.translation_m.x", "executor.cpus[0]").
void numeric_leaves(const YAML::Node& node, const std::string& path,
                    std::vector<std::pair<std::string, YAML::Node>>& out) {
  if (node.IsMap()) {
    for (const auto& kv : node) {
      numeric_leaves(kv.second, path.empty() ? kv.first.Scalar() : path + "." + kv.first.Scalar(),
                     out);
    }
  } else if (node.IsSequence()) {
    for (std::size_t i = 0; i < node.size(); ++i) {
      numeric_leaves(node[i], path + "[" + std::to_string(i) + "]", out);
    }
  } else if (double d = 0; node.IsScalar() && YAML::convert<double>::decode(node, d)) {
    out.emplace_back(path, node);
  }
}

TEST(Config, ShippedFileIsValidAndEqualsDefaults) {
  auto config = load_config_file((test::source_dir() / "config/tarmac.yaml").string());
  ASSERT_TRUE(config.ok()) << config.error().message;
  Config defaults;
  defaults.dds.participant.name = "tarmacd";
  EXPECT_EQ(to_yaml(config.value()), to_yaml(defaults));
  EXPECT_EQ(config.value().dds.participant.transport, transport::TransportMode::kLocalhost);
}

TEST(Config, UnknownKeyNamesItsPath) {
  EXPECT_EQ(error_of("version: 1\ndds:\n  qos:\n    costmap: {depht: 3}\n"),
            "dds.qos.costmap.depht: unknown key (did you mean 'depth'?)");
  EXPECT_EQ(error_of("version: 1\nmapp: {}\n"), "mapp: unknown key");
}

TEST(Config, OutOfRangeAndBadValuesNameTheKey) {
  EXPECT_EQ(error_of("version: 1\ndds: {domain_id: 300}\n"),
            "dds.domain_id: must be in [0, 232], got 300");
  EXPECT_EQ(error_of("version: 1\ndds: {domain_id: abc}\n"),
            "dds.domain_id: expected an integer, got a string 'abc'");
  EXPECT_EQ(error_of("version: 1\ndds: {transport: wifi}\n"),
            "dds.transport: must be one of {localhost, shm, network}, got 'wifi'");
  EXPECT_EQ(error_of("version: 1\ndds: {qos: {pose: {depth: 0}}}\n"),
            "dds.qos.pose.depth: must be in [1, 10000], got 0");
}

TEST(Config, EveryNumericKey_RefusesNanAndInfinityWithItsPath) {
  // The effective config with every key (and one CPU, so the list is not empty), each numeric
  // leaf in turn replaced by .nan, .inf and -.inf: every one is refused, naming its path.
  Config c;
  c.executor.cpus = {0};
  const std::string text = to_yaml(c);
  ASSERT_TRUE(load_config_string(text).ok()) << text;
  const YAML::Node pristine = YAML::Load(text);
  std::vector<std::pair<std::string, YAML::Node>> probe;
  numeric_leaves(pristine, "", probe);
  // 94 today: every numeric key the loader reads, except rpy_deg (to_yaml writes the rotation
  // as a quaternion; the angles are checked in the next test).
  ASSERT_GE(probe.size(), 94u);
  const double inf = std::numeric_limits<double>::infinity();
  for (const auto& [value, shown] : {std::pair{std::numeric_limits<double>::quiet_NaN(), ".nan"},
                                     std::pair{inf, ".inf"}, std::pair{-inf, "-.inf"}}) {
    for (std::size_t i = 0; i < probe.size(); ++i) {
      YAML::Node doc = YAML::Load(text);  // a fresh copy, then the i-th leaf replaced
      std::vector<std::pair<std::string, YAML::Node>> leaves;
      numeric_leaves(doc, "", leaves);
      leaves[i].second = value;
      YAML::Emitter out;
      out << doc;
      const auto result = load_config_string(out.c_str());
      ASSERT_FALSE(result.ok()) << leaves[i].first << " = " << shown;
      EXPECT_EQ(result.error().message,
                leaves[i].first + ": must be a finite number, got " + std::string(shown));
      EXPECT_EQ(result.error().code, "config.not_finite");
    }
  }
}

TEST(Config, NonFiniteNumbers_AreRefusedInEveryKindOfField) {
  // Scalars of the executor (a NaN rate never ticks), as yaml-cpp spells them.
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: .nan}\n"),
            "executor.rate_hz: must be a finite number, got .nan");
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: .NaN}\n"),
            "executor.rate_hz: must be a finite number, got .NaN");
  EXPECT_EQ(error_of("version: 1\nexecutor: {input_delay_ms: .inf}\n"),
            "executor.input_delay_ms: must be a finite number, got .inf");
  EXPECT_EQ(error_of("version: 1\nexecutor: {input_delay_ms: -.Inf}\n"),
            "executor.input_delay_ms: must be a finite number, got -.Inf");
  // Beyond a double: not finite either, not "not a number".
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: 1e400}\n"),
            "executor.rate_hz: must be a finite number, got 1e400");
  // A float key (TSDF): finite as a double but beyond a float is out of range.
  EXPECT_EQ(error_of("version: 1\ntsdf: {voxel_size_m: .inf}\n"),
            "tsdf.voxel_size_m: must be a finite number, got .inf");
  EXPECT_EQ(error_of("version: 1\ntsdf: {voxel_size_m: 1e39}\n"),
            "tsdf.voxel_size_m: must be in [0.01, 2], got 1e39");
  // Integer keys and list elements.
  EXPECT_EQ(error_of("version: 1\nexecutor: {workers: .inf}\n"),
            "executor.workers: must be a finite number, got .inf");
  EXPECT_EQ(error_of("version: 1\nexecutor: {cpus: [0, .nan]}\n"),
            "executor.cpus[1]: must be a finite number, got .nan");
  // Nested in a sensor: the extrinsic's translation, quaternion and angles, and its own keys.
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - id: front\n  - id: rear\n"
                     "    extrinsic: {translation_m: {x: 1.0, y: .nan}}\n"),
            "sensors[1].extrinsic.translation_m.y: must be a finite number, got .nan");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, extrinsic: {quaternion: {w: .nan}}}\n"),
            "sensors[0].extrinsic.quaternion.w: must be a finite number, got .nan");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, extrinsic: {rpy_deg: {yaw: -.inf}}}\n"),
            "sensors[0].extrinsic.rpy_deg.yaw: must be a finite number, got -.inf");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, max_age_ms: .inf}\n"),
            "sensors[0].max_age_ms: must be a finite number, got .inf");
  EXPECT_EQ(error_of("version: 1\nfilters: {ego_box_min_m: {z: .nan}}\n"),
            "filters.ego_box_min_m.z: must be a finite number, got .nan");
  EXPECT_EQ(code_of("version: 1\nexecutor: {rate_hz: .nan}\n"), "config.not_finite");
  // Finite values in range are still read.
  auto ok = load_config_string("version: 1\nexecutor: {rate_hz: +5.0, workers: +3, cpus: [1]}\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok.value().executor.rate_hz, 5.0);
  EXPECT_EQ(ok.value().executor.workers, 3u);
}

TEST(Config, DuplicateKeys_AreRefusedWithBothLines) {
  EXPECT_EQ(error_of("version: 1\nexecutor: {workers: 2}\nbudgets: {}\nexecutor: {workers: 3}\n"),
            "executor: duplicate key (line 2 and line 4)");
  EXPECT_EQ(error_of("version: 1\nversion: 1\n"), "version: duplicate key (line 1 and line 2)");
  EXPECT_EQ(error_of("version: 1\nexecutor:\n  rate_hz: 5\n  workers: 2\n  rate_hz: 8\n"),
            "executor.rate_hz: duplicate key (line 3 and line 5)");
  EXPECT_EQ(error_of("version: 1\ndds:\n  qos:\n    pose:\n      depth: 3\n      depth: 4\n"),
            "dds.qos.pose.depth: duplicate key (line 5 and line 6)");
  // Inside a list: the second sensor's extrinsic.
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - id: front\n  - id: rear\n    extrinsic:\n"
                     "      translation_m: {x: 1.0}\n      translation_m: {x: 2.0}\n"),
            "sensors[1].extrinsic.translation_m: duplicate key (line 6 and line 7)");
  // Two on one line (flow map): the columns tell them apart.
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: 5, rate_hz: 8}\n"),
            "executor.rate_hz: duplicate key (line 2 column 12 and line 2 column 24)");
  // Refused even where the reader would not look (an unknown section is reported as such only
  // after the structure is sound) and whatever the values.
  EXPECT_EQ(error_of("version: 1\nfoo: {a: 1, a: 1}\n"),
            "foo.a: duplicate key (line 2 column 7 and line 2 column 13)");
  EXPECT_EQ(code_of("version: 1\nversion: 1\n"), "config.duplicate_key");
}

TEST(Config, TypeErrors_SayWhatWasExpectedAndWhatWasFound) {
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: fast}\n"),
            "executor.rate_hz: expected a number, got a string 'fast'");
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: [10]}\n"),
            "executor.rate_hz: expected a number, got a list");
  EXPECT_EQ(error_of("version: 1\nexecutor: {workers: 2.5}\n"),
            "executor.workers: expected an integer, got a number '2.5'");
  EXPECT_EQ(error_of("version: 1\nexecutor: {workers: 0x10}\n"),
            "executor.workers: expected an integer, got a string '0x10'");
  EXPECT_EQ(error_of("version: 1\nexecutor: {workers: true}\n"),
            "executor.workers: expected an integer, got a bool 'true'");
  EXPECT_EQ(error_of("version: 1\nexecutor: {lock_memory: 1}\n"),
            "executor.lock_memory: expected a bool (true or false), got a number '1'");
  EXPECT_EQ(error_of("version: 1\npose: {topic: {name: x}}\n"),
            "pose.topic: expected a string, got a map");
  EXPECT_EQ(error_of("version: 1\ndds: {transport: [localhost]}\n"),
            "dds.transport: expected a string (one of {localhost, shm, network}), got a list");
  EXPECT_EQ(error_of("version: 1\nexecutor: {cpus: 3}\n"),
            "executor.cpus: expected a list of integers, got a number '3'");
  EXPECT_EQ(error_of("version: 1\nexecutor: {cpus: [0, one]}\n"),
            "executor.cpus[1]: expected an integer, got a string 'one'");
  EXPECT_EQ(error_of("version: 1\ndds: {network_interfaces: [lo, [eth0]]}\n"),
            "dds.network_interfaces[1]: expected a string, got a list");
  EXPECT_EQ(error_of("version: 1\ndds: {initial_peers: 10.0.0.1}\n"),
            "dds.initial_peers: expected a list of strings, got a string '10.0.0.1'");
  EXPECT_EQ(error_of("version: 1\nexecutor: [rate_hz, 5]\n"),
            "executor: expected a map, got a list");
  EXPECT_EQ(error_of("version: 1\nsensors: {id: front}\n"),
            "sensors: expected a list of maps, got a map");
  EXPECT_EQ(error_of("version: 1\nsensors: [front]\n"),
            "sensors[0]: expected a map, got a string 'front'");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, extrinsic: {translation_m: [1, 2, 3]}}\n"),
            "sensors[0].extrinsic.translation_m: expected a map, got a list");
  EXPECT_EQ(error_of("- version\n- 1\n"), "<root>: expected a map, got a list");
  EXPECT_EQ(error_of("version: 1\n[a, b]: 1\n"),
            "<root>: keys must be strings, got a list at line 2 column 1");
  EXPECT_EQ(code_of("version: 1\nexecutor: {workers: 2.5}\n"), "config.type");
}

TEST(Config, SelfContainingOrExpandingAliases_AreRefusedNotFollowedForever) {
  EXPECT_EQ(code_of("version: 1\nexecutor: {cpus: &loop [*loop]}\n"), "config.structure");
  EXPECT_NE(error_of("version: 1\nexecutor: {cpus: &loop [*loop]}\n").find("nested deeper than"),
            std::string::npos);
  // 2^30 leaves from 30 lines ("billion laughs"): refused after kMaxNodes visits.
  std::string laughs = "version: 1\nl0: &l0 [1, 1]\n";
  for (int i = 1; i <= 30; ++i) {
    laughs += "l" + std::to_string(i) + ": &l" + std::to_string(i) + " [*l" +
              std::to_string(i - 1) + ", *l" + std::to_string(i - 1) + "]\n";
  }
  EXPECT_NE(error_of(laughs).find("more than 100000 nodes"), std::string::npos);
}

TEST(Config, CorrectionKeysAreReadAndChecked) {
  auto ok = load_config_string(
      "version: 1\ncorrections: {retain_scans: 20, jump_threshold_m: 1.5, "
      "jump_threshold_deg: 5, max_prediction_gap_s: 0.2, rebuild_points_per_cycle: 0}\n"
      "pose: {correction_topic: rt/loop/path}\nbudgets: {rebuild_ms: 80}\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  const auto& k = ok.value().mapping.corrections;
  EXPECT_EQ(k.retain_scans, 20);
  EXPECT_EQ(k.jump_threshold_m, 1.5);
  EXPECT_EQ(k.jump_threshold_deg, 5.0);
  EXPECT_EQ(k.max_prediction_gap_s, 0.2);
  EXPECT_EQ(k.rebuild_points_per_cycle, 0u);
  EXPECT_EQ(ok.value().pose.correction_topic, "rt/loop/path");
  EXPECT_EQ(ok.value().budgets.rebuild_ms, 80.0);
  EXPECT_EQ(error_of("version: 1\ncorrections: {retain_scans: 0}\n"),
            "corrections.retain_scans: must be in [1, 10000], got 0");
  EXPECT_EQ(error_of("version: 1\ncorrections: {jump_threshold_deg: 181}\n"),
            "corrections.jump_threshold_deg: must be in [0.01, 180], got 181");
  EXPECT_EQ(error_of("version: 1\ncorrections: {retain: 3}\n"), "corrections.retain: unknown key");
  EXPECT_NE(error_of("version: 1\npose: {correction_topic: ''}\n").find("pose.correction_topic"),
            std::string::npos);
}

TEST(Config, VersionIsRequiredAndChecked) {
  EXPECT_NE(error_of("dds: {}\n").find("version:"), std::string::npos);
  EXPECT_NE(error_of("version: 2\n").find("this build reads version 1"), std::string::npos);
}

TEST(Config, NetworkTransportIsAnExplicitOptIn) {
  EXPECT_NE(error_of("version: 1\ndds: {transport: network}\n").find("dds.network_interfaces"),
            std::string::npos);
  auto ok =
      load_config_string("version: 1\ndds: {transport: network, network_interfaces: [10.1.0.5]}\n");
  ASSERT_TRUE(ok.ok()) << ok.error().message;
  EXPECT_EQ(ok.value().dds.participant.network_interfaces, std::vector<std::string>{"10.1.0.5"});
}

TEST(Config, QosOverridesApplyAndChangeTheHash) {
  auto config = load_config_string(
      "version: 1\ndds: {qos: {esdf_slice: {reliability: reliable, depth: 3}}}\n");
  ASSERT_TRUE(config.ok());
  EXPECT_EQ(config.value().dds.qos.esdf_slice.reliability, transport::Reliability::kReliable);
  EXPECT_EQ(config.value().dds.qos.esdf_slice.history_depth, 3u);
  EXPECT_NE(config_hash(config.value()), config_hash(Config{}));
  EXPECT_EQ(config_hash(Config{}), config_hash(Config{}));
}

TEST(Config, SyntaxErrorsAreReportedNotThrown) {
  auto result = load_config_string("version: 1\ndds: {domain_id: [1,\n");
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.error().code, "config.syntax");
}

TEST(Config, TsdfSectionAppliesAndIsValidated) {
  auto config = load_config_string(
      "version: 1\ntsdf: {enabled: false, voxel_size_m: 0.2, truncation_m: 0.6, max_weight: 20,\n"
      "       max_range_m: 80, space_carving: true, reserve_blocks: 4096}\n");
  ASSERT_TRUE(config.ok()) << config.error().message;
  const auto& t = config.value().mapping.tsdf;
  EXPECT_FALSE(t.enabled);
  EXPECT_FLOAT_EQ(t.voxel_size_m, 0.2f);
  EXPECT_FLOAT_EQ(t.truncation_m, 0.6f);
  EXPECT_FLOAT_EQ(t.max_weight, 20.f);
  EXPECT_FLOAT_EQ(t.max_range_m, 80.f);
  EXPECT_TRUE(t.space_carving);
  EXPECT_EQ(t.reserve_blocks, 4096u);
  EXPECT_NE(config_hash(config.value()), config_hash(Config{}));
  EXPECT_EQ(error_of("version: 1\ntsdf: {trunction_m: 0.3}\n"),
            "tsdf.trunction_m: unknown key (did you mean 'truncation_m'?)");
  EXPECT_EQ(error_of("version: 1\ntsdf: {max_weight: 0}\n"),
            "tsdf.max_weight: must be in [1, 1e+06], got 0");
  EXPECT_EQ(error_of("version: 1\ntsdf: {voxel_size_m: 0.2, truncation_m: 0.1}\n"),
            "tsdf.truncation_m: must be in [voxel_size_m, 32 * voxel_size_m]");
}

// Found by tools/fuzz.sh config: the cross-key checks the core makes (a TSDF truncation against
// its voxel size) came back with the core's code "tsdf.invalid", where every refused config
// carries a config.* code (the fuzz target's contract, and what tarmacd prints in brackets).
TEST(Config, CoreCrossKeyChecks_RefuseWithAConfigCode) {
  EXPECT_EQ(code_of("version: 1\ntsdf: {voxel_size_m: 0.2, truncation_m: 0.1}\n"), "config.range");
  EXPECT_EQ(code_of("version: 1\ntsdf: {voxel_size_m: 0.2, truncation_m: 6.5}\n"), "config.range");
  EXPECT_EQ(code_of("version: 1\nesdf_band: {enabled: true, above_m: 10}\n"), "config.range");
}

TEST(Config, EsdfBandSectionAppliesAndIsValidated) {
  auto config = load_config_string(
      "version: 1\nesdf_band: {enabled: true, below_m: 0.4, above_m: 2.0, unknown: occupied,\n"
      "            publish_radius_m: 0}\nbudgets: {esdf_band_ms: 12}\n"
      "outputs: {esdf_band_topic: rt/vehicle7/esdf_band}\n"
      "dds: {qos: {esdf_band: {reliability: reliable}}}\n");
  ASSERT_TRUE(config.ok()) << config.error().message;
  const auto& c = config.value();
  EXPECT_TRUE(c.mapping.esdf_band.enabled);
  EXPECT_EQ(c.mapping.esdf_band.below_m, 0.4);
  EXPECT_EQ(c.mapping.esdf_band.above_m, 2.0);
  EXPECT_EQ(c.mapping.esdf_band.unknown, core::UnknownPolicy::kUnknownIsOccupied);
  EXPECT_EQ(c.mapping.esdf_band.publish_radius_m, 0.0);
  EXPECT_EQ(c.budgets.esdf_band_ms, 12.0);
  EXPECT_EQ(c.outputs.esdf_band_topic, "rt/vehicle7/esdf_band");
  EXPECT_EQ(c.dds.qos.esdf_band.reliability, transport::Reliability::kReliable);
  EXPECT_FALSE(Config{}.mapping.esdf_band.enabled) << "off by default";
  // The band must fit the window (default: 3 m below the base, 5 m above).
  EXPECT_EQ(error_of("version: 1\nesdf_band: {enabled: true, above_m: 10}\n"),
            "esdf_band.above_m: reaches above the window's top (5.000000 m above the base)");
  EXPECT_EQ(error_of("version: 1\nesdf_band: {enabled: true, below_m: 4}\n"),
            "esdf_band.below_m: reaches below the window (occupancy.window_below_m)");
  EXPECT_EQ(error_of("version: 1\nesdf_band: {unknown: maybe}\n"),
            "esdf_band.unknown: must be one of {report, occupied}, got 'maybe'");
  EXPECT_EQ(error_of("version: 1\nesdf_band: {enabled: true}\noutputs: {esdf_band_topic: \"\"}\n"),
            "outputs.esdf_band_topic: must not be empty when esdf_band.enabled is true");
}

TEST(Config, FleetSectionIsReadAndValidated) {
  auto config = load_config_string(
      "version: 1\nfleet: {vehicle_id: tug-7, topic: /tarmac/fleet/bev, publish_period_s: 0.5,\n"
      "        max_age_s: 20}\n");
  ASSERT_TRUE(config.ok()) << config.error().message;
  const FleetConfig& f = config.value().fleet;
  EXPECT_FALSE(f.enabled);
  EXPECT_EQ(f.vehicle_id, "tug-7");
  EXPECT_EQ(f.topic, "rt/tarmac/fleet/bev");  // ROS form mapped to the DDS form
  EXPECT_EQ(f.publish_period_s, 0.5);
  EXPECT_EQ(f.max_age_s, 20.0);
  EXPECT_EQ(Config{}.fleet.topic, "rt/tarmac/fleet/bev");
  EXPECT_EQ(error_of("version: 1\nfleet: {enabled: true}\n"),
            "fleet.vehicle_id: must be 1..64 of [A-Za-z0-9_-] when fleet.enabled is true");
  EXPECT_EQ(error_of("version: 1\nfleet: {enabled: true, vehicle_id: \"tug 7\"}\n"),
            "fleet.vehicle_id: must be 1..64 of [A-Za-z0-9_-] when fleet.enabled is true");
  EXPECT_EQ(error_of("version: 1\nfleet: {enabled: true, vehicle_id: tug-7, max_age_s: 0.5}\n"),
            "fleet.max_age_s: must be at least fleet.publish_period_s");
  auto enabled = load_config_string("version: 1\nfleet: {enabled: true, vehicle_id: tug-7}\n");
  ASSERT_TRUE(enabled.ok()) << enabled.error().message;
  EXPECT_TRUE(enabled.value().fleet.enabled);
}

TEST(Config, ShippedDefaultsAreOneFrontLidarOnTheDesignTopics) {
  const Config c;
  ASSERT_EQ(c.sensors.size(), 1u);
  EXPECT_EQ(c.sensors[0].id, "front");
  EXPECT_EQ(c.sensors[0].frame_id, "lidar_front");
  EXPECT_EQ(c.sensors[0].topic, "rt/tarmac/lidar/front/points");
  EXPECT_TRUE(c.sensors[0].T_base_sensor.isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_EQ(c.pose.topic, "rt/tarmac/pose");
  EXPECT_EQ(c.outputs.costmap_topic, "rt/tarmac/costmap");
  EXPECT_EQ(c.executor.rate_hz, 10.0);
}

TEST(Config, SensorsListIsReadWithExtrinsicsAndDefaultsPerId) {
  auto config = load_config_string(
      "version: 1\n"
      "sensors:\n"
      "  - id: front\n"
      "    extrinsic: {translation_m: {x: 1.5, z: 2.0}, rpy_deg: {yaw: 90}}\n"
      "  - id: rear\n"
      "    extrinsic: {quaternion: {x: 0, y: 0, z: 1, w: 0}}\n"
      "    max_age_ms: 300\n");
  ASSERT_TRUE(config.ok()) << config.error().message;
  const auto& s = config.value().sensors;
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s[1].topic, "rt/tarmac/lidar/rear/points");
  EXPECT_EQ(s[1].frame_id, "lidar_rear");
  EXPECT_EQ(s[1].max_age_ms, 300.0);
  const Eigen::Vector3d p = s[0].T_base_sensor * Eigen::Vector3d(1, 0, 0);
  EXPECT_NEAR(p.x(), 1.5, 1e-12);  // yaw 90: sensor x is base y
  EXPECT_NEAR(p.y(), 1.0, 1e-12);
  EXPECT_NEAR(p.z(), 2.0, 1e-12);
  EXPECT_NEAR((s[1].T_base_sensor * Eigen::Vector3d(1, 0, 0)).x(), -1.0, 1e-12);
}

TEST(Config, DaemonKeysNameTheirPathWhenWrong) {
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: front, frme_id: x}\n"),
            "sensors[0].frme_id: unknown key (did you mean 'frame_id'?)");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a}\n  - {id: a}\n"),
            "sensors[1].id: duplicate id 'a'");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {frame_id: x}\n"),
            "sensors[0].id: is required and must not be empty");
  EXPECT_EQ(error_of("version: 1\nsensors:\n  - {id: a, extrinsic: {quaternion: {x: 1, w: 1}}}\n"),
            "sensors[0].extrinsic.quaternion: must be a unit quaternion (norm 1.414214)");
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: 0}\n"),
            "executor.rate_hz: must be in [0.1, 1000], got 0");
  EXPECT_EQ(error_of("version: 1\nexecutor: {cpus: [0, -1]}\n"),
            "executor.cpus[1]: must be in [0, 1023], got -1");
  EXPECT_EQ(error_of("version: 1\npose: {type: Twist}\n"),
            "pose.type: must be one of {PoseWithCovarianceStamped, Odometry}, got 'Twist'");
  EXPECT_EQ(error_of("version: 1\nbudgets: {integrat_ms: 3}\n"),
            "budgets.integrat_ms: unknown key (did you mean 'integrate_ms'?)");
  EXPECT_EQ(error_of("version: 1\nexecutor: {rate_hz: 20}\n"),
            "budgets.cycle_ms: exceeds the period of executor.rate_hz (50.000000 ms)");
  EXPECT_EQ(error_of("version: 1\nexecutor: {sensor_phase_ms: 100}\n"),
            "executor.sensor_phase_ms: must be below the period of executor.rate_hz");
  EXPECT_EQ(error_of("version: 1\nquotas: {points_per_cycle: 10, points_per_scan: 20}\n"),
            "quotas.points_per_scan: must be <= quotas.points_per_cycle");
}

TEST(Config, SecurityIsOffByDefaultAndItsKeysNameTheirPath) {
  EXPECT_FALSE(Config{}.dds.participant.security.enabled);
  EXPECT_EQ(error_of("version: 1\ndds: {security: {enable: true}}\n"),
            "dds.security.enable: unknown key (did you mean 'enabled'?)");
  EXPECT_EQ(error_of("version: 1\ndds: {security: {enabled: 2}}\n"),
            "dds.security.enabled: expected a bool (true or false), got a number '2'");
  EXPECT_EQ(error_of("version: 1\ndds: {security: {enabled: true}}\n"),
            "dds.security.identity_ca: must be set when dds.security.enabled is true");
  EXPECT_EQ(
      error_of("version: 1\ndds:\n  security: {enabled: true, identity_ca: /nonexistent/ca.pem}\n"),
      "dds.security.identity_ca: '/nonexistent/ca.pem' does not exist");
  // Disabled: paths are kept but not checked, so the switch is one key.
  auto off =
      load_config_string("version: 1\ndds: {security: {identity_ca: /nonexistent/ca.pem}}\n");
  ASSERT_TRUE(off.ok()) << off.error().message;
  EXPECT_EQ(off.value().dds.participant.security.identity_ca, "/nonexistent/ca.pem");
}

TEST(Config, SecurityPathsAreRelativeToTheConfigFileAndChecked) {
  char pattern[] = "/tmp/tarmac-config-security-XXXXXX";
  ASSERT_NE(mkdtemp(pattern), nullptr);
  const std::filesystem::path dir = pattern;
  std::filesystem::create_directories(dir / "dds" / "tarmacd");
  const std::string cert = "-----BEGIN CERTIFICATE-----\nx\n-----END CERTIFICATE-----\n";
  std::ofstream(dir / "dds/ca.cert.pem") << cert;
  std::ofstream(dir / "dds/tarmacd/cert.pem") << cert;
  std::ofstream(dir / "dds/tarmacd/key.pem") << "-----BEGIN PRIVATE KEY-----\nx\n";
  std::ofstream(dir / "dds/governance.p7s") << "MIME-Version: 1.0\n";
  std::ofstream(dir / "dds/permissions.p7s") << "MIME-Version: 1.0\n";
  const std::string security =
      "version: 1\n"
      "dds:\n"
      "  security:\n"
      "    enabled: true\n"
      "    identity_ca: dds/ca.cert.pem\n"
      "    identity_certificate: dds/tarmacd/cert.pem\n"
      "    private_key: dds/tarmacd/key.pem\n"
      "    permissions_ca: " +
      (dir / "dds/ca.cert.pem").string() +
      "\n"
      "    governance: dds/governance.p7s\n"
      "    permissions: dds/permissions.p7s\n";
  std::ofstream(dir / "tarmac.yaml") << security;
  auto config = load_config_file((dir / "tarmac.yaml").string());
  ASSERT_TRUE(config.ok()) << config.error().message;
  const auto& s = config.value().dds.participant.security;
  EXPECT_TRUE(s.enabled);
  EXPECT_EQ(s.identity_ca, (dir / "dds/ca.cert.pem").string());
  EXPECT_EQ(s.identity_certificate, (dir / "dds/tarmacd/cert.pem").string());
  EXPECT_EQ(s.private_key, (dir / "dds/tarmacd/key.pem").string());
  EXPECT_EQ(s.permissions_ca, (dir / "dds/ca.cert.pem").string());
  EXPECT_EQ(s.governance, (dir / "dds/governance.p7s").string());
  EXPECT_EQ(s.permissions, (dir / "dds/permissions.p7s").string());
  EXPECT_NE(to_yaml(config.value()).find("private_key: " + s.private_key), std::string::npos);
  EXPECT_NE(config_hash(config.value()), config_hash(Config{}));

  // A private key that is a certificate (swapped paths) is caught with the key path.
  std::string swapped = security;
  swapped.replace(swapped.find("dds/tarmacd/key.pem"), 19, "dds/tarmacd/cert.pem");
  std::ofstream(dir / "swapped.yaml") << swapped;
  auto bad = load_config_file((dir / "swapped.yaml").string());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, "config.security");
  EXPECT_EQ(bad.error().message, (dir / "swapped.yaml").string() + ": dds.security.private_key: '" +
                                     (dir / "dds/tarmacd/cert.pem").string() +
                                     "' is not a PEM private key (no 'PRIVATE KEY-----')");
  // Relative to the file's folder, not to the working directory.
  auto from_string = load_config_string(security);
  ASSERT_FALSE(from_string.ok());
  EXPECT_EQ(from_string.error().message,
            "dds.security.identity_ca: 'dds/ca.cert.pem' does not exist");
  std::filesystem::remove_all(dir);
}

TEST(Config, RosTopicNamesAreMappedToTheirDdsForm_OthersRefused) {
  auto c = load_config_string(
      "version: 1\nsensors: [{id: roof, topic: /vehicle/roof/points}]\npose: {topic: /loc/pose}\n"
      "outputs: {costmap_topic: /tarmac/costmap, obstacle_grid_topic: /tarmac/obstacle_grid}\n");
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c.value().sensors[0].topic, "rt/vehicle/roof/points");
  EXPECT_EQ(c.value().pose.topic, "rt/loc/pose");
  EXPECT_EQ(c.value().outputs.costmap_topic, "rt/tarmac/costmap");
  EXPECT_EQ(c.value().outputs.obstacle_grid_topic, "rt/tarmac/obstacle_grid");
  // Already in DDS form: kept.
  auto d = load_config_string("version: 1\noutputs: {costmap_topic: rt/a/b}\n");
  ASSERT_TRUE(d.ok());
  EXPECT_EQ(d.value().outputs.costmap_topic, "rt/a/b");
  // Names a ROS 2 node could not see are refused, saying why.
  const std::string plain = error_of("version: 1\noutputs: {costmap_topic: tarmac_costmap}\n");
  EXPECT_NE(plain.find("outputs.costmap_topic: 'tarmac_costmap' is not a ROS 2 topic"),
            std::string::npos)
      << plain;
  EXPECT_NE(error_of("version: 1\npose: {topic: /loc//pose}\n").find("pose.topic"),
            std::string::npos);
  EXPECT_NE(error_of("version: 1\npose: {topic: /loc/9pose}\n").find("starting with a digit"),
            std::string::npos);
  EXPECT_NE(error_of("version: 1\npose: {topic: /loc/pose/}\n").find("ends with '/'"),
            std::string::npos);
  EXPECT_NE(error_of("version: 1\npose: {topic: /loc/po-se}\n").find("'-'"), std::string::npos);
  // A ROS name and its DDS form are the same topic.
  EXPECT_NE(error_of("version: 1\nsensors: [{id: a, topic: /x/p}, {id: b, topic: rt/x/p}]\n")
                .find("duplicate topic"),
            std::string::npos);
  EXPECT_NE(error_of("version: 1\noutputs: {obstacle_grid_topic: /tarmac/costmap}\n")
                .find("must differ from outputs.costmap_topic"),
            std::string::npos);
}

// Found by fuzzing (tests/fuzz/config_fuzz.cpp): an id such as "front-left" made the default
// topic rt/tarmac/lidar/front-left/points, which was accepted unchecked, written by to_yaml and
// refused when that output was loaded again. The default is checked as a given topic is.
TEST(Config, SensorIdThatMakesAnInvalidDefaultTopic_IsRefused_AGivenTopicIsNot) {
  const std::string why = error_of("version: 1\nsensors: [{id: front-left}]\n");
  EXPECT_NE(why.find("sensors[0].id: 'front-left' makes the default topic "
                     "'rt/tarmac/lidar/front-left/points', which has a character ROS 2 names "
                     "refuse: '-'"),
            std::string::npos)
      << why;
  EXPECT_EQ(code_of("version: 1\nsensors: [{id: front-left}]\n"), "config.value");
  auto given = load_config_string(
      "version: 1\nsensors: [{id: front-left, topic: /lidar/front_left/points}]\n");
  ASSERT_TRUE(given.ok()) << given.error().message;
  EXPECT_EQ(given.value().sensors[0].id, "front-left");
  // What to_yaml writes of an accepted config loads again.
  EXPECT_TRUE(load_config_string(to_yaml(given.value())).ok());
}

/// Sets an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    setenv(name, value, 1);
  }
  ~ScopedEnv() {
    if (old_.empty()) {
      unsetenv(name_);
    } else {
      setenv(name_, old_.c_str(), 1);
    }
  }

 private:
  const char* name_;
  std::string old_;
};

TEST(Config, RosDomainIdApplies_OnlyWhenTheFileSetsNoDomain) {
  {
    ScopedEnv env("ROS_DOMAIN_ID", "42");
    auto unset = load_config_string("version: 1\n");
    ASSERT_TRUE(unset.ok());
    EXPECT_EQ(unset.value().dds.participant.domain_id, 42u);
    auto set = load_config_string("version: 1\ndds: {domain_id: 7}\n");
    ASSERT_TRUE(set.ok());
    EXPECT_EQ(set.value().dds.participant.domain_id, 7u) << "the file wins";
  }
  {
    ScopedEnv env("ROS_DOMAIN_ID", "300");
    EXPECT_NE(error_of("version: 1\n").find("ROS_DOMAIN_ID='300'"), std::string::npos);
  }
  {
    ScopedEnv env("ROS_DOMAIN_ID", "");
    auto c = load_config_string("version: 1\n");
    ASSERT_TRUE(c.ok());
    EXPECT_EQ(c.value().dds.participant.domain_id, 0u);
  }
}

TEST(Config, RvizViewSubscribesToTheTopicsTarmacPublishes) {
  // config/tarmac.rviz names ROS 2 topics; with the outputs its header asks for, each must be one
  // tarmacd publishes or reads, with a QoS that matches.
  const auto view = YAML::LoadFile(std::string(TARMAC_SOURCE_DIR) + "/config/tarmac.rviz");
  auto cfg = load_config_string(
      "version: 1\noutputs: {obstacle_grid_topic: /tarmac/obstacle_grid, "
      "esdf_slice_grid_topic: /tarmac/esdf_slice_grid}\n");
  ASSERT_TRUE(cfg.ok()) << cfg.error().message;
  const auto& o = cfg.value().outputs;
  const std::vector<std::string> grids{o.costmap_topic, o.obstacle_grid_topic,
                                       o.esdf_slice_grid_topic};
  int maps = 0;
  for (const auto& display : view["Visualization Manager"]["Displays"]) {
    const auto cls = display["Class"].as<std::string>();
    if (cls == "rviz_default_plugins/Map") {
      ++maps;
      const std::string dds = "rt" + display["Topic"]["Value"].as<std::string>();
      EXPECT_NE(std::find(grids.begin(), grids.end(), dds), grids.end()) << dds;
      // tarmac's grids are reliable + transient local (dds.qos.costmap).
      EXPECT_EQ(display["Topic"]["Durability Policy"].as<std::string>(), "Transient Local");
      EXPECT_EQ(display["Topic"]["Reliability Policy"].as<std::string>(), "Reliable");
    } else if (cls == "rviz_default_plugins/PoseWithCovariance") {
      EXPECT_EQ("rt" + display["Topic"]["Value"].as<std::string>(), cfg.value().pose.topic);
    } else if (cls == "rviz_default_plugins/PointCloud2") {
      EXPECT_EQ("rt" + display["Topic"]["Value"].as<std::string>(), cfg.value().sensors[0].topic);
    }
  }
  EXPECT_EQ(maps, 3);
  EXPECT_EQ(view["Visualization Manager"]["Global Options"]["Fixed Frame"].as<std::string>(),
            o.frame_id);
}

}  // namespace
}  // namespace tarmac::config
