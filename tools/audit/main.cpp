// tarmac-audit: subscribes to tarmacd's CycleReport and costmap over localhost DDS and prints,
// per stage, the last, p50, p99 and max duration against its budget and the overruns, plus the
// end-to-end latency from scan stamp to costmap reception (the costmap's stamp is the newest
// integrated scan's). Optionally writes the same as JSON and the last costmap as PNG, and with
// --score scores every costmap against a simulated dataset's ground truth, as tarmac-map does.

#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "geometry_msgsPubSubTypes.h"
#include "nav_msgsPubSubTypes.h"
#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/tools/array_io.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/stamped_safety.hpp"
#include "tarmac/tools/stats.hpp"
#include "tarmac_msgsPubSubTypes.h"

namespace {

using namespace tarmac;
using namespace std::chrono_literals;

constexpr int kExitData = 65;
constexpr int kExitUnavailable = 69;
constexpr int kExitIo = 74;
constexpr int kExitConfig = 78;

std::atomic<bool> g_stop{false};

std::int64_t realtime_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

using tools::percentile;

struct Series {
  std::vector<double> ms;
  std::vector<std::uint64_t> cycle;  // the CycleReport's cycle_index of each duration
  double budget_ms = 0.0;
  std::uint64_t overruns = 0;

  [[nodiscard]] double max() const { return ms.empty() ? 0.0 : ms[tools::index_of_max(ms)]; }
  /// The cycle of the longest duration: the first cycles from an empty map are 0, 1, ...
  [[nodiscard]] std::uint64_t worst_cycle() const {
    return cycle.empty() ? 0 : cycle[tools::index_of_max(ms)];
  }
};

std::vector<std::uint8_t> render(const transport::OccupancyGridMsg& grid) {
  const std::uint32_t w = grid.info().width(), h = grid.info().height();
  std::vector<std::uint8_t> rgb(std::size_t{w} * h * 3);
  for (std::uint32_t y = 0; y < h; ++y) {
    for (std::uint32_t x = 0; x < w; ++x) {
      const int c = grid.data()[std::size_t{y} * w + x];
      std::uint8_t* px = &rgb[(std::size_t{h - 1 - y} * w + x) * 3];
      if (c < 0) {
        px[0] = 70, px[1] = 80, px[2] = 110;
      } else if (c >= 100) {
        px[0] = px[1] = px[2] = 0;
      } else if (c == 99) {
        px[0] = 180, px[1] = 0, px[2] = 0;
      } else if (c > 0) {
        px[0] = 255, px[1] = static_cast<std::uint8_t>(230 - 2 * c), px[2] = 60;
      } else {
        px[0] = px[1] = px[2] = 245;
      }
    }
  }
  return rgb;
}

/// --score: a dataset's ground truth, and the scans' stamps learnt from the pose topic.
struct Scoring {
  std::string dir;
  /// The pose tarmac-replay publishes for each scan (T_world_base, the config's first sensor).
  std::vector<Eigen::Isometry3d> T_W_B;
  std::optional<tools::StampedSafetyScorer> scorer;
  double min_obstacle_height_m = 0.08;  ///< the config's: lower small objects are not scored
  std::size_t poses = 0;
  std::string error;  ///< the first failure; scoring stops there
};

/// Reads DIR's poses.txt, obstacle_columns.txt and (when present) ground_cells.txt,
/// curb_columns.txt and dynamic_boxes.txt.
core::Result<Scoring> open_scoring(const std::string& dir, const Eigen::Isometry3d& T_B_S) {
  auto seq = tools::open_kitti(dir);
  if (!seq) return seq.error();
  auto truth = tools::read_dataset_truth(dir);
  if (!truth) return truth.error();
  std::vector<tools::DynamicBox> moving;
  if (const auto file = std::filesystem::path(dir) / "dynamic_boxes.txt";
      std::filesystem::exists(file)) {
    auto boxes = tools::read_dynamic_truth(file);
    if (!boxes) return boxes.error();
    moving = std::move(boxes).value().boxes;
  }
  Scoring s;
  s.dir = dir;
  std::vector<Eigen::Vector2d> vehicle_xy;
  for (const Eigen::Isometry3d& T_W_S : seq.value().T_W_S) {
    s.T_W_B.push_back(T_W_S * T_B_S.inverse());
    // tarmac-map's vehicle position: the base under the sensor, i.e. the sensor's x, y.
    vehicle_xy.push_back(T_W_S.translation().head<2>());
  }
  s.scorer.emplace(std::move(truth).value(), std::move(vehicle_xy), std::move(moving));
  if (const auto file = std::filesystem::path(dir) / "small_objects.txt";
      std::filesystem::exists(file)) {
    auto objects = tools::read_small_objects(file);
    if (!objects) return objects.error();
    s.scorer->score_small_objects(std::move(objects).value());
  }
  return s;
}

/// One pose of the replay: the stamp of the next scan, once its pose is the dataset's.
void on_pose(Scoring& s, const transport::PoseStampedMsg& m) {
  if (!s.error.empty()) return;
  const std::size_t k = s.poses++;
  const auto T = transport::from_pose_msg(m.pose().pose());
  if (!T || k >= s.T_W_B.size() ||
      (T.value().translation() - s.T_W_B[k].translation()).norm() > 1e-3) {
    s.error = "pose " + std::to_string(k) + " on the pose topic is not scan " + std::to_string(k) +
              " of " + s.dir +
              " (another dataset, another --sensor, or the replay started before this audit "
              "matched: give tarmac-replay --pose-readers 2)";
    return;
  }
  if (auto added = s.scorer->add_scan_stamp(transport::from_time_msg(m.header().stamp())); !added) {
    s.error = added.error().message;
  }
}

void on_costmap(Scoring& s, const transport::OccupancyGridMsg& m) {
  if (!s.error.empty()) return;
  auto costmap = transport::from_occupancy_grid(m);
  if (!costmap) {
    s.error = "costmap: " + costmap.error().message;
    return;
  }
  if (auto added = s.scorer->add_costmap(std::move(costmap).value(),
                                         transport::from_time_msg(m.header().stamp()));
      !added) {
    s.error = added.error().message;
  }
}

/// The command line.
struct Options {
  std::string config, json, png, identity, score;
  std::uint64_t max_cycles = 0;  // 0: no limit
  double idle_s = 0.0, timeout_s = 600.0;
};

/// Parses the command line into `opt`. Empty: go on; otherwise main returns the value.
std::optional<int> parse_options(int argc, char** argv, Options& opt) {
  cli::App app("tarmac-audit",
               "Listens on the CycleReport and costmap topics of the config and, at the end, "
               "prints a per-stage table (last, p50, p99, max vs budget, overruns) and the "
               "end-to-end latency scan stamp -> costmap received.");
  app.add_option("--config", opt.config, "tarmacd config (default: the built-in defaults)")
      ->type_name("FILE");
  app.add_option("--cycles", opt.max_cycles, "stop after N cycle reports (0: no limit)")
      ->transform(cli::number<std::uint64_t>());
  app.add_option("--idle-s", opt.idle_s,
                 "stop S seconds after the last costmap, once one arrived (0: never)")
      ->transform(cli::non_negative<double>());
  app.add_option("--timeout-s", opt.timeout_s, "stop after S seconds in any case")
      ->transform(cli::positive<double>());
  app.add_option("--json", opt.json, "write the table as JSON")->type_name("FILE");
  app.add_option("--png", opt.png,
                 "write the last costmap as PNG (white free, black lethal, yellow to dark red "
                 "inflated, slate unknown; north up)")
      ->type_name("FILE");
  app.add_option("--identity", opt.identity,
                 "DDS Security identity DIR/cert.pem, DIR/key.pem instead of the config's "
                 "(dds.security; e.g. the 'monitor' of make-dds-security.sh)")
      ->check(CLI::ExistingDirectory);
  app.add_option("--score", opt.score,
                 "score every costmap against the ground truth of DIR, a tarmac-sim dataset "
                 "(obstacle_columns.txt, ground_cells.txt, curb_columns.txt, dynamic_boxes.txt, "
                 "poses.txt) being replayed with tarmac-replay: each costmap as the map of the "
                 "latest scan stamped at or before it, the scans' stamps read from the pose "
                 "topic (start the replay after 'matched', with --pose-readers 2); prints the "
                 "'safety (...)' line of tarmac-map, --json adds it under \"safety\"")
      ->check(CLI::ExistingDirectory);
  app.footer("Stops on SIGINT/SIGTERM too. Exit 0 when at least one report arrived.");
  return cli::parse(app, argc, argv);
}

/// Reads the config and, with --score, the dataset's ground truth. 0, or the exit code after
/// saying why on stderr.
int load_inputs(const Options& opt, config::Config& cfg, std::optional<Scoring>& scoring) {
  if (const int rc = config::load_tool_config("tarmac-audit", opt.config, cfg); rc != 0) return rc;
  if (!opt.score.empty()) {
    if (cfg.pose.type != config::PoseType::kPoseWithCovarianceStamped) {
      std::fprintf(stderr, "tarmac-audit: --score reads PoseWithCovarianceStamped poses only\n");
      return kExitConfig;
    }
    auto opened = open_scoring(opt.score, cfg.sensors.front().T_base_sensor);
    if (!opened) {
      std::fprintf(stderr, "tarmac-audit: --score: %s\n", opened.error().message.c_str());
      return kExitData;
    }
    scoring.emplace(std::move(opened).value());
    scoring->min_obstacle_height_m = cfg.mapping.costmap.min_obstacle_height_m;
  }
  return 0;
}

using ReportReader = transport::Reader<tarmac_msgs::msg::dds_::CycleReport_PubSubType>;
using GridReader = transport::Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
using PoseReader =
    transport::Reader<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;

/// The DDS participant and the readers of the audit.
struct Readers {
  std::optional<transport::Participant> participant;
  std::unique_ptr<ReportReader> reports;
  std::unique_ptr<GridReader> grids;
  std::unique_ptr<PoseReader> poses;  ///< with --score only
};

/// Creates the participant (named tarmac-audit, with --identity's identity) and the readers of
/// the CycleReport and costmap topics and, when `with_poses`, of the pose topic. 0, or the exit
/// code after saying why on stderr.
int open_readers(const Options& opt, config::Config& cfg, bool with_poses, Readers& readers) {
  cfg.dds.participant.name = "tarmac-audit";
  if (!opt.identity.empty()) cfg.dds.participant.security.use_identity_dir(opt.identity);
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) {
    std::fprintf(stderr, "tarmac-audit: %s\n", participant.error().message.c_str());
    return kExitUnavailable;
  }
  const transport::Participant& p = readers.participant.emplace(std::move(participant).value());
  auto reports =
      ReportReader::create(p, cfg.outputs.cycle_report_topic, cfg.dds.qos.diagnostics, 1000);
  auto grids = GridReader::create(p, cfg.outputs.costmap_topic, cfg.dds.qos.costmap, 16);
  if (with_poses) {
    auto created = PoseReader::create(p, cfg.pose.topic, cfg.dds.qos.pose, 1000);
    if (created) readers.poses = std::move(created).value();
  }
  if (!reports || !grids || (with_poses && !readers.poses)) {
    std::fprintf(stderr, "tarmac-audit: cannot create readers\n");
    return kExitUnavailable;
  }
  readers.reports = std::move(reports).value();
  readers.grids = std::move(grids).value();
  return 0;
}

/// SIGINT and SIGTERM end the collection (and the wait for a match) instead of the process.
void install_stop_handlers() {
  struct sigaction sa {};
  sa.sa_handler = [](int) { g_stop = true; };
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

/// Waits (at most `timeout_s`) until both readers have matched tarmacd's writers, and says so.
void wait_for_match(const Readers& readers, const config::Config& cfg, double timeout_s) {
  // Say when both readers have matched tarmacd's writers: a script starts its publisher after
  // this line, so the first costmaps (the cold start) are in the figures, not lost to discovery.
  const auto matched = [&] {
    return readers.reports->matched_writers() > 0 && readers.grids->matched_writers() > 0;
  };
  const auto t_wait = std::chrono::steady_clock::now();
  while (!g_stop && !matched() &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t_wait).count() <
             timeout_s) {
    std::this_thread::sleep_for(10ms);
  }
  if (matched()) {
    std::fprintf(stderr, "tarmac-audit: matched (%s, %s)\n", cfg.outputs.costmap_topic.c_str(),
                 cfg.outputs.cycle_report_topic.c_str());
  }
}

/// What the audit accumulates from the reports and costmaps it receives.
struct Tally {
  std::map<std::string, Series> stages;
  std::vector<std::string> stage_order;  ///< the stages as they first appeared
  Series cycle;
  std::vector<double> e2e_ms, jitter_ms;
  std::uint64_t n_reports = 0, skipped = 0, points_in = 0, points_used = 0;
  std::vector<std::uint64_t> skipped_before;  // cycles that came after skipped ticks
  std::int64_t last_costmap_stamp = 0;
  transport::CycleReport last;
  transport::OccupancyGridMsg last_grid;
  bool have_grid = false;

  /// Costmaps received at `now_ns` (realtime), moved from `batch`: one end-to-end latency per
  /// new stamp.
  void add_grids(std::vector<transport::OccupancyGridMsg>& batch, std::int64_t now_ns) {
    for (auto& g : batch) {
      const std::int64_t stamp = transport::from_time_msg(g.header().stamp());
      if (stamp != last_costmap_stamp) {
        e2e_ms.push_back(static_cast<double>(now_ns - stamp) / 1e6);
        last_costmap_stamp = stamp;
      }
      last_grid = std::move(g);
      have_grid = true;
    }
  }

  /// Cycle reports, oldest first: the counters and each stage's and the cycle's durations.
  void add_reports(const std::vector<transport::CycleReportMsg>& batch) {
    for (const auto& m : batch) {
      last = transport::from_cycle_report(m);
      ++n_reports;
      skipped += last.skipped_ticks;
      if (last.skipped_ticks > 0) skipped_before.push_back(last.cycle_index);
      points_in += last.points_in;
      points_used += last.points_used;
      jitter_ms.push_back(last.wake_jitter_ms);
      for (const auto& s : last.stages) {
        auto [it, fresh] = stages.try_emplace(s.name);
        if (fresh) stage_order.push_back(s.name);
        it->second.ms.push_back(s.duration_ms);
        it->second.cycle.push_back(last.cycle_index);
        it->second.budget_ms = s.budget_ms;
        it->second.overruns += s.overrun ? 1 : 0;
      }
      cycle.ms.push_back(last.cycle_duration_ms);
      cycle.cycle.push_back(last.cycle_index);
      cycle.budget_ms = last.cycle_budget_ms;
      cycle.overruns += last.overrun ? 1 : 0;
    }
  }

  [[nodiscard]] double e2e_max() const {
    return e2e_ms.empty() ? 0.0 : *std::max_element(e2e_ms.begin(), e2e_ms.end());
  }
};

/// Takes the costmaps, reports (and, with --score, poses) until SIGINT/SIGTERM, --cycles,
/// --idle-s or --timeout-s, with a progress line when stderr is a terminal.
void collect(const Options& opt, Readers& readers, std::optional<Scoring>& scoring, Tally& tally) {
  std::vector<transport::CycleReportMsg> report_batch;
  std::vector<transport::OccupancyGridMsg> grid_batch;
  std::vector<transport::PoseStampedMsg> pose_batch;
  const auto t_start = std::chrono::steady_clock::now();
  auto t_last_grid = t_start;
  const bool tty = isatty(STDERR_FILENO) != 0;
  while (!g_stop) {
    // Woken by the costmap listener, so the reception time is taken within a few µs of arrival.
    readers.grids->wait_for_sample(10ms);
    const std::int64_t now = realtime_ns();
    grid_batch.clear();
    readers.grids->take_all(grid_batch);
    if (scoring) {
      // The poses first: a costmap's scan has normally been stamped by then.
      pose_batch.clear();
      readers.poses->take_all(pose_batch);
      for (const auto& p : pose_batch) on_pose(*scoring, p);
      for (const auto& g : grid_batch) on_costmap(*scoring, g);
    }
    tally.add_grids(grid_batch, now);
    if (!grid_batch.empty()) t_last_grid = std::chrono::steady_clock::now();
    report_batch.clear();
    readers.reports->take_all(report_batch);
    tally.add_reports(report_batch);
    if (tty && !report_batch.empty()) {
      std::fprintf(stderr,
                   "\rtarmac-audit: %llu cycles, cycle last %.2f ms p99 %.2f ms, e2e p99 %.1f ms "
                   "(%zu costmaps)   ",
                   static_cast<unsigned long long>(tally.n_reports), tally.last.cycle_duration_ms,
                   percentile(tally.cycle.ms, 0.99), percentile(tally.e2e_ms, 0.99),
                   tally.e2e_ms.size());
    }
    const auto now_steady = std::chrono::steady_clock::now();
    if (opt.max_cycles > 0 && tally.n_reports >= opt.max_cycles) break;
    if (opt.idle_s > 0 && tally.have_grid &&
        std::chrono::duration<double>(now_steady - t_last_grid).count() > opt.idle_s) {
      break;
    }
    if (std::chrono::duration<double>(now_steady - t_start).count() > opt.timeout_s) break;
  }
  if (tty) std::fprintf(stderr, "\n");
}

void print_row(const std::string& name, const Series& s) {
  std::printf("%-22s %9.3f %9.3f %9.3f %9.3f %9llu %9.3f %9llu\n", name.c_str(),
              s.ms.empty() ? 0.0 : s.ms.back(), percentile(s.ms, 0.5), percentile(s.ms, 0.99),
              s.max(), static_cast<unsigned long long>(s.worst_cycle()), s.budget_ms,
              static_cast<unsigned long long>(s.overruns));
}

/// The summary on stdout: the counters, the per-stage table, the end-to-end latency, the last
/// report's drop and rejection totals and the last costmap.
void print_table(const Tally& t) {
  std::printf(
      "tarmac-audit: %llu cycles (config %s), %llu skipped ticks, wake jitter p50 %.3f "
      "ms p99 %.3f ms, %llu points in, %llu used\n",
      static_cast<unsigned long long>(t.n_reports), t.last.config_hash.c_str(),
      static_cast<unsigned long long>(t.skipped), percentile(t.jitter_ms, 0.5),
      percentile(t.jitter_ms, 0.99), static_cast<unsigned long long>(t.points_in),
      static_cast<unsigned long long>(t.points_used));
  if (!t.skipped_before.empty()) {
    std::string at;
    for (const std::uint64_t c : t.skipped_before) at += " " + std::to_string(c);
    std::printf("skipped ticks came before cycles:%s\n", at.c_str());
  }
  std::printf("%-22s %9s %9s %9s %9s %9s %9s %9s\n", "stage (ms)", "last", "p50", "p99", "max",
              "worst", "budget", "overruns");
  for (const auto& name : t.stage_order) print_row(name, t.stages.at(name));
  print_row("cycle", t.cycle);
  std::printf("%-22s %9.3f %9.3f %9.3f %9.3f   (%zu costmaps)\n", "scan stamp -> costmap",
              t.e2e_ms.empty() ? 0.0 : t.e2e_ms.back(), percentile(t.e2e_ms, 0.5),
              percentile(t.e2e_ms, 0.99), t.e2e_max(), t.e2e_ms.size());
  for (const auto* list : {&t.last.drops, &t.last.rejections}) {
    std::string text;
    for (const auto& r : *list) {
      if (r.total > 0) text += " " + r.reason + "=" + std::to_string(r.total);
    }
    std::printf("%s (totals):%s\n", list == &t.last.drops ? "drops" : "rejections",
                text.empty() ? " none" : text.c_str());
  }
  if (t.have_grid) {
    const auto& d = t.last_grid.data();
    std::printf("last costmap: %ux%u cells, stamp %.3f s, digest %s\n", t.last_grid.info().width(),
                t.last_grid.info().height(), static_cast<double>(t.last_costmap_stamp) / 1e9,
                tools::digest({reinterpret_cast<const std::uint8_t*>(d.data()), d.size()}).c_str());
  }
}

/// Ends the scoring (the scans still waiting for a costmap) and prints tarmac-map's 'safety
/// (...)' line and what was scored.
void finish_scoring(Scoring& scoring) {
  scoring.scorer->finish();
  const tools::StampedSafetyScorer& sc = *scoring.scorer;
  std::printf("%s\n", tools::safety_summary(sc.tracker().report()).c_str());
  if (const tools::SmallObjectTracker* small = sc.small_objects(); small != nullptr) {
    std::printf("%s", tools::small_objects_summary(*small, scoring.min_obstacle_height_m).c_str());
  }
  std::printf(
      "scored %zu costmaps against %zu of the %zu scans stamped on the pose topic (%s); %zu "
      "costmaps stamped between scans, %zu before the first\n",
      sc.costmaps(), sc.scans_with_costmap(), sc.scans_stamped(), scoring.dir.c_str(),
      sc.stamp_not_a_scan(), sc.before_first_scan());
}

nlohmann::ordered_json series_json(const Series& s) {
  return nlohmann::ordered_json{{"last", s.ms.empty() ? 0.0 : s.ms.back()},
                                {"p50", percentile(s.ms, 0.5)},
                                {"p99", percentile(s.ms, 0.99)},
                                {"max", s.max()},
                                {"worst_cycle", s.worst_cycle()},
                                {"budget", s.budget_ms},
                                {"overruns", s.overruns}};
}

/// The table as --json writes it; with --score, "scored" and "safety" too.
nlohmann::ordered_json summary_json(const Tally& t, const std::optional<Scoring>& scoring) {
  nlohmann::ordered_json stages_ms = nlohmann::ordered_json::object();
  for (const auto& name : t.stage_order) stages_ms[name] = series_json(t.stages.at(name));
  stages_ms["cycle"] = series_json(t.cycle);
  nlohmann::ordered_json j = {
      {"cycles", t.n_reports},
      {"skipped_ticks", t.skipped},
      {"skipped_before_cycles", t.skipped_before},
      {"config_hash", t.last.config_hash},
      {"stages_ms", std::move(stages_ms)},
      {"e2e_latency_ms",
       {{"samples", t.e2e_ms.size()},
        {"p50", percentile(t.e2e_ms, 0.5)},
        {"p99", percentile(t.e2e_ms, 0.99)},
        {"max", t.e2e_max()}}},
      {"wake_jitter_ms",
       {{"p50", percentile(t.jitter_ms, 0.5)}, {"p99", percentile(t.jitter_ms, 0.99)}}}};
  if (scoring) {
    const tools::StampedSafetyScorer& sc = *scoring->scorer;
    j["scored"] = {{"dataset", scoring->dir},
                   {"scans_stamped", sc.scans_stamped()},
                   {"costmaps", sc.costmaps()},
                   {"scans_with_costmap", sc.scans_with_costmap()},
                   {"stamp_not_a_scan", sc.stamp_not_a_scan()},
                   {"before_first_scan", sc.before_first_scan()},
                   {"error", scoring->error}};
    j["safety"] = tools::safety_json(sc.tracker());
    if (const tools::SmallObjectTracker* small = sc.small_objects(); small != nullptr) {
      j["small_objects"] = tools::small_objects_json(*small);
    }
  }
  return j;
}

/// Writes --json and --png. 0, or the exit code after saying why on stderr.
int write_outputs(const Options& opt, const Tally& t, const std::optional<Scoring>& scoring) {
  if (!opt.json.empty()) {
    if (auto w = tools::write_json(opt.json, summary_json(t, scoring)); !w) {
      std::fprintf(stderr, "tarmac-audit: %s\n", w.error().message.c_str());
      return kExitIo;
    }
    std::printf("wrote %s\n", opt.json.c_str());
  }
  if (!opt.png.empty()) {
    if (!t.have_grid) {
      std::fprintf(stderr, "tarmac-audit: no costmap received, no PNG written\n");
      return kExitUnavailable;
    }
    if (auto w = tools::write_png(opt.png, render(t.last_grid), t.last_grid.info().width(),
                                  t.last_grid.info().height());
        !w) {
      std::fprintf(stderr, "tarmac-audit: %s\n", w.error().message.c_str());
      return kExitIo;
    }
    std::printf("wrote %s\n", opt.png.c_str());
  }
  return 0;
}

/// With --score: kExitData, after saying why, when the scoring stopped or scored nothing.
int scoring_exit(const std::optional<Scoring>& scoring) {
  if (scoring && !scoring->error.empty()) {
    std::fprintf(stderr, "tarmac-audit: --score stopped: %s\n", scoring->error.c_str());
    return kExitData;
  }
  if (scoring && scoring->scorer->costmaps() == 0) {
    std::fprintf(stderr, "tarmac-audit: --score: no costmap scored\n");
    return kExitData;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (auto exit = parse_options(argc, argv, opt)) return *exit;
  config::Config cfg;
  std::optional<Scoring> scoring;
  if (const int exit = load_inputs(opt, cfg, scoring); exit != 0) return exit;
  Readers readers;
  if (const int exit = open_readers(opt, cfg, scoring.has_value(), readers); exit != 0) {
    return exit;
  }
  install_stop_handlers();
  wait_for_match(readers, cfg, opt.timeout_s);

  Tally tally;
  collect(opt, readers, scoring, tally);
  if (tally.n_reports == 0) {
    std::fprintf(stderr, "tarmac-audit: no CycleReport received on %s (domain %u)\n",
                 cfg.outputs.cycle_report_topic.c_str(), cfg.dds.participant.domain_id);
    return kExitUnavailable;
  }
  print_table(tally);
  if (scoring) finish_scoring(*scoring);
  if (const int exit = write_outputs(opt, tally, scoring); exit != 0) return exit;
  return scoring_exit(scoring);
}
