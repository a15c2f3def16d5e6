#include "tarmac/sim/scene.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace tarmac::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// The parameter interval [lo, hi] of a ray inside a convex solid; empty when lo > hi.
struct Interval {
  double lo = -kInf;
  double hi = kInf;

  bool empty() const { return lo > hi; }
  void clip(double new_lo, double new_hi) {
    lo = std::max(lo, new_lo);
    hi = std::min(hi, new_hi);
  }
};

constexpr Interval kEmpty{kInf, -kInf};

/// Where o + t·d lies in the slab lo <= x <= hi (one coordinate).
Interval slab(double o, double d, double lo, double hi) {
  if (d == 0.0) return (o >= lo && o <= hi) ? Interval{} : kEmpty;
  const double t0 = (lo - o) / d;
  const double t1 = (hi - o) / d;
  return {std::min(t0, t1), std::max(t0, t1)};
}

/// Real roots r0 <= r1 of a·t² + b·t + c (a != 0), computed without cancellation; false when
/// there are none.
bool solve_quadratic(double a, double b, double c, double& r0, double& r1) {
  const double disc = b * b - 4.0 * a * c;
  if (disc < 0.0) return false;
  const double q = -0.5 * (b + std::copysign(std::sqrt(disc), b));
  if (q == 0.0) {  // b = 0 and c = 0: a double root at 0
    r0 = r1 = 0.0;
    return true;
  }
  r0 = q / a;
  r1 = c / q;
  if (r0 > r1) std::swap(r0, r1);
  return true;
}

/// Nearest surface crossing at t >= 0 of a ray whose interval in a convex solid is `in`.
std::optional<double> entry_or_exit(const Interval& in) {
  if (in.empty() || in.hi < 0.0) return std::nullopt;
  return in.lo >= 0.0 ? in.lo : in.hi;
}

int axis_index(Axis axis) {
  return static_cast<int>(axis);
}

Interval interval(const Box& box, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  Interval in;
  for (int i = 0; i < 3 && !in.empty(); ++i) {
    const Interval s = slab(o[i], d[i], box.min_W[i], box.max_W[i]);
    in.clip(s.lo, s.hi);
  }
  return in;
}

/// Where o + t·d lies in the half-space n·p <= limit, given n·o and n·d.
Interval half_space(double n_dot_o, double n_dot_d, double limit) {
  if (n_dot_d == 0.0) return n_dot_o <= limit ? Interval{} : kEmpty;
  const double t = (limit - n_dot_o) / n_dot_d;
  return n_dot_d > 0.0 ? Interval{-kInf, t} : Interval{t, kInf};
}

Interval interval(const SlopedBox& box, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  Interval in = slab(o.x(), d.x(), box.min_xy_W.x(), box.max_xy_W.x());
  const Interval along_y = slab(o.y(), d.y(), box.min_xy_W.y(), box.max_xy_W.y());
  in.clip(along_y.lo, along_y.hi);
  const Interval above_bottom = half_space(-o.z(), -d.z(), -box.bottom_z_m);
  in.clip(above_bottom.lo, above_bottom.hi);
  // Below the top: n·(p − corner) <= 0 with n = (−grade, 1), taken from the footprint's corner
  // at the top's height so that the sums stay small.
  const double gx = box.grade.x(), gy = box.grade.y();
  const double n_dot_o =
      (o.z() - box.top_z_m) - gx * (o.x() - box.min_xy_W.x()) - gy * (o.y() - box.min_xy_W.y());
  const Interval below_top = half_space(n_dot_o, d.z() - gx * d.x() - gy * d.y(), 0.0);
  in.clip(below_top.lo, below_top.hi);
  return in;
}

Interval interval(const Cylinder& cyl, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  const int a = axis_index(cyl.axis);
  const int u = (a + 1) % 3;
  const int v = (a + 2) % 3;
  Interval in = slab(o[a], d[a], cyl.base_W[a], cyl.base_W[a] + cyl.length_m);
  if (in.empty()) return in;
  // Infinite cylinder: |(o + t·d − base) projected on the (u, v) plane|² <= r².
  const double pu = o[u] - cyl.base_W[u];
  const double pv = o[v] - cyl.base_W[v];
  const double qa = d[u] * d[u] + d[v] * d[v];
  const double qb = 2.0 * (pu * d[u] + pv * d[v]);
  const double qc = pu * pu + pv * pv - cyl.radius_m * cyl.radius_m;
  if (qa == 0.0) return qc <= 0.0 ? in : kEmpty;  // parallel to the axis
  double r0 = 0.0, r1 = 0.0;
  if (!solve_quadratic(qa, qb, qc, r0, r1)) return kEmpty;
  in.clip(r0, r1);
  return in;
}

Interval interval(const Cone& cone, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  const double apex_z = cone.base_W.z() + cone.height_m;
  // Between the base and the apex only the lower nappe of the double cone exists, and the solid
  // there is convex: f(t) = horizontal² − k²·(apex_z − z)² <= 0 with k = radius / height.
  Interval in = slab(o.z(), d.z(), cone.base_W.z(), apex_z);
  if (in.empty()) return in;
  const double k = cone.radius_m / cone.height_m;
  const double k2 = k * k;
  const double px = o.x() - cone.base_W.x();
  const double py = o.y() - cone.base_W.y();
  const double pz = apex_z - o.z();  // height below the apex
  const double qa = d.x() * d.x() + d.y() * d.y() - k2 * d.z() * d.z();
  const double qb = 2.0 * (px * d.x() + py * d.y() + k2 * pz * d.z());
  const double qc = px * px + py * py - k2 * pz * pz;
  if (qa == 0.0) {  // parallel to a generator: f is linear
    if (qb == 0.0) return qc <= 0.0 ? in : kEmpty;
    const double t = -qc / qb;
    if (qb > 0.0) {
      in.clip(-kInf, t);
    } else {
      in.clip(t, kInf);
    }
    return in;
  }
  double r0 = 0.0, r1 = 0.0;
  if (!solve_quadratic(qa, qb, qc, r0, r1)) return qa > 0.0 ? kEmpty : in;
  if (qa > 0.0) {
    in.clip(r0, r1);
    return in;
  }
  // f <= 0 outside [r0, r1]: one piece per nappe; keep the one below the apex inside the slab
  // (the slab is finite here because a steep ray has d.z() != 0).
  Interval below = in;
  below.clip(-kInf, r0);
  Interval above = in;
  above.clip(r1, kInf);
  const auto in_lower_nappe = [&](const Interval& piece) {
    return !piece.empty() && o.z() + 0.5 * (piece.lo + piece.hi) * d.z() <= apex_z;
  };
  if (in_lower_nappe(below)) return below;
  if (in_lower_nappe(above)) return above;
  return kEmpty;
}

std::optional<double> nearest(const Plane& plane, const Eigen::Vector3d& o,
                              const Eigen::Vector3d& d) {
  const double denom = plane.normal_W.dot(d);
  if (denom == 0.0) return std::nullopt;  // parallel: no crossing
  const double t = (plane.offset_m - plane.normal_W.dot(o)) / denom;
  if (!(t >= 0.0)) return std::nullopt;
  return t;
}

template <typename ConvexSolid>
std::optional<double> nearest(const ConvexSolid& solid, const Eigen::Vector3d& o,
                              const Eigen::Vector3d& d) {
  return entry_or_exit(interval(solid, o, d));
}

// ---- JSON writing (deterministic: shortest round-trip number formatting) ----

std::string number(double value) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof(buf), value);
  return std::string(buf, res.ptr);
}

std::string vec(const Eigen::Vector3d& v) {
  return "[" + number(v.x()) + ", " + number(v.y()) + ", " + number(v.z()) + "]";
}

std::string vec2(const Eigen::Vector2d& v) {
  return "[" + number(v.x()) + ", " + number(v.y()) + "]";
}

std::string quoted(std::string_view s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

const char* axis_name(Axis axis) {
  switch (axis) {
    case Axis::kX: return "x";
    case Axis::kY: return "y";
    case Axis::kZ: return "z";
  }
  return "?";
}

std::string primitive_json(const Primitive& primitive) {
  struct Visitor {
    std::string operator()(const Plane& p) const {
      return "{\"type\": \"plane\", \"normal\": " + vec(p.normal_W) +
             ", \"offset_m\": " + number(p.offset_m) + "}";
    }
    std::string operator()(const Box& b) const {
      return "{\"type\": \"box\", \"min\": " + vec(b.min_W) + ", \"max\": " + vec(b.max_W) + "}";
    }
    std::string operator()(const Cylinder& c) const {
      return "{\"type\": \"cylinder\", \"axis\": \"" + std::string(axis_name(c.axis)) +
             "\", \"base\": " + vec(c.base_W) + ", \"length_m\": " + number(c.length_m) +
             ", \"radius_m\": " + number(c.radius_m) + "}";
    }
    std::string operator()(const Cone& c) const {
      return "{\"type\": \"cone\", \"base\": " + vec(c.base_W) +
             ", \"radius_m\": " + number(c.radius_m) + ", \"height_m\": " + number(c.height_m) +
             "}";
    }
    std::string operator()(const SlopedBox& b) const {
      return "{\"type\": \"sloped_box\", \"min_xy\": " + vec2(b.min_xy_W) +
             ", \"max_xy\": " + vec2(b.max_xy_W) + ", \"bottom_z_m\": " + number(b.bottom_z_m) +
             ", \"top_z_m\": " + number(b.top_z_m) + ", \"grade\": " + vec2(b.grade) + "}";
    }
  };
  return std::visit(Visitor{}, primitive);
}

}  // namespace

Eigen::Vector3d LinearMotion::displacement_W(double t_s) const {
  const double moving_s = std::clamp(t_s, start_s, std::max(start_s, stop_s)) - start_s;
  return velocity_W_mps * moving_s;
}

std::optional<double> intersect(const Primitive& primitive, const Eigen::Vector3d& origin_W,
                                const Eigen::Vector3d& dir_W) {
  return std::visit([&](const auto& shape) { return nearest(shape, origin_W, dir_W); }, primitive);
}

bool contains(const Primitive& primitive, const Eigen::Vector3d& p_W) {
  struct Visitor {
    const Eigen::Vector3d& p;
    bool operator()(const Plane& plane) const { return plane.normal_W.dot(p) < plane.offset_m; }
    bool operator()(const Box& b) const {
      return (p.array() >= b.min_W.array()).all() && (p.array() <= b.max_W.array()).all();
    }
    bool operator()(const Cylinder& c) const {
      const int a = axis_index(c.axis);
      const int u = (a + 1) % 3;
      const int v = (a + 2) % 3;
      const double du = p[u] - c.base_W[u];
      const double dv = p[v] - c.base_W[v];
      return p[a] >= c.base_W[a] && p[a] <= c.base_W[a] + c.length_m &&
             du * du + dv * dv <= c.radius_m * c.radius_m;
    }
    bool operator()(const Cone& c) const {
      const double h = p.z() - c.base_W.z();
      if (h < 0.0 || h > c.height_m) return false;
      const double r = c.radius_m * (1.0 - h / c.height_m);
      const double dx = p.x() - c.base_W.x();
      const double dy = p.y() - c.base_W.y();
      return dx * dx + dy * dy <= r * r;
    }
    bool operator()(const SlopedBox& b) const {
      const Eigen::Vector2d xy = p.head<2>();
      return b.covers(xy) && p.z() >= b.bottom_z_m && p.z() <= b.top_at(xy);
    }
  };
  return std::visit(Visitor{p_W}, primitive);
}

Aabb bounds(const Primitive& primitive) {
  struct Visitor {
    Aabb operator()(const Plane& p) const {
      Aabb box{Eigen::Vector3d::Constant(-kInf), Eigen::Vector3d::Constant(kInf)};
      // An axis-aligned half-space is bounded along its normal; any other plane is not.
      for (int i = 0; i < 3; ++i) {
        if (std::abs(p.normal_W[i]) != 1.0) continue;
        if (p.normal_W[i] > 0.0) {
          box.max_W[i] = p.offset_m;
        } else {
          box.min_W[i] = -p.offset_m;
        }
      }
      return box;
    }
    Aabb operator()(const Box& b) const { return {b.min_W, b.max_W}; }
    Aabb operator()(const Cylinder& c) const {
      const int a = axis_index(c.axis);
      Aabb box{c.base_W.array() - c.radius_m, c.base_W.array() + c.radius_m};
      box.min_W[a] = c.base_W[a];
      box.max_W[a] = c.base_W[a] + c.length_m;
      return box;
    }
    Aabb operator()(const Cone& c) const {
      Aabb box{c.base_W.array() - c.radius_m, c.base_W.array() + c.radius_m};
      box.min_W.z() = c.base_W.z();
      box.max_W.z() = c.base_W.z() + c.height_m;
      return box;
    }
    Aabb operator()(const SlopedBox& b) const {
      // A plane over a rectangle is highest at one of its corners.
      double top = -kInf;
      for (const double x : {b.min_xy_W.x(), b.max_xy_W.x()}) {
        for (const double y : {b.min_xy_W.y(), b.max_xy_W.y()}) {
          top = std::max(top, b.top_at({x, y}));
        }
      }
      return {Eigen::Vector3d(b.min_xy_W.x(), b.min_xy_W.y(), b.bottom_z_m),
              Eigen::Vector3d(b.max_xy_W.x(), b.max_xy_W.y(), top)};
    }
  };
  return std::visit(Visitor{}, primitive);
}

Primitive translated(const Primitive& primitive, const Eigen::Vector3d& offset_W) {
  struct Visitor {
    const Eigen::Vector3d& offset;
    Primitive operator()(Plane p) const {
      p.offset_m += p.normal_W.dot(offset);
      return p;
    }
    Primitive operator()(Box b) const {
      b.min_W += offset;
      b.max_W += offset;
      return b;
    }
    Primitive operator()(Cylinder c) const {
      c.base_W += offset;
      return c;
    }
    Primitive operator()(Cone c) const {
      c.base_W += offset;
      return c;
    }
    Primitive operator()(SlopedBox b) const {
      b.min_xy_W += offset.head<2>();
      b.max_xy_W += offset.head<2>();
      b.bottom_z_m += offset.z();
      b.top_z_m += offset.z();
      return b;
    }
  };
  return std::visit(Visitor{offset_W}, primitive);
}

std::optional<double> Terrain::height_m(const Eigen::Vector2d& xy_W) const {
  if (flat()) return 0.0;
  std::optional<double> height;
  for (const SlopedBox& patch : patches) {
    if (!patch.covers(xy_W)) continue;
    // Patches share their edges: on one, the higher top is the surface.
    const double z = patch.top_at(xy_W);
    if (!height || z > *height) height = z;
  }
  return height;
}

int Scene::add(std::string name, std::string kind, Primitive shape_W,
               std::optional<LinearMotion> motion) {
  Object object;
  object.id = static_cast<int>(objects_.size());
  object.name = std::move(name);
  object.kind = std::move(kind);
  object.shape_W = std::move(shape_W);
  object.motion = std::move(motion);
  objects_.push_back(std::move(object));
  return objects_.back().id;
}

const Object* Scene::find(std::string_view name) const {
  for (const Object& object : objects_) {
    if (object.name == name) return &object;
  }
  return nullptr;
}

Primitive Scene::shape_at(int id, double t_s) const {
  const Object& object = objects_.at(static_cast<std::size_t>(id));
  if (!object.motion) return object.shape_W;
  return translated(object.shape_W, object.motion->displacement_W(t_s));
}

Aabb Scene::bounds_at(int id, double t_s) const {
  return bounds(shape_at(id, t_s));
}

std::vector<int> Scene::near(const Eigen::Vector3d& p_W, double radius_m, double t_s) const {
  std::vector<int> ids;
  for (const Object& object : objects_) {
    const Aabb b = bounds_at(object.id, t_s);
    bool in = true;
    for (int a = 0; a < 3; ++a) {
      in = in && b.min_W[a] <= p_W[a] + radius_m && b.max_W[a] >= p_W[a] - radius_m;
    }
    if (in) ids.push_back(object.id);
  }
  return ids;
}

std::optional<Hit> Scene::raycast(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                                  double max_range_m, double t_s,
                                  const std::vector<int>* candidates) const {
  const Eigen::Vector3d d = dir_W.normalized();
  std::optional<Hit> best;
  const std::size_t n = candidates != nullptr ? candidates->size() : objects_.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Object& object =
        candidates != nullptr ? objects_[static_cast<std::size_t>((*candidates)[i])] : objects_[i];
    const std::optional<double> range_m = object.motion
                                              ? intersect(shape_at(object.id, t_s), origin_W, d)
                                              : intersect(object.shape_W, origin_W, d);
    if (!range_m || *range_m > max_range_m) continue;
    if (best && *range_m >= best->range_m) continue;  // ties go to the lower id
    best = Hit{*range_m, origin_W + *range_m * d, object.id};
  }
  return best;
}

bool Scene::occupied(const Eigen::Vector3d& p_W, double t_s) const {
  for (const Object& object : objects_) {
    if (contains(shape_at(object.id, t_s), p_W)) return true;
  }
  return false;
}

Terrain Scene::terrain() const {
  Terrain terrain;
  for (const Object& object : objects_) {
    if (object.kind != "ground" || object.dynamic()) continue;
    if (const auto* patch = std::get_if<SlopedBox>(&object.shape_W)) {
      terrain.patches.push_back(*patch);
    }
  }
  return terrain;
}

std::string Scene::to_json(const Eigen::Isometry3d& T_world_W) const {
  std::string out = "{\n";
  out += terrain().flat()
             ? "  \"frame\": \"scene frame: x forward along the apron, y left, z up, metres; "
               "ground plane z = 0; time in seconds from the first scan\",\n"
             : "  \"frame\": \"scene frame: x forward along the apron, y left, z up, metres; "
               "ground: the tops of the objects of kind ground; time in seconds from the first "
               "scan\",\n";
  out += "  \"T_world_scene\": [";
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      out += number(T_world_W.matrix()(r, c));
      if (r < 2 || c < 3) out += ", ";
    }
  }
  out += "],\n";
  out += "  \"objects\": [\n";
  for (const Object& object : objects_) {
    out += "    {\"id\": " + std::to_string(object.id) + ", \"name\": " + quoted(object.name) +
           ", \"kind\": " + quoted(object.kind) +
           ", \"dynamic\": " + (object.dynamic() ? "true" : "false") +
           ",\n     \"primitive\": " + primitive_json(object.shape_W);
    if (object.motion) {
      out += ",\n     \"motion\": {\"velocity_mps\": " + vec(object.motion->velocity_W_mps) +
             ", \"start_s\": " + number(object.motion->start_s) +
             ", \"stop_s\": " + number(object.motion->stop_s) + "}";
    }
    out += "}";
    out += (object.id + 1 < static_cast<int>(objects_.size())) ? ",\n" : "\n";
  }
  out += "  ]\n}\n";
  return out;
}

Scene Scene::terminal_walls() {
  using V = Eigen::Vector3d;
  Scene scene;
  scene.add("ground", "ground", Plane{V::UnitZ(), 0.0});
  scene.add("terminal_left", "building", Box{V(-30.0, 8.1, 0.0), V(90.0, 8.5, 6.0)});
  scene.add("terminal_right", "building", Box{V(-30.0, -16.5, 0.0), V(90.0, -16.1, 6.0)});
  scene.add("pillar", "pillar", Cylinder{Axis::kZ, V(30.0, -6.0, 0.0), 4.0, 0.4});
  return scene;
}

Scene Scene::aircraft_stand() {
  using V = Eigen::Vector3d;
  Scene scene;
  scene.add("ground", "ground", Plane{V::UnitZ(), 0.0});
  scene.add("fuselage", "fuselage", Cylinder{Axis::kX, V(-18.0, 0.0, 3.3), 36.0, 1.8});
  scene.add("wing_right", "wing", Box{V(-3.0, -15.0, 3.3), V(3.0, -1.5, 3.6)});
  scene.add("wing_left", "wing", Box{V(-3.0, 1.5, 3.3), V(3.0, 15.0, 3.6)});
  scene.add("engine_right", "engine", Cylinder{Axis::kX, V(-4.0, -6.0, 1.9), 4.0, 0.7});
  scene.add("engine_left", "engine", Cylinder{Axis::kX, V(-4.0, 6.0, 1.9), 4.0, 0.7});
  scene.add("gear_nose", "landing_gear", Cylinder{Axis::kZ, V(14.0, 0.0, 0.0), 1.6, 0.25});
  scene.add("gear_main_right", "landing_gear", Cylinder{Axis::kZ, V(1.0, -2.5, 0.0), 1.6, 0.35});
  scene.add("gear_main_left", "landing_gear", Cylinder{Axis::kZ, V(1.0, 2.5, 0.0), 1.6, 0.35});
  scene.add("tail", "tail", Box{V(15.0, -0.2, 3.3), V(18.0, 0.2, 8.0)});
  scene.add("cone_nose", "cone", Cone{V(20.0, 0.0, 0.0), 0.2, 0.5});
  scene.add("cone_wing", "cone", Cone{V(0.0, -16.0, 0.0), 0.2, 0.5});
  return scene;
}

Scene Scene::airport_site() {
  using V = Eigen::Vector3d;
  Scene scene;
  scene.add("ground", "ground", Plane{V::UnitZ(), 0.0});
  const Eigen::Vector2d lo = site_route_min(), hi = site_route_max();
  // The road's four sides, counter-clockwise; `out` points away from the apron.
  struct Side {
    Eigen::Vector2d from, to, out;
  };
  const Side sides[] = {{{lo.x(), lo.y()}, {hi.x(), lo.y()}, {0.0, -1.0}},
                        {{hi.x(), lo.y()}, {hi.x(), hi.y()}, {1.0, 0.0}},
                        {{hi.x(), hi.y()}, {lo.x(), hi.y()}, {0.0, 1.0}},
                        {{lo.x(), hi.y()}, {lo.x(), lo.y()}, {-1.0, 0.0}}};
  // An axis-aligned box from a centre on the ground and its extents along and across the road.
  const auto box = [](const Eigen::Vector2d& c, const Eigen::Vector2d& along, double half_along,
                      double half_across, double z0, double z1) {
    const Eigen::Vector2d across(-along.y(), along.x());
    const Eigen::Vector2d e = (along * half_along + across * half_across).cwiseAbs();
    return Box{V(c.x() - e.x(), c.y() - e.y(), z0), V(c.x() + e.x(), c.y() + e.y(), z1)};
  };
  int n = 0;
  for (const Side& side : sides) {
    const Eigen::Vector2d dir = (side.to - side.from).normalized();
    const double length = (side.to - side.from).norm();
    const Axis along_axis = std::abs(dir.x()) > 0.5 ? Axis::kX : Axis::kY;
    // Keep the corners' turning arcs clear (20 m radius) and the sides' ends apart.
    for (double s = 40.0; s + 40.0 <= length; s += 10.0, ++n) {
      const Eigen::Vector2d at = side.from + s * dir;
      const std::string id = std::to_string(n);
      const int step = static_cast<int>(std::lround(s / 10.0));
      if (step % 6 == 0) {  // a building outside the road, its height varying along the site
        const double height = 8.0 + 2.0 * static_cast<double>(n % 4);
        scene.add("building_" + id, "building",
                  box(at + 32.0 * side.out, dir, 18.0, 10.0, 0.0, height));
      }
      if (step % 9 == 4) {  // a parked aircraft inside, nose along the road
        const Eigen::Vector2d c = at - 28.0 * side.out;
        // The fuselage spans c ± 17 m along the road; a cylinder grows along +axis from its base.
        V base(c.x(), c.y(), 3.2);
        base[static_cast<int>(along_axis)] -= 17.0;
        scene.add("fuselage_" + id, "fuselage", Cylinder{along_axis, base, 34.0, 1.9});
        scene.add("wings_" + id, "wing", box(c + 2.0 * dir, dir, 3.0, 16.0, 3.4, 3.7));
        scene.add("tail_" + id, "tail", box(c - 15.0 * dir, dir, 1.5, 0.2, 3.2, 9.0));
        scene.add(
            "gear_" + id, "landing_gear",
            Cylinder{Axis::kZ, V(c.x(), c.y(), 0.0) + V(dir.x(), dir.y(), 0.0) * 12.0, 1.5, 0.25});
      }
      if (step % 5 == 2) {  // a light pole beside the road
        const Eigen::Vector2d p = at + 9.0 * side.out;
        scene.add("pole_" + id, "pole", Cylinder{Axis::kZ, V(p.x(), p.y(), 0.0), 10.0, 0.2});
      }
      if (step % 13 == 7) {  // a cone on the road's edge
        const Eigen::Vector2d p = at - 4.0 * side.out;
        scene.add("cone_" + id, "cone", Cone{V(p.x(), p.y(), 0.0), 0.2, 0.5});
      }
    }
  }
  return scene;
}

Scene Scene::airside_default() {
  using V = Eigen::Vector3d;
  Scene scene;
  scene.add("ground", "ground", Plane{V::UnitZ(), 0.0});
  // Parked aircraft, nose towards +x, fuselage parallel to the path 12 m to its left; the right
  // wing reaches across the path 4 m up.
  scene.add("fuselage", "fuselage", Cylinder{Axis::kX, V(10.0, 12.0, 3.0), 40.0, 2.0});
  scene.add("wing_right", "wing", Box{V(26.0, -8.0, 4.0), V(34.0, 12.0, 4.4)});
  scene.add("wing_left", "wing", Box{V(26.0, 12.0, 4.0), V(34.0, 32.0, 4.4)});
  scene.add("engine_right", "engine", Cylinder{Axis::kX, V(23.0, 5.0, 2.2), 5.0, 1.0});
  scene.add("engine_left", "engine", Cylinder{Axis::kX, V(23.0, 19.0, 2.2), 5.0, 1.0});
  scene.add("gear_front", "landing_gear", Cylinder{Axis::kZ, V(29.0, 3.0, 0.0), 3.0, 0.3});
  scene.add("gear_rear", "landing_gear", Cylinder{Axis::kZ, V(33.0, 3.0, 0.0), 3.0, 0.3});
  // Jet bridge across the path, 4 m clearance, on pillars outside the path.
  scene.add("jet_bridge", "jet_bridge", Box{V(52.0, -6.0, 4.0), V(56.0, 6.0, 7.0)});
  scene.add("jet_bridge_pillar_right", "jet_bridge_pillar",
            Cylinder{Axis::kZ, V(54.0, -5.0, 0.0), 4.0, 0.4});
  scene.add("jet_bridge_pillar_left", "jet_bridge_pillar",
            Cylinder{Axis::kZ, V(54.0, 5.0, 0.0), 4.0, 0.4});
  scene.add("cone_right", "cone", Cone{V(20.0, -1.5, 0.0), 0.2, 0.5});
  scene.add("cone_left", "cone", Cone{V(20.0, 1.5, 0.0), 0.2, 0.5});
  scene.add("cone_path", "cone", Cone{V(40.0, 0.0, 0.0), 0.2, 0.5});
  scene.add("debris", "debris", Box{V(46.9, 0.4, 0.0), V(47.1, 0.6, 0.1)});
  // A tug crossing the path ahead of the vehicle, then parked clear of the path and aircraft.
  scene.add("tug", "tug", Box{V(14.2, -5.5, 0.0), V(15.8, -2.5, 1.5)},
            LinearMotion{V(0.0, 2.0, 0.0), 0.0, 6.0});
  return scene;
}

namespace {

/// Below every terrain scene's lowest ground, m.
constexpr double kTerrainBottomM = -20.0;
/// The terrain scenes' extent: beyond the sensor's range from their drives, m.
constexpr double kTerrainMinX = -150.0, kTerrainMaxX = 250.0, kTerrainHalfWidth = 150.0;

/// Ground over [min_xy, max_xy], its top `top_z_m` at min_xy, rising by `grade`.
SlopedBox ground_patch(const Eigen::Vector2d& min_xy, const Eigen::Vector2d& max_xy, double top_z_m,
                       const Eigen::Vector2d& grade = Eigen::Vector2d::Zero()) {
  return SlopedBox{min_xy, max_xy, kTerrainBottomM, top_z_m, grade};
}

/// The lowest and highest ground over the rectangle [min_xy, max_xy], from its corners and
/// centre: exact for planar patches, and for the terrain scenes' kinks (straight lines across
/// the drive, where a ramp meets a level).
std::pair<double, double> ground_range(const Terrain& terrain, const Eigen::Vector2d& min_xy,
                                       const Eigen::Vector2d& max_xy) {
  double lo = kInf, hi = -kInf;
  for (const Eigen::Vector2d& xy :
       {min_xy, max_xy, Eigen::Vector2d(min_xy.x(), max_xy.y()),
        Eigen::Vector2d(max_xy.x(), min_xy.y()), Eigen::Vector2d(0.5 * (min_xy + max_xy))}) {
    const double z = terrain.height_m(xy).value();
    lo = std::min(lo, z);
    hi = std::max(hi, z);
  }
  return {lo, hi};
}

/// A cone standing on `terrain` at xy: its base as low as the ground under it, so that it stands
/// on the slope without a gap, its apex height_m above the ground at xy.
Cone cone_on(const Terrain& terrain, const Eigen::Vector2d& xy, double radius_m, double height_m) {
  const Eigen::Vector2d r(radius_m, radius_m);
  const double base_z = ground_range(terrain, xy - r, xy + r).first;
  const double apex_z = terrain.height_m(xy).value() + height_m;
  return Cone{Eigen::Vector3d(xy.x(), xy.y(), base_z), radius_m, apex_z - base_z};
}

/// A crate on `terrain` over [min_xy, max_xy]: its bottom as low as the ground under it, its top
/// height_m above the highest ground under it.
Box crate_on(const Terrain& terrain, const Eigen::Vector2d& min_xy, const Eigen::Vector2d& max_xy,
             double height_m) {
  const auto [lo, hi] = ground_range(terrain, min_xy, max_xy);
  return Box{Eigen::Vector3d(min_xy.x(), min_xy.y(), lo),
             Eigen::Vector3d(max_xy.x(), max_xy.y(), hi + height_m)};
}

/// Adds `patches` to `scene` as its ground, named ground_0, ground_1, ...
void add_ground(Scene& scene, const std::vector<SlopedBox>& patches) {
  for (std::size_t i = 0; i < patches.size(); ++i) {
    scene.add("ground_" + std::to_string(i), "ground", patches[i]);
  }
}

}  // namespace

Scene Scene::apron_ramp(double grade, double ramp_length_m) {
  using V2 = Eigen::Vector2d;
  const double foot_x = 20.0, top_x = foot_x + ramp_length_m, top_z = grade * ramp_length_m;
  Scene scene;
  add_ground(
      scene,
      {ground_patch({kTerrainMinX, -kTerrainHalfWidth}, {foot_x, kTerrainHalfWidth}, 0.0),
       ground_patch({foot_x, -kTerrainHalfWidth}, {top_x, kTerrainHalfWidth}, 0.0, {grade, 0.0}),
       ground_patch({top_x, -kTerrainHalfWidth}, {kTerrainMaxX, kTerrainHalfWidth}, top_z)});
  const Terrain terrain = scene.terrain();
  const double mid_x = foot_x + 0.5 * ramp_length_m;
  scene.add("cone_apron_right", "cone", cone_on(terrain, {10.0, -2.5}, 0.2, 0.5));
  scene.add("cone_apron_left", "cone", cone_on(terrain, {14.0, 3.0}, 0.25, 0.7));
  scene.add("cone_ramp_foot", "cone", cone_on(terrain, {21.0, -2.0}, 0.15, 0.3));
  scene.add("cone_ramp_left", "cone", cone_on(terrain, {mid_x, 2.0}, 0.2, 0.5));
  scene.add("crate_ramp", "crate",
            crate_on(terrain, {mid_x + 4.0, -3.5}, {mid_x + 5.2, -2.5}, 0.5));
  scene.add("cone_crest", "cone", cone_on(terrain, {top_x + 1.0, 2.0}, 0.2, 0.5));
  scene.add("cone_top_right", "cone", cone_on(terrain, {70.0, -2.5}, 0.15, 0.3));
  scene.add("crate_top", "crate", crate_on(terrain, V2(78.0, 2.0), V2(79.2, 3.0), 0.6));
  scene.add("cone_ahead", "cone", cone_on(terrain, {95.0, 1.5}, 0.2, 0.5));
  return scene;
}

Scene Scene::crowned_road() {
  using V2 = Eigen::Vector2d;
  constexpr double kCrownZ = 0.1, kRoadHalfWidth = 5.0, kShoulderEdge = 8.0, kVergeZ = -0.12;
  constexpr double kCrossFall = kCrownZ / kRoadHalfWidth;                        // 2 %
  constexpr double kShoulderFall = -kVergeZ / (kShoulderEdge - kRoadHalfWidth);  // 4 %
  Scene scene;
  add_ground(
      scene,
      {ground_patch({kTerrainMinX, -kTerrainHalfWidth}, {kTerrainMaxX, -kShoulderEdge}, kVergeZ),
       ground_patch({kTerrainMinX, -kShoulderEdge}, {kTerrainMaxX, -kRoadHalfWidth}, kVergeZ,
                    {0.0, kShoulderFall}),
       ground_patch({kTerrainMinX, -kRoadHalfWidth}, {kTerrainMaxX, 0.0}, 0.0, {0.0, kCrossFall}),
       ground_patch({kTerrainMinX, 0.0}, {kTerrainMaxX, kRoadHalfWidth}, kCrownZ,
                    {0.0, -kCrossFall}),
       ground_patch({kTerrainMinX, kRoadHalfWidth}, {kTerrainMaxX, kShoulderEdge}, 0.0,
                    {0.0, -kShoulderFall}),
       ground_patch({kTerrainMinX, kShoulderEdge}, {kTerrainMaxX, kTerrainHalfWidth}, kVergeZ)});
  const Terrain terrain = scene.terrain();
  scene.add("cone_centre", "cone", cone_on(terrain, {25.0, 0.0}, 0.2, 0.5));
  scene.add("cone_right_edge", "cone", cone_on(terrain, {35.0, -4.6}, 0.15, 0.3));
  scene.add("cone_left_lane", "cone", cone_on(terrain, {45.0, 2.5}, 0.25, 0.7));
  scene.add("crate_right_shoulder", "crate",
            crate_on(terrain, V2(55.0, -7.0), V2(56.2, -6.0), 0.5));
  scene.add("cone_left_shoulder", "cone", cone_on(terrain, {65.0, 6.5}, 0.2, 0.5));
  scene.add("crate_left_lane", "crate", crate_on(terrain, V2(75.0, 1.5), V2(76.5, 3.0), 0.8));
  scene.add("cone_ahead", "cone", cone_on(terrain, {96.0, -2.5}, 0.2, 0.5));
  return scene;
}

Scene Scene::parking_levels() {
  using V = Eigen::Vector3d;
  using V2 = Eigen::Vector2d;
  constexpr double kLowerZ = -2.25, kRampX0 = 30.0, kRampX1 = 55.0, kCut = 5.3;
  constexpr double kRampGrade = kLowerZ / (kRampX1 - kRampX0);  // -9 %
  constexpr double kRoadEnd = 130.3, kBaysX0 = 74.7, kBaysX1 = 115.3, kBaysY1 = 25.3;
  constexpr double kW = kTerrainHalfWidth;
  Scene scene;
  add_ground(scene,
             {// The apron round the cut.
              ground_patch({kTerrainMinX, -kW}, {kRampX0, kW}, 0.0),
              ground_patch({kRampX0, -kW}, {kTerrainMaxX, -kCut}, 0.0),
              ground_patch({kRampX0, kCut}, {kBaysX0, kW}, 0.0),
              ground_patch({kBaysX0, kBaysY1}, {kBaysX1, kW}, 0.0),
              ground_patch({kBaysX1, kCut}, {kTerrainMaxX, kW}, 0.0),
              ground_patch({kRoadEnd, -kCut}, {kTerrainMaxX, kCut}, 0.0),
              // The cut: the ramp, the lower road, the bays.
              ground_patch({kRampX0, -kCut}, {kRampX1, kCut}, 0.0, {kRampGrade, 0.0}),
              ground_patch({kRampX1, -kCut}, {kRoadEnd, kCut}, kLowerZ),
              ground_patch({kBaysX0, kCut}, {kBaysX1, kBaysY1}, kLowerZ)});
  // Walls from below the lower level to a parapet over the apron, on every edge of the cut.
  constexpr double kWallLow = kLowerZ - 0.5, kWallTop = 1.0, kT = 0.3;
  const auto wall = [&](const std::string& name, double x0, double y0, double x1, double y1) {
    scene.add(name, "wall", Box{V(x0, y0, kWallLow), V(x1, y1, kWallTop)});
  };
  wall("wall_right", kRampX0, -kCut, kRoadEnd, -kCut + kT);
  wall("wall_left_ramp", kRampX0, kCut - kT, kBaysX0, kCut);
  wall("wall_left_end", kBaysX1, kCut - kT, kRoadEnd, kCut);
  wall("wall_bays_west", kBaysX0, kCut - kT, kBaysX0 + kT, kBaysY1);
  wall("wall_bays_east", kBaysX1 - kT, kCut - kT, kBaysX1, kBaysY1);
  wall("wall_bays_north", kBaysX0, kBaysY1 - kT, kBaysX1, kBaysY1);
  wall("wall_end", kRoadEnd - kT, -kCut, kRoadEnd, kCut);
  // A 15 cm curb along the right side, following the ramp down to the road.
  constexpr double kCurbY0 = -4.3, kCurbY1 = -4.0, kCurbH = 0.15;
  scene.add("curb_ramp", "curb",
            SlopedBox{{kRampX0, kCurbY0}, {kRampX1, kCurbY1}, kWallLow, kCurbH, {kRampGrade, 0.0}});
  scene.add("curb_road", "curb",
            Box{V(kRampX1, kCurbY0, kWallLow), V(kRoadEnd - kT, kCurbY1, kLowerZ + kCurbH)});
  // The road under the terminal: a deck 3.6 m over the lower level.
  scene.add("deck", "deck", Box{V(100.0, -kCut, kLowerZ + 3.6), V(kRoadEnd, kCut, kLowerZ + 4.0)});
  const Terrain terrain = scene.terrain();
  const auto car = [&](const std::string& name, const V2& min_xy, const V2& max_xy) {
    scene.add(name, "car", crate_on(terrain, min_xy, max_xy, 1.5));
  };
  car("car_1", {80.0, 20.0}, {81.9, 24.6});
  car("car_2", {84.0, 20.0}, {85.9, 24.6});
  car("car_3", {96.0, 20.0}, {97.9, 24.6});
  car("car_4", {102.0, 7.0}, {106.6, 8.9});
  scene.add("cone_apron", "cone", cone_on(terrain, {15.0, -3.0}, 0.2, 0.5));
  scene.add("cone_ramp", "cone", cone_on(terrain, {42.0, 2.5}, 0.2, 0.5));
  scene.add("cone_ramp_curb", "cone", cone_on(terrain, {48.0, -3.2}, 0.15, 0.3));
  scene.add("cone_road", "cone", cone_on(terrain, {70.0, -3.0}, 0.25, 0.7));
  scene.add("crate_road", "crate", crate_on(terrain, V2(90.0, 2.5), V2(91.2, 3.5), 0.6));
  scene.add("cone_under_deck", "cone", cone_on(terrain, {112.0, 3.0}, 0.2, 0.5));
  return scene;
}

}  // namespace tarmac::sim
