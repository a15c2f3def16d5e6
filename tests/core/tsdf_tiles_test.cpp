// TSDF tiles (tsdf_tiles.hpp): a tile leaves a layer and comes back bit for bit, through bytes;
// while it is away nothing is built in it; a digest taken tile by tile is the layer's.
#include "tarmac/core/tsdf_tiles.hpp"

#include <algorithm>
#include <map>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/core/occupancy_map.hpp"

namespace tarmac::core {
namespace {

/// Rays onto walls around the origin, so the map spans tiles (and top nodes) on both sides of
/// zero along every axis.
std::vector<Eigen::Vector3f> walls() {
  std::vector<Eigen::Vector3f> pts;
  for (int i = -60; i <= 60; ++i) {
    for (int j = -20; j <= 20; ++j) {
      pts.emplace_back(14.03f, 0.21f * static_cast<float>(i), 0.13f * static_cast<float>(j));
      pts.emplace_back(-13.1f, 0.19f * static_cast<float>(i), 0.11f * static_cast<float>(j));
      pts.emplace_back(0.23f * static_cast<float>(i), -12.9f, 0.17f * static_cast<float>(j));
    }
  }
  return pts;
}

TsdfLayer mapped(const TsdfParams& p, int scans) {
  TsdfIntegrator integrator(p);
  TsdfLayer layer = integrator.make_layer();
  SerialRunner runner;
  for (int s = 0; s < scans; ++s) {
    integrator.integrate(Eigen::Vector3d(0.1 * s, 0.05 * s, 0.02), walls(), layer, runner);
  }
  return layer;
}

std::uint64_t tile_digest(const TsdfTile& tile) {
  TsdfDigest d;
  tile.for_each_block([&d](const TsdfBlockView& b) { d.add(b); });
  return d.value();
}

TEST(TsdfTiles, EncodeDecode_BitIdentical_IntegerAndFloatWeights) {
  for (const float max_weight : {64.f, 400.f, 2.5f}) {  // u8, u16 and float32 weights
    TsdfParams p;
    p.max_weight = max_weight;
    TsdfLayer layer = mapped(p, max_weight > 300.f ? 300 : 4);
    const std::vector<TsdfTileInfo> tiles = layer.resident_tiles();
    ASSERT_GE(tiles.size(), 4u);
    for (const TsdfTileInfo& info : tiles) {
      const std::optional<TsdfTile> tile = layer.copy_tile(info.tile);
      ASSERT_TRUE(tile.has_value());
      EXPECT_EQ(tile->block_count(), info.blocks);
      const std::vector<std::uint8_t> bytes = tile->encode(p.voxel_size_m, p.truncation_m);
      // Smaller than the blocks in memory: only the observed voxels are written.
      EXPECT_LT(bytes.size(), info.blocks * kTsdfBlockBytes);
      Result<TsdfTile> back = TsdfTile::decode(bytes, p.voxel_size_m, p.truncation_m, info.tile);
      ASSERT_TRUE(back.ok()) << back.error().message;
      EXPECT_EQ(tile_digest(back.value()), tile_digest(*tile)) << "max_weight " << max_weight;
      EXPECT_EQ(back.value().encode(p.voxel_size_m, p.truncation_m), bytes);
    }
  }
}

TEST(TsdfTiles, Decode_RefusesDamagedOrForeignBytes) {
  const TsdfParams p;
  TsdfLayer layer = mapped(p, 2);
  const TileIndex t = layer.resident_tiles().front().tile;
  const std::vector<std::uint8_t> bytes =
      layer.copy_tile(t)->encode(p.voxel_size_m, p.truncation_m);
  const auto refused = [&](std::vector<std::uint8_t> b, const char* code, float trunc = 0.3f,
                           TileIndex at = TileIndex::Zero()) {
    const Result<TsdfTile> r =
        TsdfTile::decode(b, p.voxel_size_m, trunc, at == TileIndex::Zero() ? t : at);
    return !r.ok() && r.error().code == code;
  };
  EXPECT_TRUE(refused({bytes.begin(), bytes.begin() + 20}, "tsdf_tile.corrupt"));
  EXPECT_TRUE(refused({bytes.begin(), bytes.end() - 1}, "tsdf_tile.corrupt"));
  std::vector<std::uint8_t> flipped = bytes;
  flipped[flipped.size() / 2] ^= 0x10;
  EXPECT_TRUE(refused(flipped, "tsdf_tile.corrupt"));
  std::vector<std::uint8_t> magic = bytes;
  magic[0] = 'X';
  EXPECT_TRUE(refused(magic, "tsdf_tile.corrupt"));
  EXPECT_TRUE(refused(bytes, "tsdf_tile.mismatch", 0.4f));
  EXPECT_TRUE(refused(bytes, "tsdf_tile.mismatch", 0.3f, t + TileIndex(1, 0, 0)));
  EXPECT_TRUE(refused({}, "tsdf_tile.corrupt"));
}

TEST(TsdfTiles, DetachAttach_NothingBuiltWhileAbsent_SameMapAfter) {
  const TsdfParams p;
  TsdfLayer layer = mapped(p, 3);
  const std::uint64_t before = layer.digest();
  const std::size_t blocks = layer.block_count();
  // The tile of the +x wall.
  const TileIndex t = tile_of_block(BlockIndex(140 / 8, 0, 0));
  std::optional<TsdfTile> tile = layer.detach_tile(t);
  ASSERT_TRUE(tile.has_value());
  EXPECT_TRUE(layer.is_absent(t));
  EXPECT_EQ(layer.block_count(), blocks - tile->block_count());
  EXPECT_FALSE(layer.detach_tile(t).has_value());

  // A scan of the same walls while the tile is away: its samples there are refused, no block
  // appears in it, and the other tiles take theirs.
  TsdfIntegrator integrator(p);
  SerialRunner runner;
  TsdfLayer other = mapped(p, 3);
  const TsdfUpdate& u =
      integrator.integrate(Eigen::Vector3d(0.3, 0.15, 0.02), walls(), layer, runner);
  EXPECT_GT(u.blocks_refused, 0u);
  EXPECT_GT(u.samples_refused, 0u);
  for (const BlockIndex& b : u.blocks) EXPECT_NE(tile_of_block(b), t);
  for (const TsdfTileInfo& info : layer.resident_tiles()) EXPECT_NE(info.tile, t);

  // Back: the tile's blocks are the ones it left with.
  const std::uint64_t tile_before = tile_digest(*tile);
  layer.attach_tile(std::move(*tile));
  EXPECT_FALSE(layer.is_absent(t));
  EXPECT_EQ(tile_digest(*layer.copy_tile(t)), tile_before);

  // Detach and attach alone change nothing.
  const std::uint64_t other_before = other.digest();
  for (const TsdfTileInfo& info : other.resident_tiles()) {
    std::optional<TsdfTile> away = other.detach_tile(info.tile);
    other.attach_tile(std::move(*away));
  }
  EXPECT_EQ(other.digest(), other_before);
  EXPECT_EQ(other_before, before);
}

TEST(TsdfTiles, DigestTileByTileInKeyOrder_EqualsTheLayers) {
  const TsdfParams p;
  TsdfLayer layer = mapped(p, 2);
  std::map<TileKey, TsdfTile> away;
  for (const TsdfTileInfo& info : layer.resident_tiles()) {
    away.emplace(TileKey::of(info.tile), *layer.copy_tile(info.tile));
  }
  ASSERT_GE(away.size(), 4u);
  TsdfDigest d;
  for (const auto& [key, tile] : away)
    tile.for_each_block([&d](const TsdfBlockView& b) { d.add(b); });
  EXPECT_EQ(d.value(), layer.digest());
}

TEST(StaticTiles, EncodeDecode_SameVoxels_DamageAndForeignTilesRefused) {
  StaticTile tile{StaticTileIndex(-2, 3), {}};
  for (int z = -3; z < 4; ++z) {
    for (int y = 3 * kStaticTileEdge; y < 4 * kStaticTileEdge; y += 7) {
      tile.voxels.emplace_back(-2 * kStaticTileEdge + (y % kStaticTileEdge), y, z);
    }
  }
  const std::vector<std::uint8_t> bytes = tile.encode(0.2f);
  const Result<StaticTile> back = StaticTile::decode(bytes, 0.2f, tile.index);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back.value().voxels, tile.voxels);
  EXPECT_EQ(static_voxels_digest(back.value().voxels), static_voxels_digest(tile.voxels));

  std::vector<std::uint8_t> flipped = bytes;
  flipped.back() ^= 1;
  EXPECT_EQ(StaticTile::decode(flipped, 0.2f, tile.index).error().code, "static_tile.corrupt");
  const std::vector<std::uint8_t> cut(bytes.begin(), bytes.end() - 3);
  EXPECT_EQ(StaticTile::decode(cut, 0.2f, tile.index).error().code, "static_tile.corrupt");
  EXPECT_EQ(StaticTile::decode(bytes, 0.1f, tile.index).error().code, "static_tile.mismatch");
  EXPECT_EQ(StaticTile::decode(bytes, 0.2f, StaticTileIndex(0, 0)).error().code,
            "static_tile.mismatch");
  StaticTile unsorted = tile;
  std::swap(unsorted.voxels[0], unsorted.voxels[1]);
  EXPECT_EQ(StaticTile::decode(unsorted.encode(0.2f), 0.2f, tile.index).error().code,
            "static_tile.corrupt");
}

/// A window of 64 x 64 x 16 voxels with a static layer spread over many blocks and columns
/// (static voxels join when they leave the window: the window drives along a wall).
TEST(StaticTiles, TakeAndPutColumns_LayerUnchanged_RefusedInTheWindow) {
  OccupancyParams p;
  p.window_x_vox = 64;
  p.window_y_vox = 64;
  p.window_z_vox = 16;
  ASSERT_TRUE(p.validate().ok());
  OccupancyMap map(p);
  std::vector<VoxelIndex> statics;
  for (int x = -300; x < 300; x += 3) {
    for (int z = 0; z < 12; z += 2) statics.emplace_back(x, 17 + (x & 7), z);
  }
  map.import_static(statics);
  map.recenter(Eigen::Vector3d(0.0, 0.0, 0.0));
  std::vector<VoxelIndex> all;
  map.export_static(all);
  ASSERT_EQ(all.size(), statics.size());

  std::vector<VoxelIndex> taken;
  // The window (voxels -32..31) meets column tile 0: refused, nothing taken.
  EXPECT_FALSE(map.take_static_columns(0, 0, 63, 63, taken));
  EXPECT_TRUE(taken.empty());
  std::vector<Eigen::Vector2i> tiles;
  map.static_tiles(kStaticTileEdge, tiles);
  EXPECT_GE(tiles.size(), 8u);
  std::vector<std::vector<VoxelIndex>> away;
  for (const Eigen::Vector2i& t : tiles) {
    const int x0 = t.x() * kStaticTileEdge, y0 = t.y() * kStaticTileEdge;
    std::vector<VoxelIndex> v;
    if (map.take_static_columns(x0, y0, x0 + kStaticTileEdge - 1, y0 + kStaticTileEdge - 1, v)) {
      EXPECT_TRUE(std::is_sorted(v.begin(), v.end(), [](const VoxelIndex& a, const VoxelIndex& b) {
        return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
      }));
      away.push_back(std::move(v));
    }
  }
  ASSERT_GE(away.size(), 6u);
  EXPECT_LT(map.static_count(), statics.size());
  for (const VoxelIndex& v : away.front()) EXPECT_FALSE(map.is_static(v));
  // Every other voxel is still found (removal keeps the table's probe chains intact).
  std::vector<VoxelIndex> left;
  map.export_static(left);
  for (const VoxelIndex& v : left) EXPECT_TRUE(map.is_static(v));
  for (const auto& v : away) map.put_static(v);
  std::vector<VoxelIndex> again;
  map.export_static(again);
  EXPECT_EQ(again, all);
  // A tile put back under the window reads static there at once.
  map.recenter(Eigen::Vector3d(0.2 * 128, 0.0, 0.0));
  std::vector<VoxelIndex> under;
  const int x0 = 128, y0 = 0;
  EXPECT_FALSE(map.take_static_columns(x0, y0, x0 + 63, y0 + 63, under));
  map.recenter(Eigen::Vector3d(0.0, 0.0, 0.0));
  ASSERT_TRUE(map.take_static_columns(x0, y0, x0 + 63, y0 + 63, under));
  ASSERT_FALSE(under.empty());
  EXPECT_EQ(map.log_odds(under.front()), OccupancyMap::kUnknown);
  map.recenter(Eigen::Vector3d(0.2 * 128, 0.0, 0.0));  // the window reaches the tile first
  EXPECT_LT(map.log_odds(under.front()), 0.0f);
  map.put_static(under);
  EXPECT_TRUE(map.is_static(under.front()));
  EXPECT_GT(map.log_odds(under.front()), 0.0f);
}

}  // namespace
}  // namespace tarmac::core
