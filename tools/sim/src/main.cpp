// tarmac-sim: writes a synthetic airside sequence in KITTI layout (scans, poses, times) from a
// simulated spinning LiDAR driving through an analytic scene, with the scene as ground truth.

#include <charconv>
#include <cstdio>
#include <string>
#include <string_view>

#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace {

using namespace tarmac;

constexpr int kExitUsage = 64;
constexpr int kExitIo = 74;

void usage(std::FILE* to) {
  std::fprintf(
      to,
      "usage: tarmac-sim --out DIR [--scans N] [--rate-hz HZ] [--speed M/S] [--beams N]\n"
      "                  [--azimuth-steps N] [--max-range M] [--noise-m M] [--seed N]\n"
      "                  [--tilt-deg DEG] [--scene airside|terminal|aircraft]\n"
      "                  [--drift-m M [--drift-ramp-s S] [--correct-at K]]\n"
      "  Drives a vehicle along y = 0 from x = 0 to x = 60 m through a synthetic airside apron\n"
      "  and writes DIR/scans/NNNNNN.bin (sensor frame), poses.txt (T_world_sensor), times.txt,\n"
      "  scene.json (ground truth) and README.txt. Same arguments, same bytes.\n"
      "  --out DIR          output directory (created; stale scans/NNNNNN.bin are removed)\n"
      "  --scans N          number of scans (default: enough to drive the whole path)\n"
      "  --rate-hz HZ       scan rate (default 10)\n"
      "  --speed M/S        vehicle speed (default 3)\n"
      "  --beams N          beams, elevations evenly spaced over -22.5 .. 22.5 deg (default 32)\n"
      "  --azimuth-steps N  firings per revolution (default 1024)\n"
      "  --max-range M      maximum range (default 100)\n"
      "  --noise-m M        Gaussian range noise, 1 sigma (default 0)\n"
      "  --seed N           noise seed (default 1)\n"
      "  --tilt-deg DEG     rotate the poses' world frame about x (default 0)\n"
      "  --scene NAME       airside (default), terminal (long walls beside the path) or\n"
      "                     aircraft (a loop round a parked aircraft whose belly is in the\n"
      "                     vehicle envelope, turns of 20 m radius, default speed 10 m/s)\n"
      "  --drift-m M        pose drift: written poses shifted along scene y, growing to M\n"
      "  --drift-ramp-s S   time the drift takes to reach M (default 2 s)\n"
      "  --correct-at K     true poses again from scan K on; writes corrections.txt (the\n"
      "                     corrected trajectory of scans 0..K-1, for tarmac-map --corrections)\n");
}

template <typename T>
bool parse(std::string_view text, T& value) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  return ec == std::errc{} && ptr == end;
}

}  // namespace

int main(int argc, char** argv) {
  sim::SequenceParams params;
  std::string out_dir;
  std::string scene_name = "airside";
  bool speed_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      usage(stdout);
      return 0;
    }
    if (i + 1 >= argc) {
      std::fprintf(stderr, "tarmac-sim: %s: missing value or unknown option\n", argv[i]);
      usage(stderr);
      return kExitUsage;
    }
    const std::string_view value = argv[++i];
    bool ok = true;
    if (arg == "--out") {
      out_dir = value;
      ok = !out_dir.empty();
    } else if (arg == "--scans") {
      ok = parse(value, params.scans) && params.scans > 0;
    } else if (arg == "--rate-hz") {
      ok = parse(value, params.rate_hz);
    } else if (arg == "--speed") {
      ok = parse(value, params.path.speed_mps);
      speed_given = true;
    } else if (arg == "--beams") {
      ok = parse(value, params.lidar.beams);
    } else if (arg == "--azimuth-steps") {
      ok = parse(value, params.lidar.azimuth_steps);
    } else if (arg == "--max-range") {
      ok = parse(value, params.lidar.max_range_m);
    } else if (arg == "--noise-m") {
      ok = parse(value, params.lidar.range_noise_m);
    } else if (arg == "--seed") {
      ok = parse(value, params.seed);
    } else if (arg == "--tilt-deg") {
      ok = parse(value, params.tilt_deg);
    } else if (arg == "--scene") {
      scene_name = value;
      ok = scene_name == "airside" || scene_name == "terminal" || scene_name == "aircraft";
    } else if (arg == "--drift-m") {
      ok = parse(value, params.drift_m);
    } else if (arg == "--drift-ramp-s") {
      ok = parse(value, params.drift_ramp_s);
    } else if (arg == "--correct-at") {
      ok = parse(value, params.correct_at_scan);
    } else {
      std::fprintf(stderr, "tarmac-sim: unknown option %s\n", argv[i - 1]);
      usage(stderr);
      return kExitUsage;
    }
    if (!ok) {
      std::fprintf(stderr, "tarmac-sim: %s: bad value '%s'\n", argv[i - 1], argv[i]);
      usage(stderr);
      return kExitUsage;
    }
  }
  if (out_dir.empty()) {
    std::fprintf(stderr, "tarmac-sim: --out is required\n");
    usage(stderr);
    return kExitUsage;
  }
  if (scene_name == "aircraft") {
    const double sensor_height_m = params.path.sensor_height_m;
    // Turns of 20 m radius: at 10 m/s the heading changes 2.9 deg per scan at 10 Hz, as a
    // vehicle can drive it (an instant 90 deg turn is a pose jump, and tarmac treats it so).
    params.path = sim::DrivePath::loop({-30.0, -22.0}, {30.0, 22.0},
                                       speed_given ? params.path.speed_mps : 10.0, 20.0);
    params.path.sensor_height_m = sensor_height_m;
  }
  if (const std::string error = params.validate(); !error.empty()) {
    std::fprintf(stderr, "tarmac-sim: %s\n", error.c_str());
    usage(stderr);
    return kExitUsage;
  }

  const sim::Scene scene = scene_name == "terminal"   ? sim::Scene::terminal_walls()
                           : scene_name == "aircraft" ? sim::Scene::aircraft_stand()
                                                      : sim::Scene::airside_default();
  const sim::SequenceResult result = sim::write_sequence(scene, params, out_dir);
  if (!result.ok()) {
    std::fprintf(stderr, "tarmac-sim: %s\n", result.error.c_str());
    return kExitIo;
  }
  std::printf("tarmac-sim: wrote %d scans to %s; points per scan min %zu, median %zu, max %zu\n",
              result.summary.scans, out_dir.c_str(), result.summary.min_points,
              result.summary.median_points, result.summary.max_points);
  return 0;
}
