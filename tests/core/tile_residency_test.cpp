// The residency policy of a paged site (tile_residency.hpp): which TSDF tiles leave memory and
// which are asked back, from the vehicle's position, the resident set and the limit alone; and
// the static occupancy's column tiles round the window.
#include "tarmac/core/tile_residency.hpp"

#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

constexpr double kTileM = 12.8;  // 128 voxels of 0.1 m

/// Bytes a resident tile of `blocks` blocks costs.
std::size_t cost(std::size_t blocks) {
  return kTsdfTileNodeBytes + kTsdfBlockBytes * blocks;
}

TileResidencyParams params(std::size_t limit_bytes) {
  TileResidencyParams p;
  p.limit_bytes = limit_bytes;
  p.voxel_size_m = 0.1f;
  p.need_radius_m = 20.0;
  p.load_radius_m = 30.0;
  p.keep_scans = 2;
  return p;
}

std::size_t bytes_of(const std::vector<TsdfTileInfo>& resident) {
  std::size_t b = 0;
  for (const TsdfTileInfo& t : resident) b += cost(t.blocks);
  return b;
}

/// Ten tiles of 100 blocks along +x from the origin's tile, all changed by scan 1.
std::vector<TsdfTileInfo> row_of_tiles(TsdfResidency& r) {
  std::vector<TsdfTileInfo> resident;
  std::vector<TileIndex> touched;
  for (int x = 0; x < 10; ++x) {
    resident.push_back({TileIndex(x, 0, 0), 100});
    touched.emplace_back(x, 0, 0);
  }
  r.scan_changed(touched);
  return resident;
}

void scans_elsewhere(TsdfResidency& r, int n) {
  for (int i = 0; i < n; ++i) r.scan_changed({});
}

/// row_of_tiles under a limit, last changed `scans_ago` scans ago; evictions with the sensor at
/// the origin.
struct Row {
  explicit Row(std::size_t limit_bytes, int scans_ago = 3) : r(params(limit_bytes)) {
    resident = row_of_tiles(r);
    scans_elsewhere(r, scans_ago);
  }
  std::size_t evict(bool hold = false) {
    return r.choose_evictions(resident, bytes_of(resident), {0, 0, 0}, hold, out);
  }
  TsdfResidency r;
  std::vector<TsdfTileInfo> resident;
  std::vector<TileEviction> out;
};

TEST(TileDistance, InsideIsZero_OutsideToTheNearestEdgeInXY) {
  const TileIndex t(1, 0, 5);  // x in [12.8, 25.6), y in [0, 12.8); z plays no part
  EXPECT_EQ(tile_distance_xy_m(t, {15.0, 3.0, -40.0}, kTileM), 0.0);
  EXPECT_DOUBLE_EQ(tile_distance_xy_m(t, {10.8, 3.0, 0.0}, kTileM), 2.0);
  EXPECT_NEAR(tile_distance_xy_m(t, {28.6, -4.0, 0.0}, kTileM), 5.0, 1e-12);
}

TEST(TsdfResidency, WithinTheLimit_NothingLeaves) {
  Row row(cost(100) * 10);
  EXPECT_EQ(row.evict(), bytes_of(row.resident));
  EXPECT_TRUE(row.out.empty());
}

TEST(TsdfResidency, OverTheLimit_FarthestFirstDownTo90Percent_NeverWithinTheLoadRadius) {
  Row row(cost(100) * 6);
  const std::size_t left = row.evict();
  // 10 tiles over a limit of 6: down to 90 % of it, 5 tiles, so 5 leave, from x = 9 down.
  ASSERT_EQ(row.out.size(), 5u);
  for (std::size_t i = 0; i < row.out.size(); ++i) {
    EXPECT_EQ(row.out[i].tile, TileIndex(9 - static_cast<int>(i), 0, 0));
    EXPECT_TRUE(row.out[i].write);  // never stored: written
  }
  EXPECT_EQ(left, cost(100) * 5);
  EXPECT_EQ(row.r.resident_count(), 5u);
  // Tiles 0..2 lie within 30 m of the sensor: with a tiny limit they still stay.
  Row tight(1);
  tight.evict();
  EXPECT_EQ(tight.out.size(), 7u);
  EXPECT_EQ(tight.out.back().tile, TileIndex(3, 0, 0));
}

TEST(TsdfResidency, TilesChangedByTheLastScans_Stay) {
  Row row(1, 1);  // the tiles were changed one scan ago; keep_scans is 2
  row.evict();
  EXPECT_TRUE(row.out.empty());
  scans_elsewhere(row.r, 1);
  row.evict();
  EXPECT_EQ(row.out.size(), 7u);
}

TEST(TsdfResidency, Hold_NothingLeaves) {
  Row row(1);
  EXPECT_EQ(row.evict(true), bytes_of(row.resident));
  EXPECT_TRUE(row.out.empty());
}

TEST(TsdfResidency, EqualDistances_TieBrokenByTileKey) {
  TsdfResidency r(params(1));
  const std::vector<TsdfTileInfo> resident = {
      {TileIndex(0, 5, 0), 1}, {TileIndex(0, -5, 0), 1}, {TileIndex(0, 5, -1), 1}};
  // Half a tile up in y, the sensor is 4.5 tiles from tiles y = 5 and y = -5 alike.
  const double tile_m = params(1).tile_m();
  std::vector<TileEviction> out;
  r.choose_evictions(resident, bytes_of(resident), {6.4, tile_m / 2, 0}, false, out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[0].tile, TileIndex(0, -5, 0));
  EXPECT_EQ(out[1].tile, TileIndex(0, 5, -1));
  EXPECT_EQ(out[2].tile, TileIndex(0, 5, 0));
}

TEST(TsdfResidency, StoredTile_AskedBackNear_NeededWithinTheNeedRadius) {
  TsdfResidency r(params(1));
  r.add_stored(TileIndex(2, 0, 0), 1000);  // 25.6 .. 38.4 m in x
  r.add_stored(TileIndex(5, 0, 0), 2000);
  EXPECT_EQ(r.stored_count(), 2u);
  EXPECT_EQ(r.stored_bytes(), 3000u);
  const std::vector<Eigen::Vector3d> at = {{0.0, 5.0, 0.0}};
  EXPECT_FALSE(r.needed_away(at));  // 25.6 m away: beyond the need radius
  std::vector<TileIndex> reads;
  r.ask_back(at, reads);
  ASSERT_EQ(reads.size(), 1u);
  EXPECT_EQ(reads[0], TileIndex(2, 0, 0));
  r.ask_back(at, reads);  // loading already: not read twice
  EXPECT_EQ(reads.size(), 1u);
  const std::vector<Eigen::Vector3d> nearer = {{10.0, 5.0, 0.0}};
  EXPECT_TRUE(r.needed_away(nearer));
  r.loaded(TileIndex(2, 0, 0));
  EXPECT_FALSE(r.needed_away(nearer));
  EXPECT_EQ(r.resident_count(), 1u);
}

TEST(TsdfResidency, LoadedAndUnchanged_DroppedUnwritten_ChangedWrittenAgain) {
  TsdfResidency r(params(1));
  r.add_stored(TileIndex(9, 0, 0), 1000);
  std::vector<TileIndex> reads;
  const std::vector<Eigen::Vector3d> at = {{100.0, 0.0, 0.0}};
  r.ask_back(at, reads);
  r.loaded(TileIndex(9, 0, 0));
  scans_elsewhere(r, 3);
  const std::vector<TsdfTileInfo> resident = {{TileIndex(9, 0, 0), 10}};
  std::vector<TileEviction> out;
  r.choose_evictions(resident, bytes_of(resident), {0, 0, 0}, false, out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_FALSE(out[0].write);
  // Back again and changed by a scan: its stored copy is stale, so it is written.
  reads.clear();
  r.ask_back(at, reads);
  r.loaded(TileIndex(9, 0, 0));
  const std::vector<TileIndex> touched = {TileIndex(9, 0, 0)};
  r.scan_changed(touched);
  scans_elsewhere(r, 3);
  out.clear();
  r.choose_evictions(resident, bytes_of(resident), {0, 0, 0}, false, out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_TRUE(out[0].write);
}

TEST(TsdfResidency, AskedBackWhileWritten_ReadOnceWritten) {
  Row row(1);
  row.evict();
  const std::vector<TileEviction>& out = row.out;
  ASSERT_EQ(out.front().tile, TileIndex(9, 0, 0));
  std::vector<TileIndex> reads;
  const std::vector<Eigen::Vector3d> at = {{9 * kTileM, 0.0, 0.0}};
  row.r.ask_back(at, reads);
  EXPECT_TRUE(std::find(reads.begin(), reads.end(), TileIndex(9, 0, 0)) == reads.end());
  EXPECT_TRUE(row.r.written(TileIndex(9, 0, 0), false, out.front().version, 500));
  ASSERT_EQ(out.back().tile, TileIndex(3, 0, 0));  // 64 m from the sensor: not asked back
  EXPECT_FALSE(row.r.written(out.back().tile, false, out.back().version, 500));
  EXPECT_EQ(row.r.stored_bytes(), 1000u);
}

TEST(TsdfResidency, CopyOfATileChangedWhileWritten_IsNotCurrent) {
  TsdfResidency r(params(1));
  const std::vector<TsdfTileInfo> resident = row_of_tiles(r);
  std::vector<TileCopy> copies;
  r.stale_copies(resident, copies);
  ASSERT_EQ(copies.size(), 10u);
  const std::vector<TileIndex> touched = {TileIndex(0, 0, 0)};
  r.changed(touched);  // tile 0 changes while its copy is written
  for (const TileCopy& c : copies) r.written(c.tile, true, c.version, 100);
  copies.clear();
  r.stale_copies(resident, copies);
  ASSERT_EQ(copies.size(), 1u);
  EXPECT_EQ(copies[0].tile, TileIndex(0, 0, 0));
}

TEST(TsdfResidency, FailedWriteBringsTheTileBack_FailedLoadForgetsIt) {
  Row row(1);
  row.evict();
  TsdfResidency& r = row.r;
  EXPECT_EQ(r.resident_count(), 3u);
  r.write_failed(row.out[0].tile, false);
  EXPECT_EQ(r.resident_count(), 4u);
  r.add_stored(TileIndex(-4, 0, 0), 700);
  std::vector<TileIndex> reads;
  const std::vector<Eigen::Vector3d> at = {{-40.0, 0.0, 0.0}};
  r.ask_back(at, reads);
  r.load_failed(TileIndex(-4, 0, 0));
  EXPECT_FALSE(r.needed_away(at));
  EXPECT_EQ(r.stored_count(), 0u);
  std::vector<TileIndex> away;
  r.stored_away(away);
  EXPECT_EQ(away.size(), 6u);  // the evicted tiles but the one written back
}

TEST(StaticFootprint, CoversTheWindowWithMargin_FloorDividesNegativeVoxels) {
  const StaticFootprint f = static_footprint({-65, 0, -10}, {130, 64, 40}, 0);
  EXPECT_EQ(f.lo, StaticTileIndex(-2, 0));
  EXPECT_EQ(f.hi, StaticTileIndex(1, 0));
  const StaticFootprint wide = static_footprint({-65, 0, -10}, {130, 64, 40}, 2);
  EXPECT_EQ(wide.lo, StaticTileIndex(-4, -2));
  EXPECT_EQ(wide.hi, StaticTileIndex(3, 2));
  EXPECT_TRUE(wide.contains({3, -2}));
  EXPECT_FALSE(wide.contains({4, 0}));
}

TEST(StaticResidency, TilesBeyondTheRingLeave_OnlyWhenTheWindowMoved) {
  StaticResidency r;
  const Eigen::Vector3i size(50, 50, 40);
  EXPECT_TRUE(r.window_moved({0, 0, 0}, size));
  EXPECT_FALSE(r.window_moved({10, 10, 0}, size));  // still in tile (0, 0)
  const std::vector<StaticTileIndex> resident = {{0, 0}, {2, 0}, {3, 0}, {0, -3}};
  std::vector<StaticTileIndex> out;
  r.beyond_ring(resident, out);
  EXPECT_EQ(out, (std::vector<StaticTileIndex>{{3, 0}, {0, -3}}));
  EXPECT_TRUE(r.window_moved({64, 0, 0}, size));
  out.clear();
  r.beyond_ring(resident, out);
  EXPECT_EQ(out, (std::vector<StaticTileIndex>{{0, -3}}));
}

TEST(StaticResidency, LeavingTiles_ForgottenDroppedOrWritten) {
  StaticResidency r;
  const std::vector<Eigen::Vector3i> voxels = {{1, 2, 3}, {4, 5, 6}};
  EXPECT_EQ(r.leave({5, 0}, {}), StaticLeave::kForget);
  EXPECT_EQ(r.leave({5, 0}, voxels), StaticLeave::kWrite);
  EXPECT_FALSE(r.written({5, 0}, false, voxels, 64));
  EXPECT_EQ(r.stored_count(), 1u);
  // Asked back and unchanged: dropped unwritten when it leaves again.
  std::vector<StaticTileIndex> reads;
  r.ask_back({5 * kStaticTileEdge, 0, 0}, {64, 64, 40}, reads);
  EXPECT_EQ(reads, (std::vector<StaticTileIndex>{{5, 0}}));
  EXPECT_TRUE(r.needed_away({5 * kStaticTileEdge, 0, 0}, {64, 64, 40}));
  r.loaded({5, 0}, voxels);
  EXPECT_FALSE(r.needed_away({5 * kStaticTileEdge, 0, 0}, {64, 64, 40}));
  EXPECT_FALSE(r.needs_copy({5, 0}, voxels));
  EXPECT_EQ(r.leave({5, 0}, voxels), StaticLeave::kDrop);
  EXPECT_EQ(r.evicted(), 2u);
  // Changed since: written, and a save copies it.
  const std::vector<Eigen::Vector3i> more = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  EXPECT_TRUE(r.needs_copy({5, 0}, more));
  EXPECT_EQ(r.leave({5, 0}, more), StaticLeave::kWrite);
}

TEST(StaticResidency, Replaced_ForgetsEveryTileAndBumpsTheGeneration) {
  StaticResidency r;
  r.add_stored({1, 1}, 100);
  const Eigen::Vector3i size(64, 64, 40);
  EXPECT_TRUE(r.window_moved({0, 0, 0}, size));
  const std::uint64_t before = r.generation();
  r.replaced();
  EXPECT_GT(r.generation(), before);
  EXPECT_EQ(r.stored_count(), 0u);
  EXPECT_EQ(r.stored_bytes(), 0u);
  std::vector<StaticTileIndex> away;
  r.stored_away(away);
  EXPECT_TRUE(away.empty());
  EXPECT_TRUE(r.window_moved({0, 0, 0}, size));  // a pass right after
}

}  // namespace
}  // namespace tarmac::core
