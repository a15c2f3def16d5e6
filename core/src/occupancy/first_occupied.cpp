/// @file OccupancyMap::first_occupied: the walk that ends a beam without return at the first
/// voxel the map holds occupied (Mapper), and the brick flags that let it cross empty space
/// many voxels at a time.
///
/// The walk is Amanatides & Woo's, with each boundary's crossing time computed from the
/// boundary's index, (i·voxel − origin) / direction, never accumulated: the times, and so the
/// voxels visited, depend only on the voxel the walk stands in. That lets it jump across a box
/// of bricks that holds nothing occupied and land in exactly the state the voxel-by-voxel walk
/// would reach, so the flags change how fast it goes, never what it returns.
///
/// Most beams without return need no walk at all: the same flags draw the sky round the sensor
/// (OccupancyMap::sky_horizon), and a beam that rises above it would find nothing.

#include <algorithm>
#include <cmath>
#include <limits>

#include "tarmac/core/occupancy_map.hpp"
#include "window.hpp"

namespace tarmac::core {
namespace {

using occupancy::floor_to_int;
using occupancy::wrap;

constexpr double kNone = std::numeric_limits<double>::infinity();
/// The farthest a brick's empty surroundings are counted (brick_skip_), in bricks.
constexpr int kMaxBrickSkip = 15;  // fits brick_skip_'s bytes

/// The walk's state: the voxel (world and window-relative, ring coordinates) and, per axis, the
/// crossing time of the next boundary ahead.
struct Walk {
  Eigen::Vector3d origin;
  double voxel = 0.0;
  double inv_voxel = 0.0;
  int step[3] = {0, 0, 0};
  double dir[3] = {0.0, 0.0, 0.0};
  double inv_dir[3] = {0.0, 0.0, 0.0};
  int v[3] = {0, 0, 0};
  int rel[3] = {0, 0, 0};
  int ring[3] = {0, 0, 0};
  double t_next[3] = {0.0, 0.0, 0.0};

  /// Crossing time of the j-th boundary ahead along `a` (j = 1: the next); j ≥ 1. Always this
  /// expression of the boundary's index, so that equal boundaries give equal times.
  [[nodiscard]] double t_ahead(int a, int j) const {
    const int i = step[a] > 0 ? v[a] + j : v[a] - j + 1;  // the boundary's world index
    return (static_cast<double>(i) * voxel - origin[a]) * inv_dir[a];
  }
  /// The axis whose crossing comes first; ties go to the lowest axis (the order every walk of
  /// the same ray takes them in).
  [[nodiscard]] static int first_of(const double (&t)[3]) {
    int a = 0;
    if (t[1] < t[a]) a = 1;
    if (t[2] < t[a]) a = 2;
    return a;
  }
  /// Boundaries ahead along `b` that the voxel-by-voxel walk crosses before the crossing at
  /// `t` on axis `a`: earlier, or at the same time on a lower axis. At most `limit`. `after`
  /// gets the crossing time of the boundary past those (the next one once they are crossed).
  [[nodiscard]] int crossed_before(int b, double t, int a, int limit, double& after) const {
    const auto before = [&](double tb) { return tb < t || (tb == t && b < a); };
    // A guess from where the ray is at t, then settled on the crossing times themselves (any
    // guess in [0, limit] settles to the same count: the times grow with j).
    const std::int64_t at = floor_to_int((origin[b] + t * dir[b]) * inv_voxel);
    const std::int64_t guess = step[b] > 0 ? at - v[b] : v[b] - at;
    int j = static_cast<int>(std::clamp<std::int64_t>(guess, 0, limit));
    after = t_ahead(b, j + 1);
    while (j < limit && before(after)) after = t_ahead(b, ++j + 1);
    while (j > 0) {
      const double tj = t_ahead(b, j);
      if (before(tj)) break;
      after = tj;
      --j;
    }
    return j;
  }
  /// Moves `n` ≥ 1 voxels along `a`, where the next boundary's crossing is `t_after` (t_ahead(a,
  /// n + 1) before the move); false when that leaves the window (`dims`).
  bool move(int a, int n, double t_after, const Eigen::Vector3i& dims) {
    const int d = step[a] * n;
    v[a] += d;
    rel[a] += d;
    if (rel[a] < 0 || rel[a] >= dims[a]) return false;
    // Inside the window after the move, so |d| < dims[a]: one fold brings the ring back.
    const int r = ring[a] + d;
    ring[a] = r < 0 ? r + dims[a] : (r >= dims[a] ? r - dims[a] : r);
    t_next[a] = t_after;
    return true;
  }
};

}  // namespace

double OccupancyMap::first_occupied(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                                    double max_t) const {
  return first_occupied(origin_W, voxel_of(origin_W), dir_W, max_t);
}

double OccupancyMap::first_occupied(const Eigen::Vector3d& origin_W, const VoxelIndex& v0,
                                    const Eigen::Vector3d& dir_W, double max_t) const {
  if (!in_window(v0)) return kNone;
  constexpr int kBrick = 1 << kBrickShift;
  Walk w;
  w.origin = origin_W;
  w.voxel = params_.voxel_size_m;
  w.inv_voxel = 1.0 / params_.voxel_size_m;
  for (int a = 0; a < 3; ++a) {
    w.step[a] = dir_W[a] > 0.0 ? 1 : (dir_W[a] < 0.0 ? -1 : 0);
    w.dir[a] = dir_W[a];
    w.inv_dir[a] = w.step[a] == 0 ? 0.0 : 1.0 / dir_W[a];
    w.v[a] = v0[a];
    w.rel[a] = v0[a] - min_[a];
    w.ring[a] = wrap(v0[a], dims_[a]);
    w.t_next[a] = w.step[a] == 0 ? kNone : w.t_ahead(a, 1);
  }
  // The thinnest brick across x and y (the last of a row is thinner when the window is not a
  // multiple of 8): what each brick of empty surroundings is counted as.
  int thinnest = kBrick;
  for (int a = 0; a < 2; ++a) {
    if (dims_[a] % kBrick != 0) thinnest = std::min(thinnest, dims_[a] % kBrick);
  }
  const int thinnest_z = dims_.z() % kBrick != 0 ? dims_.z() % kBrick : kBrick;
  const std::size_t nx = static_cast<std::size_t>(dims_.x());
  const std::size_t ny = static_cast<std::size_t>(dims_.y());
  bool at_origin = true;  // the origin's own voxel is not looked at
  double t_entry = 0.0;   // when the walk entered the voxel it stands in
  for (;;) {
    const std::size_t brick = brick_of_ring(w.ring[0], w.ring[1], w.ring[2]);
    const int skip = brick_skip_[brick];
    if (skip > 0) {
      // Nothing occupied in this brick, nor in the skip − 1 bricks round it in x and y, in its
      // layer of bricks and in the run of layers ahead whose skip there is at least as large:
      // to the voxel past that box. Along each axis, the voxels to its side ahead (ring
      // coordinates; the ring's end is a brick's end too; each brick counted as the thinnest).
      int to_exit[3] = {0, 0, 0};
      double t_exit_of[3] = {kNone, kNone, kNone};
      for (int a = 0; a < 3; ++a) {
        if (w.step[a] == 0) continue;
        const int lo = (w.ring[a] >> kBrickShift) << kBrickShift;
        to_exit[a] =
            w.step[a] > 0 ? std::min(lo + kBrick, dims_[a]) - w.ring[a] : w.ring[a] - lo + 1;
        if (a < 2) to_exit[a] += (skip - 1) * thinnest;
        if (a == 2) {
          to_exit[a] +=
              (w.step[a] > 0 ? brick_run_up_[brick] : brick_run_down_[brick]) * thinnest_z;
        }
        t_exit_of[a] = w.t_ahead(a, to_exit[a]);
      }
      const int exit_axis = Walk::first_of(t_exit_of);
      const double t_exit = t_exit_of[exit_axis];
      if (!(t_exit < max_t)) return kNone;
      int crossed[3] = {0, 0, 0};
      double after[3] = {kNone, kNone, kNone};
      for (int b = 0; b < 3; ++b) {
        if (w.step[b] == 0) continue;
        if (b == exit_axis) {
          crossed[b] = to_exit[b];
          after[b] = w.t_ahead(b, to_exit[b] + 1);
        } else {
          crossed[b] = w.crossed_before(b, t_exit, exit_axis, to_exit[b] - 1, after[b]);
        }
      }
      for (int a = 0; a < 3; ++a) {
        if (crossed[a] == 0) continue;
        if (!w.move(a, crossed[a], after[a], dims_)) return kNone;  // a box: it does not come back
      }
      t_entry = t_exit;
      at_origin = false;
      continue;
    }
    if (!at_origin) {
      const std::size_t s =
          (static_cast<std::size_t>(w.ring[2]) * ny + static_cast<std::size_t>(w.ring[1])) * nx +
          static_cast<std::size_t>(w.ring[0]);
      if (log_odds_[s] > 0.0f) return t_entry;  // occupied (unknown is negative)
    }
    const int a = Walk::first_of(w.t_next);
    t_entry = w.t_next[a];
    if (!(t_entry < max_t)) return kNone;
    if (!w.move(a, 1, w.t_ahead(a, 2), dims_)) return kNone;
    at_origin = false;
  }
}

double SkyHorizon::turn(double x, double y) {
  // The "diamond angle": 0 along +x, 1 along +y, 2 along -x, 3 along -y, 4 round again.
  if (y >= 0.0) return x >= 0.0 ? y / (x + y) : 1.0 - x / (y - x);
  return x < 0.0 ? 2.0 - y / (-x - y) : 3.0 + x / (x - y);
}

int SkyHorizon::sector(double turn) {
  return std::min(kSectors - 1, static_cast<int>(turn * (kSectors / 4.0)));
}

bool SkyHorizon::clears(const Eigen::Vector3d& dir_W) const {
  if (overhead_ || !(dir_W.z() >= 0.0)) return false;
  const double x = dir_W.x(), y = dir_W.y(), z = dir_W.z();
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) return false;
  if (x == 0.0 && y == 0.0) return true;  // straight up: its own column, nothing flagged over it
  const double s = slope_[static_cast<std::size_t>(sector(turn(x, y)))];
  // z > s · run, squared (both sides ≥ 0 when s ≥ 0); the boxes' margin of a voxel dwarfs
  // the rounding.
  return s < 0.0 || z * z > s * s * (x * x + y * y);
}

void OccupancyMap::sky_horizon(const Eigen::Vector3d& origin_W, SkyHorizon& sky) const {
  // Each flagged brick whose occupied voxels reach above the origin, as the world boxes its
  // ring voxels stand for (a brick across the ring's seam is two pieces along that axis), from
  // the brick's x-y extent and its highest occupied voxel, grown by a voxel each way against
  // rounding in the walk. A beam that does not descend is at the box's height or below only
  // while nearer than the box's nearest horizontal distance, so the box's top over that
  // distance bounds the slope of the beams that can touch it; the box's sectors (those of its
  // corners, and one more each side) take the largest.
  sky.slope_.fill(-1.0);
  sky.overhead_ = false;
  constexpr int kBrick = 1 << kBrickShift;
  constexpr int kN = SkyHorizon::kSectors;
  const double v = params_.voxel_size_m;
  const Eigen::Vector3d& o = origin_W;
  const std::array<int, 3> seam = ring_origin();  // the ring index of the window's lowest voxel
  // World voxel intervals [lo, hi) of ring interval [r0, r1) along `a`: one or two pieces.
  const auto world_pieces = [&](int a, int r0, int r1, int(&lo)[2], int(&hi)[2]) {
    const auto world = [&](int r) { return world_of_ring(a, r, seam[a]); };
    if (r0 < seam[a] && seam[a] < r1) {
      lo[0] = world(r0), hi[0] = lo[0] + (seam[a] - r0);
      lo[1] = min_[a], hi[1] = min_[a] + (r1 - seam[a]);
      return 2;
    }
    lo[0] = world(r0), hi[0] = lo[0] + (r1 - r0);
    return 1;
  };
  const auto ring_end = [&](int a, int b) { return std::min((b + 1) * kBrick, dims_[a]); };
  const auto nx = static_cast<std::size_t>(dims_.x()), ny = static_cast<std::size_t>(dims_.y());
  // World z index of the brick's highest voxel reading occupied; INT_MIN when none does (the
  // flags may be stale).
  const auto highest_occupied = [&](int bx, int by, int bz) {
    int best = std::numeric_limits<int>::min();
    for (int rz = bz * kBrick; rz < ring_end(2, bz); ++rz) {
      const int wz = world_of_ring(2, rz, seam[2]);
      bool any = false;
      for (int ry = by * kBrick; ry < ring_end(1, by) && !any && wz > best; ++ry) {
        const float* line = log_odds_.data() + (static_cast<std::size_t>(rz) * ny + ry) * nx;
        for (int rx = bx * kBrick; rx < ring_end(0, bx); ++rx) any = any || line[rx] > 0.0f;
      }
      if (any) best = wz;
    }
    return best;
  };
  // Raises the horizon over the box [x0, x1] × [y0, y1] (relative to the origin) to `top` over
  // its nearest horizontal distance; false when the box stands over the origin's column.
  const auto raise = [&](double x0, double x1, double y0, double y1, double top) {
    const double near = std::hypot(std::max({x0, -x1, 0.0}), std::max({y0, -y1, 0.0}));
    if (!(near > 0.0)) return false;
    const double slope = top / near;
    double t[4] = {SkyHorizon::turn(x0, y0), SkyHorizon::turn(x1, y0), SkyHorizon::turn(x0, y1),
                   SkyHorizon::turn(x1, y1)};
    // Not round the origin, so the box spans less than half a turn (2): a wider span of the
    // raw values means that it crosses turn 0.
    if (*std::max_element(t, t + 4) - *std::min_element(t, t + 4) > 2.0) {
      for (double& x : t) x += x < 2.0 ? 4.0 : 0.0;
    }
    const int first = static_cast<int>(std::floor(*std::min_element(t, t + 4) * (kN / 4.0))) - 1;
    const int last = static_cast<int>(std::floor(*std::max_element(t, t + 4) * (kN / 4.0))) + 1;
    for (int k = first; k <= last; ++k) {
      double& s = sky.slope_[static_cast<std::size_t>(wrap(k, kN))];
      s = std::max(s, slope);
    }
    return true;
  };
  for (int bz = 0; bz < bricks_.z(); ++bz) {
    int zlo[2], zhi[2];
    const int nz = world_pieces(2, bz * kBrick, ring_end(2, bz), zlo, zhi);
    const int layer_top = nz == 2 ? std::max(zhi[0], zhi[1]) : zhi[0];  // exclusive
    if (!((layer_top + 1) * v - o.z() > 0.0)) continue;  // the layer lies below the origin
    for (int by = 0; by < bricks_.y(); ++by) {
      for (int bx = 0; bx < bricks_.x(); ++bx) {
        if (!brick_flagged(brick_of_ring(bx * kBrick, by * kBrick, bz * kBrick))) continue;
        const int top_z = highest_occupied(bx, by, bz);
        if (top_z == std::numeric_limits<int>::min()) continue;
        const double top = (top_z + 2) * v - o.z();  // the voxel's top, and a voxel's margin
        if (!(top > 0.0)) continue;
        int xlo[2], xhi[2], ylo[2], yhi[2];
        const int pieces_x = world_pieces(0, bx * kBrick, ring_end(0, bx), xlo, xhi);
        const int pieces_y = world_pieces(1, by * kBrick, ring_end(1, by), ylo, yhi);
        for (int i = 0; i < pieces_x; ++i) {
          for (int j = 0; j < pieces_y; ++j) {
            if (!raise((xlo[i] - 1) * v - o.x(), (xhi[i] + 1) * v - o.x(), (ylo[j] - 1) * v - o.y(),
                       (yhi[j] + 1) * v - o.y(), top)) {
              sky.overhead_ = true;  // over the origin's column: every rising beam may meet it
              return;
            }
          }
        }
      }
    }
  }
}

void OccupancyMap::flag_brick(std::size_t slot) {
  const auto nx = static_cast<std::size_t>(dims_.x()), ny = static_cast<std::size_t>(dims_.y());
  const auto rx = static_cast<int>(slot % nx);
  const auto ry = static_cast<int>((slot / nx) % ny);
  const auto rz = static_cast<int>(slot / (nx * ny));
  const std::size_t b = brick_of_ring(rx, ry, rz);
  const std::uint64_t bit = std::uint64_t{1} << (b & 63);
  if ((brick_bits_[b >> 6] & bit) != 0) return;
  brick_bits_[b >> 6] |= bit;
  bricks_dirty_ = true;
}

void OccupancyMap::refresh_bricks(int rows) {
  const int n_rows = bricks_.y() * bricks_.z();
  const auto nx = static_cast<std::size_t>(dims_.x()), ny = static_cast<std::size_t>(dims_.y());
  constexpr int kBrick = 1 << kBrickShift;
  for (int r = 0; r < std::min(rows, n_rows); ++r) {
    const int row = brick_refresh_row_;
    brick_refresh_row_ = (brick_refresh_row_ + 1) % n_rows;
    const int by = row % bricks_.y(), bz = row / bricks_.y();
    for (int bx = 0; bx < bricks_.x(); ++bx) {
      bool occupied = false;
      const int x_end = std::min((bx + 1) * kBrick, dims_.x());
      for (int z = bz * kBrick; z < std::min((bz + 1) * kBrick, dims_.z()) && !occupied; ++z) {
        for (int y = by * kBrick; y < std::min((by + 1) * kBrick, dims_.y()); ++y) {
          const float* line = log_odds_.data() +
                              (static_cast<std::size_t>(z) * ny + static_cast<std::size_t>(y)) * nx;
          for (int x = bx * kBrick; x < x_end; ++x) occupied |= line[x] > 0.0f;
        }
      }
      const std::size_t b = brick_of_ring(bx * kBrick, by * kBrick, bz * kBrick);
      const std::uint64_t bit = std::uint64_t{1} << (b & 63);
      const std::uint64_t word =
          occupied ? (brick_bits_[b >> 6] | bit) : (brick_bits_[b >> 6] & ~bit);
      bricks_dirty_ = bricks_dirty_ || word != brick_bits_[b >> 6];  // the skips follow a change
      brick_bits_[b >> 6] = word;
    }
  }
}

void OccupancyMap::update_brick_skips() {
  // Chebyshev distance in x and y to the nearest flagged brick of the same layer, round the
  // ring, capped: along x (two sweeps round each row), then the min over y of max(|dy|, that).
  const int nbx = bricks_.x(), nby = bricks_.y(), nbz = bricks_.z();
  const int cap = kMaxBrickSkip;
  std::vector<std::uint8_t>& along_x = brick_row_scratch_;
  along_x.assign(brick_skip_.size(), 0);
  for (int bz = 0; bz < nbz; ++bz) {
    for (int by = 0; by < nby; ++by) {
      const std::size_t row = (static_cast<std::size_t>(bz) * nby + by) * nbx;
      const auto flagged = [&](int bx) {
        return brick_flagged(row + static_cast<std::size_t>(bx));
      };
      int d = cap;
      for (int k = 0; k < 2 * nbx; ++k) {  // forward, twice round: the wrap's distances too
        const int bx = k % nbx;
        d = flagged(bx) ? 0 : std::min(d + 1, cap);
        if (k >= nbx) along_x[row + bx] = static_cast<std::uint8_t>(d);
      }
      d = cap;
      for (int k = 2 * nbx - 1; k >= 0; --k) {
        const int bx = k % nbx;
        d = flagged(bx) ? 0 : std::min(d + 1, cap);
        if (k < nbx) along_x[row + bx] = std::min(along_x[row + bx], static_cast<std::uint8_t>(d));
      }
    }
  }
  const int reach = std::min(cap, nby / 2);
  for (int bz = 0; bz < nbz; ++bz) {
    for (int by = 0; by < nby; ++by) {
      for (int bx = 0; bx < nbx; ++bx) {
        int best = along_x[(static_cast<std::size_t>(bz) * nby + by) * nbx + bx];
        for (int dy = 1; dy <= reach && dy < best; ++dy) {
          for (const int y : {wrap(by + dy, nby), wrap(by - dy, nby)}) {
            const int here = along_x[(static_cast<std::size_t>(bz) * nby + y) * nbx + bx];
            best = std::min(best, std::max(dy, here));
          }
        }
        brick_skip_[(static_cast<std::size_t>(bz) * nby + by) * nbx + bx] =
            static_cast<std::uint8_t>(best);
      }
    }
  }
  // The runs of layers along z (round the ring, at most nbz - 1 layers each way).
  const std::size_t layer = static_cast<std::size_t>(nbx) * static_cast<std::size_t>(nby);
  for (std::size_t c = 0; c < layer; ++c) {
    for (int bz = 0; bz < nbz; ++bz) {
      const std::size_t b = static_cast<std::size_t>(bz) * layer + c;
      const int own = brick_skip_[b];
      int up = 0, down = 0;
      if (own > 0) {
        while (up < nbz - 1 &&
               brick_skip_[static_cast<std::size_t>(wrap(bz + up + 1, nbz)) * layer + c] >= own) {
          ++up;
        }
        while (down < nbz - 1 &&
               brick_skip_[static_cast<std::size_t>(wrap(bz - down - 1, nbz)) * layer + c] >= own) {
          ++down;
        }
      }
      brick_run_up_[b] = static_cast<std::uint8_t>(up);
      brick_run_down_[b] = static_cast<std::uint8_t>(down);
    }
  }
  bricks_dirty_ = false;
}

}  // namespace tarmac::core
