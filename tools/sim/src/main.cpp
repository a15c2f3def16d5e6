// tarmac-sim: writes a synthetic airside sequence in KITTI layout (scans, poses, times) from a
// simulated spinning LiDAR driving through an analytic scene, with the scene as ground truth.

#include <cstdio>
#include <string>

#include "tarmac/config/cli.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace {

using namespace tarmac;

constexpr int kExitIo = 74;

}  // namespace

int main(int argc, char** argv) {
  sim::SequenceParams params;
  std::string out_dir;
  std::string scene_name = "airside";
  cli::App app("tarmac-sim",
               "Drives a vehicle along y = 0 from x = 0 to x = 60 m through a synthetic airside "
               "apron and writes DIR/scans/NNNNNN.bin (sensor frame), poses.txt "
               "(T_world_sensor), times.txt, scene.json (ground truth) and README.txt. Same "
               "arguments, same bytes.");
  app.add_option("--out", out_dir, "output directory (created; stale scans/NNNNNN.bin are removed)")
      ->type_name("DIR")
      ->required();
  app.add_option("--scans", params.scans,
                 "number of scans (default: enough to drive the whole path)")
      ->default_str("")
      ->transform(cli::positive<int>());
  app.add_option("--rate-hz", params.rate_hz, "scan rate")->transform(cli::positive<double>());
  auto* speed = app.add_option("--speed", params.path.speed_mps, "vehicle speed, m/s")
                    ->transform(cli::positive<double>());
  app.add_option("--beams", params.lidar.beams,
                 "beams, elevations evenly spaced over -22.5 .. 22.5 deg")
      ->transform(cli::positive<int>());
  app.add_option("--azimuth-steps", params.lidar.azimuth_steps, "firings per revolution")
      ->transform(cli::positive<int>());
  app.add_option("--max-range", params.lidar.max_range_m, "maximum range, m")
      ->transform(cli::positive<double>());
  app.add_option("--noise-m", params.lidar.range_noise_m, "Gaussian range noise, 1 sigma, m")
      ->transform(cli::non_negative<double>());
  app.add_option("--seed", params.seed, "noise seed")->transform(cli::number<std::uint64_t>());
  app.add_option("--dropout", params.lidar.dropout,
                 "share of returns lost at random (0..1; a real sensor's dark, wet and specular "
                 "spots): NaN in the organised sweep")
      ->transform(cli::in_range(0.0, 1.0));
  app.add_option("--dropout-seed", params.lidar.dropout_seed, "which returns --dropout loses")
      ->transform(cli::number<std::uint64_t>());
  app.add_option("--tilt-deg", params.tilt_deg, "rotate the poses' world frame about x, deg")
      ->transform(cli::in_range(-180.0, 180.0));
  app.add_option("--scene", scene_name,
                 "airside, terminal (long walls beside the path) or aircraft (a loop round a "
                 "parked aircraft whose belly is in the vehicle envelope, turns of 20 m radius, "
                 "default speed 10 m/s) or site (a 2.2 km service road round an apron: "
                 "buildings, parked aircraft, poles; 10 m/s)")
      ->check(CLI::IsMember({"airside", "terminal", "aircraft", "site"}));
  auto* drift = app.add_option("--drift-m", params.drift_m,
                               "pose drift: written poses shifted along scene y, growing to M")
                    ->transform(cli::in_range(-100.0, 100.0));
  app.add_option("--drift-ramp-s", params.drift_ramp_s, "time the drift takes to reach M, s")
      ->transform(cli::positive<double>())
      ->needs(drift);
  app.add_option("--correct-at", params.correct_at_scan,
                 "true poses again from scan K on; writes corrections.txt (the corrected "
                 "trajectory of scans 0..K-1, for tarmac-map --corrections)")
      ->transform(cli::non_negative<int>())
      ->needs(drift);
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  if (out_dir.empty()) return cli::usage_error(app, "--out: the directory name is empty");
  const bool speed_given = speed->count() > 0;
  if (scene_name == "aircraft") {
    const double sensor_height_m = params.path.sensor_height_m;
    // Turns of 20 m radius: at 10 m/s the heading changes 2.9 deg per scan at 10 Hz, as a
    // vehicle can drive it (an instant 90 deg turn is a pose jump, and tarmac treats it so).
    params.path = sim::DrivePath::loop({-30.0, -22.0}, {30.0, 22.0},
                                       speed_given ? params.path.speed_mps : 10.0, 20.0);
    params.path.sensor_height_m = sensor_height_m;
  }
  if (scene_name == "site") {
    const double sensor_height_m = params.path.sensor_height_m;
    // The service road round the apron, 2.2 km, at 10 m/s by default, turns of 20 m radius.
    params.path = sim::DrivePath::loop(sim::Scene::site_route_min(), sim::Scene::site_route_max(),
                                       speed_given ? params.path.speed_mps : 10.0, 20.0);
    params.path.sensor_height_m = sensor_height_m;
  }
  if (const std::string error = params.validate(); !error.empty()) {
    return cli::usage_error(app, error);
  }

  const sim::Scene scene = scene_name == "terminal"   ? sim::Scene::terminal_walls()
                           : scene_name == "aircraft" ? sim::Scene::aircraft_stand()
                           : scene_name == "site"     ? sim::Scene::airport_site()
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
