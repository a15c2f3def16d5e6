#pragma once
/// @file The TSDF's ray walk: Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray
/// Tracing" (Eurographics 1987), over the segment of a ray that meets the truncation band. Not
/// the occupancy walk (occupancy/ray_walk.hpp): that one counts whole voxels from the sensor's to
/// the return's and steps through the window's ring-buffer slots; this one walks a parameter
/// interval in world coordinates and needs each voxel's centre for its signed distance. Kept
/// apart from the integrator so that tarmac-bench --walk-compare can time it against OpenVDB's
/// DDA on the same rays. Internal to core (and that benchmark).

#include <cmath>
#include <cstddef>

#include <Eigen/Core>

namespace tarmac::core {

/// Every voxel of the lattice [i·v, (i+1)·v) the segment o + t·dir, t in [t0, t1], passes
/// through, in order (|dir| = 1). For each, the projective signed distance r − |c − o| of its
/// centre c; `emit(ix, iy, iz, sdf)` is called for those within the band [−trunc, +trunc]
/// (kCarve: in front of the band, clamped to +trunc, so every voxel from the sensor on).
/// The centre offset c − o is kept per axis and moved by ±v on each step (one add instead of a
/// convert, multiply and two adds). Needs |o + t0·dir| / v < 2^23 (the integrator checks).
/// @return the voxels emitted.
template <bool kCarve, typename Emit>
[[gnu::always_inline]] inline std::size_t walk_band(const Eigen::Vector3d& o,
                                                    const Eigen::Vector3d& dir, double range,
                                                    double t0, double t1, double v, double trunc,
                                                    Emit emit) {
  const Eigen::Vector3d q0 = (o + t0 * dir) / v;  // voxel units
  // floor() inline (without SSE4.1 std::floor is a libm call); exact for |q0| < 2^23.
  Eigen::Vector3i idx;
  for (int a = 0; a < 3; ++a) {
    idx[a] = static_cast<int>(q0[a]);
    idx[a] -= q0[a] < static_cast<double>(idx[a]) ? 1 : 0;
  }
  int step[3];
  double t_max[3], t_delta[3];
  // A huge finite value for axes the ray does not cross (0 · kNever must stay 0 below).
  constexpr double kNever = 1e300;
  for (int a = 0; a < 3; ++a) {
    if (dir[a] > 0.0) {
      step[a] = 1;
      t_delta[a] = v / dir[a];
      t_max[a] = t0 + (idx[a] + 1 - q0[a]) * t_delta[a];
    } else if (dir[a] < 0.0) {
      step[a] = -1;
      t_delta[a] = -v / dir[a];
      t_max[a] = t0 + (q0[a] - idx[a]) * t_delta[a];
    } else {
      step[a] = 0;
      t_delta[a] = 0.0;
      t_max[a] = kNever;
    }
  }
  // Traversal state in registers; the axis of the nearest boundary is chosen without branches
  // (a branch there mispredicts about half of the time).
  int ix = idx.x(), iy = idx.y(), iz = idx.z();
  double tx = t_max[0], ty = t_max[1], tz = t_max[2];
  const double half = 0.5 * v;
  double cx = ix * v + half - o.x(), cy = iy * v + half - o.y(), cz = iz * v + half - o.z();
  const double vx = step[0] * v, vy = step[1] * v, vz = step[2] * v;
  std::size_t written = 0;
  while (true) {
    double sdf = range - std::sqrt(cx * cx + cy * cy + cz * cz);
    if (kCarve && sdf > trunc) sdf = trunc;
    if (sdf <= trunc && sdf >= -trunc) {
      emit(ix, iy, iz, static_cast<float>(sdf));
      ++written;
    }
    const bool xy = tx < ty, xz = tx < tz, yz = ty < tz;
    const bool bx = xy & xz, by = !xy & yz, bz = !bx & !by;
    const double t_next = bx ? tx : (by ? ty : tz);
    if (t_next > t1) break;
    ix += bx ? step[0] : 0;
    iy += by ? step[1] : 0;
    iz += bz ? step[2] : 0;
    tx += bx ? t_delta[0] : 0.0;
    ty += by ? t_delta[1] : 0.0;
    tz += bz ? t_delta[2] : 0.0;
    cx += bx ? vx : 0.0;
    cy += by ? vy : 0.0;
    cz += bz ? vz : 0.0;
  }
  return written;
}

}  // namespace tarmac::core
