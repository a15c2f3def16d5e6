// to_yaml and the loader agree: what tarmac writes out loads back to exactly the same text, so
// the config hash (the hash of to_yaml) names one config however often it is written and read.

#include <cstdlib>
#include <utility>

#include <gtest/gtest.h>

#include "tarmac/config/config.hpp"
#include "test_env.hpp"

namespace tarmac::config {
namespace {

TEST(ConfigRoundTrip, DefaultsWriteAndReloadToTheSameText) {
  const std::string written = to_yaml(Config{});
  const auto reloaded = load_config_string(written);
  ASSERT_TRUE(reloaded.ok()) << reloaded.error().message;
  EXPECT_EQ(to_yaml(reloaded.value()), written);
}

// config_hash is the hash of to_yaml and is stored in saved map files: the same config must
// write the same text in every build, so these hashes only change with a deliberate format change.
TEST(ConfigRoundTrip, HashesOfTheShippedConfigsArePinned) {
  unsetenv("ROS_DOMAIN_ID");
  EXPECT_EQ(config_hash(Config{}), "7d037e0ae6ed07d2");
  for (const auto& [file, hash] : {std::pair{"config/tarmac.yaml", "35d8cffc2a1dcf02"},
                                   std::pair{"config/four_lidars.yaml", "e0c7014365daef7c"}}) {
    const auto loaded = load_config_file((test::source_dir() / file).string());
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    EXPECT_EQ(config_hash(loaded.value()), hash) << file;
  }
}

// Every kind of value away from its default: enums, lists, paths, topics given in ROS form,
// rotations as roll-pitch-yaw and as a quaternion, floats.
TEST(ConfigRoundTrip, HashOfAConfigWithEveryKindOfValueIsPinned) {
  const auto loaded = load_config_string(
      "version: 1\n"
      "dds: {domain_id: 7, participant_name: x, transport: network, network_interfaces: "
      "[10.0.0.2], initial_peers: [10.0.0.3, 10.0.0.4], security: {enabled: false, "
      "identity_ca: ca.pem, governance: /etc/g.p7s}, qos: {lidar: {reliability: reliable, "
      "durability: transient_local, depth: 3}}}\n"
      "sensors:\n"
      "  - {id: a, topic: /x/points, deskew: false, max_age_ms: 123.25,\n"
      "     extrinsic: {translation_m: {x: 1.5, y: -0.25}, rpy_deg: {roll: 1, pitch: 2, yaw: "
      "33}}}\n"
      "  - {id: b, driver: hesai, extrinsic: {quaternion: {x: 0, y: 0, z: 0.7071068, w: "
      "0.7071068}}}\n"
      "pose: {type: Odometry, frame_id: odom}\n"
      "executor: {cpus: [1, 0], realtime_priority: 0, lock_memory: false}\n"
      "outputs: {obstacle_grid_topic: /tarmac/obstacles, esdf_slice_grid_range_m: 2.5}\n"
      "occupancy: {prob_hit: 0.66, clamp_max: 0.9}\n"
      "costmap: {unknown_cost: lethal, free_rule: any_voxel}\n"
      "esdf_band: {enabled: true, unknown: occupied}\n"
      "tsdf: {voxel_size_m: 0.15, max_weight: 10}\n"
      "corrections: {enabled: false}\n");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(config_hash(loaded.value()), "f7dc0bd03fa6ed36");
}

// Found by tools/fuzz.sh config (config/four_lidars.yaml with one yaw changed to -45): the
// extrinsic was kept as a matrix only and written as the quaternion of that matrix; reading that
// quaternion back gave a matrix whose quaternion differed in the last digit
// (z: -0.38268343236508984 -> -0.38268343236508989), so the config hash changed on reload.
TEST(ConfigRoundTrip, ExtrinsicYawWritesAndReloadsToTheSameText) {
  const auto loaded = load_config_string(
      "version: 1\n"
      "sensors:\n"
      "  - id: right\n"
      "    extrinsic: {translation_m: {x: 0.0, y: -1.1, z: 1.9}, "
      "rpy_deg: {roll: 0, pitch: 0, yaw: -45}}\n");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  const std::string written = to_yaml(loaded.value());
  const auto reloaded = load_config_string(written);
  ASSERT_TRUE(reloaded.ok()) << reloaded.error().message;
  EXPECT_EQ(to_yaml(reloaded.value()), written);
  EXPECT_EQ(config_hash(reloaded.value()), config_hash(loaded.value()));
}

}  // namespace
}  // namespace tarmac::config
