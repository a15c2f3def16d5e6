#pragma once
/// @file The ray walk through the occupancy window, one ray at a time: the reference every
/// faster walk (walk_lanes4.cpp, walk_lanes8.cpp) must match bit for bit (OccupancyMap tests
/// compare their maps). Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing"
/// (Eurographics 1987), on the lattice [i·v, (i+1)·v), clipped to the window: marks each voxel
/// from the origin's voxel up to the end point's voxel, excluding it unless `include_end`, and
/// stops when the ray leaves the window (a box: it cannot come back). The walk steps through
/// ring-buffer slots, not coordinates (see AxisWalk). Internal to core/src/occupancy.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>

#include <Eigen/Core>

#include "window.hpp"

namespace tarmac::core::occupancy {

/// The window's size, its lowest voxel and the voxel size.
struct WindowGeometry {
  Eigen::Vector3i dims;
  Eigen::Vector3i min;
  double voxel_size_m;
};

/// One ray task's marks: a bit per voxel, and (large windows only) a bit per mark word that holds
/// a mark.
struct FreeMarks {
  std::uint64_t* bits;
  std::uint64_t* dirty;
};

/// The window-relative box (inclusive, per axis) that holds every voxel a set of rays marked;
/// empty while lo > hi. The apply pass reads the marks inside it only: indoors the rays end at
/// the walls, and most of a window sized for 50 m outdoors is never passed through.
struct MarkBox {
  std::array<int, 3> lo{std::numeric_limits<int>::max(), std::numeric_limits<int>::max(),
                        std::numeric_limits<int>::max()};
  std::array<int, 3> hi{std::numeric_limits<int>::min(), std::numeric_limits<int>::min(),
                        std::numeric_limits<int>::min()};

  void add(int axis, int a, int b) {
    lo[axis] = std::min(lo[axis], std::min(a, b));
    hi[axis] = std::max(hi[axis], std::max(a, b));
  }
  void add(const MarkBox& o) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], o.lo[a]);
      hi[a] = std::max(hi[a], o.hi[a]);
    }
  }
  [[nodiscard]] bool empty() const { return lo[0] > hi[0]; }
  [[nodiscard]] bool holds(int axis, int rel) const { return rel >= lo[axis] && rel <= hi[axis]; }
};

/// One axis of a traversal. A step moves the slot by one stride; `events` counts the steps to the
/// next place where that is not all: the ring wraps (the slot jumps back by a whole ring) or the
/// walk leaves the window. So a step tests one counter instead of the window bounds and the ring.
struct AxisWalk {
  std::int64_t delta;  ///< slot change of one step (step · stride)
  std::int64_t wrap;   ///< slot correction where the ring wraps (−step · n · stride)
  double t_max;        ///< ray parameter of the next boundary crossing
  double t_delta;      ///< parameter length of one voxel
  int events;          ///< steps until the next event (wrap or exit)
  int span;            ///< value `events` started from
  int to_exit;         ///< steps, counted at the last event, until the walk leaves the window
  int to_wrap;         ///< steps, counted at the last event, until the ring wraps
  int n;               ///< window size along the axis
  int step;            ///< −1, 0 or +1
  int exit0;           ///< to_exit at the start

  void init(int rel, int ring, int step_sign, int size, int stride) {
    n = size;
    step = step_sign;
    delta = static_cast<std::int64_t>(step) * stride;
    wrap = -static_cast<std::int64_t>(step) * size * stride;
    if (step > 0) {
      to_exit = size - rel;
      to_wrap = size - ring;
    } else if (step < 0) {
      to_exit = rel + 1;
      to_wrap = ring + 1;
    } else {
      to_exit = to_wrap = std::numeric_limits<int>::max();
    }
    events = span = std::min(to_exit, to_wrap);
    exit0 = to_exit;
  }
  /// Window-relative index along the axis where the walk ended, clamped into the window (a walk
  /// that left it last marked the boundary voxel; the step out over-counts, the clamp undoes it).
  [[nodiscard]] int end_rel(int rel) const {
    if (step == 0) return rel;
    const int taken = (exit0 - to_exit) + (span - events);
    return std::clamp(rel + step * taken, 0, n - 1);
  }
  /// Steps once; updates the slot; false when the walk left the window.
  bool advance(std::int64_t& slot) {
    slot += delta;
    t_max += t_delta;
    return --events != 0 || on_event(slot);
  }
  bool on_event(std::int64_t& slot) {
    to_exit -= span;
    to_wrap -= span;
    if (to_exit == 0) return false;
    slot += wrap;  // to_wrap == 0: the ring index went from one end to the other
    to_wrap = n;
    events = span = std::min(to_exit, to_wrap);
    return true;
  }
};

/// Where every ray of a scan starts: the origin's voxel, and for each axis and each direction
/// of travel along it the walk's start state (computed once per scan: a ray only picks its three
/// and sets the parameters that depend on its direction).
struct RayStart {
  Eigen::Vector3d o;  ///< origin in voxel units
  std::array<int, 3> cur, rel, ring;
  std::int64_t slot = 0;  ///< slot of the origin's voxel
  bool inside = false;
  /// axis_walk[a][k]: axis a stepping −1, 0, +1 for k = 0, 1, 2. Its t_max holds the distance
  /// (in voxels) from the origin to the first boundary crossed, which the ray multiplies by its
  /// t_delta; infinite t_delta times 1.0 for an axis that does not step.
  std::array<std::array<AxisWalk, 3>, 3> axis_walk{};

  RayStart(const WindowGeometry& w, const Eigen::Vector3d& origin_W)
      : o(origin_W / w.voxel_size_m), cur{}, rel{}, ring{} {
    inside = true;
    const int strides[3] = {1, w.dims[0], w.dims[0] * w.dims[1]};
    for (int a = 0; a < 3; ++a) {
      cur[a] = static_cast<int>(std::floor(o[a]));
      rel[a] = cur[a] - w.min[a];
      inside = inside && static_cast<unsigned>(rel[a]) < static_cast<unsigned>(w.dims[a]);
      ring[a] = wrap(cur[a], w.dims[a]);
      for (int k = 0; k < 3; ++k) {
        AxisWalk& walk = axis_walk[a][k];
        walk.init(rel[a], ring[a], k - 1, w.dims[a], strides[a]);
        walk.t_max = k == 2 ? cur[a] + 1 - o[a] : (k == 0 ? o[a] - cur[a] : 1.0);
      }
    }
    slot = (static_cast<std::int64_t>(ring[2]) * w.dims[1] + ring[1]) * w.dims[0] + ring[0];
  }
};

/// The start of a ray's walk to `end_W` (world frame): each axis's state for the ray's direction
/// along it, picked by index, not by branch (the signs of a scan's rays are as good as random),
/// and the number of steps to the end point's voxel (with `moved`: those along each axis).
[[gnu::always_inline]] inline void begin_walk(const WindowGeometry& w, const RayStart& start,
                                              const Eigen::Vector3d& end_W, AxisWalk& x,
                                              AxisWalk& y, AxisWalk& z, std::int64_t& steps,
                                              int* moved = nullptr) {
  const Eigen::Vector3d e = end_W / w.voxel_size_m;
  const Eigen::Vector3d d = e - start.o;
  steps = 0;
  const auto axis = [&](int a) {
    const int m = std::abs(static_cast<int>(floor_to_int(e[a])) - start.cur[a]);
    if (moved != nullptr) moved[a] = m;
    steps += m;
    AxisWalk k = start.axis_walk[a][static_cast<int>(d[a] > 0) - static_cast<int>(d[a] < 0) + 1];
    k.t_delta = 1.0 / std::abs(d[a]);  // the same value as ±1.0 / d; infinite when d is 0
    k.t_max *= k.t_delta;
    return k;
  };
  x = axis(0);
  y = axis(1);
  z = axis(2);
}

/// Marks one voxel in a ray task's marks.
template <bool kFlagWords>
[[gnu::always_inline]] inline void mark_voxel(std::uint64_t* bits, std::uint64_t* dirty,
                                              std::int64_t s) {
  bits[s >> 6] |= std::uint64_t{1} << (s & 63);
  if constexpr (kFlagWords) dirty[s >> (6 + kBlockShift)] |= std::uint64_t{1} << ((s >> 6) & 63);
}

/// Grows `box` by a walk that has ended (every axis moves one way, so the voxels marked span the
/// start and end of the walk). Large windows flag words instead: the apply pass does not read
/// the box.
template <bool kFlagWords>
void add_walk_box(const RayStart& start, const AxisWalk& x, const AxisWalk& y, const AxisWalk& z,
                  MarkBox& box) {
  if constexpr (kFlagWords) return;
  box.add(0, start.rel[0], x.end_rel(start.rel[0]));
  box.add(1, start.rel[1], y.end_rel(start.rel[1]));
  box.add(2, start.rel[2], z.end_rel(start.rel[2]));
}

/// Runs a walk from any point of it (`remaining` of its `steps` steps left, at `slot`) to its
/// end; returns its voxel visits in all.
template <bool kFlagWords>
[[gnu::always_inline]] inline std::uint64_t finish_walk(const RayStart& start, AxisWalk x,
                                                        AxisWalk y, AxisWalk z, std::int64_t slot,
                                                        std::int64_t remaining, std::int64_t steps,
                                                        bool include_end, FreeMarks marks,
                                                        MarkBox& box) {
  // Scalars the loop keeps in registers (the marks too: a byte store may alias anything, so
  // they are not read through a reference); ties go to the later axis (x, then y, then z).
  std::uint64_t* const bits = marks.bits;
  std::uint64_t* const dirty = marks.dirty;
  for (; remaining > 0; --remaining) {
    mark_voxel<kFlagWords>(bits, dirty, slot);
    bool inside;  // NOLINT(cppcoreguidelines-init-variables): every branch sets it
    if (x.t_max < y.t_max) {
      inside = x.t_max < z.t_max ? x.advance(slot) : z.advance(slot);
    } else {
      inside = y.t_max < z.t_max ? y.advance(slot) : z.advance(slot);
    }
    if (!inside) {
      add_walk_box<kFlagWords>(start, x, y, z, box);
      return static_cast<std::uint64_t>(steps - remaining + 1);
    }
  }
  if (steps > 0 || include_end) add_walk_box<kFlagWords>(start, x, y, z, box);
  if (!include_end) return static_cast<std::uint64_t>(steps);
  mark_voxel<kFlagWords>(bits, dirty, slot);
  return static_cast<std::uint64_t>(steps + 1);
}

/// One ray's walk from the scan's origin to `end_W`; returns its voxel visits.
template <bool kFlagWords>
std::uint64_t traverse(const WindowGeometry& w, const RayStart& start, const Eigen::Vector3d& end_W,
                       bool include_end, FreeMarks marks, MarkBox& box) {
  if (!start.inside) return 0;
  AxisWalk x, y, z;  // NOLINT(cppcoreguidelines-pro-type-member-init): begin_walk sets them
  std::int64_t steps = 0;
  begin_walk(w, start, end_W, x, y, z, steps);
  return finish_walk<kFlagWords>(start, x, y, z, start.slot, steps, steps, include_end, marks, box);
}

}  // namespace tarmac::core::occupancy
