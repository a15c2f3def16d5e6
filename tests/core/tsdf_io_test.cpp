#include "tarmac/core/tsdf_io.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <random>
#include <tuple>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

namespace fs = std::filesystem;

/// A small map: a few hundred rays onto a wall, integrated twice.
TsdfLayer small_map() {
  TsdfParams p;
  TsdfIntegrator integrator(p);
  TsdfLayer layer = integrator.make_layer();
  std::vector<Eigen::Vector3f> pts;
  for (int i = -20; i <= 20; ++i)
    for (int j = -10; j <= 10; ++j) pts.emplace_back(6.03f, 0.05f * i, 0.05f * j);
  SerialRunner runner;
  integrator.integrate(Eigen::Vector3d(0.01, 0.02, 0.03), pts, layer, runner);
  integrator.integrate(Eigen::Vector3d(0.21, 0.02, 0.03), pts, layer, runner);
  return layer;
}

class TsdfIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("tarmac_tsdf_io_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TsdfMapInfo info() {
  TsdfMapInfo i;
  i.frame_id = "map";
  i.config_hash = "0123456789abcdef";
  i.stamp_ns = 1767225600123456789;
  return i;
}

std::string read_all(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void write_all(const fs::path& f, const std::string& bytes) {
  std::ofstream out(f, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

TEST_F(TsdfIo, SaveLoad_RoundTripIsIdentical) {
  const TsdfLayer layer = small_map();
  ASSERT_GT(layer.voxel_count(), 1000u);
  const fs::path f = dir_ / "tsdf.vdb";
  ASSERT_TRUE(save_tsdf(f, layer, info()).ok());
  EXPECT_FALSE(fs::exists(dir_ / "tsdf.vdb.tmp"));
  auto loaded = load_tsdf(f);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  const LoadedTsdf& l = loaded.value();
  EXPECT_EQ(l.layer.digest(), layer.digest());
  EXPECT_EQ(l.layer.voxel_count(), layer.voxel_count());
  EXPECT_EQ(l.layer.block_count(), layer.block_count());
  EXPECT_EQ(l.info.frame_id, "map");
  EXPECT_EQ(l.info.config_hash, "0123456789abcdef");
  EXPECT_EQ(l.info.stamp_ns, 1767225600123456789);
  EXPECT_EQ(l.info.voxel_size_m, layer.voxel_size_m());
  EXPECT_EQ(l.info.truncation_m, layer.truncation_m());
  EXPECT_TRUE(check_tsdf_matches(l.info, "map", 0.1f, 0.3f).ok());
}

TEST_F(TsdfIo, SaveLoad_LoadedMapKeepsIntegratingLikeTheOriginal) {
  TsdfLayer original = small_map();
  const fs::path f = dir_ / "tsdf.vdb";
  ASSERT_TRUE(save_tsdf(f, original, info()).ok());
  auto loaded = load_tsdf(f);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  TsdfLayer again = std::move(loaded).value().layer;
  TsdfIntegrator integrator{TsdfParams{}};
  std::vector<Eigen::Vector3f> pts;
  for (int i = -30; i <= 30; ++i) pts.emplace_back(5.93f, 0.04f * i, 0.1f);
  SerialRunner runner;
  integrator.integrate(Eigen::Vector3d(0.1, 0.0, 0.0), pts, original, runner);
  integrator.integrate(Eigen::Vector3d(0.1, 0.0, 0.0), pts, again, runner);
  EXPECT_EQ(again.digest(), original.digest());
  EXPECT_EQ(again.voxel_count(), original.voxel_count());
}

TEST_F(TsdfIo, Save_ReplacesAtomicallyAndKeepsOldFileOnFailure) {
  const TsdfLayer layer = small_map();
  const fs::path f = dir_ / "tsdf.vdb";
  ASSERT_TRUE(save_tsdf(f, layer, info()).ok());
  TsdfLayer empty(0.1f, 0.3f);
  ASSERT_TRUE(save_tsdf(f, empty, info()).ok());
  EXPECT_EQ(load_tsdf(f).value().layer.voxel_count(), 0u);
  // A save into a missing directory fails with a Result and leaves nothing behind.
  const auto bad = save_tsdf(dir_ / "missing" / "tsdf.vdb", layer, info());
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, "tsdf_io.write");
}

TEST_F(TsdfIo, Load_RefusesTruncatedFiles) {
  const fs::path f = dir_ / "tsdf.vdb";
  ASSERT_TRUE(save_tsdf(f, small_map(), info()).ok());
  const std::string bytes = read_all(f);
  for (const std::size_t keep :
       {std::size_t{0}, std::size_t{10}, bytes.size() / 3, bytes.size() - 33, bytes.size() - 1}) {
    const fs::path t = dir_ / "truncated.vdb";
    write_all(t, bytes.substr(0, keep));
    const auto r = load_tsdf(t);
    ASSERT_FALSE(r.ok()) << keep;
    EXPECT_EQ(r.error().code, "tsdf_io.truncated") << keep;
  }
  const auto missing = load_tsdf(dir_ / "nope.vdb");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().code, "tsdf_io.open");
}

TEST_F(TsdfIo, Load_RefusesCorruptedFiles) {
  const fs::path f = dir_ / "tsdf.vdb";
  ASSERT_TRUE(save_tsdf(f, small_map(), info()).ok());
  const std::string bytes = read_all(f);
  std::mt19937 rng(3);
  // Single flipped bytes anywhere in the .vdb part (header, metadata, tree, compressed data).
  for (int trial = 0; trial < 40; ++trial) {
    std::string bad = bytes;
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, bytes.size() - 33)(rng);
    bad[at] = static_cast<char>(bad[at] ^ 0x5a);
    const fs::path c = dir_ / "corrupt.vdb";
    write_all(c, bad);
    const auto r = load_tsdf(c);
    ASSERT_FALSE(r.ok()) << at;
    EXPECT_EQ(r.error().code, "tsdf_io.corrupt") << at;
  }
}

TEST_F(TsdfIo, Load_RefusesForeignFilesAndMismatchedMaps) {
  const fs::path f = dir_ / "not_a_map.vdb";
  write_all(f, std::string(4096, 'x'));
  const auto r = load_tsdf(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().code, "tsdf_io.truncated");
  TsdfMapInfo i = info();
  i.voxel_size_m = 0.1f;
  i.truncation_m = 0.3f;
  EXPECT_EQ(check_tsdf_matches(i, "map", 0.2f, 0.3f).error().code, "tsdf_io.mismatch");
  EXPECT_EQ(check_tsdf_matches(i, "map", 0.1f, 0.4f).error().code, "tsdf_io.mismatch");
  EXPECT_EQ(check_tsdf_matches(i, "odom", 0.1f, 0.3f).error().code, "tsdf_io.mismatch");
  EXPECT_TRUE(check_tsdf_matches(i, "map", 0.1f, 0.3f).ok());
}

/// A static occupancy layer with voxels on both sides of 0 along every axis, unsorted.
StaticOccupancy static_layer() {
  StaticOccupancy s;
  s.voxel_size_m = 0.2f;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> d(-3000, 3000);
  for (int i = 0; i < 5000; ++i) s.voxels.emplace_back(d(rng), d(rng), d(rng) / 100);
  s.voxels.emplace_back(0, 0, 0);
  s.voxels.emplace_back(-1, -1, -1);
  return s;
}

TEST_F(TsdfIo, StaticOccupancy_RoundTripIsIdentical) {
  const TsdfLayer layer = small_map();
  StaticOccupancy occ = static_layer();
  const fs::path f = dir_ / "map.vdb";
  ASSERT_TRUE(save_tsdf(f, layer, info(), &occ).ok());
  auto loaded = load_tsdf(f);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded.value().layer.digest(), layer.digest());
  std::sort(occ.voxels.begin(), occ.voxels.end(),
            [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
              return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
            });
  occ.voxels.erase(std::unique(occ.voxels.begin(), occ.voxels.end()), occ.voxels.end());
  EXPECT_EQ(loaded.value().occupancy.voxel_size_m, 0.2f);
  EXPECT_EQ(loaded.value().occupancy.voxels, occ.voxels);
  EXPECT_TRUE(check_static_occupancy_matches(loaded.value().occupancy, 0.2f).ok());
  // A TSDF saved without it loads with none (and matches any occupancy voxel size).
  ASSERT_TRUE(save_tsdf(f, layer, info()).ok());
  auto bare = load_tsdf(f);
  ASSERT_TRUE(bare.ok());
  EXPECT_EQ(bare.value().occupancy.voxel_size_m, 0.0f);
  EXPECT_TRUE(bare.value().occupancy.voxels.empty());
  EXPECT_TRUE(check_static_occupancy_matches(bare.value().occupancy, 0.1f).ok());
}

TEST_F(TsdfIo, StaticOccupancy_RefusesOtherVoxelSizeAndDamage) {
  const TsdfLayer layer = small_map();
  const StaticOccupancy occ = static_layer();
  const fs::path f = dir_ / "map.vdb";
  ASSERT_TRUE(save_tsdf(f, layer, info(), &occ).ok());
  auto loaded = load_tsdf(f);
  ASSERT_TRUE(loaded.ok());
  const Status other = check_static_occupancy_matches(loaded.value().occupancy, 0.1f);
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.error().code, "tsdf_io.mismatch");
  EXPECT_NE(other.error().message.find("static occupancy voxel 0.2 m, expected 0.1 m"),
            std::string::npos)
      << other.error().message;
  // One flipped byte in the middle of the file (the static grid is in the checksummed part).
  std::string bytes = read_all(f);
  bytes[bytes.size() / 2] ^= 0x10;
  write_all(f, bytes);
  auto damaged = load_tsdf(f);
  ASSERT_FALSE(damaged.ok());
  EXPECT_EQ(damaged.error().code, "tsdf_io.corrupt");
}

}  // namespace
}  // namespace tarmac::core
