#include "tarmac/sim/scene_catalog.hpp"

#include <utility>

namespace tarmac::sim {
namespace {

/// The straight drive from `from` to `to` over `scene`'s terrain.
SceneDrive straight(Scene scene, const Eigen::Vector2d& from, const Eigen::Vector2d& to) {
  DrivePath path;
  path.start_W = from;
  path.end_W = to;
  path.terrain = scene.terrain();
  return {std::move(scene), std::move(path)};
}

}  // namespace

std::optional<SceneDrive> scene_drive(std::string_view name, std::optional<double> speed_mps,
                                      double sensor_height_m) {
  std::optional<SceneDrive> drive;
  if (name == "airside" || name == "terminal") {
    drive = SceneDrive{name == "airside" ? Scene::airside_default() : Scene::terminal_walls(), {}};
  } else if (name == "aircraft") {
    // Turns of 20 m radius: at 10 m/s the heading changes 2.9 deg per scan at 10 Hz, as a
    // vehicle can drive it (an instant 90 deg turn is a pose jump, and tarmac treats it so).
    drive = SceneDrive{Scene::aircraft_stand(), DrivePath::loop({-30.0, -22.0}, {30.0, 22.0},
                                                                speed_mps.value_or(10.0), 20.0)};
  } else if (name == "site") {
    // The service road round the apron, 2.2 km, at 10 m/s by default, turns of 20 m radius.
    drive = SceneDrive{Scene::airport_site(),
                       DrivePath::loop(Scene::site_route_min(), Scene::site_route_max(),
                                       speed_mps.value_or(10.0), 20.0)};
  } else if (name == "ramp5") {
    drive = straight(Scene::apron_ramp(0.05, 30.0), {0.0, 0.0}, {90.0, 0.0});
  } else if (name == "ramp10") {
    drive = straight(Scene::apron_ramp(0.10, 25.0), {0.0, 0.0}, {90.0, 0.0});
  } else if (name == "crown") {
    drive = straight(Scene::crowned_road(), {0.0, -2.5}, {90.0, -2.5});
  } else if (name == "parking") {
    drive = straight(Scene::parking_levels(), {0.0, -1.0}, {120.0, -1.0});
  } else if (name == "debris" || name == "apron") {
    drive = SceneDrive{name == "debris" ? Scene::debris_apron() : Scene::empty_apron(), {}};
    drive->path.end_W = {100.0, 0.0};
  }
  if (!drive) return std::nullopt;
  if (speed_mps) drive->path.speed_mps = *speed_mps;
  drive->path.sensor_height_m = sensor_height_m;
  return drive;
}

}  // namespace tarmac::sim
