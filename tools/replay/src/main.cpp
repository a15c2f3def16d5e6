// tarmac-replay: publishes a KITTI-layout sequence (scans + poses) over localhost DDS as a
// ROS 2-style LiDAR driver and localiser would, on the topics of a tarmacd config.

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/tools/kitti.hpp"

namespace {

using namespace tarmac;

constexpr int kExitData = 65;
constexpr int kExitUnavailable = 69;
constexpr int kExitConfig = 78;

std::atomic<bool> g_stop{false};

/// The command line.
struct Args {
  std::string dataset, config_path, poses_file = "poses.txt", sensor_id, identity_dir,
                                    corrections_file, layout = "beams", driver;
  std::size_t pace_ahead = 0;
  double pace_patience_s = 60.0;
  tools::ReplayOptions options;
};

/// The command line's options, bound to `a`.
void add_options(cli::App& app, Args& a) {
  app.add_option("--dataset", a.dataset, "the sequence")->required()->check(CLI::ExistingDirectory);
  app.add_option("--rate-scale", a.options.rate_scale, "replay X times faster than recorded")
      ->transform(cli::positive<double>());
  app.add_option("--config", a.config_path, "tarmacd config whose topics and sensors are used")
      ->type_name("FILE");
  app.add_option("--scans", a.options.max_scans, "first N scans only (0: all)")
      ->transform(cli::number<std::size_t>());
  app.add_option("--poses", a.poses_file, "pose file in DIR")->type_name("FILE");
  app.add_option("--jitter-ms", a.options.jitter_ms,
                 "publish each message up to MS late, uniformly (tests)")
      ->transform(cli::non_negative<double>());
  app.add_option("--sensor", a.sensor_id,
                 "which configured sensor the scans belong to (default: the first)")
      ->type_name("ID");
  app.add_option("--loop", a.options.loops,
                 "replay the sequence N times, stamps continuing (soak tests)")
      ->transform(cli::positive<std::size_t>());
  app.add_flag_callback(
      "--no-poses", [&a] { a.options.publish_poses = false; },
      "scans only (one replay per LiDAR, one of them with poses)");
  app.add_option("--align-ms", a.options.align_ms,
                 "first stamp on a multiple of MS since the epoch, like a LiDAR phase-locked to "
                 "PTP (tarmacd ticks on the same grid; 0: no alignment)")
      ->transform(cli::non_negative<double>());
  app.add_option("--identity", a.identity_dir,
                 "DDS Security identity DIR/cert.pem, DIR/key.pem instead of the config's "
                 "(dds.security; e.g. make-dds-security.sh's 'publisher')")
      ->check(CLI::ExistingDirectory);
  app.add_option("--corrections", a.corrections_file,
                 "corrected trajectories (tarmac-sim --correct-at writes DIR/corrections.txt): "
                 "each sent as nav_msgs/Path on the config's pose.correction_topic right after "
                 "its scan K")
      ->check(CLI::ExistingFile);
  app.add_option("--pose-readers", a.options.pose_readers,
                 "wait for N matched readers of the poses before the first message (1: tarmacd; "
                 "2 with tarmac-audit --score)")
      ->transform(cli::positive<std::size_t>());
  app.add_option("--layout", a.layout,
                 "an organised sequence's sweeps as 'beams' (rows = beams, as ouster-ros) or "
                 "'firings' (rows = firings, one column per laser, as velodyne's "
                 "organize_cloud and rslidar_sdk) or 'list' (height 1, the returns only, in "
                 "firing order, as HesaiLidar_ROS_2.0)")
      ->check(CLI::IsMember({"beams", "firings", "list"}));
  std::string driver_names;
  for (const auto d : sim::all_drivers()) {
    driver_names += (driver_names.empty() ? "" : ", ") + std::string(sim::driver_name(d));
  }
  app.add_option("--driver", a.driver,
                 "an organised sequence's sweeps as this ROS 2 driver publishes them (" +
                     driver_names +
                     "): its field table, padding, layout, ring order, no-return marker and "
                     "point times, every point timed at the stamp, as the simulator's sweeps are "
                     "instantaneous (docs/lidar-drivers.md)")
      ->check([](const std::string& name) {
        sim::Driver d;
        return sim::driver_from_name(name, d) ? std::string() : "no driver " + name;
      });
  app.add_flag("--ring", a.options.ring_field,
               "an organised sequence's sweeps carry a ring field (uint16, 0 = lowest beam)");
  app.add_option("--pace-costmap", a.pace_ahead,
                 "send scan K only once tarmacd's costmap (the config's outputs.costmap_topic) "
                 "holds scan K-N or a later one: as fast as the daemon takes the input, never "
                 "faster than the schedule; stamps unchanged (0: the schedule alone)")
      ->transform(cli::number<std::size_t>());
  app.add_option("--pace-patience-s", a.pace_patience_s,
                 "with --pace-costmap: give up (exit 69) when no newer costmap came for S seconds")
      ->transform(cli::positive<double>());
}

/// The sweeps' layout and driver from the command line, and from the config (--config, or the
/// built-in defaults) its participant and the topics, QoS and extrinsic of the sensor the scans
/// belong to, into a.options. 0, or kExitConfig after a message.
int apply_config(Args& a, config::Config& cfg) {
  if (a.layout == "firings") a.options.layout = tools::ReplayOptions::Layout::kRowsAreFirings;
  if (a.layout == "list") a.options.layout = tools::ReplayOptions::Layout::kUnorganised;
  if (!a.driver.empty()) {
    sim::Driver d;
    sim::driver_from_name(a.driver, d);
    a.options.driver = d;
  }
  cfg.dds.participant.name = "tarmac-replay";
  if (!a.config_path.empty()) {
    auto loaded = config::load_config_file(a.config_path);
    if (!loaded) {
      std::fprintf(stderr, "tarmac-replay: invalid config: %s\n", loaded.error().message.c_str());
      return kExitConfig;
    }
    cfg = std::move(loaded).value();
    cfg.dds.participant.name = "tarmac-replay";
  }
  if (!a.identity_dir.empty()) cfg.dds.participant.security.use_identity_dir(a.identity_dir);
  const config::SensorConfig* sensor = &cfg.sensors.front();
  if (!a.sensor_id.empty()) {
    sensor = nullptr;
    for (const auto& s : cfg.sensors) {
      if (s.id == a.sensor_id) sensor = &s;
    }
    if (sensor == nullptr) {
      std::fprintf(stderr, "tarmac-replay: no sensor '%s' in the config\n", a.sensor_id.c_str());
      return kExitConfig;
    }
  }
  a.options.lidar_topic = sensor->topic;
  a.options.frame_id = sensor->frame_id;
  a.options.T_base_sensor = sensor->T_base_sensor;
  a.options.lidar_qos = cfg.dds.qos.lidar;
  a.options.pose_topic = cfg.pose.topic;
  a.options.pose_frame_id = cfg.pose.frame_id;
  if (cfg.pose.type != config::PoseType::kPoseWithCovarianceStamped) {
    std::fprintf(stderr, "tarmac-replay: publishes PoseWithCovarianceStamped only\n");
    return kExitConfig;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Args a;
  cli::App app(
      "tarmac-replay",
      "Publishes --dataset DIR (KITTI layout: scans/NNNNNN.bin in the sensor frame, poses.txt "
      "T_world_sensor, optional times.txt) as sensor_msgs/PointCloud2 and "
      "geometry_msgs/PoseWithCovarianceStamped on the topics of the config (default: the "
      "built-in defaults, i.e. config/tarmac.yaml). Poses are T_world_base = "
      "T_world_sensor * T_base_sensor^-1 with the sensor's extrinsic from the config. "
      "Stamps are re-based on this machine's clock; scan k is sent at its stamp.");
  add_options(app, a);
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  config::Config cfg;
  if (const int exit = apply_config(a, cfg); exit != 0) return exit;

  auto seq = tools::open_kitti(a.dataset, a.poses_file);
  if (!seq) {
    std::fprintf(stderr, "tarmac-replay: %s\n", seq.error().message.c_str());
    return kExitData;
  }
  if (!a.corrections_file.empty()) {
    auto read = tools::read_corrections(a.corrections_file);
    if (!read) {
      std::fprintf(stderr, "tarmac-replay: %s\n", read.error().message.c_str());
      return kExitData;
    }
    a.options.corrections = std::move(read).value();
    a.options.correction_topic = cfg.pose.correction_topic;
  }
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) {
    std::fprintf(stderr, "tarmac-replay: %s\n", participant.error().message.c_str());
    return kExitUnavailable;
  }
  if (a.pace_ahead > 0) {
    auto pace = tools::pace_by_costmap(
        participant.value(), cfg.outputs.costmap_topic, cfg.dds.qos.costmap, a.pace_ahead,
        std::chrono::milliseconds(std::llround(a.pace_patience_s * 1000.0)), &g_stop);
    if (!pace) {
      std::fprintf(stderr, "tarmac-replay: %s\n", pace.error().message.c_str());
      return kExitUnavailable;
    }
    a.options.pace = std::move(pace).value();
  }
  struct sigaction sa {};
  sa.sa_handler = [](int) { g_stop = true; };
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  if (isatty(STDERR_FILENO) != 0) {
    a.options.progress = [](std::size_t k, std::size_t n) {
      constexpr int kWidth = 40;
      const int filled = static_cast<int>(kWidth * k / n);
      std::fprintf(stderr, "\rtarmac-replay [%.*s%*s] %zu/%zu", filled,
                   "########################################", kWidth - filled, "", k, n);
      if (k == n) std::fprintf(stderr, "\n");
    };
  }
  std::fprintf(stderr, "tarmac-replay: %zu scans from %s on %s (domain %u), x%.2f\n",
               a.options.loops * (a.options.max_scans == 0
                                      ? seq.value().scans.size()
                                      : std::min(a.options.max_scans, seq.value().scans.size())),
               a.dataset.c_str(), a.options.lidar_topic.c_str(), cfg.dds.participant.domain_id,
               a.options.rate_scale);
  auto stats = tools::replay(participant.value(), seq.value(), a.options, &g_stop);
  if (!stats) {
    std::fprintf(stderr, "tarmac-replay: %s\n", stats.error().message.c_str());
    return kExitUnavailable;
  }
  std::printf(
      "tarmac-replay: published %zu scans (and %zu corrected trajectories), stamps %.3f .. %.3f "
      "s, worst send delay %.2f ms\n",
      stats.value().scans, stats.value().corrections,
      static_cast<double>(stats.value().first_stamp_ns) / 1e9,
      static_cast<double>(stats.value().last_stamp_ns) / 1e9, stats.value().max_late_ms);
  return g_stop ? 130 : 0;
}
