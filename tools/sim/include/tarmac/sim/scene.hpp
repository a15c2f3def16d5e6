#pragma once
/// @file A synthetic airside scene built from exact analytic primitives (plane, axis-aligned box,
/// axis-aligned finite cylinder, upright cone, box with a sloped top), with exact ray casting and
/// point occupancy, so that simulated scans and maps can be checked against analytic ground truth.
///
/// Frame W (the scene frame): x forward along the apron, y left, z up, metres. The ground is the
/// plane z = 0, or, in the terrain scenes, the sloped tops of boxes laid edge to edge (Terrain).
/// Time t_s is seconds since the start of the sequence.

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

/// Solid axis-aligned box whose top face is a sloped plane: the points with x in
/// [min_xy_W.x, max_xy_W.x], y in [min_xy_W.y, max_xy_W.y] and bottom_z_m <= z <= top_at(x, y).
/// Laid edge to edge with matching heights, such boxes make piecewise-planar ground (an apron, a
/// ramp, one side of a crowned road); on that ground, a curb that follows a ramp. Requires
/// min_xy_W <= max_xy_W component-wise and the top at or above bottom_z_m over the footprint.
struct SlopedBox {
  Eigen::Vector2d min_xy_W = Eigen::Vector2d::Zero();
  Eigen::Vector2d max_xy_W = Eigen::Vector2d::Zero();
  double bottom_z_m = 0.0;
  double top_z_m = 0.0;                             ///< height of the top at min_xy_W
  Eigen::Vector2d grade = Eigen::Vector2d::Zero();  ///< the top's rise over run along x and y

  /// Height of the top's plane over xy_W (inside the footprint or not), m.
  double top_at(const Eigen::Vector2d& xy_W) const { return top_z_m + grade.dot(xy_W - min_xy_W); }
  /// True when xy_W lies in the footprint (edges included).
  bool covers(const Eigen::Vector2d& xy_W) const {
    return (xy_W.array() >= min_xy_W.array()).all() && (xy_W.array() <= max_xy_W.array()).all();
  }
  bool operator==(const SlopedBox&) const = default;
};

/// One exact analytic shape in frame W.
using Primitive = std::variant<Plane, Box, Cylinder, Cone, SlopedBox>;

/// The surface the vehicle drives on: the highest top of `patches` over a point; with no
/// patches, the plane z = 0 (the flat scenes).
struct Terrain {
  std::vector<SlopedBox> patches;

  /// True for the plane z = 0.
  [[nodiscard]] bool flat() const { return patches.empty(); }
  /// Height of the surface over xy_W, m; nothing where no patch covers it.
  [[nodiscard]] std::optional<double> height_m(const Eigen::Vector2d& xy_W) const;
  bool operator==(const Terrain&) const = default;
};

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

  /// True when p_W lies inside any object at time t_s, the ground's solid included (below the
  /// plane z = 0, or inside a terrain patch).
  bool occupied(const Eigen::Vector3d& p_W, double t_s) const;

  /// The ground the vehicle drives on: the SlopedBoxes of kind "ground" (static). Flat (no
  /// patches) for the scenes whose ground is the plane z = 0.
  [[nodiscard]] Terrain terrain() const;

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

  // Terrain scenes. Their ground is SlopedBoxes of kind "ground" (no plane) spanning x in
  // [-150, 250] and y in [-150, 150], beyond the sensor's range from the drive; the vehicle drives
  // on it (DrivePath::terrain) and every obstacle stands on it: a cone's base is sunk so that no
  // gap opens under its downhill edge, its apex at its height above the ground under its centre;
  // a crate's top is its height above the highest ground under it. Every step in the ground has
  // a wall on it. Coordinates in m, frame W.

  /// An apron at z = 0 for x <= 20, a ramp over the scene's width climbing at `grade` for
  /// `ramp_length_m`, and the level it reaches (x_top = 20 + ramp_length_m, z = grade ·
  /// ramp_length_m). Obstacles beside the drive (y = 0, x from 0 to 90), on the apron, on the
  /// ramp and on the upper level:
  ///  - cone_apron_right  (10, -2.5), r = 0.2, h = 0.5
  ///  - cone_apron_left   (14, 3), r = 0.25, h = 0.7
  ///  - cone_ramp_foot    (21, -2), r = 0.15, h = 0.3
  ///  - cone_ramp_left    (20 + ramp_length_m / 2, 2), r = 0.2, h = 0.5
  ///  - crate_ramp        [24 + ramp_length_m / 2, -3.5] .. [25.2 + ramp_length_m / 2, -2.5],
  ///                      h = 0.5
  ///  - cone_crest        (x_top + 1, 2), r = 0.2, h = 0.5
  ///  - cone_top_right    (70, -2.5), r = 0.15, h = 0.3
  ///  - crate_top         [78, 2] .. [79.2, 3], h = 0.6
  ///  - cone_ahead        (95, 1.5), r = 0.2, h = 0.5 (past the end of the drive)
  static Scene apron_ramp(double grade, double ramp_length_m);

  /// A crowned road along x: its centre line y = 0 at z = 0.1, falling 2 % to z = 0 at |y| = 5,
  /// shoulders falling 4 % to z = -0.12 at |y| = 8, a flat verge beyond. The drive: the right
  /// lane, y = -2.5, x from 0 to 90 (the vehicle rolled by the cross fall). Obstacles:
  ///  - cone_centre          (25, 0), r = 0.2, h = 0.5 (on the crown)
  ///  - cone_right_edge      (35, -4.6), r = 0.15, h = 0.3
  ///  - cone_left_lane       (45, 2.5), r = 0.25, h = 0.7
  ///  - crate_right_shoulder [55, -7] .. [56.2, -6], h = 0.5
  ///  - cone_left_shoulder   (65, 6.5), r = 0.2, h = 0.5
  ///  - crate_left_lane      [75, 1.5] .. [76.5, 3], h = 0.8
  ///  - cone_ahead           (96, -2.5), r = 0.2, h = 0.5 (past the end of the drive)
  static Scene crowned_road();

  /// A lower parking level joined to the apron by a ramp in a walled cut, part of it under a
  /// deck. The apron is at z = 0; the ramp, x in [30, 55], |y| <= 5.3, descends 9 % to the
  /// lower road (x in [55, 130.3], |y| <= 5.3) and the bays beside it (x in [74.7, 115.3], y in
  /// [5.3, 25.3]), both at z = -2.25. The drive: y = -1, x from 0 to 120. Objects:
  ///  - walls                0.3 m thick from below the lower level to z = 1 (a parapet over the
  ///                         apron) on every edge of the cut: y in [-5.3, -5] (x in [30, 130.3]),
  ///                         y in [5, 5.3] (x in [30, 74.7] and [115.3, 130.3]), round the bays
  ///                         and across the road's end (x in [130, 130.3])
  ///  - curb_ramp, curb_road a 0.15 m curb, y in [-4.3, -4], along the ramp (following its
  ///                         slope) and the lower road to x = 130
  ///  - deck                 box [100, -5.3, 1.35] .. [130.3, 5.3, 1.75]: the road under the
  ///                         terminal, 3.6 m of headroom
  ///  - car_1 .. car_4       parked cars, 1.5 m high: [80, 20] .. [81.9, 24.6], [84, 20] ..
  ///                         [85.9, 24.6], [96, 20] .. [97.9, 24.6], [102, 7] .. [106.6, 8.9]
  ///  - cone_apron           (15, -3), r = 0.2, h = 0.5
  ///  - cone_ramp            (42, 2.5), r = 0.2, h = 0.5
  ///  - cone_ramp_curb       (48, -3.2), r = 0.15, h = 0.3
  ///  - cone_road            (70, -3), r = 0.25, h = 0.7
  ///  - crate_road           [90, 2.5] .. [91.2, 3.5], h = 0.6
  ///  - cone_under_deck      (112, 3), r = 0.2, h = 0.5
  static Scene parking_levels();

  /// Foreign object debris on an open apron, then under a parked aircraft (issue 39's scene).
  /// The drive: y = 0, x from 0 to 100. Cubes standing on the ground, named
  /// debris_<size>cm_<x> (kind "debris"), at three sizes along three rows, each first seen
  /// from well beyond 20 m:
  ///  - x = 25: 10 cm at y = 0.6, 5 cm at y = -1.5, 20 cm at y = 3
  ///  - x = 45: 10 cm at y = -0.8, 20 cm at y = 1.5, 5 cm at y = 4
  ///  - x = 65: 10 cm at y = 2, 5 cm at y = 0.5, 20 cm at y = -3
  /// and the aircraft of airside_default() moved 60 m on (fuselage y = 12, x in [70, 110]; the
  /// right wing [86, -8, 4] .. [94, 12, 4.4] over the path; engine_right along x from 83 at
  /// y = 5, z = 2.2, r = 1; gear at (89, 3) and (93, 3)), with 10 cm debris under the wing at
  /// (88, -1) and beside the front gear at (89, 2.3).
  static Scene debris_apron();
  /// An empty apron: the ground plane only (the drive of debris_apron()): nothing may read lethal,
  /// no debris may be reported.
  static Scene empty_apron();

 private:
  std::vector<Object> objects_;
};

}  // namespace tarmac::sim
