/// @file tarmac-sim's debris scenes (issue 39): foreign object debris on an open apron and under
/// a parked aircraft, and the empty apron it must leave clear.

#include <cmath>
#include <string>

#include "tarmac/sim/scene.hpp"

namespace tarmac::sim {

namespace {

/// A cube of `size_m` standing on the ground (z = 0) centred at (x, y), named by its size and x.
void add_debris(Scene& scene, double size_m, double x, double y) {
  using V = Eigen::Vector3d;
  const double h = size_m / 2.0;
  const std::string name = "debris_" +
                           std::to_string(static_cast<int>(std::lround(size_m * 100.0))) + "cm_" +
                           std::to_string(static_cast<int>(std::lround(x)));
  scene.add(name, "debris", Box{V(x - h, y - h, 0.0), V(x + h, y + h, size_m)});
}

}  // namespace

Scene Scene::debris_apron() {
  using V = Eigen::Vector3d;
  Scene scene;
  scene.add("ground", "ground", Plane{V::UnitZ(), 0.0});
  struct Piece {
    double size_m, x, y;
  };
  for (const Piece& d : {Piece{0.10, 25.0, 0.6}, Piece{0.05, 25.0, -1.5}, Piece{0.20, 25.0, 3.0},
                         Piece{0.10, 45.0, -0.8}, Piece{0.20, 45.0, 1.5}, Piece{0.05, 45.0, 4.0},
                         Piece{0.10, 65.0, 2.0}, Piece{0.05, 65.0, 0.5}, Piece{0.20, 65.0, -3.0}}) {
    add_debris(scene, d.size_m, d.x, d.y);
  }
  // airside_default()'s aircraft, 60 m on.
  scene.add("fuselage", "fuselage", Cylinder{Axis::kX, V(70.0, 12.0, 3.0), 40.0, 2.0});
  scene.add("wing_right", "wing", Box{V(86.0, -8.0, 4.0), V(94.0, 12.0, 4.4)});
  scene.add("engine_right", "engine", Cylinder{Axis::kX, V(83.0, 5.0, 2.2), 5.0, 1.0});
  scene.add("gear_front", "landing_gear", Cylinder{Axis::kZ, V(89.0, 3.0, 0.0), 3.0, 0.3});
  scene.add("gear_rear", "landing_gear", Cylinder{Axis::kZ, V(93.0, 3.0, 0.0), 3.0, 0.3});
  add_debris(scene, 0.10, 88.0, -1.0);
  add_debris(scene, 0.10, 89.0, 2.3);
  return scene;
}

Scene Scene::empty_apron() {
  Scene scene;
  scene.add("ground", "ground", Plane{Eigen::Vector3d::UnitZ(), 0.0});
  return scene;
}

}  // namespace tarmac::sim
