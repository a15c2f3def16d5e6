// tarmac-sim: writes a synthetic airside sequence in KITTI layout (scans, poses, times) from a
// simulated spinning LiDAR driving through an analytic scene, with the scene as ground truth.

#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "tarmac/config/cli.hpp"
#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene_catalog.hpp"

namespace {

using namespace tarmac;

constexpr int kExitIo = 74;

}  // namespace

int main(int argc, char** argv) {
  sim::SequenceParams params;
  std::string out_dir;
  std::string scene_name = "airside";
  cli::App app("tarmac-sim",
               "Drives a vehicle through a synthetic airside scene (by default along y = 0 from "
               "x = 0 to x = 60 m over a flat apron) and writes DIR/scans/NNNNNN.bin (sensor "
               "frame), poses.txt (T_world_sensor), times.txt, scene.json, the costmap's ground "
               "truth (obstacle_columns.txt; on terrain, ground_cells.txt) and README.txt. Same "
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
                 "buildings, parked aircraft, poles; 10 m/s); on terrain, the vehicle pitched "
                 "and rolled with the ground under its wheels: ramp5 and ramp10 (an apron, a "
                 "ramp climbing 5 % over 30 m or 10 % over 25 m, the upper level; cones and "
                 "crates on all three; 90 m), crown (the right lane of a road with a 2 % cross "
                 "fall each side of its crown, shoulders beyond; 90 m) or parking (a ramp down "
                 "9 % in a walled cut to a road and bays 2.25 m below, a 15 cm curb along the "
                 "right, the road's end under a deck with 3.6 m of headroom; 120 m); debris "
                 "(5, 10 and 20 cm cubes on an open apron, then two under a parked aircraft; "
                 "100 m) or apron (the same drive over an empty apron)")
      ->check(CLI::IsMember(
          std::vector<std::string>(sim::kSceneNames.begin(), sim::kSceneNames.end())));
  auto* drift = app.add_option("--drift-m", params.drift_m,
                               "pose drift: written poses shifted along scene y, growing to M")
                    ->transform(cli::in_range(-100.0, 100.0));
  auto* drift_z =
      app.add_option("--drift-z-m", params.drift_z_m,
                     "height drift: written poses raised along scene z, evenly over the drive, "
                     "by M at its end (the truth stays exact)")
          ->transform(cli::in_range(-100.0, 100.0));
  app.add_option("--drift-ramp-s", params.drift_ramp_s, "time the drift takes to reach M, s")
      ->transform(cli::positive<double>())
      ->needs(drift);
  auto* correct_at =
      app.add_option("--correct-at", params.correct_at_scan,
                     "true poses again from scan K on (needs --drift-m or --drift-z-m); writes "
                     "corrections.txt (the corrected trajectory of scans 0..K-1, for tarmac-map "
                     "--corrections)")
          ->transform(cli::non_negative<int>());
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  if (out_dir.empty()) return cli::usage_error(app, "--out: the directory name is empty");
  if (correct_at->count() > 0 && drift->count() == 0 && drift_z->count() == 0) {
    return cli::usage_error(app, "--correct-at requires --drift-m or --drift-z-m");
  }
  std::optional<sim::SceneDrive> drive = sim::scene_drive(
      scene_name, speed->count() > 0 ? std::optional<double>(params.path.speed_mps) : std::nullopt,
      params.path.sensor_height_m);
  params.path = std::move(drive->path);
  if (const std::string error = params.validate(); !error.empty()) {
    return cli::usage_error(app, error);
  }

  const sim::SequenceResult result = sim::write_sequence(drive->scene, params, out_dir);
  if (!result.ok()) {
    std::fprintf(stderr, "tarmac-sim: %s\n", result.error.c_str());
    return kExitIo;
  }
  std::printf("tarmac-sim: wrote %d scans to %s; points per scan min %zu, median %zu, max %zu\n",
              result.summary.scans, out_dir.c_str(), result.summary.min_points,
              result.summary.median_points, result.summary.max_points);
  return 0;
}
