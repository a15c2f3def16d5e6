// Fleet sharing between two tarmacd executors over loopback DDS (docs/fleet.md): each is fed
// half of the simulator's loop round a parked aircraft at the same time; A's costmap must gain
// the cells only B saw, by the fusion rules, cell by cell; bad summaries are counted and change
// nothing; peers' cells expire.

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <iterator>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "child_process.hpp"
#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "executor_harness.hpp"
#include "loopback_only.hpp"
#include "nav_msgsPubSubTypes.h"
#include "site_view.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/daemon/clock.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/transport/fleet.hpp"
#include "tarmac_msgsPubSubTypes.h"
#include "test_env.hpp"

namespace tarmac::daemon {
namespace {

using namespace std::chrono_literals;
using test::kTimeScale;
using test::peer;
using test::ReportReader;
using test::RunningExecutor;
using test::test_config;
using test::total_of;
using test::wait_for_report;
using GridReader = transport::Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
using FleetWriter = transport::Writer<tarmac_msgs::msg::dds_::FleetBev_PubSubType>;

constexpr std::int64_t kSecondNs = 1'000'000'000;
constexpr double kSensorHeightM = 2.0;

/// The aircraft loop (tarmac-sim --scene aircraft) at 5 Hz, 16 beams, cut in two halves: A
/// drives from the middle of the lower side round the right to the top, B from the top round
/// the left back to the start. Generated once for the binary.
const std::pair<tools::KittiSequence, tools::KittiSequence>& halves() {
  static const auto cut = [] {
    const auto dir = std::filesystem::temp_directory_path() /
                     ("tarmac-fleet-test-" + std::to_string(::getpid()));
    sim::SequenceParams p;
    p.path = sim::DrivePath::loop({-30.0, -22.0}, {30.0, 22.0}, 10.0, 20.0);
    p.rate_hz = 5.0;
    p.lidar.beams = 16;
    p.lidar.azimuth_steps = 512;
    const auto written = sim::write_sequence(sim::Scene::aircraft_stand(), p, dir);
    EXPECT_TRUE(written.ok()) << written.error;
    auto opened = tools::open_kitti(dir);
    EXPECT_TRUE(opened.ok()) << (opened.ok() ? "" : opened.error().message);
    const tools::KittiSequence& all = opened.value();
    const std::size_t mid = all.scans.size() / 2;
    const auto part = [&](std::size_t from, std::size_t to) {
      tools::KittiSequence s;
      s.dir = all.dir;
      const auto d = [](std::size_t i) { return static_cast<std::ptrdiff_t>(i); };
      s.scans.assign(all.scans.begin() + d(from), all.scans.begin() + d(to));
      s.T_W_S.assign(all.T_W_S.begin() + d(from), all.T_W_S.begin() + d(to));
      s.times_s.assign(all.times_s.begin() + d(from), all.times_s.begin() + d(to));
      return s;
    };
    return std::pair{part(0, mid), part(mid, all.scans.size())};
  }();
  return cut;
}

/// Vehicle `id`'s config on `domain`: its own LiDAR, pose and output topics under rt/<id>/, the
/// fleet's topic shared; the obstacle grid (the costmap's classes without inflation) published.
config::Config vehicle(std::uint32_t domain, const std::string& id, bool share) {
  auto c = test_config(domain, 2);
  c.dds.participant.name = "tarmacd-" + id;
  c.sensors[0].topic = "rt/" + id + "/lidar";
  // The LiDAR 2 m above the base, the base on the ground: the costmap's ground is at the base.
  c.sensors[0].T_base_sensor.translation().z() = kSensorHeightM;
  c.pose.topic = "rt/" + id + "/pose";
  c.outputs.costmap_topic = "rt/" + id + "/costmap";
  c.outputs.esdf_slice_topic = "rt/" + id + "/esdf_slice";
  c.outputs.cycle_report_topic = "rt/" + id + "/diagnostics";
  c.outputs.diagnostic_array_topic = "rt/" + id + "/diagnostic_array";
  c.outputs.obstacle_grid_topic = "rt/" + id + "/obstacle_grid";
  // No pose-jump rebuilds: the loop's corners at this speed would trigger some, spread over
  // ticks as the machine allows; the comparison below wants A's own map the same in both runs.
  c.mapping.corrections.enabled = false;
  c.fleet.enabled = share;
  c.fleet.vehicle_id = id;
  // A summary every tick (10 Hz): a summary carries the sender's costmap window, so with one a
  // second what B sent of its drive depended on where the wall clock's summaries caught it
  // (4 to 6 of them, 922 to 1305 cells gained). Every tick, each of B's windows is sent.
  c.fleet.publish_period_s = 0.1 * kTimeScale;
  // Ages are taken at the summary's tick, on the wall clock, while a busy machine makes the
  // acknowledged-pace replays run late: a bound no run reaches keeps every cell B saw. The
  // expiry itself is PeerCellsExpire's.
  c.fleet.max_age_s = 120.0 * kTimeScale;
  // Fed at the pace each vehicle acknowledges (replay_options): every scan integrated, however
  // busy the machine, so what A gains from B is the same in every run.
  test::take_late_input(c);
  return c;
}

/// The replay of vehicle `c` from `start_ns`, at twice its speed but never more than four scans
/// ahead of what `executor` has integrated.
tools::ReplayOptions replay_options(const config::Config& c, std::int64_t start_ns,
                                    const Executor& executor) {
  tools::ReplayOptions o;
  o.pace = test::paced_by(executor, 4, executor.totals().scans_integrated);
  o.lidar_qos = c.dds.qos.lidar;
  o.lidar_topic = c.sensors[0].topic;
  o.pose_topic = c.pose.topic;
  o.T_base_sensor = c.sensors[0].T_base_sensor;
  o.rate_scale = 2.0 / kTimeScale;
  o.start_ns = start_ns;
  return o;
}

/// An obstacle grid as received: lattice index of its first cell, size, values (100/0/−1).
struct Grid {
  std::int64_t i0 = 0, j0 = 0;
  std::uint32_t width = 0, height = 0;
  std::int64_t stamp_ns = 0;
  std::vector<std::int8_t> cells;
};

/// The newest obstacle grid stamped `stamp_ns` received within the timeout.
Grid newest_grid(GridReader& reader, std::int64_t stamp_ns) {
  Grid g;
  std::vector<transport::OccupancyGridMsg> batch;
  const auto deadline = std::chrono::steady_clock::now() + 10s * kTimeScale;
  while (std::chrono::steady_clock::now() < deadline) {
    reader.wait_for_sample(100ms);
    batch.clear();
    reader.take_all(batch);
    for (const auto& m : batch) {
      if (transport::from_time_msg(m.header().stamp()) != stamp_ns) continue;
      const double r = m.info().resolution();
      g.i0 = core::bev_lattice_index(m.info().origin().position().x(), r);
      g.j0 = core::bev_lattice_index(m.info().origin().position().y(), r);
      g.width = m.info().width();
      g.height = m.info().height();
      g.stamp_ns = stamp_ns;
      g.cells = m.data();
    }
    if (!g.cells.empty() && batch.empty()) break;  // the newest, and nothing more came
  }
  return g;
}

/// Every summary a listener (no vehicle id: the site view's link) received from `vehicle`.
class Recorder final : public transport::FleetSink {
 public:
  explicit Recorder(std::string vehicle) : vehicle_(std::move(vehicle)) {}
  void summary(core::BevMessage&& m) override {
    if (m.vehicle_id == vehicle_) messages.push_back(std::move(m));
  }
  void reject(std::string_view reason) override { rejected.emplace_back(reason); }
  std::vector<core::BevMessage> messages;
  std::vector<std::string> rejected;

 private:
  std::string vehicle_;
};

class Fleet : public test::LoopbackOnly {
 protected:
  Fleet() { expect_loopback_traffic_ = true; }
};

// A alone, then A and B sharing: A's cells unknown alone take B's class, its known cells
// that B does not know are unchanged, the rest take one of the two; bad summaries refused.
TEST_F(Fleet, TwoVehiclesOnHalvesOfTheLoop_AGainsWhatOnlyBSaw_KeepsItsOwn_BadSummariesCounted) {
  const auto& [half_a, half_b] = halves();
  ASSERT_GT(half_a.scans.size(), 30u);
  constexpr std::uint32_t kDomain = test::kDomainFleetTwoVehicles;
  auto participant = peer(kDomain);
  const auto last_stamp = [](const tools::ReplayStats& s) { return s.last_stamp_ns; };

  // ---- A alone ----
  Grid alone;
  {
    const auto cfg = vehicle(kDomain, "tug-a", false);
    RunningExecutor a(cfg);
    auto grids =
        GridReader::create(participant, cfg.outputs.obstacle_grid_topic, cfg.dds.qos.costmap, 4);
    ASSERT_TRUE(grids.ok());
    auto stats = tools::replay(
        participant, half_a,
        replay_options(cfg, clock_now_ns(CLOCK_REALTIME) + 2 * kSecondNs * kTimeScale, a.get()));
    ASSERT_TRUE(stats.ok()) << stats.error().message;
    alone = newest_grid(*grids.value(), last_stamp(stats.value()));
    ASSERT_FALSE(alone.cells.empty()) << "no obstacle grid of A's last scan";
  }

  // ---- A and B sharing, a listener, and a writer of bad summaries ----
  const auto cfg_a = vehicle(kDomain, "tug-a", true);
  const auto cfg_b = vehicle(kDomain, "tug-b", true);
  RunningExecutor a(cfg_a);
  RunningExecutor b(cfg_b);
  auto grids =
      GridReader::create(participant, cfg_a.outputs.obstacle_grid_topic, cfg_a.dds.qos.costmap, 4);
  ASSERT_TRUE(grids.ok());
  auto reports = ReportReader::create(participant, cfg_a.outputs.cycle_report_topic,
                                      cfg_a.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  transport::FleetLinkOptions listen;
  listen.topic = cfg_a.fleet.topic;
  listen.queue_depth = 1000;
  auto listener = transport::FleetLink::create(participant, listen);
  ASSERT_TRUE(listener.ok()) << listener.error().message;
  const std::int64_t start = clock_now_ns(CLOCK_REALTIME) + 2 * kSecondNs * kTimeScale;
  core::Result<tools::ReplayStats> stats_a = core::Error{"", ""}, stats_b = core::Error{"", ""};
  std::thread play_b(
      [&] { stats_b = tools::replay(participant, half_b, replay_options(cfg_b, start, b.get())); });
  stats_a = tools::replay(participant, half_a, replay_options(cfg_a, start, a.get()));
  play_b.join();
  ASSERT_TRUE(stats_a.ok()) << stats_a.error().message;
  ASSERT_TRUE(stats_b.ok()) << stats_b.error().message;
  const std::int64_t a_last = last_stamp(stats_a.value());

  // Bad summaries: stale (twice the max age), malformed (runs past the tile), from a sender stating
  // a position uncertainty beyond A's bound, and one claiming to be tug-b from tug-x's partition.
  // Each must be counted by A and change nothing.
  {
    auto rogue = FleetWriter::create(participant, cfg_a.fleet.topic, transport::qos::kFleet,
                                     transport::fleet_partition("tug-x"));
    ASSERT_TRUE(rogue.ok()) << rogue.error().message;
    auto impostor = FleetWriter::create(participant, cfg_a.fleet.topic, transport::qos::kFleet,
                                        transport::fleet_partition("tug-x"));
    ASSERT_TRUE(impostor.ok());
    ASSERT_TRUE(rogue.value()->wait_for_readers(3, 5s * kTimeScale));
    core::BevMessage bad;
    bad.vehicle_id = "tug-x";
    bad.keyframe = true;
    bad.resolution_m = cfg_a.mapping.occupancy.voxel_size_m;
    bad.stamp_ns =
        clock_now_ns(CLOCK_REALTIME) - 2 * static_cast<std::int64_t>(cfg_a.fleet.max_age_s * 1e9);
    std::vector<std::uint8_t> occupied(16 * 3);
    for (std::size_t k = 0; k < 16; ++k) occupied[3 * k] = (2 << 6) | 63;  // 16 × 64 cells
    bad.tiles = {core::BevTile{0, 0, occupied}};
    ASSERT_TRUE(rogue.value()->write(transport::to_fleet_bev(bad, "map")));
    bad.stamp_ns = clock_now_ns(CLOCK_REALTIME);
    bad.tiles[0].runs.push_back(0);  // one cell past the tile's 1024
    ASSERT_TRUE(rogue.value()->write(transport::to_fleet_bev(bad, "map")));
    bad.tiles[0].runs.pop_back();
    bad.stamp_ns += 1;
    bad.position_std_m = 5.0;  // a peer lost in its localisation
    ASSERT_TRUE(rogue.value()->write(transport::to_fleet_bev(bad, "map")));
    bad.position_std_m = 0.0;
    bad.vehicle_id = "tug-b";
    bad.sequence = 1000;
    ASSERT_TRUE(impostor.value()->write(transport::to_fleet_bev(bad, "map")));
  }

  // B's summaries after its last scan carry its final cells: once A applied two more, A's
  // costmap holds them.
  const auto b_messages = [](const transport::CycleReport& r) -> std::uint64_t {
    for (const auto& p : r.fleet_peers) {
      if (p.vehicle_id == "tug-b") return p.messages;
    }
    return 0;
  };
  const auto now_report = wait_for_report(*reports.value(), [](const auto&) { return true; });
  const std::uint64_t seen = b_messages(now_report);
  const auto report = wait_for_report(*reports.value(), [&](const transport::CycleReport& r) {
    return b_messages(r) >= seen + 2 && total_of(r.rejections, "fleet.impersonation") > 0 &&
           total_of(r.rejections, "fleet.malformed") > 0 &&
           total_of(r.rejections, "fleet.localisation") > 0;
  });
  ASSERT_GE(b_messages(report), seen + 2) << "A did not apply B's summaries";
  const Grid shared = newest_grid(*grids.value(), a_last);
  a.stop();
  b.stop();
  Recorder recorded("tug-b");
  listener.value()->drain(recorded);
  EXPECT_TRUE(recorded.rejected.size() == 1 && recorded.rejected[0] == "fleet.impersonation");

  // Counted and ignored.
  EXPECT_EQ(total_of(report.rejections, "fleet.stale"), 1u);
  EXPECT_EQ(total_of(report.rejections, "fleet.malformed"), 1u);
  EXPECT_EQ(total_of(report.rejections, "fleet.impersonation"), 1u);
  EXPECT_EQ(total_of(report.rejections, "fleet.localisation"), 1u);
  for (const auto& p : report.fleet_peers) {
    if (p.vehicle_id == "tug-x") {
      EXPECT_EQ(p.cells, 0u);
      EXPECT_EQ(p.messages, 0u);
      EXPECT_EQ(p.rejected, 3u);
    }
  }

  // What A should hold of B: B's summaries applied in stamp order, aged on A's costmap clock.
  ASSERT_FALSE(recorded.messages.empty());
  core::BevPeers b_cells("tug-a", cfg_a.mapping.occupancy.voxel_size_m,
                         static_cast<std::int64_t>(cfg_a.fleet.max_age_s * 1e9), INT64_MAX / 4);
  for (const auto& m : recorded.messages) ASSERT_TRUE(b_cells.apply(m, m.stamp_ns).ok());
  b_cells.expire(shared.stamp_ns);

  ASSERT_EQ(shared.cells.size(), alone.cells.size());
  ASSERT_EQ(shared.i0, alone.i0);
  ASSERT_EQ(shared.j0, alone.j0);
  std::size_t gained = 0, gained_lethal = 0, kept = 0, both = 0;
  for (std::uint32_t y = 0; y < alone.height; ++y) {
    for (std::uint32_t x = 0; x < alone.width; ++x) {
      const std::size_t k = std::size_t{y} * alone.width + x;
      const core::BevPeerCell p = b_cells.lookup(alone.i0 + x, alone.j0 + y);
      const std::int8_t peer_class = p.vehicle_id == nullptr                     ? std::int8_t{-1}
                                     : p.cell.state == core::BevState::kOccupied ? std::int8_t{100}
                                                                                 : std::int8_t{0};
      const std::int8_t own = alone.cells[k];
      const std::int8_t got = shared.cells[k];
      if (own == -1) {
        ASSERT_EQ(got, peer_class) << "cell (" << x << ", " << y << "): unknown to A alone";
        gained += peer_class != -1 ? 1 : 0;
        gained_lethal += peer_class == 100 ? 1 : 0;
      } else if (peer_class == -1) {
        ASSERT_EQ(got, own) << "cell (" << x << ", " << y << "): B does not know it";
        ++kept;
      } else {
        ASSERT_TRUE(got == own || got == peer_class) << "cell (" << x << ", " << y << ")";
        ++both;
      }
    }
  }
  std::printf(
      "fleet: A's %u x %u cells: %zu gained from B (%zu lethal), %zu A's alone, %zu known "
      "to both; B sent %zu summaries\n",
      alone.width, alone.height, gained, gained_lethal, kept, both, recorded.messages.size());
  EXPECT_GT(gained, 1000u) << "B's half of the loop should show A much it did not see";
  EXPECT_GT(gained_lethal, 0u);
  for (const auto& p : report.fleet_peers) {
    if (p.vehicle_id == "tug-b") {
      EXPECT_GE(p.cells, gained);
      EXPECT_GE(p.age_ms, 0.0);
    }
  }
  EXPECT_GE(report.fleet_newest_age_ms, 0.0);
}

// B maps a few scans and goes quiet; A maps on: once B's newest observation is older than
// fleet.max_age_s on A's costmap clock, no cell of A's costmap comes from B.
TEST_F(Fleet, PeerCellsExpireAfterMaxAge) {
  const auto& [half_a, half_b] = halves();
  constexpr std::uint32_t kDomain = test::kDomainFleetExpiry;
  auto participant = peer(kDomain);
  auto cfg_a = vehicle(kDomain, "tug-a", true);
  auto cfg_b = vehicle(kDomain, "tug-b", true);
  cfg_a.fleet.publish_period_s = cfg_b.fleet.publish_period_s = 0.5 * kTimeScale;
  cfg_a.fleet.max_age_s = cfg_b.fleet.max_age_s = 1.0 * kTimeScale;
  RunningExecutor a(cfg_a);
  auto reports = ReportReader::create(participant, cfg_a.outputs.cycle_report_topic,
                                      cfg_a.dds.qos.diagnostics, 400);
  ASSERT_TRUE(reports.ok());
  const std::int64_t start = clock_now_ns(CLOCK_REALTIME) + 2 * kSecondNs * kTimeScale;
  core::Result<tools::ReplayStats> stats = core::Error{"", ""};
  std::thread play_a(
      [&] { stats = tools::replay(participant, half_a, replay_options(cfg_a, start, a.get())); });
  {
    RunningExecutor b(cfg_b);
    auto options = replay_options(cfg_b, start, b.get());
    options.max_scans = 8;
    ASSERT_TRUE(tools::replay(participant, half_b, options).ok());
    const auto from_b = wait_for_report(*reports.value(), [](const transport::CycleReport& r) {
      for (const auto& p : r.fleet_peers) {
        if (p.vehicle_id == "tug-b" && p.cells > 0) return true;
      }
      return false;
    });
    ASSERT_FALSE(from_b.fleet_peers.empty()) << "A never took a cell from B";
  }  // B stops: no summary after this
  play_a.join();
  ASSERT_TRUE(stats.ok()) << stats.error().message;
  const auto last = wait_for_report(*reports.value(), [&](const transport::CycleReport& r) {
    return r.stamp_ns == stats.value().last_stamp_ns;
  });
  ASSERT_EQ(last.stamp_ns, stats.value().last_stamp_ns);
  ASSERT_EQ(last.fleet_peers.size(), 1u);
  EXPECT_EQ(last.fleet_peers[0].cells, 0u) << "B's cells outlived fleet.max_age_s";
  EXPECT_EQ(last.fleet_newest_age_ms, -1.0);
}

// tarmac-fleet, live then from its recording: two vehicles' summaries fused into one site view.
TEST_F(Fleet, SiteView_LiveAndFromItsRecording_TheSameSite) {
  constexpr std::uint32_t kDomain = test::kDomainFleetSiteView;
  const auto dir =
      std::filesystem::temp_directory_path() / ("tarmac-fleet-site-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  {
    std::ofstream yaml(dir / "tarmac.yaml");
    // Cells older than fleet.max_age_s read unknown in the site view: the live view is taken at
    // its stop, however long it ran on a loaded machine, so a long max age.
    yaml << "version: 1\ndds: {domain_id: " << kDomain << "}\nfleet: {max_age_s: 600}\n";
  }
  auto participant = peer(kDomain);
  const double r = config::Config{}.mapping.occupancy.voxel_size_m;
  // Two vehicles' windows 10 m apart, each with a wall: 64 x 64 cells, free, a line occupied.
  const auto snapshot_of = [&](double x0, std::vector<core::BevState>& state,
                               std::vector<std::int64_t>& seen, std::int64_t t) {
    state.assign(64 * 64, core::BevState::kFree);
    seen.assign(64 * 64, t);
    for (int y = 0; y < 64; ++y)
      state[static_cast<std::size_t>(y * 64 + 40)] = core::BevState::kOccupied;
    return core::BevSnapshot{core::GridGeometry2D{x0, 0.0, r, 64, 64}, state, seen};
  };
  std::vector<transport::FleetLinkOptions> options(2);
  std::vector<std::unique_ptr<transport::FleetLink>> links;
  for (int v = 0; v < 2; ++v) {
    options[v].vehicle_id = v == 0 ? "tug-a" : "tug-b";
    auto link = transport::FleetLink::create(participant, options[v]);
    ASSERT_TRUE(link.ok()) << link.error().message;
    links.push_back(std::move(link).value());
  }
  // Live until told to stop (SIGTERM, as its user would), so that however slowly it starts
  // and receives on a loaded machine, it takes both summaries before it writes the view.
  const std::string fleet_tool = TARMAC_FLEET;
  const pid_t live =
      test::spawn({fleet_tool, "--config", (dir / "tarmac.yaml").string(), "--seconds", "0",
                   "--out", (dir / "live").string(), "--record", (dir / "rec").string()},
                  dir / "live.log");
  ASSERT_TRUE(test::eventually([&] { return links[1]->matched_readers() >= 3; }))
      << "tarmac-fleet never subscribed";
  const std::int64_t t = clock_now_ns(CLOCK_REALTIME);
  std::vector<core::BevState> state;
  std::vector<std::int64_t> seen;
  for (int v = 0; v < 2; ++v) {
    core::BevEncoder encoder(options[v].vehicle_id, r);
    const auto snap = snapshot_of(v * 10.0, state, seen, t);
    ASSERT_TRUE(
        links[static_cast<std::size_t>(v)]->publish(encoder.encode(snap, t, true, 10 * kSecondNs)));
  }
  // It records each summary as it applies it (flushed): both recorded, it has both.
  EXPECT_TRUE(test::eventually([&] {
    const auto recorded = fleet::read_recording(dir / "rec");
    return recorded.ok() && recorded.value().size() == 2;
  })) << "tarmac-fleet did not record both summaries";
  kill(live, SIGTERM);
  ASSERT_EQ(test::wait_exit(live, test::kPatience), 0) << std::ifstream(dir / "live.log").rdbuf();
  const std::string play = fleet_tool + " --play " + (dir / "rec").string() + " --out " +
                           (dir / "play").string() + " > " + (dir / "play.log").string() + " 2>&1";
  ASSERT_EQ(std::system(play.c_str()), 0) << std::ifstream(dir / "play.log").rdbuf();

  const auto bytes = [](const std::filesystem::path& f) {
    std::ifstream in(f, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  // The same cells and owners; the ages (and so the PNG's shades) are taken at the end of the
  // listening live, at the newest stamp from a recording.
  for (const char* f : {"site.npy", "site_vehicle.npy"}) {
    EXPECT_FALSE(bytes(dir / "live" / f).empty()) << f;
    EXPECT_EQ(bytes(dir / "live" / f), bytes(dir / "play" / f)) << f;
  }
  EXPECT_GT(bytes(dir / "live" / "site.png").size(), 100u);
  // 64 + 50 columns wide (the windows overlap by 14), one wall each: occupied cells 64 + 64.
  const std::string json = bytes(dir / "play" / "site.json");
  EXPECT_NE(json.find("\"id\": \"tug-a\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"id\": \"tug-b\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"occupied_cells\": 64"), std::string::npos) << json;
  const std::string log = bytes(dir / "play.log");
  EXPECT_NE(log.find("2 summaries from 2 vehicles (0 refused)"), std::string::npos) << log;
  EXPECT_NE(log.find(std::to_string(64 * 64 + 50 * 64) + " known, 128 occupied"), std::string::npos)
      << log;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tarmac::daemon
