// Fleet BEV summaries: the tile runs round-trip, only changed tiles are resent, a receiver that
// lost a message waits for the keyframe, bad and stale messages are refused and counted, peers'
// observations expire, and the freshest peer wins a cell.

#include "tarmac/core/fleet_bev.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/mapper.hpp"

namespace tarmac::core {
namespace {

constexpr double kRes = 0.2;
constexpr std::int64_t kSecond = 1'000'000'000;
constexpr std::int64_t kMaxAge = 10 * kSecond;

/// A vehicle's cells on a lattice-aligned geometry.
struct Cells {
  GridGeometry2D geometry;
  std::vector<BevState> state;
  std::vector<std::int64_t> observed_ns;

  Cells(std::int64_t i0, std::int64_t j0, std::uint32_t w, std::uint32_t h) {
    geometry =
        GridGeometry2D{static_cast<double>(i0) * kRes, static_cast<double>(j0) * kRes, kRes, w, h};
    state.assign(geometry.cell_count(), BevState::kUnknown);
    observed_ns.assign(geometry.cell_count(), 0);
  }
  void set(std::uint32_t x, std::uint32_t y, BevState s, std::int64_t t) {
    state[y * geometry.width + x] = s;
    observed_ns[y * geometry.width + x] = t;
  }
  [[nodiscard]] BevSnapshot snapshot() const { return {geometry, state, observed_ns}; }
};

/// Random states and observation times within the last 5 s of `stamp`, in patches (as a
/// costmap has them), some cells unknown.
Cells random_cells(std::mt19937& rng, std::int64_t i0, std::int64_t j0, std::uint32_t w,
                   std::uint32_t h, std::int64_t stamp) {
  Cells c(i0, j0, w, h);
  std::uniform_int_distribution<int> state(0, 2);
  std::uniform_int_distribution<std::int64_t> age(0, 5 * kSecond);
  for (std::uint32_t y = 0; y < h; ++y) {
    for (std::uint32_t x = 0; x < w; x += 5) {
      const auto s = static_cast<BevState>(state(rng));
      const std::int64_t t = stamp - age(rng);
      for (std::uint32_t k = x; k < std::min(w, x + 5); ++k) c.set(k, y, s, t);
    }
  }
  return c;
}

/// Every cell of `c` as a peer holding it must read: its state, its time to 0.1 s.
void expect_peer_holds(const BevPeers& peers, const Cells& c, const std::string& id) {
  const std::int64_t i0 = bev_lattice_index(c.geometry.origin_x_m, kRes);
  const std::int64_t j0 = bev_lattice_index(c.geometry.origin_y_m, kRes);
  for (std::uint32_t y = 0; y < c.geometry.height; ++y) {
    for (std::uint32_t x = 0; x < c.geometry.width; ++x) {
      const std::size_t k = y * c.geometry.width + x;
      const BevPeerCell got = peers.lookup(i0 + x, j0 + y);
      if (c.state[k] == BevState::kUnknown) {
        ASSERT_EQ(got.vehicle_id, nullptr) << x << "," << y;
        continue;
      }
      ASSERT_NE(got.vehicle_id, nullptr) << x << "," << y;
      EXPECT_EQ(*got.vehicle_id, id);
      ASSERT_EQ(got.cell.state, c.state[k]) << x << "," << y;
      EXPECT_EQ(got.cell.observed_ns, c.observed_ns[k] / kBevTimeStepNs * kBevTimeStepNs);
    }
  }
}

/// tug-a's random cells and encoder, and tug-b's store of what tug-a sends.
struct Link {
  Cells a;
  BevEncoder enc{"tug-a", kRes};
  BevPeers peers{"tug-b", kRes, kMaxAge};
  Link(unsigned seed, std::int64_t t0, std::int64_t i0, std::int64_t j0, std::uint32_t w,
       std::uint32_t h)
      : a([&] {
          std::mt19937 rng(seed);
          return random_cells(rng, i0, j0, w, h, t0);
        }()) {}
  /// A keyframe of `a` at `t`, applied by tug-b at `t`; returns it.
  BevMessage sync(std::int64_t t) {
    BevMessage m = enc.encode(a.snapshot(), t, true, kMaxAge);
    EXPECT_TRUE(peers.apply(m, t).ok());
    return m;
  }
};

TEST(FleetBev, KeyframeRoundTrip_EveryCellAsSent_AcrossNegativeTilesAndThe16BitWrap) {
  std::mt19937 rng(3);
  // Stamped just after the 16-bit decisecond counter wraps: older cells are before it.
  const std::int64_t stamp = (std::int64_t{65536} * 20 + 30) * kBevTimeStepNs;
  const Cells a = random_cells(rng, -70, -45, 150, 100, stamp);
  BevEncoder enc("tug-a", kRes);
  const BevMessage m = enc.encode(a.snapshot(), stamp, true, kMaxAge);
  EXPECT_TRUE(m.keyframe);
  EXPECT_EQ(m.sequence, 0u);
  BevPeers peers("tug-b", kRes, kMaxAge);
  ASSERT_TRUE(peers.apply(m, stamp).ok());
  expect_peer_holds(peers, a, "tug-a");
  EXPECT_EQ(peers.stats().at("tug-a").messages, 1u);
}

TEST(FleetBev, ChangeMessages_CarryOnlyTheTilesThatChanged) {
  const std::int64_t t0 = 1000 * kSecond;
  Link link(5, t0, 0, 0, 200, 200);
  auto& [a, enc, peers] = link;
  link.sync(t0);
  // Nothing changed: nothing sent.
  const BevMessage same = enc.encode(a.snapshot(), t0 + kSecond, false, kMaxAge);
  EXPECT_TRUE(same.tiles.empty());
  ASSERT_TRUE(peers.apply(same, t0 + kSecond).ok());
  // One cell observed again: its tile only.
  a.set(100, 70, BevState::kOccupied, t0 + 2 * kSecond);
  const BevMessage one = enc.encode(a.snapshot(), t0 + 2 * kSecond, false, kMaxAge);
  ASSERT_EQ(one.tiles.size(), 1u);
  EXPECT_EQ(one.tiles[0].x, 100 / kBevTileEdge);
  EXPECT_EQ(one.tiles[0].y, 70 / kBevTileEdge);
  ASSERT_TRUE(peers.apply(one, t0 + 2 * kSecond).ok());
  expect_peer_holds(peers, a, "tug-a");
  // A tile that becomes unknown is sent once as unknown, and the peer forgets it.
  for (std::uint32_t y = 0; y < 32; ++y) {
    for (std::uint32_t x = 0; x < 32; ++x) a.set(x, y, BevState::kUnknown, 0);
  }
  const BevMessage gone = enc.encode(a.snapshot(), t0 + 3 * kSecond, false, kMaxAge);
  ASSERT_EQ(gone.tiles.size(), 1u);
  ASSERT_TRUE(peers.apply(gone, t0 + 3 * kSecond).ok());
  expect_peer_holds(peers, a, "tug-a");
  EXPECT_TRUE(enc.encode(a.snapshot(), t0 + 4 * kSecond, false, kMaxAge).tiles.empty());
}

TEST(FleetBev, ALostChangeMessage_IgnoresChangesUntilTheNextKeyframe) {
  const std::int64_t t0 = 500 * kSecond;
  Link link(7, t0, 10, 10, 64, 64);
  auto& [a, enc, peers] = link;
  // A change message before any keyframe: a late joiner waits.
  a.set(0, 0, BevState::kOccupied, t0);
  (void)enc.encode(a.snapshot(), t0, true, kMaxAge);  // lost: the late joiner never saw it
  a.set(1, 0, BevState::kOccupied, t0 + kSecond);
  ASSERT_TRUE(
      peers.apply(enc.encode(a.snapshot(), t0 + kSecond, false, kMaxAge), t0 + kSecond).ok());
  EXPECT_EQ(peers.stats().at("tug-a").gaps, 1u);
  EXPECT_EQ(peers.lookup(11, 10).vehicle_id, nullptr);
  // The keyframe syncs; then a lost change message makes the next one a gap too.
  ASSERT_TRUE(
      peers.apply(enc.encode(a.snapshot(), t0 + 2 * kSecond, true, kMaxAge), t0 + 2 * kSecond)
          .ok());
  expect_peer_holds(peers, a, "tug-a");
  a.set(2, 0, BevState::kFree, t0 + 3 * kSecond);
  (void)enc.encode(a.snapshot(), t0 + 3 * kSecond, false, kMaxAge);  // lost
  a.set(3, 0, BevState::kFree, t0 + 4 * kSecond);
  ASSERT_TRUE(
      peers.apply(enc.encode(a.snapshot(), t0 + 4 * kSecond, false, kMaxAge), t0 + 4 * kSecond)
          .ok());
  EXPECT_EQ(peers.stats().at("tug-a").gaps, 2u);
  EXPECT_EQ(peers.lookup(13, 10).vehicle_id, nullptr);  // the change after the gap: not applied
  ASSERT_TRUE(
      peers.apply(enc.encode(a.snapshot(), t0 + 5 * kSecond, true, kMaxAge), t0 + 5 * kSecond)
          .ok());
  expect_peer_holds(peers, a, "tug-a");
}

TEST(FleetBev, BadStaleFutureAndForeignMessages_AreRefusedCountedAndChangeNothing) {
  const std::int64_t t0 = 300 * kSecond;
  Link link(9, t0, 0, 0, 40, 40);
  auto& [a, enc, peers] = link;
  const BevMessage good = link.sync(t0);
  const auto refused = [&](BevMessage m, std::int64_t now, const std::string& code) {
    const auto r = peers.apply(m, now);
    ASSERT_FALSE(r.ok()) << code;
    EXPECT_EQ(r.error().code, "fleet." + code) << r.error().message;
  };
  BevMessage m = good;
  m.stamp_ns = t0 + kSecond;
  refused(m, t0 + 20 * kSecond, "stale");
  refused(m, t0, "future");
  m.resolution_m = 0.1;
  refused(m, t0 + kSecond, "resolution");
  m = good;
  m.vehicle_id = "tug-b";
  refused(m, t0, "own_id");
  m = good;
  refused(m, t0 + kSecond, "order");  // the same stamp again
  m.stamp_ns = t0 + kSecond;
  m.tiles[0].runs.pop_back();  // a truncated time
  refused(m, t0 + kSecond, "malformed");
  m.tiles[0].runs = {63, 63};  // 128 of 1024 cells
  refused(m, t0 + kSecond, "malformed");
  m.tiles[0].runs.assign(17, 63);  // 1088 cells
  refused(m, t0 + kSecond, "malformed");
  m.tiles[0].runs = {0xff};  // state 3
  refused(m, t0 + kSecond, "malformed");
  m.tiles = {good.tiles[0], good.tiles[0]};  // one tile twice
  refused(m, t0 + kSecond, "malformed");
  m.tiles.assign(kBevMaxPeerTiles + 1, good.tiles[0]);
  refused(m, t0 + kSecond, "too_large");
  EXPECT_EQ(peers.stats().at("tug-a").rejected, 10u);
  EXPECT_EQ(peers.stats().at("tug-b").rejected, 1u);
  expect_peer_holds(peers, a, "tug-a");  // unchanged by any of them
}

TEST(FleetBev, PeerObservations_ExpireAfterMaxAge) {
  const std::int64_t t0 = 100 * kSecond;
  Cells a(0, 0, 64, 32);
  a.set(3, 3, BevState::kOccupied, t0 - 8 * kSecond);
  a.set(40, 3, BevState::kFree, t0);
  BevEncoder enc("tug-a", kRes);
  BevPeers peers("tug-b", kRes, kMaxAge);
  ASSERT_TRUE(peers.apply(enc.encode(a.snapshot(), t0, true, kMaxAge), t0).ok());
  EXPECT_NE(peers.lookup(3, 3).vehicle_id, nullptr);
  peers.expire(t0 + 3 * kSecond);  // 11 s old
  EXPECT_EQ(peers.lookup(3, 3).vehicle_id, nullptr);
  EXPECT_EQ(peers.stats().at("tug-a").tiles, 1u);  // the tile of (40, 3) is kept
  peers.expire(t0 + 11 * kSecond);
  EXPECT_EQ(peers.lookup(40, 3).vehicle_id, nullptr);
  EXPECT_EQ(peers.stats().at("tug-a").tiles, 0u);
  // The encoder does not send what receivers would drop.
  a.set(5, 5, BevState::kOccupied, t0 - 11 * kSecond);
  const BevMessage m = enc.encode(a.snapshot(), t0, true, kMaxAge);
  BevPeers fresh("tug-c", kRes, kMaxAge);
  ASSERT_TRUE(fresh.apply(m, t0).ok());
  EXPECT_EQ(fresh.lookup(5, 5).vehicle_id, nullptr);
}

TEST(FleetBev, TheFreshestPeerWins_TiesGoToOccupied) {
  const std::int64_t t0 = 100 * kSecond;
  Cells a(0, 0, 32, 32), c(0, 0, 32, 32);
  a.set(1, 1, BevState::kFree, t0);
  c.set(1, 1, BevState::kOccupied, t0 - kSecond);
  a.set(2, 2, BevState::kFree, t0);
  c.set(2, 2, BevState::kOccupied, t0);
  BevEncoder ea("tug-a", kRes), ec("tug-c", kRes);
  BevPeers peers("tug-b", kRes, kMaxAge);
  ASSERT_TRUE(peers.apply(ea.encode(a.snapshot(), t0, true, kMaxAge), t0).ok());
  ASSERT_TRUE(peers.apply(ec.encode(c.snapshot(), t0, true, kMaxAge), t0).ok());
  EXPECT_EQ(peers.lookup(1, 1).cell.state, BevState::kFree);
  EXPECT_EQ(*peers.lookup(1, 1).vehicle_id, "tug-a");
  EXPECT_EQ(peers.lookup(2, 2).cell.state, BevState::kOccupied);
  EXPECT_EQ(*peers.lookup(2, 2).vehicle_id, "tug-c");
}

TEST(FleetBev, AMostlyUniformCostmap_EncodesInAFewKilobytes) {
  // 400 x 400 cells (the shipped window), free and seen by the last scan, a few obstacles.
  const std::int64_t t0 = 100 * kSecond;
  Cells a(-200, -200, 400, 400);
  for (std::uint32_t y = 0; y < 400; ++y) {
    for (std::uint32_t x = 0; x < 400; ++x) {
      const bool obstacle = (x % 50 == 7) && (y % 40 < 3);
      a.set(x, y, obstacle ? BevState::kOccupied : BevState::kFree, t0);
    }
  }
  BevEncoder enc("tug-a", kRes);
  const BevMessage m = enc.encode(a.snapshot(), t0, true, kMaxAge);
  std::size_t bytes = 0;
  for (const BevTile& t : m.tiles) bytes += t.runs.size() + 8;
  EXPECT_EQ(m.tiles.size(), 196u);  // lattice cells −200 … 199: tiles −7 … 6 on each axis
  EXPECT_LT(bytes, 16u * 1024u);
}

/// ColumnClass values (costmap_builder.hpp).
constexpr std::uint8_t kFreeClass = 0, kObstacleClass = 1, kUnknownClass = 2, kVirtualClass = 3;

TEST(FleetBevFusion, TheRules_CellByCell) {
  const std::int64_t t0 = 100 * kSecond;
  // The peer saw seven cells of one row occupied or free at t0 + 1 s; the own map has, cell by
  // cell: unknown; free older; free newer; obstacle older (peer free); a virtual zone; the same
  // time as the peer's; and a peer observation past max age.
  Cells peer(0, 0, 8, 1);
  for (std::uint32_t x = 0; x < 6; ++x) peer.set(x, 0, BevState::kOccupied, t0 + kSecond);
  peer.set(3, 0, BevState::kFree, t0 + kSecond);
  peer.set(6, 0, BevState::kOccupied, t0 - 20 * kSecond);
  BevEncoder enc("tug-a", kRes);
  BevPeers peers("tug-b", kRes, kMaxAge);
  ASSERT_TRUE(
      peers.apply(enc.encode(peer.snapshot(), t0 + kSecond, true, 30 * kSecond), t0 + kSecond)
          .ok());
  const GridGeometry2D g = peer.geometry;
  std::vector<std::uint8_t> cls = {kUnknownClass, kFreeClass, kFreeClass,    kObstacleClass,
                                   kVirtualClass, kFreeClass, kUnknownClass, kFreeClass};
  const std::vector<std::int64_t> own = {
      0, t0, t0 + 2 * kSecond, t0, t0 + 5 * kSecond, t0 + kSecond, 0, t0};
  const BevFusionCounts n = peers.fuse(g, own, t0 + 2 * kSecond, cls);
  const std::vector<std::uint8_t> want = {kObstacleClass, kObstacleClass, kFreeClass,
                                          kFreeClass,     kVirtualClass,  kFreeClass,
                                          kUnknownClass,  kFreeClass};
  EXPECT_EQ(cls, want);
  EXPECT_EQ(n.cells, 3u);
  EXPECT_EQ(n.occupied, 2u);
  EXPECT_EQ(n.cells_by_peer.at("tug-a"), 3u);
  EXPECT_EQ(n.newest_observed_ns, t0 + kSecond);
}

TEST(FleetBevFusion, TileByTile_EqualsTheRulesAppliedThroughLookup) {
  std::mt19937 rng(11);
  const std::int64_t t0 = 2000 * kSecond;
  BevPeers peers("own", kRes, kMaxAge);
  for (const char* id : {"tug-c", "tug-a", "tug-d"}) {
    const Cells c = random_cells(rng, -90 + static_cast<int>(rng() % 40),
                                 -60 + static_cast<int>(rng() % 40), 120, 110, t0);
    BevEncoder enc(id, kRes);
    ASSERT_TRUE(peers.apply(enc.encode(c.snapshot(), t0, true, kMaxAge), t0).ok());
  }
  const std::int64_t now = t0 + 6 * kSecond;  // some peer cells past max age
  Cells own = random_cells(rng, -100, -70, 150, 130, t0 + kSecond);
  std::vector<std::uint8_t> cls(own.state.size());
  for (std::size_t k = 0; k < cls.size(); ++k) {
    cls[k] = own.state[k] == BevState::kUnknown ? kUnknownClass
             : own.state[k] == BevState::kFree  ? kFreeClass
                                                : kObstacleClass;
    if (k % 97 == 0) cls[k] = kVirtualClass;
  }
  std::vector<std::uint8_t> want = cls;
  const std::int64_t i0 = -100, j0 = -70;
  std::uint64_t filled = 0;
  for (std::uint32_t y = 0; y < own.geometry.height; ++y) {
    for (std::uint32_t x = 0; x < own.geometry.width; ++x) {
      const std::size_t k = y * own.geometry.width + x;
      const BevPeerCell p = peers.lookup(i0 + x, j0 + y);
      if (p.vehicle_id == nullptr || p.cell.observed_ns < now - kMaxAge) continue;
      if (want[k] == kVirtualClass) continue;
      if (want[k] != kUnknownClass && own.observed_ns[k] >= p.cell.observed_ns) continue;
      want[k] = p.cell.state == BevState::kOccupied ? kObstacleClass : kFreeClass;
      ++filled;
    }
  }
  const BevFusionCounts n = peers.fuse(own.geometry, own.observed_ns, now, cls);
  EXPECT_EQ(cls, want);
  EXPECT_EQ(n.cells, filled);
  EXPECT_GT(filled, 1000u);
}

/// A ring wall 6 m round a sensor 1.8 m up, and the ground inside it.
PointCloud ring_scan(std::int64_t stamp_ns) {
  PointCloud cloud;
  cloud.stamp_ns = stamp_ns;
  for (int i = 0; i < 3000; ++i) {
    const float a = 2.0f * static_cast<float>(M_PI) * static_cast<float>(i) / 3000.0f;
    for (float z = -1.7f; z < 0.7f; z += 0.3f) {
      cloud.points_S.emplace_back(6.0f * std::cos(a), 6.0f * std::sin(a), z);
    }
    for (float r = 1.0f; r < 6.0f; r += 0.5f) {
      cloud.points_S.emplace_back(r * std::cos(a), r * std::sin(a), -1.8f);
    }
  }
  return cloud;
}

TEST(FleetBevMapper, BSeesTheWallOnlyASaw_BsOwnCellsKeepTheirClasses) {
  constexpr std::int64_t kT = 1'000'000'000;
  MapperParams params;
  params.costmap.free_rule = FreeRule::kAnyVoxel;  // no sky beams in this scan
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = 1.8;
  const auto base_at = [](double x) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation().x() = x;
    return T;
  };
  SerialRunner runner;
  const auto run = [&](Mapper& m, double x, const BevPeers* peers, BevFusionCounts& counts) {
    m.track_fleet_observations();
    m.integrate(m.ingest(ring_scan(kT), base_at(x), T_B_S), runner);
    m.update_costmap(m.vehicle_pose(), {}, kT, runner, peers, counts);
  };
  // A at x = 0 sees its ring; its summary goes to B at x = 20 m (A's ring is inside B's 80 m
  // window but beyond what B's own ring shows it).
  Mapper a(params), b(params), b_alone(params);
  BevFusionCounts counts;
  run(a, 0.0, nullptr, counts);
  BevEncoder enc("tug-a", params.occupancy.voxel_size_m);
  const BevMessage m = enc.encode(a.fleet_snapshot(), kT, true, 10 * kT);
  EXPECT_GE(m.tiles.size(), 4u);  // the 12 m ring over 6.4 m tiles
  BevPeers peers("tug-b", params.occupancy.voxel_size_m, 10 * kT);
  ASSERT_TRUE(peers.apply(m, kT).ok());
  run(b, 20.0, &peers, counts);
  BevFusionCounts none;
  run(b_alone, 20.0, nullptr, none);
  EXPECT_GT(counts.cells, 1000u);
  EXPECT_GT(counts.occupied, 100u);
  EXPECT_EQ(none.cells, 0u);
  const Costmap& fused = b.costmap().costmap;
  const Costmap& alone = b_alone.costmap().costmap;
  const auto cost = [](const Costmap& c, double x, double y) {
    const auto cell = c.geometry().cell_of(x, y);
    return c.at(static_cast<std::uint32_t>(cell->x()), static_cast<std::uint32_t>(cell->y()));
  };
  EXPECT_EQ(cost(fused, 6.0, 0.1), kCostLethal) << "A's wall, east of A";
  EXPECT_EQ(cost(alone, 6.0, 0.1), kCostUnknown);
  EXPECT_EQ(cost(fused, 1.5, 0.1), kCostFree) << "A's ground, beyond the wall's inflation";
  EXPECT_EQ(cost(alone, 1.5, 0.1), kCostUnknown);
  // Every cell B observed itself keeps B's own class.
  const auto& cls_alone = b_alone.costmap().column_class.cells();
  const auto& cls_fused = b.costmap().column_class.cells();
  ASSERT_EQ(cls_fused.size(), cls_alone.size());
  std::size_t compared = 0;
  for (std::size_t i = 0; i < cls_alone.size(); ++i) {
    if (cls_alone[i] == static_cast<std::uint8_t>(ColumnClass::kUnknown)) continue;
    ASSERT_EQ(cls_fused[i], cls_alone[i]) << i;
    ++compared;
  }
  EXPECT_GT(compared, 2000u);  // B's ring: ~113 m² of 0.04 m² cells
  // B's own summary carries B's observations only, never what A told it.
  BevPeers c("tug-c", params.occupancy.voxel_size_m, 10 * kT);
  BevEncoder enc_b("tug-b", params.occupancy.voxel_size_m);
  ASSERT_TRUE(c.apply(enc_b.encode(b.fleet_snapshot(), kT, true, 10 * kT), kT).ok());
  const double r = params.occupancy.voxel_size_m;
  EXPECT_EQ(c.lookup(static_cast<std::int64_t>(std::floor(6.0 / r)), 0).vehicle_id, nullptr);
  EXPECT_NE(c.lookup(static_cast<std::int64_t>(std::floor(26.0 / r)), 0).vehicle_id, nullptr);
}

// A pose correction rebuilds the window from the retained scans: the rebuilt window keeps each
// column's observation time (the scan's stamp), or the vehicle's summary would hold nothing
// until its columns were observed again.
TEST(FleetBevMapper, RebuiltWindowAfterACorrection_KeepsTheObservationTimes) {
  constexpr std::int64_t kT = 1'000'000'000;
  MapperParams params;
  params.costmap.free_rule = FreeRule::kAnyVoxel;
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = 1.8;
  SerialRunner runner;
  Mapper m(params);
  m.track_fleet_observations();
  BevFusionCounts counts;
  for (int k = 1; k <= 3; ++k) {
    Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
    T_W_B.translation().x() = 0.5 * k;
    m.integrate(m.ingest(ring_scan(k * kT), T_W_B, T_B_S), runner);
    m.rebuild_step(runner);
  }
  m.update_costmap(m.vehicle_pose(), {}, 3 * kT, runner, nullptr, counts);
  const BevSnapshot before = m.fleet_snapshot();
  const std::vector<BevState> states(before.state.begin(), before.state.end());
  const std::vector<std::int64_t> times(before.observed_ns.begin(), before.observed_ns.end());
  ASSERT_GT(std::count_if(times.begin(), times.end(), [](std::int64_t t) { return t > 0; }), 1000);

  // An identity correction of the first two scans: the rebuilt window is the same window.
  ASSERT_GT(m.correct_rigid(Eigen::Isometry3d::Identity(), 3 * kT), 0u);
  for (int i = 0; i < 10 && m.rebuilding(); ++i) m.rebuild_step(runner);
  ASSERT_FALSE(m.rebuilding());
  ASSERT_EQ(m.correction_stats().rebuilds_completed, 1u);
  m.update_costmap(m.vehicle_pose(), {}, 3 * kT, runner, nullptr, counts);
  const BevSnapshot after = m.fleet_snapshot();
  EXPECT_TRUE(std::equal(states.begin(), states.end(), after.state.begin(), after.state.end()));
  EXPECT_TRUE(
      std::equal(times.begin(), times.end(), after.observed_ns.begin(), after.observed_ns.end()));
}

// A peer whose localiser states more position uncertainty than the bound is not used: its cells
// may sit further from where they are than the receiver's inflation margin covers.
TEST(FleetBev, APeerBeyondThePositionBound_IsRefused_UnstatedIsTrusted) {
  constexpr std::int64_t kT = 1'000'000'000;
  BevPeers peers("tug-b", 0.2, 10 * kT, kT, 0.5);
  BevMessage m;
  m.vehicle_id = "tug-a";
  m.stamp_ns = kT;
  m.keyframe = true;
  m.position_std_m = 0.6;
  const auto refused = peers.apply(m, kT);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, "fleet.localisation");
  m.position_std_m = 0.5;
  EXPECT_TRUE(peers.apply(m, kT).ok());
  m.stamp_ns += kT;
  m.position_std_m = 0.0;  // the localiser states none
  EXPECT_TRUE(peers.apply(m, 2 * kT).ok());
  EXPECT_EQ(peers.stats().at("tug-a").rejected, 1u);
  EXPECT_EQ(peers.stats().at("tug-a").messages, 2u);
}

}  // namespace
}  // namespace tarmac::core
