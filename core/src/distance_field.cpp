#include "tarmac/core/distance_field.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr std::size_t kTasksPerPass = 16;
/// Lines along y (3D middle pass) are processed this many adjacent ones at a time: their cells
/// are contiguous in memory, so the gathers and scatters read and write whole cache lines.
constexpr int kBlock = 16;
/// Offset (cell − site, cells) meaning "no site on this line"; larger than any real offset.
constexpr std::int32_t kNone = 1 << 14;

/// Bit of a CellState that makes it a site: occupied (1), or occupied and unknown (1 | 2).
std::uint8_t site_mask(UnknownPolicy policy) {
  return policy == UnknownPolicy::kUnknownIsOccupied ? 3 : 1;
}

/// One parabola of a lower envelope: its root v, F = f[v] + v², and its left breakpoint as the
/// fraction zn / (2·zd) (zd > 0; the first parabola's is −inf and never read).
struct Parabola {
  std::int64_t F, zn, zd;
  std::int64_t v;
};

/// Lower envelope (FH Algorithm 1) of the parabolas q ↦ (q − p)² + f[p] over the p with
/// f[p] >= 0 (f[p] < 0: no site), in exact integer arithmetic. The breakpoint between
/// parabolas p < q is z = (F_q − F_p) / (2 (q − p)); breakpoints are kept as fractions and
/// compared by cross-multiplying, so no division. A new parabola replaces the last one when it
/// is as low at that one's left breakpoint (ties go to the parabola added last). Returns the
/// number of parabolas, followed in `e` by a sentinel whose breakpoint is never passed.
/// @pre e holds n + 1 entries.
int lower_envelope(const std::int32_t* __restrict f, int n, Parabola* __restrict e) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] < 0) continue;
    const std::int64_t Fq = f[q] + std::int64_t{q} * q;
    // s(q, v_k) <= z_k  ⟺  (F_q − F_k)·zd_k <= zn_k·(q − v_k); the first parabola stays.
    while (k > 0 && (Fq - e[k].F) * e[k].zd <= e[k].zn * (q - e[k].v)) --k;
    if (k >= 0) {
      e[k + 1] = Parabola{Fq, Fq - e[k].F, q - e[k].v, q};
    } else {
      e[0] = Parabola{Fq, 0, 1, q};
    }
    ++k;
  }
  e[k + 1] = Parabola{0, 1, 0, 0};  // 1 < 2·q·0 never holds
  return k + 1;
}

/// For each q, the root of the envelope's parabola that is lowest at q: the last one whose
/// breakpoint z lies strictly below q (a tie at q stays with the earlier parabola).
/// Calls emit(q, root) in order of q. @pre the envelope is not empty.
template <typename Emit>
void scan_envelope(int n, const Parabola* __restrict e, Emit&& emit) {
  int j = 0;
  for (int q = 0; q < n; ++q) {
    // z_{j+1} < q  ⟺  zn < 2·q·zd
    while (e[j + 1].zn < 2 * std::int64_t{q} * e[j + 1].zd) ++j;
    emit(q, static_cast<int>(e[j].v));
  }
}

}  // namespace

void compute_distance_field(const std::vector<CellState>& states, const Eigen::Vector3i& dims,
                            double cell_size_m, UnknownPolicy policy, DistanceField& out,
                            DistanceFieldScratch& s, TaskRunner& runner) {
  const int nx = dims.x(), ny = dims.y(), nz = dims.z();
  const std::size_t n = static_cast<std::size_t>(nx) * ny * nz;
  TARMAC_ASSERT(states.size() == n, "states must match dims");
  TARMAC_ASSERT(nx < kNone && ny < kNone && nz < kNone, "dims must be below 16384");
  out.dims = dims;
  out.cell_size_m = cell_size_m;
  out.distance_m.resize(n);
  out.gradient_x.resize(n);
  out.gradient_y.resize(n);
  out.gradient_z.resize(n);
  const bool three_d = nz > 1;
  const std::size_t plane = static_cast<std::size_t>(nx) * ny;
  // Per cell, the offset (cell − nearest site so far) along each axis done: off[0] along the
  // first pass's axis (z in 3D, y in 2D), off[1] along y (3D only). The squared distance of a
  // cell after a pass is the sum of the squares of its offsets, so it is never stored.
  s.off[0].resize(n);
  s.off[1].resize(three_d ? n : 0);
  const int longest = std::max({nx, ny, nz});
  const std::size_t line_len = static_cast<std::size_t>(longest) + 1;
  const auto ensure = [&](auto& lines, std::size_t size) {
    lines.resize(kTasksPerPass);
    for (auto& l : lines) l.resize(size);
  };
  ensure(s.line_f, line_len * kBlock);
  ensure(s.line_e, (line_len + 1) * 4);  // Parabola = 4 × int64
  ensure(s.line_a, line_len * kBlock);
  ensure(s.line_b, line_len * kBlock);
  ensure(s.line_c, line_len);
  const std::uint8_t mask = site_mask(policy);
  const bool report_unknown = policy == UnknownPolicy::kReportUnknown;

  // Pass 1, along the outermost axis (z in 3D, y in 2D): the nearest site on each line, by a
  // sweep up and a sweep down that run across the contiguous lanes of a plane (or row) at once.
  // A tie between the site below and the one above goes to the one below.
  {
    const std::size_t lanes = three_d ? plane : static_cast<std::size_t>(nx);
    const int len = three_d ? nz : ny;
    s.lane.resize(lanes);
    // At least 64 lanes per task (a 2D row is few lanes): short lane runs do not vectorise well.
    // Each cell's result is independent of the split.
    const std::size_t tasks = std::clamp<std::size_t>(lanes / 64, 1, kTasksPerPass);
    runner.parallel_for(tasks, [&](std::size_t task) {
      const std::size_t c0 = lanes * task / tasks;
      const std::size_t c1 = lanes * (task + 1) / tasks;
      std::int32_t* __restrict last = s.lane.data();
      for (std::size_t c = c0; c < c1; ++c) last[c] = -kNone;
      for (int p = 0; p < len; ++p) {
        const auto* __restrict st =
            reinterpret_cast<const std::uint8_t*>(states.data()) + p * lanes;
        std::int16_t* __restrict o = s.off[0].data() + p * lanes;
        for (std::size_t c = c0; c < c1; ++c) {
          last[c] = (st[c] & mask) != 0 ? p : last[c];
          o[c] = static_cast<std::int16_t>(std::min(p - last[c], kNone));
        }
      }
      for (std::size_t c = c0; c < c1; ++c) last[c] = len + kNone;  // now "next"
      for (int p = len - 1; p >= 0; --p) {
        const auto* __restrict st =
            reinterpret_cast<const std::uint8_t*>(states.data()) + p * lanes;
        std::int16_t* __restrict o = s.off[0].data() + p * lanes;
        for (std::size_t c = c0; c < c1; ++c) {
          last[c] = (st[c] & mask) != 0 ? p : last[c];
          const std::int32_t down = std::min(last[c] - p, kNone);
          const std::int32_t up = o[c];
          o[c] = static_cast<std::int16_t>(down < up ? -down : up);
        }
      }
    });
  }

  // Pass 2 (3D only), along y: blocks of kBlock adjacent columns of one z plane are gathered,
  // transformed, and scattered back in place (a block's cells are touched by that block only).
  // Each cell takes the y offset to its envelope's root and carries that root's z offset.
  if (three_d) {
    const std::size_t groups_per_plane = (static_cast<std::size_t>(nx) + kBlock - 1) / kBlock;
    const std::size_t groups = groups_per_plane * static_cast<std::size_t>(nz);
    runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
      std::int32_t* f = s.line_f[task].data();
      std::int32_t* a = s.line_a[task].data();  // gathered z offsets
      Parabola* e = reinterpret_cast<Parabola*>(s.line_e[task].data());
      std::int16_t* __restrict off0 = s.off[0].data();
      std::int16_t* __restrict off1 = s.off[1].data();
      const int len = ny;
      const std::size_t stride = static_cast<std::size_t>(nx);
      const std::size_t first = groups * task / kTasksPerPass;
      const std::size_t last = groups * (task + 1) / kTasksPerPass;
      for (std::size_t group = first; group < last; ++group) {
        const std::size_t zplane = group / groups_per_plane;
        const std::size_t start = (group % groups_per_plane) * kBlock;
        const int width = static_cast<int>(std::min<std::size_t>(kBlock, nx - start));
        const std::size_t base = zplane * plane + start;
        for (int q = 0; q < len; ++q) {
          const std::int16_t* o = off0 + base + q * stride;
          for (int b = 0; b < width; ++b) {
            const std::int32_t dz = o[b];
            a[b * len + q] = dz;
            f[b * len + q] = dz == kNone ? -1 : dz * dz;
          }
        }
        for (int b = 0; b < width; ++b) {
          const std::int32_t* fl = f + b * len;
          const std::int32_t* al = a + b * len;
          const std::size_t col = base + b;
          if (lower_envelope(fl, len, e) == 0) {
            for (int q = 0; q < len; ++q) {
              off0[col + q * stride] = kNone;
              off1[col + q * stride] = kNone;
            }
            continue;
          }
          scan_envelope(len, e, [&](int q, int root) {
            off0[col + q * stride] = static_cast<std::int16_t>(al[root]);
            off1[col + q * stride] = static_cast<std::int16_t>(q - root);
          });
        }
      }
    });
  }

  // Last pass, along x (rows are contiguous): the envelope of each row over the squared
  // distances of the passes before, then metres and gradient per cell. Each cell's squared
  // distance is the exact integer dx² + dy² (+ dz²); its metres are
  // float(sqrt(double(sq)) · cell_size_m) and its gradient (cell − site) / |cell − site|.
  const std::size_t rows = static_cast<std::size_t>(ny) * nz;
  runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
    std::int32_t* f = s.line_f[task].data();
    Parabola* e = reinterpret_cast<Parabola*>(s.line_e[task].data());
    std::int32_t* __restrict ox = s.line_c[task].data();  // per cell: x offset to its site
    std::int32_t* __restrict o0 = s.line_a[task].data();  // carried offset along pass 1's axis
    std::int32_t* __restrict o1 = s.line_b[task].data();  // carried y offset (3D)
    const int width = nx;  // a local copy: stores through the buffers cannot change it
    const std::size_t first = rows * task / kTasksPerPass;
    const std::size_t last = rows * (task + 1) / kTasksPerPass;
    for (std::size_t row = first; row < last; ++row) {
      const std::size_t base = row * static_cast<std::size_t>(nx);
      const std::int16_t* __restrict a0 = s.off[0].data() + base;
      const std::int16_t* __restrict a1 = three_d ? s.off[1].data() + base : nullptr;
      if (three_d) {
        for (int x = 0; x < width; ++x) {
          const std::int32_t u = a0[x], w = a1[x];
          f[x] = u == kNone ? -1 : u * u + w * w;
        }
      } else {
        for (int x = 0; x < width; ++x) {
          const std::int32_t u = a0[x];
          f[x] = u == kNone ? -1 : u * u;
        }
      }
      const auto* __restrict st = reinterpret_cast<const std::uint8_t*>(states.data()) + base;
      float* __restrict dist = out.distance_m.data() + base;
      float* __restrict gx = out.gradient_x.data() + base;
      float* __restrict gy = out.gradient_y.data() + base;
      float* __restrict gz = out.gradient_z.data() + base;
      if (lower_envelope(f, width, e) == 0) {  // no obstacle in the grid
        for (int x = 0; x < width; ++x) {
          const bool unknown =
              report_unknown && st[x] == static_cast<std::uint8_t>(CellState::kUnknown);
          dist[x] = unknown ? std::numeric_limits<float>::quiet_NaN() : kInf;
          gx[x] = gy[x] = gz[x] = 0.0f;
        }
        continue;
      }
      // Branch-free loops so each vectorises: unknown cells get zero offsets (so a zero
      // gradient), then metres and gradients (an obstacle, r = 0, multiplies 0 by 1), then NaN.
      // Written once for both dimensions; the 2D instance drops the third offset (always 0:
      // adding 0² and multiplying 0 by 1/r leave the same bits).
      const std::uint8_t unknown_state =
          report_unknown ? static_cast<std::uint8_t>(CellState::kUnknown) : 0xff;
      const auto finish = [&](auto three_d_tag) {
        constexpr bool k3d = decltype(three_d_tag)::value;
        scan_envelope(width, e, [&](int q, int root) {
          ox[q] = q - root;
          o0[q] = a0[root];
          if constexpr (k3d) o1[q] = a1[root];
        });
        for (int x = 0; x < width; ++x) {
          const std::int32_t keep = -static_cast<std::int32_t>(st[x] != unknown_state);
          ox[x] &= keep;
          o0[x] &= keep;
          if constexpr (k3d) o1[x] &= keep;
        }
        float* __restrict g_pass1 = k3d ? gz : gy;  // gradient along pass 1's axis
        float* __restrict g_y3 = k3d ? gy : gz;     // y in 3D; z (all zero) in 2D
        const double cell = cell_size_m;
        for (int x = 0; x < width; ++x) {
          const double ex = ox[x], e0 = o0[x];
          const double e1 = k3d ? o1[x] : 0.0;
          const double r = std::sqrt(k3d ? ex * ex + e0 * e0 + e1 * e1 : ex * ex + e0 * e0);
          const double inv = 1.0 / (r + (r == 0.0));  // 1 / r; 1 for an obstacle (r = 0)
          dist[x] = static_cast<float>(r * cell);
          gx[x] = static_cast<float>(ex * inv);
          g_pass1[x] = static_cast<float>(e0 * inv);
          g_y3[x] = k3d ? static_cast<float>(e1 * inv) : 0.0f;
        }
      };
      if (three_d) {
        finish(std::true_type{});
      } else {
        finish(std::false_type{});
      }
      if (report_unknown) {
        for (int x = 0; x < width; ++x) {
          dist[x] = st[x] == unknown_state ? std::numeric_limits<float>::quiet_NaN() : dist[x];
        }
      }
    }
  });
}

}  // namespace tarmac::core
