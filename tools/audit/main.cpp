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
  std::size_t poses = 0;
  std::string error;  ///< the first failure; scoring stops there
};

/// Reads DIR's poses.txt, obstacle_columns.txt and (when present) dynamic_boxes.txt.
core::Result<Scoring> open_scoring(const std::string& dir, const Eigen::Isometry3d& T_B_S) {
  auto seq = tools::open_kitti(dir);
  if (!seq) return seq.error();
  auto truth = tools::read_obstacle_truth(std::filesystem::path(dir) / "obstacle_columns.txt");
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

}  // namespace

int main(int argc, char** argv) {
  std::string config_path, json_path, png_path, identity_dir, score_dir;
  std::uint64_t max_cycles = 0;
  double idle_s = 0.0, timeout_s = 600.0;
  cli::App app("tarmac-audit",
               "Listens on the CycleReport and costmap topics of the config and, at the end, "
               "prints a per-stage table (last, p50, p99, max vs budget, overruns) and the "
               "end-to-end latency scan stamp -> costmap received.");
  app.add_option("--config", config_path, "tarmacd config (default: the built-in defaults)")
      ->type_name("FILE");
  app.add_option("--cycles", max_cycles, "stop after N cycle reports (0: no limit)")
      ->transform(cli::number<std::uint64_t>());
  app.add_option("--idle-s", idle_s,
                 "stop S seconds after the last costmap, once one arrived (0: never)")
      ->transform(cli::non_negative<double>());
  app.add_option("--timeout-s", timeout_s, "stop after S seconds in any case")
      ->transform(cli::positive<double>());
  app.add_option("--json", json_path, "write the table as JSON")->type_name("FILE");
  app.add_option("--png", png_path,
                 "write the last costmap as PNG (white free, black lethal, yellow to dark red "
                 "inflated, slate unknown; north up)")
      ->type_name("FILE");
  app.add_option("--identity", identity_dir,
                 "DDS Security identity DIR/cert.pem, DIR/key.pem instead of the config's "
                 "(dds.security; e.g. the 'monitor' of make-dds-security.sh)")
      ->check(CLI::ExistingDirectory);
  app.add_option("--score", score_dir,
                 "score every costmap against the ground truth of DIR, a tarmac-sim dataset "
                 "(obstacle_columns.txt, dynamic_boxes.txt, poses.txt) being replayed with "
                 "tarmac-replay: each costmap as the map of the latest scan stamped at or before "
                 "it, the scans' stamps read from the pose topic (start the replay after "
                 "'matched', with --pose-readers 2); prints the 'safety (...)' line of "
                 "tarmac-map, --json adds it under \"safety\"")
      ->check(CLI::ExistingDirectory);
  app.footer("Stops on SIGINT/SIGTERM too. Exit 0 when at least one report arrived.");
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  config::Config cfg;
  if (!config_path.empty()) {
    auto loaded = config::load_config_file(config_path);
    if (!loaded) {
      std::fprintf(stderr, "tarmac-audit: invalid config: %s\n", loaded.error().message.c_str());
      return kExitConfig;
    }
    cfg = std::move(loaded).value();
  }
  std::optional<Scoring> scoring;
  if (!score_dir.empty()) {
    if (cfg.pose.type != config::PoseType::kPoseWithCovarianceStamped) {
      std::fprintf(stderr, "tarmac-audit: --score reads PoseWithCovarianceStamped poses only\n");
      return kExitConfig;
    }
    auto opened = open_scoring(score_dir, cfg.sensors.front().T_base_sensor);
    if (!opened) {
      std::fprintf(stderr, "tarmac-audit: --score: %s\n", opened.error().message.c_str());
      return kExitData;
    }
    scoring.emplace(std::move(opened).value());
  }
  cfg.dds.participant.name = "tarmac-audit";
  if (!identity_dir.empty()) cfg.dds.participant.security.use_identity_dir(identity_dir);
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) {
    std::fprintf(stderr, "tarmac-audit: %s\n", participant.error().message.c_str());
    return kExitUnavailable;
  }
  using ReportReader = transport::Reader<tarmac_msgs::msg::dds_::CycleReport_PubSubType>;
  using GridReader = transport::Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
  auto reports = ReportReader::create(participant.value(), cfg.outputs.cycle_report_topic,
                                      cfg.dds.qos.diagnostics, 1000);
  auto grids =
      GridReader::create(participant.value(), cfg.outputs.costmap_topic, cfg.dds.qos.costmap, 16);
  using PoseReader =
      transport::Reader<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;
  std::unique_ptr<PoseReader> poses;
  if (scoring) {
    auto created = PoseReader::create(participant.value(), cfg.pose.topic, cfg.dds.qos.pose, 1000);
    if (created) poses = std::move(created).value();
  }
  if (!reports || !grids || (scoring && !poses)) {
    std::fprintf(stderr, "tarmac-audit: cannot create readers\n");
    return kExitUnavailable;
  }
  struct sigaction sa {};
  sa.sa_handler = [](int) { g_stop = true; };
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // Say when both readers have matched tarmacd's writers: a script starts its publisher after
  // this line, so the first costmaps (the cold start) are in the figures, not lost to discovery.
  const auto matched = [&] {
    return reports.value()->matched_writers() > 0 && grids.value()->matched_writers() > 0;
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

  std::map<std::string, Series> stages;
  std::vector<std::string> stage_order;
  Series cycle;
  std::vector<double> e2e_ms, jitter_ms;
  std::uint64_t n_reports = 0, skipped = 0, points_in = 0, points_used = 0;
  std::vector<std::uint64_t> skipped_before;  // cycles that came after skipped ticks
  std::int64_t last_costmap_stamp = 0;
  transport::CycleReport last;
  transport::OccupancyGridMsg last_grid;
  bool have_grid = false;
  std::vector<transport::CycleReportMsg> report_batch;
  std::vector<transport::OccupancyGridMsg> grid_batch;
  std::vector<transport::PoseStampedMsg> pose_batch;
  const auto t_start = std::chrono::steady_clock::now();
  auto t_last_grid = t_start;
  const bool tty = isatty(STDERR_FILENO) != 0;
  while (!g_stop) {
    // Woken by the costmap listener, so the reception time is taken within a few µs of arrival.
    grids.value()->wait_for_sample(10ms);
    const std::int64_t now = realtime_ns();
    grid_batch.clear();
    grids.value()->take_all(grid_batch);
    if (scoring) {
      // The poses first: a costmap's scan has normally been stamped by then.
      pose_batch.clear();
      poses->take_all(pose_batch);
      for (const auto& p : pose_batch) on_pose(*scoring, p);
      for (const auto& g : grid_batch) on_costmap(*scoring, g);
    }
    for (auto& g : grid_batch) {
      const std::int64_t stamp = transport::from_time_msg(g.header().stamp());
      if (stamp != last_costmap_stamp) {
        e2e_ms.push_back(static_cast<double>(now - stamp) / 1e6);
        last_costmap_stamp = stamp;
      }
      last_grid = std::move(g);
      have_grid = true;
      t_last_grid = std::chrono::steady_clock::now();
    }
    report_batch.clear();
    reports.value()->take_all(report_batch);
    for (const auto& m : report_batch) {
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
    if (tty && !report_batch.empty()) {
      std::fprintf(stderr,
                   "\rtarmac-audit: %llu cycles, cycle last %.2f ms p99 %.2f ms, e2e p99 %.1f ms "
                   "(%zu costmaps)   ",
                   static_cast<unsigned long long>(n_reports), last.cycle_duration_ms,
                   percentile(cycle.ms, 0.99), percentile(e2e_ms, 0.99), e2e_ms.size());
    }
    const auto now_steady = std::chrono::steady_clock::now();
    if (max_cycles > 0 && n_reports >= max_cycles) break;
    if (idle_s > 0 && have_grid &&
        std::chrono::duration<double>(now_steady - t_last_grid).count() > idle_s) {
      break;
    }
    if (std::chrono::duration<double>(now_steady - t_start).count() > timeout_s) break;
  }
  if (tty) std::fprintf(stderr, "\n");
  if (n_reports == 0) {
    std::fprintf(stderr, "tarmac-audit: no CycleReport received on %s (domain %u)\n",
                 cfg.outputs.cycle_report_topic.c_str(), cfg.dds.participant.domain_id);
    return kExitUnavailable;
  }

  std::printf(
      "tarmac-audit: %llu cycles (config %s), %llu skipped ticks, wake jitter p50 %.3f "
      "ms p99 %.3f ms, %llu points in, %llu used\n",
      static_cast<unsigned long long>(n_reports), last.config_hash.c_str(),
      static_cast<unsigned long long>(skipped), percentile(jitter_ms, 0.5),
      percentile(jitter_ms, 0.99), static_cast<unsigned long long>(points_in),
      static_cast<unsigned long long>(points_used));
  if (!skipped_before.empty()) {
    std::string at;
    for (const std::uint64_t c : skipped_before) at += " " + std::to_string(c);
    std::printf("skipped ticks came before cycles:%s\n", at.c_str());
  }
  std::printf("%-22s %9s %9s %9s %9s %9s %9s %9s\n", "stage (ms)", "last", "p50", "p99", "max",
              "worst", "budget", "overruns");
  const auto row = [](const std::string& name, const Series& s) {
    std::printf("%-22s %9.3f %9.3f %9.3f %9.3f %9llu %9.3f %9llu\n", name.c_str(),
                s.ms.empty() ? 0.0 : s.ms.back(), percentile(s.ms, 0.5), percentile(s.ms, 0.99),
                s.max(), static_cast<unsigned long long>(s.worst_cycle()), s.budget_ms,
                static_cast<unsigned long long>(s.overruns));
  };
  for (const auto& name : stage_order) row(name, stages[name]);
  row("cycle", cycle);
  const double e2e_max = e2e_ms.empty() ? 0.0 : *std::max_element(e2e_ms.begin(), e2e_ms.end());
  std::printf("%-22s %9.3f %9.3f %9.3f %9.3f   (%zu costmaps)\n", "scan stamp -> costmap",
              e2e_ms.empty() ? 0.0 : e2e_ms.back(), percentile(e2e_ms, 0.5),
              percentile(e2e_ms, 0.99), e2e_max, e2e_ms.size());
  for (const auto* list : {&last.drops, &last.rejections}) {
    std::string text;
    for (const auto& r : *list) {
      if (r.total > 0) text += " " + r.reason + "=" + std::to_string(r.total);
    }
    std::printf("%s (totals):%s\n", list == &last.drops ? "drops" : "rejections",
                text.empty() ? " none" : text.c_str());
  }
  if (have_grid) {
    const auto& d = last_grid.data();
    std::printf("last costmap: %ux%u cells, stamp %.3f s, digest %s\n", last_grid.info().width(),
                last_grid.info().height(), static_cast<double>(last_costmap_stamp) / 1e9,
                tools::digest({reinterpret_cast<const std::uint8_t*>(d.data()), d.size()}).c_str());
  }
  if (scoring) {
    scoring->scorer->finish();
    const tools::StampedSafetyScorer& sc = *scoring->scorer;
    std::printf("%s\n", tools::safety_summary(sc.tracker().report()).c_str());
    std::printf(
        "scored %zu costmaps against %zu of the %zu scans stamped on the pose topic (%s); %zu "
        "costmaps stamped between scans, %zu before the first\n",
        sc.costmaps(), sc.scans_with_costmap(), sc.scans_stamped(), scoring->dir.c_str(),
        sc.stamp_not_a_scan(), sc.before_first_scan());
  }

  if (!json_path.empty()) {
    const auto stats = [](const Series& s) {
      return nlohmann::ordered_json{{"last", s.ms.empty() ? 0.0 : s.ms.back()},
                                    {"p50", percentile(s.ms, 0.5)},
                                    {"p99", percentile(s.ms, 0.99)},
                                    {"max", s.max()},
                                    {"worst_cycle", s.worst_cycle()},
                                    {"budget", s.budget_ms},
                                    {"overruns", s.overruns}};
    };
    nlohmann::ordered_json stages_ms = nlohmann::ordered_json::object();
    for (const auto& name : stage_order) stages_ms[name] = stats(stages[name]);
    stages_ms["cycle"] = stats(cycle);
    nlohmann::ordered_json j = {
        {"cycles", n_reports},
        {"skipped_ticks", skipped},
        {"skipped_before_cycles", skipped_before},
        {"config_hash", last.config_hash},
        {"stages_ms", std::move(stages_ms)},
        {"e2e_latency_ms",
         {{"samples", e2e_ms.size()},
          {"p50", percentile(e2e_ms, 0.5)},
          {"p99", percentile(e2e_ms, 0.99)},
          {"max", e2e_max}}},
        {"wake_jitter_ms",
         {{"p50", percentile(jitter_ms, 0.5)}, {"p99", percentile(jitter_ms, 0.99)}}}};
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
    }
    if (auto w = tools::write_json(json_path, j); !w) {
      std::fprintf(stderr, "tarmac-audit: %s\n", w.error().message.c_str());
      return kExitIo;
    }
    std::printf("wrote %s\n", json_path.c_str());
  }
  if (!png_path.empty()) {
    if (!have_grid) {
      std::fprintf(stderr, "tarmac-audit: no costmap received, no PNG written\n");
      return kExitUnavailable;
    }
    if (auto w = tools::write_png(png_path, render(last_grid), last_grid.info().width(),
                                  last_grid.info().height());
        !w) {
      std::fprintf(stderr, "tarmac-audit: %s\n", w.error().message.c_str());
      return kExitIo;
    }
    std::printf("wrote %s\n", png_path.c_str());
  }
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
