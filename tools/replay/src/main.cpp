// tarmac-replay: publishes a KITTI-layout sequence (scans + poses) over localhost DDS as a
// ROS 2-style LiDAR driver and localiser would, on the topics of a tarmacd config.

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tarmac/config/config.hpp"
#include "tarmac/replay/replayer.hpp"
#include "tarmac/tools/kitti.hpp"

namespace {

using namespace tarmac;

constexpr int kExitUsage = 64;
constexpr int kExitData = 65;
constexpr int kExitUnavailable = 69;
constexpr int kExitConfig = 78;

std::atomic<bool> g_stop{false};

void usage(std::FILE* to) {
  std::fprintf(to,
               "usage: tarmac-replay --dataset DIR [--rate-scale X] [--config FILE] [--scans N]\n"
               "                     [--poses FILE] [--jitter-ms MS] [--sensor ID] [--loop N]\n"
               "                     [--no-poses] [--align-ms MS] [--identity DIR]\n"
               "                     [--corrections FILE] [--pose-readers N]\n"
               "  Publishes DIR (KITTI layout: scans/NNNNNN.bin in the sensor frame, poses.txt\n"
               "  T_world_sensor, optional times.txt) as sensor_msgs/PointCloud2 and\n"
               "  geometry_msgs/PoseWithCovarianceStamped on the topics of FILE (default: the\n"
               "  built-in defaults, i.e. config/tarmac.yaml). Poses are T_world_base =\n"
               "  T_world_sensor * T_base_sensor^-1 with the sensor's extrinsic from FILE.\n"
               "  Stamps are re-based on this machine's clock; scan k is sent at its stamp.\n"
               "  --rate-scale X  replay X times faster than recorded (default 1)\n"
               "  --scans N       first N scans only\n"
               "  --poses FILE    pose file in DIR (default poses.txt)\n"
               "  --jitter-ms MS  publish each message up to MS late, uniformly (tests)\n"
               "  --sensor ID     which configured sensor the scans belong to (default: first)\n"
               "  --loop N        replay the sequence N times, stamps continuing (soak tests)\n"
               "  --no-poses      scans only (one replay per LiDAR, one of them with poses)\n"
               "  --align-ms MS   first stamp on a multiple of MS since the epoch, like a LiDAR\n"
               "                  phase-locked to PTP (tarmacd ticks on the same grid)\n"
               "  --identity DIR  DDS Security identity DIR/cert.pem, DIR/key.pem instead of\n"
               "                  the config's (dds.security; e.g. make-dds-security.sh's\n"
               "                  'publisher')\n"
               "  --corrections FILE  corrected trajectories (tarmac-sim --correct-at writes\n"
               "                  DIR/corrections.txt): each sent as nav_msgs/Path on the\n"
               "                  config's pose.correction_topic right after its scan K\n"
               "  --pose-readers N  wait for N matched readers of the poses before the first\n"
               "                  message (default 1, tarmacd; 2 with tarmac-audit --score)\n");
}

}  // namespace

int main(int argc, char** argv) {
  std::string dataset, config_path, poses_file = "poses.txt", sensor_id, identity_dir,
                                    corrections_file;
  tools::ReplayOptions options;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--dataset" && has_value) {
      dataset = argv[++i];
    } else if (a == "--config" && has_value) {
      config_path = argv[++i];
    } else if (a == "--rate-scale" && has_value) {
      options.rate_scale = std::atof(argv[++i]);
    } else if (a == "--scans" && has_value) {
      options.max_scans = static_cast<std::size_t>(std::max(0, std::atoi(argv[++i])));
    } else if (a == "--pose-readers" && has_value) {
      options.pose_readers = static_cast<std::size_t>(std::max(1, std::atoi(argv[++i])));
    } else if (a == "--align-ms" && has_value) {
      options.align_ms = std::atof(argv[++i]);
    } else if (a == "--no-poses") {
      options.publish_poses = false;
    } else if (a == "--loop" && has_value) {
      options.loops = static_cast<std::size_t>(std::max(1, std::atoi(argv[++i])));
    } else if (a == "--poses" && has_value) {
      poses_file = argv[++i];
    } else if (a == "--jitter-ms" && has_value) {
      options.jitter_ms = std::atof(argv[++i]);
    } else if (a == "--sensor" && has_value) {
      sensor_id = argv[++i];
    } else if (a == "--corrections" && has_value) {
      corrections_file = argv[++i];
    } else if (a == "--identity" && has_value) {
      identity_dir = argv[++i];
    } else if (a == "--help" || a == "-h") {
      usage(stdout);
      return 0;
    } else {
      std::fprintf(stderr, "tarmac-replay: unexpected argument '%s'\n", a.c_str());
      usage(stderr);
      return kExitUsage;
    }
  }
  if (dataset.empty() || !(options.rate_scale > 0.0)) {
    usage(stderr);
    return kExitUsage;
  }
  config::Config cfg;
  cfg.dds.participant.name = "tarmac-replay";
  if (!config_path.empty()) {
    auto loaded = config::load_config_file(config_path);
    if (!loaded) {
      std::fprintf(stderr, "tarmac-replay: invalid config: %s\n", loaded.error().message.c_str());
      return kExitConfig;
    }
    cfg = std::move(loaded).value();
    cfg.dds.participant.name = "tarmac-replay";
  }
  if (!identity_dir.empty()) cfg.dds.participant.security.use_identity_dir(identity_dir);
  const config::SensorConfig* sensor = &cfg.sensors.front();
  if (!sensor_id.empty()) {
    sensor = nullptr;
    for (const auto& s : cfg.sensors) {
      if (s.id == sensor_id) sensor = &s;
    }
    if (sensor == nullptr) {
      std::fprintf(stderr, "tarmac-replay: no sensor '%s' in the config\n", sensor_id.c_str());
      return kExitConfig;
    }
  }
  options.lidar_topic = sensor->topic;
  options.frame_id = sensor->frame_id;
  options.T_base_sensor = sensor->T_base_sensor;
  options.lidar_qos = cfg.dds.qos.lidar;
  options.pose_topic = cfg.pose.topic;
  options.pose_frame_id = cfg.pose.frame_id;
  if (cfg.pose.type != config::PoseType::kPoseWithCovarianceStamped) {
    std::fprintf(stderr, "tarmac-replay: publishes PoseWithCovarianceStamped only\n");
    return kExitConfig;
  }

  auto seq = tools::open_kitti(dataset, poses_file);
  if (!seq) {
    std::fprintf(stderr, "tarmac-replay: %s\n", seq.error().message.c_str());
    return kExitData;
  }
  if (!corrections_file.empty()) {
    auto read = tools::read_corrections(corrections_file);
    if (!read) {
      std::fprintf(stderr, "tarmac-replay: %s\n", read.error().message.c_str());
      return kExitData;
    }
    options.corrections = std::move(read).value();
    options.correction_topic = cfg.pose.correction_topic;
  }
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) {
    std::fprintf(stderr, "tarmac-replay: %s\n", participant.error().message.c_str());
    return kExitUnavailable;
  }
  struct sigaction sa {};
  sa.sa_handler = [](int) { g_stop = true; };
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  if (isatty(STDERR_FILENO) != 0) {
    options.progress = [](std::size_t k, std::size_t n) {
      constexpr int kWidth = 40;
      const int filled = static_cast<int>(kWidth * k / n);
      std::fprintf(stderr, "\rtarmac-replay [%.*s%*s] %zu/%zu", filled,
                   "########################################", kWidth - filled, "", k, n);
      if (k == n) std::fprintf(stderr, "\n");
    };
  }
  std::fprintf(stderr, "tarmac-replay: %zu scans from %s on %s (domain %u), x%.2f\n",
               options.loops * (options.max_scans == 0
                                    ? seq.value().scans.size()
                                    : std::min(options.max_scans, seq.value().scans.size())),
               dataset.c_str(), options.lidar_topic.c_str(), cfg.dds.participant.domain_id,
               options.rate_scale);
  auto stats = tools::replay(participant.value(), seq.value(), options, &g_stop);
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
