#pragma once
/// @file The scenes tarmac-sim writes (--scene NAME), each with the drive through it.

#include <array>
#include <optional>
#include <string_view>

#include "tarmac/sim/lidar.hpp"
#include "tarmac/sim/scene.hpp"

namespace tarmac::sim {

/// A scene and the vehicle's drive through it (on its terrain).
struct SceneDrive {
  Scene scene;
  DrivePath path;
};

/// Every scene name, in the order tarmac-sim's --help gives them.
inline constexpr std::array<std::string_view, 10> kSceneNames = {
    "airside", "terminal", "aircraft", "site",   "ramp5",
    "ramp10",  "crown",    "parking",  "debris", "apron"};

/// The scene called `name` and its drive, at `speed_mps` (nothing: the scene's own speed), the
/// sensor sensor_height_m above the base; nothing for an unknown name.
///  - airside, terminal: DrivePath's line y = 0, x from 0 to 60, 3 m/s
///  - aircraft: the loop (−30, −22)–(30, 22) round Scene::aircraft_stand, 20 m turns, 10 m/s
///  - site: the loop round Scene::airport_site's apron, 20 m turns, 10 m/s
///  - ramp5, ramp10: Scene::apron_ramp at 5 % over 30 m, 10 % over 25 m; y = 0, x from 0 to 90
///  - crown: Scene::crowned_road's right lane, y = −2.5, x from 0 to 90
///  - parking: Scene::parking_levels, y = −1, x from 0 to 120, down the ramp and under the deck
/// The terrain scenes at 3 m/s.
std::optional<SceneDrive> scene_drive(std::string_view name, std::optional<double> speed_mps,
                                      double sensor_height_m);

}  // namespace tarmac::sim
