// Paging the TSDF (tsdf.resident_limit_mb, daemon/tsdf_pager.hpp): a vehicle drives the
// simulator's loop round a parked aircraft twice, so the tiles of the far side leave memory and
// come back. The map paged through a small limit is the unlimited map bit for bit; the store
// written at the end is the whole map for a restart; damaged tiles are refused and counted.
#include "tarmac/daemon/tsdf_pager.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_changes.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_mesh.hpp"
#include "tarmac/daemon/cycle.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace tarmac::daemon {
namespace {

namespace fs = std::filesystem;

struct Drive {
  std::vector<core::PointCloud> clouds;
  std::vector<Eigen::Isometry3d> T_W_B;
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
};

/// Two laps of the aircraft loop (60 m x 44 m), 16 beams, 5 Hz at 10 m/s.
const Drive& drive() {
  static const Drive d = [] {
    const sim::Scene scene = sim::Scene::aircraft_stand();
    sim::SequenceParams p;
    p.lidar.beams = 16;
    p.lidar.azimuth_steps = 512;
    p.path = sim::DrivePath::loop({-30.0, -22.0}, {30.0, 22.0}, 10.0, 20.0);
    p.rate_hz = 5.0;
    const sim::Lidar lidar(p.lidar);
    Drive out;
    out.T_B_S.translation().z() = p.path.sensor_height_m;
    const int per_lap = p.scan_count() - 1;
    std::vector<sim::LidarReturn> returns;
    for (int i = 0; i < 2 * per_lap; ++i) {
      const double t_s = p.stamp_s(i % per_lap);
      lidar.scan(scene, p.path.T_W_S(t_s), t_s, nullptr, returns);
      core::PointCloud cloud;
      cloud.stamp_ns = static_cast<std::int64_t>(i) * 200'000'000;
      for (const auto& r : returns) cloud.points_S.push_back(r.point_S.cast<float>());
      out.clouds.push_back(std::move(cloud));
      out.T_W_B.push_back(p.path.T_W_S(t_s) * out.T_B_S.inverse());
    }
    return out;
  }();
  return d;
}

core::MapperParams params() {
  core::MapperParams p;
  p.tsdf.max_range_m = 12.0;  // a small working set: tiles within ~25 m of the vehicle
  p.corrections.enabled = false;
  return p;
}

class TsdfPaging : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("tarmac_tsdf_paging_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  TsdfPagerParams pager_params(bool wait) const {
    core::MapperParams mp = params();
    mp.tsdf.resident_limit_mb = 1;
    TsdfPagerParams pp = TsdfPagerParams::for_mapper(mp, dir_);
    pp.wait_for_loads = wait;
    return pp;
  }

  /// Maps the drive; with a pager when given; `shift_W` moves every pose (a drifted map).
  static void map(core::Mapper& mapper, TsdfPager* pager,
                  const Eigen::Vector3d& shift_W = Eigen::Vector3d::Zero()) {
    ThreadPool pool(2);
    Cycle cycle(mapper, pool, Cycle::Quotas{});
    cycle.page_tsdf(pager);
    const Drive& d = drive();
    for (std::size_t i = 0; i < d.clouds.size(); ++i) {
      cycle.begin();
      Eigen::Isometry3d T = d.T_W_B[i];
      T.translation() += shift_W;
      cycle.scan(d.clouds[i], T, d.T_B_S);
    }
    cycle.update_costmap(cycle.mapper().vehicle_pose(), {}, d.clouds.back().stamp_ns);
    if (pager != nullptr) pager->flush(mapper.tsdf());
  }

  fs::path dir_;
};

TEST_F(TsdfPaging, SmallLimit_SameMapBitForBit_TilesLeaveAndComeBack) {
  core::Mapper whole(params());
  map(whole, nullptr);
  const std::uint64_t expected = whole.tsdf().digest();

  core::Mapper paged(params());
  auto pager = TsdfPager::open(pager_params(true), paged.tsdf());
  ASSERT_TRUE(pager.ok()) << pager.error().message;
  map(paged, pager.value().get());
  const TsdfPagerStats st = pager.value()->stats();
  EXPECT_GT(st.evicted, 5u);
  EXPECT_GT(st.loaded, 2u);  // the second lap brings the first lap's far tiles back
  EXPECT_GT(st.stored_tiles, 0u);
  EXPECT_EQ(st.loads_late, 0u);
  EXPECT_EQ(st.write_errors + st.load_errors, 0u);
  EXPECT_LT(paged.tsdf().resident_bytes(), whole.tsdf().resident_bytes());
  EXPECT_EQ(pager.value()->site(paged.tsdf()).digest(), expected);
  EXPECT_EQ(whole.occupancy().static_count(), paged.occupancy().static_count());

  // The store alone is the whole map: a restart over it (every tile absent) has the same site.
  ASSERT_TRUE(pager.value()->store_all(paged.tsdf()).ok());
  pager.value().reset();
  core::Mapper restarted(params());
  auto reopened = TsdfPager::open(pager_params(true), restarted.tsdf());
  ASSERT_TRUE(reopened.ok()) << reopened.error().message;
  EXPECT_EQ(restarted.tsdf().block_count(), 0u);
  EXPECT_GT(restarted.tsdf().absent_count(), 0u);
  EXPECT_EQ(reopened.value()->site(restarted.tsdf()).digest(), expected);
}

/// The static occupancy paged in column tiles with the TSDF: a window of 32 m drives the 60 m
/// loop, so the far side's static tiles leave and come back; the site's static layer, the
/// window and the costmap are the unlimited run's, and the store restarts the same layer.
TEST_F(TsdfPaging, StaticLayer_PagedInColumns_SameLayerWindowAndCostmap) {
  core::MapperParams mp = params();
  mp.occupancy.window_x_vox = 160;
  mp.occupancy.window_y_vox = 160;
  core::Mapper whole(mp);
  map(whole, nullptr);
  std::vector<core::VoxelIndex> expected;
  whole.occupancy().export_static(expected);
  ASSERT_GT(expected.size(), 1000u);

  TsdfPagerParams pp = pager_params(true);
  core::Mapper paged(mp);
  auto pager = TsdfPager::open(pp, paged.tsdf(), &paged.occupancy());
  ASSERT_TRUE(pager.ok()) << pager.error().message;
  map(paged, pager.value().get());
  const TsdfPagerStats st = pager.value()->stats();
  EXPECT_GT(st.static_evicted, 3u);
  EXPECT_GT(st.static_loaded, 1u);  // the second lap brings the far side's static tiles back
  EXPECT_GT(st.static_tiles_stored, 0u);
  EXPECT_EQ(st.loads_late, 0u);
  EXPECT_EQ(st.write_errors + st.load_errors, 0u);
  EXPECT_LT(paged.occupancy().static_count(), expected.size());
  std::vector<core::VoxelIndex> site;
  ASSERT_TRUE(pager.value()->site(paged.tsdf()).static_voxels(site));
  EXPECT_EQ(site, expected);
  std::vector<float> a, b;
  whole.occupancy().export_log_odds(a);
  paged.occupancy().export_log_odds(b);
  EXPECT_EQ(a, b);
  EXPECT_EQ(whole.costmap().costmap.cells(), paged.costmap().costmap.cells());

  // The store alone holds the site's static layer for a restart.
  ASSERT_TRUE(pager.value()->store_all(paged.tsdf()).ok());
  pager.value().reset();
  core::Mapper restarted(mp);
  auto reopened = TsdfPager::open(pp, restarted.tsdf(), &restarted.occupancy());
  ASSERT_TRUE(reopened.ok()) << reopened.error().message;
  EXPECT_EQ(restarted.occupancy().static_count(), 0u);
  ASSERT_TRUE(reopened.value()->site(restarted.tsdf()).static_voxels(site));
  EXPECT_EQ(site, expected);
}

/// The .vdb export in parts: each part a tsdf_io file, together every block of the site once.
TEST_F(TsdfPaging, VdbExportInParts_TogetherTheWholeMap) {
  core::Mapper whole(params());
  map(whole, nullptr);
  core::Mapper paged(params());
  auto pager = TsdfPager::open(pager_params(true), paged.tsdf());
  ASSERT_TRUE(pager.ok()) << pager.error().message;
  map(paged, pager.value().get());
  ASSERT_GT(pager.value()->stats().evicted, 0u);
  std::vector<fs::path> files;
  const core::Status exported =
      pager.value()
          ->site(paged.tsdf())
          .export_parts(2, [&](const Eigen::Vector2i& r, const core::TsdfLayer& part) {
            EXPECT_GT(part.block_count(), 0u);
            files.push_back(
                dir_ / ("part_" + std::to_string(r.x()) + "_" + std::to_string(r.y()) + ".vdb"));
            return core::save_tsdf(files.back(), part, core::TsdfMapInfo{});
          });
  ASSERT_TRUE(exported.ok()) << exported.error().message;
  ASSERT_GT(files.size(), 2u);
  core::TsdfLayer merged(whole.tsdf().voxel_size_m(), whole.tsdf().truncation_m());
  for (const fs::path& f : files) {
    auto loaded = core::load_tsdf(f);
    ASSERT_TRUE(loaded.ok()) << loaded.error().message;
    for (const core::TsdfTileInfo& t : loaded.value().layer.resident_tiles()) {
      EXPECT_FALSE(merged.copy_tile(t.tile).has_value());  // each tile in one part only
      merged.attach_tile(std::move(*loaded.value().layer.copy_tile(t.tile)));
    }
  }
  EXPECT_EQ(merged.digest(), whole.tsdf().digest());
}

/// Change detection against a prior held as a tile store, strip by strip: the same raster and
/// counts as core::detect_changes over the two maps held whole.
TEST_F(TsdfPaging, ChangesAgainstATileStorePrior_SameLayerAsTheWholeMaps) {
  const Eigen::Vector3d drift(0.35, -0.2, 0.0);
  core::Mapper prior_whole(params()), whole(params());
  map(prior_whole, nullptr, drift);
  map(whole, nullptr);
  core::ChangeMap expected;
  ASSERT_TRUE(core::detect_changes(prior_whole.tsdf(), whole.tsdf(), {}, expected).ok());
  ASSERT_GT(expected.new_voxels, 100u);
  ASSERT_GT(expected.removed_voxels, 100u);

  TsdfPagerParams prior_params = pager_params(true);
  prior_params.dir = dir_ / "prior";
  {
    core::Mapper prior(params());
    auto pager = TsdfPager::open(prior_params, prior.tsdf());
    ASSERT_TRUE(pager.ok()) << pager.error().message;
    map(prior, pager.value().get(), drift);
    ASSERT_TRUE(pager.value()->store_all(prior.tsdf()).ok());
  }
  core::Mapper paged(params());
  auto pager = TsdfPager::open(pager_params(true), paged.tsdf());
  ASSERT_TRUE(pager.ok()) << pager.error().message;
  map(paged, pager.value().get());
  ASSERT_GT(pager.value()->stats().evicted, 0u);

  core::GridGeometry2D geometry;
  std::vector<float> raster;
  std::vector<int> strips;
  core::ChangeCounts counts;
  const core::Status done =
      pager.value()
          ->site(paged.tsdf())
          .changes(
              prior_params.dir, {}, counts,
              [&](const core::GridGeometry2D& g) {
                geometry = g;
                raster.assign(g.cell_count(), -7.0f);  // every cell is written once
                return core::Status(core::Ok{});
              },
              [&](int y0, int rows, std::span<const float> cells) {
                EXPECT_EQ(cells.size(), static_cast<std::size_t>(rows) * geometry.width);
                if (!strips.empty()) {
                  EXPECT_LT(y0, strips.back());  // from the top down
                }
                strips.push_back(y0);
                std::copy(cells.begin(), cells.end(),
                          raster.begin() + static_cast<std::ptrdiff_t>(y0) * geometry.width);
                return core::Status(core::Ok{});
              });
  ASSERT_TRUE(done.ok()) << done.error().message;
  EXPECT_GT(strips.size(), 1u);
  EXPECT_EQ(geometry.width, expected.geometry.width);
  EXPECT_EQ(geometry.height, expected.geometry.height);
  EXPECT_EQ(geometry.origin_x_m, expected.geometry.origin_x_m);
  EXPECT_EQ(geometry.origin_y_m, expected.geometry.origin_y_m);
  EXPECT_EQ(counts.compared_voxels, expected.compared_voxels);
  EXPECT_EQ(counts.new_voxels, expected.new_voxels);
  EXPECT_EQ(counts.removed_voxels, expected.removed_voxels);
  ASSERT_EQ(raster.size(), expected.change.size());
  EXPECT_EQ(std::memcmp(raster.data(), expected.change.data(), raster.size() * sizeof(float)), 0);
}

/// A mesh's triangles as sorted tuples of their corners' coordinates (each triangle rotated to
/// start at its smallest corner, winding kept): equal for the same surface however the vertices
/// are numbered or shared.
std::vector<std::array<float, 9>> triangle_set(const std::vector<core::TriangleMesh>& pieces) {
  std::vector<std::array<float, 9>> out;
  for (const core::TriangleMesh& m : pieces) {
    for (const Eigen::Vector3i& t : m.triangles) {
      std::array<std::array<float, 3>, 3> c;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3f& v = m.vertices_W[static_cast<std::size_t>(t[k])];
        c[static_cast<std::size_t>(k)] = {v.x(), v.y(), v.z()};
      }
      const auto first = std::min_element(c.begin(), c.end()) - c.begin();
      std::rotate(c.begin(), c.begin() + first, c.end());
      out.push_back(
          {c[0][0], c[0][1], c[0][2], c[1][0], c[1][1], c[1][2], c[2][0], c[2][1], c[2][2]});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST_F(TsdfPaging, SiteMeshTileByTile_HoldsTheWholeMapsTriangles) {
  core::Mapper whole(params());
  map(whole, nullptr);
  core::TriangleMesh whole_mesh;
  ASSERT_TRUE(core::extract_mesh(whole.tsdf(), 1.0f, whole_mesh).ok());
  ASSERT_GT(whole_mesh.triangles.size(), 1000u);

  core::Mapper paged(params());
  auto pager = TsdfPager::open(pager_params(true), paged.tsdf());
  ASSERT_TRUE(pager.ok());
  map(paged, pager.value().get());
  ASSERT_GT(pager.value()->stats().evicted, 0u);  // some tiles are read back from the store
  std::vector<core::TriangleMesh> pieces;
  ASSERT_TRUE(pager.value()
                  ->site(paged.tsdf())
                  .mesh(1.0f,
                        [&pieces](const core::TriangleMesh& piece) -> core::Status {
                          pieces.push_back(piece);
                          return core::Ok{};
                        })
                  .ok());
  EXPECT_GT(pieces.size(), 4u);
  const auto from_tiles = triangle_set(pieces);
  EXPECT_EQ(from_tiles.size(), whole_mesh.triangles.size());
  EXPECT_TRUE(from_tiles == triangle_set({whole_mesh}));
}

TEST_F(TsdfPaging, DamagedTile_RefusedCountedRenamed_MapGoesOn) {
  {
    core::Mapper first(params());
    auto pager = TsdfPager::open(pager_params(true), first.tsdf());
    ASSERT_TRUE(pager.ok());
    map(first, pager.value().get());
    ASSERT_TRUE(pager.value()->store_all(first.tsdf()).ok());
  }
  // Damage every tile file: a restart driving the loop again must refuse them all, count them,
  // rename them .refused, and map the ground afresh (never a crash, never a half-read tile).
  std::size_t damaged = 0;
  for (const auto& f : fs::directory_iterator(dir_)) {
    std::fstream io(f.path(), std::ios::in | std::ios::out | std::ios::binary);
    io.seekp(60);
    io.put('\x5a');
    ++damaged;
  }
  ASSERT_GT(damaged, 0u);
  core::Mapper again(params());
  auto pager = TsdfPager::open(pager_params(true), again.tsdf());
  ASSERT_TRUE(pager.ok());
  map(again, pager.value().get());
  const TsdfPagerStats st = pager.value()->stats();
  EXPECT_GT(st.load_errors, 0u);
  std::size_t refused = 0;
  for (const auto& f : fs::directory_iterator(dir_)) refused += f.path().extension() == ".refused";
  EXPECT_EQ(refused, st.load_errors);
  // The refused tiles' ground was mapped again: the map is the one a fresh start makes.
  core::Mapper fresh(params());
  map(fresh, nullptr);
  EXPECT_EQ(pager.value()->site(again.tsdf()).digest(), fresh.tsdf().digest());
}

TEST_F(TsdfPaging, NeverWaiting_LateTilesAreCountedNotShadowed) {
  // tarmacd's mode: a scan never waits for a tile still loading; whatever the disk's speed the
  // integrator builds nothing inside a tile that is away, so every stored tile stays the only
  // copy of its ground (a reload never meets blocks in memory: attach_tile would abort).
  core::Mapper paged(params());
  auto pager = TsdfPager::open(pager_params(false), paged.tsdf());
  ASSERT_TRUE(pager.ok());
  map(paged, pager.value().get());
  const TsdfPagerStats st = pager.value()->stats();
  EXPECT_GT(st.evicted, 5u);
  EXPECT_EQ(st.write_errors + st.load_errors, 0u);
  EXPECT_NE(pager.value()->site(paged.tsdf()).digest(), 0u);
}

}  // namespace
}  // namespace tarmac::daemon
