/// @file The ray walks four at a time in AVX2 lanes (see walk_lanes4 below).

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>

#include <immintrin.h>

#include "ray_tasks.hpp"

#if defined(TARMAC_WIDE_WALK)
namespace tarmac::core::occupancy {
namespace {

/// `m ? y : x` per 64-bit lane (m: all ones or all zeros).
__attribute__((target("avx2"), always_inline)) inline __m256i select(__m256i m, __m256i y,
                                                                     __m256i x) {
  return _mm256_castpd_si256(
      _mm256_blendv_pd(_mm256_castsi256_pd(x), _mm256_castsi256_pd(y), _mm256_castsi256_pd(m)));
}

/// One axis's events in the four-lane walk, for the lanes still walking (`walking`): a window
/// exit ends the walk (its lane is set in `exited`); a ring wrap moves the slot back a ring,
/// and the next event comes a ring later or at the exit, as AxisWalk::on_event.
__attribute__((target("avx2"), always_inline)) inline void lanes4_events(
    __m256i walking, __m256i& ev, __m256i& to_exit, __m256i wrap, __m256i n, __m256i& s,
    __m256i& exited) {
  const __m256i zero = _mm256_setzero_si256();
  const __m256i m = _mm256_and_si256(_mm256_cmpgt_epi64(zero, ev), walking);
  const __m256i out = _mm256_and_si256(m, _mm256_cmpeq_epi64(to_exit, zero));
  const __m256i wrapped = _mm256_andnot_si256(out, m);
  s = _mm256_add_epi64(s, _mm256_and_si256(wrapped, wrap));
  const __m256i span = select(_mm256_cmpgt_epi64(to_exit, n), n, to_exit);
  ev = select(wrapped, _mm256_sub_epi64(span, _mm256_set1_epi64x(1)), ev);
  to_exit = select(wrapped, _mm256_sub_epi64(to_exit, span), to_exit);
  exited = _mm256_or_si256(exited, out);
}

/// Walks set up for the four-lane walk (walk_lanes4), a batch at a time, each field in its
/// own array so that four walks load into lanes at once.
struct LaneBatch {
  static constexpr int kSize = 64;
  /// Per axis: parameters and parameter steps; slot steps; steps to the next event (ring wrap
  /// or window exit) − 1; slot correction at a wrap; steps to the exit counted from the
  /// pending event.
  alignas(32) double t[3][kSize], dt[3][kSize];
  alignas(32) std::int64_t delta[3][kSize], ev[3][kSize], wrap[3][kSize], to_exit[3][kSize];
  alignas(32) std::int64_t left[kSize];  ///< voxels to mark − 1 (−1: marks nothing)
  /// The end points of the walks to set up, and whether their end voxel is marked.
  alignas(32) double end[3][kSize];
  alignas(32) std::int64_t inc[kSize];
};

/// Walks [g, g + 4) of one field of a LaneBatch (axis a), in lanes.
__attribute__((target("avx2"), always_inline)) inline __m256d lanes_at(
    int g, const double (*field)[LaneBatch::kSize], int a) {
  return _mm256_load_pd(&field[a][g]);
}
__attribute__((target("avx2"), always_inline)) inline __m256i lanes_at(
    int g, const std::int64_t (*field)[LaneBatch::kSize], int a) {
  return _mm256_load_si256(reinterpret_cast<const __m256i*>(&field[a][g]));
}

/// `neg ? v[0] : pos ? v[2] : v[1]` per lane: a per-scan value of the axis by direction sign.
__attribute__((target("avx2"), always_inline)) inline __m256d by_sign(__m256d neg, __m256d pos,
                                                                      double v0, double v1,
                                                                      double v2) {
  return _mm256_blendv_pd(_mm256_blendv_pd(_mm256_set1_pd(v1), _mm256_set1_pd(v0), neg),
                          _mm256_set1_pd(v2), pos);
}
__attribute__((target("avx2"), always_inline)) inline __m256i by_sign(__m256d neg, __m256d pos,
                                                                      std::int64_t v0,
                                                                      std::int64_t v1,
                                                                      std::int64_t v2) {
  return _mm256_castpd_si256(by_sign(neg, pos, std::bit_cast<double>(v0), std::bit_cast<double>(v1),
                                     std::bit_cast<double>(v2)));
}

/// by_sign's lanes stored at `out` (32-byte aligned).
__attribute__((target("avx2"), always_inline)) inline void store_by_sign(std::int64_t* out,
                                                                         __m256d neg, __m256d pos,
                                                                         std::int64_t v0,
                                                                         std::int64_t v1,
                                                                         std::int64_t v2) {
  _mm256_store_si256(reinterpret_cast<__m256i*>(out), by_sign(neg, pos, v0, v1, v2));
}

/// Walks [k, k + 4) of `b` from their end points: begin_walk's arithmetic in lanes (the same
/// divisions, floors and products, so the same values). Lanes from `valid` on mark nothing.
/// Books the walks' visits and grows `box` by each walk's start and its end voxel one step
/// further along each axis it moves on, clamped to the window (see walk_lanes4).
__attribute__((target("avx2"))) void set_up_lanes4(const WindowGeometry& w, const RayStart& start,
                                                   LaneBatch& b, int k, int valid,
                                                   std::uint64_t& visits, MarkBox& box) {
  const __m256d voxel = _mm256_set1_pd(w.voxel_size_m);
  const __m256d zero = _mm256_setzero_pd();
  const __m256d abs_mask = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
  __m256i steps = _mm256_setzero_si256();
  alignas(16) std::int32_t last[3][4];
  for (int a = 0; a < 3; ++a) {
    const __m256d e = _mm256_div_pd(_mm256_load_pd(&b.end[a][k]), voxel);
    const __m256d d = _mm256_sub_pd(e, _mm256_set1_pd(start.o[a]));
    const __m128i cell = _mm256_cvttpd_epi32(_mm256_round_pd(e, _MM_FROUND_TO_NEG_INF));
    steps = _mm256_add_epi64(
        steps,
        _mm256_cvtepi32_epi64(_mm_abs_epi32(_mm_sub_epi32(cell, _mm_set1_epi32(start.cur[a])))));
    const __m256d neg = _mm256_cmp_pd(d, zero, _CMP_LT_OQ);
    const __m256d pos = _mm256_cmp_pd(d, zero, _CMP_GT_OQ);
    const __m256d dt = _mm256_div_pd(_mm256_set1_pd(1.0), _mm256_and_pd(d, abs_mask));
    const auto& k3 = start.axis_walk[a];
    _mm256_store_pd(&b.dt[a][k], dt);
    _mm256_store_pd(&b.t[a][k],
                    _mm256_mul_pd(by_sign(neg, pos, k3[0].t_max, k3[1].t_max, k3[2].t_max), dt));
    store_by_sign(&b.delta[a][k], neg, pos, k3[0].delta, k3[1].delta, k3[2].delta);
    store_by_sign(&b.ev[a][k], neg, pos, k3[0].events - 1, k3[1].events - 1, k3[2].events - 1);
    store_by_sign(&b.wrap[a][k], neg, pos, k3[0].wrap, k3[1].wrap, k3[2].wrap);
    store_by_sign(&b.to_exit[a][k], neg, pos, k3[0].to_exit - k3[0].span,
                  k3[1].to_exit - k3[1].span, k3[2].to_exit - k3[2].span);
    // The end voxel and one step further, window-relative, clamped.
    const __m128i step = _mm256_cvttpd_epi32(by_sign(neg, pos, -1.0, 0.0, 1.0));
    const __m128i far = _mm_add_epi32(_mm_sub_epi32(cell, _mm_set1_epi32(w.min[a])), step);
    _mm_store_si128(
        reinterpret_cast<__m128i*>(last[a]),
        _mm_min_epi32(_mm_max_epi32(far, _mm_setzero_si128()), _mm_set1_epi32(w.dims[a] - 1)));
  }
  const __m256i left = _mm256_sub_epi64(
      _mm256_add_epi64(steps, _mm256_load_si256(reinterpret_cast<const __m256i*>(&b.inc[k]))),
      _mm256_set1_epi64x(1));
  _mm256_store_si256(reinterpret_cast<__m256i*>(&b.left[k]), left);
  for (int l = 0; l < 4; ++l) {
    std::int64_t& lane_left = b.left[k + l];
    if (l >= valid) lane_left = -1;
    if (lane_left < 0) continue;
    visits += static_cast<std::uint64_t>(lane_left + 1);
    for (int a = 0; a < 3; ++a) box.add(a, start.rel[a], last[a][l]);
  }
}

/// The same walks four at a time in AVX2 lanes (x86-64 processors that have AVX2 but not
/// AVX-512; the caller checks). A lane takes the same steps as the one-at-a-time walk, decided
/// by the same comparisons of the same sums, so the marks are the same bits; the step, one
/// unpredictable branch per visit one at a time, becomes blends.
/// The walks are taken a batch at a time in the task's (direction) order, and four neighbours
/// run in lockstep until the longest has ended: a lane whose walk ended marks nothing (an OR
/// of 0 into word 0) until then. Neighbours in direction mostly end near each other (few lane
/// steps idle); refilling a lane as its walk ends costs more than that without
/// AVX-512's expand-loads, and sorting each batch by length more still. The only branch per step
/// is to a rare path for ring wraps and window exits.
/// The box: each walk adds its start and its end voxel one step further along each axis it
/// moves on (the last steps may cross in another order than exact arithmetic would, by one
/// voxel at most), clamped to the window. A superset of the voxels marked: the apply pass
/// reads the marks inside it, so only its time changes.
template <bool kFlagWords>
__attribute__((target("avx2"))) std::uint64_t walk_lanes4(const WindowGeometry& w,
                                                          const RayStart& start,
                                                          const TaskRays& rays, FreeMarks marks,
                                                          MarkBox& box) {
  if (!start.inside) return 0;
  TaskRayCursor cursor(rays);
  std::uint64_t* const bits = marks.bits;
  std::uint64_t* const dirty = marks.dirty;
  std::uint64_t visits = 0;
  constexpr std::int64_t kNever = std::int64_t{1} << 60;
  LaneBatch batch;
  const __m256i one = _mm256_set1_epi64x(1);
  const __m256i low6 = _mm256_set1_epi64x(63);
  const __m256i zero = _mm256_setzero_si256();
  const __m256i sign = _mm256_set1_epi64x(std::numeric_limits<std::int64_t>::min());
  const __m256i never = _mm256_set1_epi64x(kNever);
  const __m256i nx = _mm256_set1_epi64x(w.dims[0]), ny = _mm256_set1_epi64x(w.dims[1]),
                nz = _mm256_set1_epi64x(w.dims[2]);
  bool more = true;
  while (more) {
    // The cursor is built without AVX, and this processor slows its SSE instructions while the
    // upper halves of the vector registers are in use (Zen 3: the walk ran at half speed):
    // they are cleared before every batch's end points.
    _mm256_zeroupper();
    int n = 0;
    Eigen::Vector3d end_W;
    bool inc = false;
    while (n < LaneBatch::kSize && (more = cursor.next(end_W, inc))) {
      for (int a = 0; a < 3; ++a) batch.end[a][n] = end_W[a];
      batch.inc[n++] = inc ? 1 : 0;
    }
    for (int k = n; k % 4 != 0; ++k) {  // lanes that mark nothing
      for (int a = 0; a < 3; ++a) batch.end[a][k] = start.o[a] * w.voxel_size_m;
      batch.inc[k] = 0;
    }
    for (int k = 0; k < n; k += 4) set_up_lanes4(w, start, batch, k, n - k, visits, box);
    for (int g = 0; g < n; g += 4) {
      __m256d tx = lanes_at(g, batch.t, 0), ty = lanes_at(g, batch.t, 1),
              tz = lanes_at(g, batch.t, 2);
      const __m256d dtx = lanes_at(g, batch.dt, 0), dty = lanes_at(g, batch.dt, 1),
                    dtz = lanes_at(g, batch.dt, 2);
      const __m256i dx = lanes_at(g, batch.delta, 0), dy = lanes_at(g, batch.delta, 1),
                    dz = lanes_at(g, batch.delta, 2);
      __m256i ex = lanes_at(g, batch.ev, 0), ey = lanes_at(g, batch.ev, 1),
              ez = lanes_at(g, batch.ev, 2);
      const __m256i wx = lanes_at(g, batch.wrap, 0), wy = lanes_at(g, batch.wrap, 1),
                    wz = lanes_at(g, batch.wrap, 2);
      __m256i xx = lanes_at(g, batch.to_exit, 0), xy = lanes_at(g, batch.to_exit, 1),
              xz = lanes_at(g, batch.to_exit, 2);
      __m256i r = _mm256_load_si256(reinterpret_cast<const __m256i*>(&batch.left[g]));
      const std::int64_t* const left = &batch.left[g];
      __m256i s = _mm256_set1_epi64x(start.slot);
      __m256i lost = zero;  // marks not made by walks that left the window
      std::int64_t longest = std::max(std::max(left[0], left[1]), std::max(left[2], left[3]));
      for (std::int64_t k = 0; k <= longest; ++k) {
        const __m256i active = _mm256_cmpgt_epi64(r, _mm256_set1_epi64x(-1));
        alignas(32) std::int64_t word[4];
        alignas(32) std::uint64_t bit[4];
        _mm256_store_si256(reinterpret_cast<__m256i*>(word),
                           _mm256_and_si256(_mm256_srli_epi64(s, 6), active));
        _mm256_store_si256(
            reinterpret_cast<__m256i*>(bit),
            _mm256_and_si256(_mm256_sllv_epi64(one, _mm256_and_si256(s, low6)), active));
        for (int l = 0; l < 4; ++l) {
          bits[word[l]] |= bit[l];
          if constexpr (kFlagWords) {
            dirty[word[l] >> kBlockShift] |= std::uint64_t{1} << (word[l] & 63);
          }
        }
        // The scalar step's comparisons: x if x < y and x < z, else y if y < z, else z.
        const __m256d x_lt_y = _mm256_cmp_pd(tx, ty, _CMP_LT_OQ);
        const __m256d x_lt_z = _mm256_cmp_pd(tx, tz, _CMP_LT_OQ);
        const __m256d y_lt_z = _mm256_cmp_pd(ty, tz, _CMP_LT_OQ);
        const __m256d kx = _mm256_and_pd(x_lt_y, x_lt_z);
        const __m256d ky = _mm256_andnot_pd(x_lt_y, y_lt_z);
        const __m256d kxy = _mm256_or_pd(kx, ky);  // not z
        tx = _mm256_blendv_pd(tx, _mm256_add_pd(tx, dtx), kx);
        ty = _mm256_blendv_pd(ty, _mm256_add_pd(ty, dty), ky);
        tz = _mm256_blendv_pd(_mm256_add_pd(tz, dtz), tz, kxy);
        s = _mm256_add_epi64(
            s, select(_mm256_castpd_si256(kx), dx, select(_mm256_castpd_si256(ky), dy, dz)));
        // Event counters count down the stepped axis (a mask is −1); z's is stepped unless x's
        // or y's was.
        ex = _mm256_add_epi64(ex, _mm256_castpd_si256(kx));
        ey = _mm256_add_epi64(ey, _mm256_castpd_si256(ky));
        ez = _mm256_sub_epi64(_mm256_sub_epi64(ez, _mm256_castpd_si256(kxy)), one);
        r = _mm256_sub_epi64(r, one);
        if (_mm256_testz_si256(_mm256_or_si256(ex, _mm256_or_si256(ey, ez)), sign) != 0) continue;
        const __m256i walking = _mm256_cmpgt_epi64(r, _mm256_set1_epi64x(-2));  // this step
        __m256i exited = zero;
        lanes4_events(walking, ex, xx, wx, nx, s, exited);
        lanes4_events(walking, ey, xy, wy, ny, s, exited);
        lanes4_events(walking, ez, xz, wz, nz, s, exited);
        // A walk that left the window made r + 1 marks fewer than booked (none when this was
        // its last step); it, and walks that had already ended, meet no further event.
        lost = _mm256_add_epi64(lost, _mm256_and_si256(exited, _mm256_add_epi64(r, one)));
        r = _mm256_or_si256(r, _mm256_and_si256(exited, _mm256_set1_epi64x(-kNever)));
        const __m256i done = _mm256_cmpgt_epi64(_mm256_set1_epi64x(-1), r);
        // A walk that left the window ends the group sooner: the group runs until its walks
        // still going have marked all theirs (sky beams leave the top of a flat window long
        // before their clearing range; the others would only idle).
        if (_mm256_movemask_pd(_mm256_castsi256_pd(exited)) != 0) {
          alignas(32) std::int64_t r_lanes[4];
          _mm256_store_si256(reinterpret_cast<__m256i*>(r_lanes), r);
          longest =
              k + 1 + std::max(std::max(r_lanes[0], r_lanes[1]), std::max(r_lanes[2], r_lanes[3]));
        }
        ex = select(done, never, ex);
        ey = select(done, never, ey);
        ez = select(done, never, ez);
      }
      alignas(32) std::int64_t lost_lanes[4];
      _mm256_store_si256(reinterpret_cast<__m256i*>(lost_lanes), lost);
      visits -=
          static_cast<std::uint64_t>(lost_lanes[0] + lost_lanes[1] + lost_lanes[2] + lost_lanes[3]);
    }
  }
  return visits;
}

}  // namespace

std::uint64_t walk_rays_lanes4(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                               FreeMarks marks, MarkBox& box) {
  return marks.dirty != nullptr ? walk_lanes4<true>(w, start, rays, marks, box)
                                : walk_lanes4<false>(w, start, rays, marks, box);
}

/// Whether this processor runs walk_rays_lanes4 (checked once).
bool lanes4_walk_supported() {
  static const bool supported = __builtin_cpu_supports("avx2") != 0;
  return supported;
}

}  // namespace tarmac::core::occupancy
#endif
