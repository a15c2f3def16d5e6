#pragma once
/// @file A synthetic airside scene built from exact analytic primitives (plane, axis-aligned box,
/// axis-aligned finite cylinder, upright cone), with exact ray casting and point occupancy, so
/// that simulated scans and maps can be checked against analytic ground truth.
///
/// Frame W (the scene frame): x forward along the apron, y left, z up, metres; the ground is the
/// plane z = 0. Time t_s is seconds since the start of the sequence.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tarmac::sim {

/// A coordinate axis of frame W.
enum class Axis : std::uint8_t { kX = 0, kY = 1, kZ = 2 };

/// Half-space bounded by the plane {p : normal_W · p = offset_m}; the solid side is
/// normal_W · p < offset_m. `normal_W` must be a unit vector.
struct Plane {
  Eigen::Vector3d normal_W = Eigen::Vector3d::UnitZ();
  double offset_m = 0.0;
};

/// Solid axis-aligned box [min_W, max_W] (m). Requires min_W <= max_W component-wise.
struct Box {
  Eigen::Vector3d min_W = Eigen::Vector3d::Zero();
  Eigen::Vector3d max_W = Eigen::Vector3d::Zero();
};

/// Solid finite cylinder with flat caps whose axis is parallel to `axis`: the disc of `radius_m`
/// centred on `base_W` (centre of the lower cap, m) swept `length_m` along +axis.
struct Cylinder {
  Axis axis = Axis::kZ;
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  double length_m = 0.0;
  double radius_m = 0.0;
};

/// Solid upright cone: base disc of `radius_m` centred on `base_W` (m), apex `height_m` above it
/// (+z). A traffic cone.
struct Cone {
  Eigen::Vector3d base_W = Eigen::Vector3d::Zero();
  double radius_m = 0.0;
  double height_m = 0.0;
};

/// One exact analytic shape in frame W.
using Primitive = std::variant<Plane, Box, Cylinder, Cone>;

/// Axis-aligned bounds in frame W (m); unbounded directions hold ±infinity (the ground plane).
struct Aabb {
  Eigen::Vector3d min_W;
  Eigen::Vector3d max_W;
};

/// Constant-velocity motion: the shape is displaced by velocity_W_mps · (clamp(t_s, start_s,
/// stop_s) − start_s), i.e. it waits at its start pose until start_s and stays at its end pose
/// after stop_s.
struct LinearMotion {
  Eigen::Vector3d velocity_W_mps = Eigen::Vector3d::Zero();
  double start_s = 0.0;
  double stop_s = 0.0;

  /// Displacement from the start pose at time t_s (m, frame W).
  Eigen::Vector3d displacement_W(double t_s) const;
};

/// A scene object: the shape at its start pose and, for dynamic objects, how it moves.
struct Object {
  int id = 0;                          ///< index in Scene::objects()
  std::string name;                    ///< unique, e.g. "wing_right"
  std::string kind;                    ///< "ground", "wing", "cone", "tug", ...
  Primitive shape_W;                   ///< at t_s <= motion->start_s
  std::optional<LinearMotion> motion;  ///< empty for static objects

  /// True when the object moves (it has a motion).
  bool dynamic() const { return motion.has_value(); }
};

/// Nearest surface crossing of a ray.
struct Hit {
  double range_m = 0.0;     ///< distance from the ray origin along the unit direction (m)
  Eigen::Vector3d point_W;  ///< origin_W + range_m · dir_W
  int object_id = -1;       ///< Object::id of the surface hit
};

/// Range (m) to the nearest surface crossing of the ray origin_W + r · dir_W, r >= 0, with
/// `primitive`, or nothing. `dir_W` must be a unit vector. The solid is convex, so the ray meets
/// it in one interval [r_in, r_out]: the answer is r_in, or r_out when the origin is inside (the
/// ray leaves through the surface at r_out). A ray parallel to and outside a face misses.
std::optional<double> intersect(const Primitive& primitive, const Eigen::Vector3d& origin_W,
                                const Eigen::Vector3d& dir_W);

/// True when p_W is inside `primitive`: closed for boxes, cylinders and cones, open for the
/// plane's half-space (a point on the ground plane is not inside the ground).
bool contains(const Primitive& primitive, const Eigen::Vector3d& p_W);

/// Axis-aligned bounds of `primitive` (exact for every type).
Aabb bounds(const Primitive& primitive);

/// `primitive` moved by `offset_W` (m).
Primitive translated(const Primitive& primitive, const Eigen::Vector3d& offset_W);

/// The scene: a list of objects, static and moving. Queries are const and thread-compatible.
class Scene {
 public:
  /// Appends an object and returns its id (ids are 0, 1, 2, ... in insertion order).
  /// Precondition: `name` is not used yet.
  int add(std::string name, std::string kind, Primitive shape_W,
          std::optional<LinearMotion> motion = std::nullopt);

  /// Every object, indexed by id.
  const std::vector<Object>& objects() const { return objects_; }

  /// The object called `name`, or nullptr.
  const Object* find(std::string_view name) const;

  /// The shape of object `id` at time t_s (frame W). Precondition: id is valid.
  Primitive shape_at(int id, double t_s) const;

  /// The axis-aligned bounds of object `id` at time t_s (frame W). Precondition: id is valid.
  Aabb bounds_at(int id, double t_s) const;

  /// Nearest surface crossing at range (0, max_range_m] — or [0, ...] for an origin on a surface —
  /// of the ray origin_W + r · dir_W over all objects at time t_s; nothing when no surface is
  /// within max_range_m. `dir_W` need not be normalised (it is normalised here; range_m is along
  /// the unit direction).
  /// `candidates` (ascending ids; null: every object): the objects that can be hit, e.g. those
  /// near(origin_W, max_range_m, t_s) — the same answer, faster on a large site.
  std::optional<Hit> raycast(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                             double max_range_m, double t_s,
                             const std::vector<int>* candidates = nullptr) const;
  /// Ids (ascending) of the objects whose bounds at t_s come within `radius_m` of p_W along
  /// every axis: the only ones a ray from p_W can hit within radius_m.
  std::vector<int> near(const Eigen::Vector3d& p_W, double radius_m, double t_s) const;

  /// True when p_W lies inside any non-ground object at time t_s, or below the ground (z < 0).
  bool occupied(const Eigen::Vector3d& p_W, double t_s) const;

  /// The scene as JSON: every object with id, name, kind, dynamic flag, primitive type and
  /// parameters (start pose) and motion. `T_world_W` (written as "T_world_scene", row-major 3×4)
  /// relates the scene frame to the frame of the poses it is shipped with.
  std::string to_json(const Eigen::Isometry3d& T_world_W = Eigen::Isometry3d::Identity()) const;

  /// The default airside apron. The vehicle's drive path is the line y = 0, x in [0, 60]; every
  /// coordinate in m, frame W (boxes as [min] .. [max]):
  ///  - id 0  ground             plane z = 0
  ///  - id 1  fuselage           cylinder along x, axis y = 12, z = 3, r = 2, x in [10, 50]
  ///                             (parallel to the path, 10 m to its left; bottom z = 1)
  ///  - id 2  wing_right         box [26, -8, 4.0] .. [34, 12, 4.4] (overhangs the path)
  ///  - id 3  wing_left          box [26, 12, 4.0] .. [34, 32, 4.4]
  ///  - id 4  engine_right       cylinder along x, axis y = 5, z = 2.2, r = 1, x in [23, 28]
  ///  - id 5  engine_left        cylinder along x, axis y = 19, z = 2.2, r = 1, x in [23, 28]
  ///  - id 6  gear_front         vertical cylinder at (29, 3), r = 0.3, z in [0, 3]
  ///  - id 7  gear_rear          vertical cylinder at (33, 3), r = 0.3, z in [0, 3]
  ///  - id 8  jet_bridge         box [52, -6, 4] .. [56, 6, 7] (over the path)
  ///  - id 9  jet_bridge_pillar_right  vertical cylinder at (54, -5), r = 0.4, z in [0, 4]
  ///  - id 10 jet_bridge_pillar_left   vertical cylinder at (54, 5), r = 0.4, z in [0, 4]
  ///  - id 11 cone_right         cone, base (20, -1.5, 0), r = 0.2, h = 0.5
  ///  - id 12 cone_left          cone, base (20, 1.5, 0), r = 0.2, h = 0.5
  ///  - id 13 cone_path          cone, base (40, 0, 0), r = 0.2, h = 0.5 (on the path)
  ///  - id 14 debris             box [46.9, 0.4, 0] .. [47.1, 0.6, 0.1] (on the path)
  ///  - id 15 tug (dynamic)      box 1.6 (x) × 3.0 (y) × 1.5 (z), centre (15, -4) at t <= 0,
  ///                             moving +y at 2 m/s until t = 6 s, then parked with centre
  ///                             (15, 8); it covers the path point (15, 0, z <= 1.5) for t in
  ///                             [1.25, 2.75] s and is clear of the path (y >= 1) from 3.25 s,
  ///                             before the default vehicle (3 m/s) gets near x = 15.
  static Scene airside_default();

  /// A terminal frontage for pose-drift tests: long walls parallel to the drive path on both
  /// sides, seen from every scan, so a pose error shows as a shifted or doubled wall:
  ///  - id 0  ground          plane z = 0
  ///  - id 1  terminal_left   box [-30, 8.1, 0] .. [90, 8.5, 6] (its face at y = 8.1, mid-voxel at
  ///  0.2 m)
  ///  - id 2  terminal_right  box [-30, -16.5, 0] .. [90, -16.1, 6] (its face at y = -16.1)
  ///  - id 3  pillar          vertical cylinder at (30, -6), r = 0.4, z in [0, 4]
  static Scene terminal_walls();

  /// A parked narrow-body aircraft to drive round (DrivePath::loop), its fuselage low enough
  /// that the belly lies inside a 2.8 m vehicle envelope; every coordinate in m, frame W:
  ///  - id 0  ground             plane z = 0
  ///  - id 1  fuselage           cylinder along x, axis y = 0, z = 3.3, r = 1.8, x in [-18, 18]
  ///                             (belly at z = 1.5)
  ///  - id 2  wing_right         box [-3, -15, 3.3] .. [3, -1.5, 3.6] (above the envelope)
  ///  - id 3  wing_left          box [-3, 1.5, 3.3] .. [3, 15, 3.6]
  ///  - id 4  engine_right       cylinder along x, axis y = -6, z = 1.9, r = 0.7, x in [-4, 0]
  ///  - id 5  engine_left        cylinder along x, axis y = 6, z = 1.9, r = 0.7, x in [-4, 0]
  ///  - id 6  gear_nose          vertical cylinder at (14, 0), r = 0.25, z in [0, 1.6]
  ///  - id 7  gear_main_right    vertical cylinder at (1, -2.5), r = 0.35, z in [0, 1.6]
  ///  - id 8  gear_main_left     vertical cylinder at (1, 2.5), r = 0.35, z in [0, 1.6]
  ///  - id 9  tail               box [15, -0.2, 3.3] .. [18, 0.2, 8] (above the envelope)
  ///  - id 10 cone_nose          cone, base (20, 0, 0), r = 0.2, h = 0.5
  ///  - id 11 cone_wing          cone, base (0, -16, 0), r = 0.2, h = 0.5
  /// The loop round it: the rectangle [-30, -22] .. [30, 22].
  static Scene aircraft_stand();

  /// A whole airport site for long drives (DrivePath::loop over site_route_min/max(): a service
  /// road round an apron, 2.2 km): along the road's outer side, hangars and terminal buildings
  /// (boxes) every 60 m; on its inner side, parked aircraft (fuselage, wings, tail) every 90 m;
  /// light poles every 50 m and a cone every 130 m beside the road. Procedural and fixed: every
  /// object's place follows from its index along the road.
  static Scene airport_site();
  static Eigen::Vector2d site_route_min() { return {-400.0, -150.0}; }
  static Eigen::Vector2d site_route_max() { return {400.0, 150.0}; }

 private:
  std::vector<Object> objects_;
};

}  // namespace tarmac::sim
