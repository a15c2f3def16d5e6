/// @file The ray walks eight at a time in AVX-512 lanes (see walk_lanes8 below).

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>

#include <immintrin.h>

#include "ray_tasks.hpp"

#if defined(TARMAC_WIDE_WALK)
namespace tarmac::core::occupancy {
namespace {

/// Walks set up for the wide walk and not yet in a lane, as the lanes load them: parameters,
/// parameter steps, slot steps, event counters and direction per axis; steps; index.
struct WideQueue {
  static constexpr int kSize = 64;
  alignas(64) double t[3][kSize], dt[3][kSize];
  alignas(64) std::int64_t delta[3][kSize], events[3][kSize], sign[3][kSize];
  alignas(64) std::int64_t steps[kSize], id[kSize];
  std::array<bool, kSize> inc{};
  int len = 0, next = 0;
};

/// Fills `q` (emptied by the caller) with the task's next walks, eight at a time: begin_walk's
/// arithmetic in lanes (the same divisions, floors and products, so the same values); the walks
/// that take a step are compressed into the queue, those that take none are done here.
template <bool kFlagWords>
__attribute__((target("avx512f,avx512dq"))) void set_up_walks(const WindowGeometry& w,
                                                              const RayStart& start,
                                                              TaskRayCursor& cursor, WideQueue& q,
                                                              std::uint64_t& visits,
                                                              FreeMarks marks, MarkBox& box) {
  constexpr int kLanes = 8;
  const __m512d voxel = _mm512_set1_pd(w.voxel_size_m);
  const __m512d one_d = _mm512_set1_pd(1.0);
  const __m512i one_i = _mm512_set1_epi64(1);
  const __m512i abs_bits = _mm512_set1_epi64(0x7fffffffffffffffLL);
  bool more = true;
  while (more && q.len + kLanes <= WideQueue::kSize) {
    alignas(64) double end[3][kLanes];
    std::array<bool, kLanes> inc{};
    int m = 0;
    Eigen::Vector3d end_W;
    while (m < kLanes && (more = cursor.next(end_W, inc[static_cast<std::size_t>(m)]))) {
      for (int a = 0; a < 3; ++a) end[a][m] = end_W[a];
      ++m;
    }
    if (m == 0) break;
    for (int j = m; j < kLanes; ++j) {
      for (int a = 0; a < 3; ++a) end[a][j] = start.o[a] * w.voxel_size_m;
    }
    __m512i steps = _mm512_setzero_si512();
    __m512d t_v[3], dt_v[3];
    __m512i delta_v[3], events_v[3], sign_v[3];
    for (int a = 0; a < 3; ++a) {
      const __m512d e = _mm512_div_pd(_mm512_load_pd(end[a]), voxel);
      const __m512d d = _mm512_sub_pd(e, _mm512_set1_pd(start.o[a]));
      const __m512i cell = _mm512_cvtpd_epi64(
          _mm512_mask_roundscale_pd(e, 0xff, e, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
      const __m512i moved = _mm512_sub_epi64(cell, _mm512_set1_epi64(start.cur[a]));
      steps = _mm512_add_epi64(
          steps, _mm512_mask_max_epi64(moved, 0xff, moved,
                                       _mm512_sub_epi64(_mm512_setzero_si512(), moved)));
      const __mmask8 pos = _mm512_cmp_pd_mask(d, _mm512_setzero_pd(), _CMP_GT_OQ);
      const __mmask8 neg = _mm512_cmp_pd_mask(d, _mm512_setzero_pd(), _CMP_LT_OQ);
      __m512i sign = _mm512_mask_add_epi64(one_i, pos, one_i, one_i);
      sign = _mm512_mask_sub_epi64(sign, neg, sign, one_i);
      const auto& walks = start.axis_walk[a];
      const __m512d num =
          _mm512_setr_pd(walks[0].t_max, walks[1].t_max, walks[2].t_max, 0.0, 0.0, 0.0, 0.0, 0.0);
      dt_v[a] = _mm512_div_pd(
          one_d, _mm512_castsi512_pd(_mm512_and_epi64(_mm512_castpd_si512(d),
                                                      abs_bits)));  // ±1 / d; infinite when d is 0
      t_v[a] = _mm512_mul_pd(_mm512_mask_permutexvar_pd(num, 0xff, sign, num), dt_v[a]);
      const __m512i delta_table =
          _mm512_setr_epi64(walks[0].delta, walks[1].delta, walks[2].delta, 0, 0, 0, 0, 0);
      const __m512i events_table =
          _mm512_setr_epi64(walks[0].events, walks[1].events, walks[2].events, 0, 0, 0, 0, 0);
      delta_v[a] = _mm512_mask_permutexvar_epi64(delta_table, 0xff, sign, delta_table);
      events_v[a] = _mm512_mask_permutexvar_epi64(events_table, 0xff, sign, events_table);
      sign_v[a] = sign;
    }
    alignas(64) std::int64_t lane_sign[3][kLanes];
    const auto valid = static_cast<__mmask8>((1u << m) - 1u);
    const auto walking =
        static_cast<__mmask8>(valid & _mm512_cmpneq_epi64_mask(steps, _mm512_setzero_si512()));
    // Walks of no step: only an included end voxel (the origin's) is marked.
    for (unsigned idle = valid & ~walking & 0xffu; idle != 0; idle &= idle - 1) {
      const int j = std::countr_zero(idle);
      if (!inc[static_cast<std::size_t>(j)]) continue;
      for (int a = 0; a < 3; ++a) _mm512_store_si512(lane_sign[a], sign_v[a]);
      visits += finish_walk<kFlagWords>(
          start, start.axis_walk[0][static_cast<std::size_t>(lane_sign[0][j])],
          start.axis_walk[1][static_cast<std::size_t>(lane_sign[1][j])],
          start.axis_walk[2][static_cast<std::size_t>(lane_sign[2][j])], start.slot, 0, 0, true,
          marks, box);
    }
    const int k = q.len;
    for (int a = 0; a < 3; ++a) {
      _mm512_mask_compressstoreu_pd(&q.t[a][k], walking, t_v[a]);
      _mm512_mask_compressstoreu_pd(&q.dt[a][k], walking, dt_v[a]);
      _mm512_mask_compressstoreu_epi64(&q.delta[a][k], walking, delta_v[a]);
      _mm512_mask_compressstoreu_epi64(&q.events[a][k], walking, events_v[a]);
      _mm512_mask_compressstoreu_epi64(&q.sign[a][k], walking, sign_v[a]);
    }
    _mm512_mask_compressstoreu_epi64(&q.steps[k], walking, steps);
    for (unsigned lanes = walking; lanes != 0; lanes &= lanes - 1) {
      const int j = std::countr_zero(lanes);
      q.id[q.len] = q.len;
      q.inc[static_cast<std::size_t>(q.len)] = inc[static_cast<std::size_t>(j)];
      ++q.len;
    }
  }
}

/// The same walks, eight at a time in the lanes of AVX-512 registers (x86-64 processors that
/// have it; the caller checks). A lane takes the same steps as the one-at-a-time walk, decided
/// by the same comparisons of the same sums, so the marks are the same bits. The step, which
/// one at a time is an unpredictable branch per visit, becomes masked arithmetic. Walks are set
/// up a batch at a time into a queue; a lane whose walk ends is booked (visits, box, end voxel)
/// and takes the next walk from the queue without leaving the vector loop. The loop is left
/// only for an event (ring wrap, window exit), which the scalar state handles one lane at a
/// time, and to set up the next batch.
/// `tarmac-bench --walk-lanes 1|4|8` compares the walks (docs/performance.md).
/// The wide walk's lanes between vector loops, per axis where it applies: parameters, parameter
/// steps, slot steps, event counters; slot, steps left, and `source`: the queue index of the
/// lane's walk, or −1 once its scalar state lives in lane_axes (after an event or a new batch),
/// −2 when idle.
struct WideLanes {
  static constexpr int kLanes = 8;
  alignas(64) double t[3][kLanes], dt[3][kLanes];
  alignas(64) std::int64_t delta[3][kLanes], events[3][kLanes], slot[kLanes], left[kLanes];
  alignas(64) std::int64_t source[kLanes];
};

/// The lanes' vector state back into `lanes` (for finish() and the event path).
__attribute__((target("avx512f,avx512dq"), always_inline)) inline void store_lanes(
    WideLanes& lanes, __m512d tx, __m512d ty, __m512d tz, __m512d dtx, __m512d dty, __m512d dtz,
    __m512i dx, __m512i dy, __m512i dz, __m512i s, __m512i ex, __m512i ey, __m512i ez, __m512i r,
    __m512i src) {
  _mm512_store_pd(lanes.t[0], tx);
  _mm512_store_pd(lanes.t[1], ty);
  _mm512_store_pd(lanes.t[2], tz);
  _mm512_store_pd(lanes.dt[0], dtx);
  _mm512_store_pd(lanes.dt[1], dty);
  _mm512_store_pd(lanes.dt[2], dtz);
  _mm512_store_si512(lanes.delta[0], dx);
  _mm512_store_si512(lanes.delta[1], dy);
  _mm512_store_si512(lanes.delta[2], dz);
  _mm512_store_si512(lanes.slot, s);
  _mm512_store_si512(lanes.events[0], ex);
  _mm512_store_si512(lanes.events[1], ey);
  _mm512_store_si512(lanes.events[2], ez);
  _mm512_store_si512(lanes.left, r);
  _mm512_store_si512(lanes.source, src);
}

template <bool kFlagWords>
__attribute__((target("avx512f,avx512dq"))) std::uint64_t walk_lanes8(const WindowGeometry& w,
                                                                      const RayStart& start,
                                                                      const TaskRays& rays,
                                                                      FreeMarks marks,
                                                                      MarkBox& box) {
  constexpr int kLanes = 8;
  if (!start.inside) return 0;
  TaskRayCursor cursor(rays);
  std::uint64_t visits = 0;
  std::uint64_t* const bits = marks.bits;
  std::uint64_t* const dirty = marks.dirty;

  // The queue: walks set up and not yet in a lane, as the lanes load them (parameters,
  // parameter steps, slot steps, event counters per axis; steps; index), and their scalar state.
  WideQueue q;
  // The lanes between vector loops (see WideLanes), and the scalar state of walks that left the
  // queue.
  WideLanes lanes;
  AxisWalk lane_axes[kLanes][3];
  std::array<std::int64_t, kLanes> lane_steps{};
  std::array<bool, kLanes> lane_inc{};

  // The lane's walk's scalar state moves out of the queue (which is about to change, or whose
  // entry the lane's events will modify).
  const auto own = [&](int l) {
    const auto k = static_cast<std::size_t>(lanes.source[l]);
    if (lanes.source[l] < 0) return;
    for (int a = 0; a < 3; ++a) {
      lane_axes[l][a] = start.axis_walk[a][static_cast<std::size_t>(q.sign[a][k])];
      lane_axes[l][a].t_delta = q.dt[a][k];
    }
    lane_steps[static_cast<std::size_t>(l)] = q.steps[k];
    lane_inc[static_cast<std::size_t>(l)] = q.inc[k];
    lanes.source[l] = -1;
  };
  // The next batch of walks into the queue (walks of no step are done on the spot); false
  // when the task has none left.
  const auto refill_queue = [&] {
    for (int l = 0; l < kLanes; ++l) own(l);
    q.len = 0;
    q.next = 0;
    set_up_walks<kFlagWords>(w, start, cursor, q, visits, marks, box);
    return q.len > 0;
  };
  // Lane l's scalar state with its vector state written in.
  const auto scalar = [&](int l) {
    own(l);
    for (int a = 0; a < 3; ++a) {
      lane_axes[l][a].t_max = lanes.t[a][l];
      lane_axes[l][a].events = static_cast<int>(lanes.events[a][l]);
    }
  };
  // The rest of lane l's walk one step at a time; its visits in all.
  const auto finish = [&](int l) {
    scalar(l);
    return finish_walk<kFlagWords>(
        start, lane_axes[l][0], lane_axes[l][1], lane_axes[l][2], lanes.slot[l], lanes.left[l],
        lane_steps[static_cast<std::size_t>(l)], lane_inc[static_cast<std::size_t>(l)], marks, box);
  };
  // Lane l takes the queue's next walk (stored lanes; the vector loop takes them by itself).
  const auto take = [&](int l) {
    const auto k = static_cast<std::size_t>(q.next++);
    for (int a = 0; a < 3; ++a) {
      lanes.t[a][l] = q.t[a][k];
      lanes.dt[a][l] = q.dt[a][k];
      lanes.delta[a][l] = q.delta[a][k];
      lanes.events[a][l] = q.events[a][k];
    }
    lanes.slot[l] = start.slot;
    lanes.left[l] = q.steps[k];
    lanes.source[l] = q.id[k];
  };

  for (int l = 0; l < kLanes; ++l) lanes.source[l] = -2;
  while (true) {
    // Idle lanes take walks; when the task has fewer left than lanes, the lanes finish one at
    // a time.
    bool short_of_walks = false;
    for (int l = 0; l < kLanes; ++l) {
      if (lanes.source[l] != -2) continue;
      if (q.next == q.len && !refill_queue()) {
        short_of_walks = true;
        break;
      }
      take(l);
    }
    if (short_of_walks) {
      for (int l = 0; l < kLanes; ++l) {
        if (lanes.source[l] != -2) visits += finish(l);
      }
      return visits;
    }
    __m512d tx = _mm512_load_pd(lanes.t[0]), ty = _mm512_load_pd(lanes.t[1]),
            tz = _mm512_load_pd(lanes.t[2]);
    __m512d dtx = _mm512_load_pd(lanes.dt[0]), dty = _mm512_load_pd(lanes.dt[1]);
    __m512d dtz = _mm512_load_pd(lanes.dt[2]);
    __m512i s = _mm512_load_si512(lanes.slot);
    __m512i dx = _mm512_load_si512(lanes.delta[0]), dy = _mm512_load_si512(lanes.delta[1]);
    __m512i dz = _mm512_load_si512(lanes.delta[2]);
    __m512i ex = _mm512_load_si512(lanes.events[0]), ey = _mm512_load_si512(lanes.events[1]);
    __m512i ez = _mm512_load_si512(lanes.events[2]);
    __m512i r = _mm512_load_si512(lanes.left);
    __m512i src = _mm512_load_si512(lanes.source);
    const __m512i one = _mm512_set1_epi64(1);
    const __m512i zero = _mm512_setzero_si512();
    const __m512i start_slot = _mm512_set1_epi64(start.slot);
    __mmask8 event = 0, ended = 0;
    while (true) {
      _mm512_store_si512(lanes.slot, s);
      for (int l = 0; l < kLanes; ++l) mark_voxel<kFlagWords>(bits, dirty, lanes.slot[l]);
      // The scalar step's comparisons: x if x < y and x < z, else y if y < z, else z.
      const __mmask8 x_lt_y = _mm512_cmp_pd_mask(tx, ty, _CMP_LT_OQ);
      const __mmask8 x_lt_z = _mm512_cmp_pd_mask(tx, tz, _CMP_LT_OQ);
      const __mmask8 y_lt_z = _mm512_cmp_pd_mask(ty, tz, _CMP_LT_OQ);
      const auto kx = static_cast<__mmask8>(x_lt_y & x_lt_z);
      const auto ky = static_cast<__mmask8>(~x_lt_y & y_lt_z);
      const auto kz = static_cast<__mmask8>(~(kx | ky));
      tx = _mm512_mask_add_pd(tx, kx, tx, dtx);
      ty = _mm512_mask_add_pd(ty, ky, ty, dty);
      tz = _mm512_mask_add_pd(tz, kz, tz, dtz);
      s = _mm512_mask_add_epi64(s, kx, s, dx);
      s = _mm512_mask_add_epi64(s, ky, s, dy);
      s = _mm512_mask_add_epi64(s, kz, s, dz);
      ex = _mm512_mask_sub_epi64(ex, kx, ex, one);
      ey = _mm512_mask_sub_epi64(ey, ky, ey, one);
      ez = _mm512_mask_sub_epi64(ez, kz, ez, one);
      r = _mm512_sub_epi64(r, one);
      event = static_cast<__mmask8>(_mm512_cmpeq_epi64_mask(ex, zero) |
                                    _mm512_cmpeq_epi64_mask(ey, zero) |
                                    _mm512_cmpeq_epi64_mask(ez, zero));
      ended = _mm512_cmpeq_epi64_mask(r, zero);
      if ((ended | event) == 0) continue;
      const int n_ended = std::popcount(static_cast<unsigned>(ended));
      if (event != 0 || q.len - q.next < n_ended) break;
      // Walks that ended without an event: booked here (finish() with no step lanes.left), and
      // their lanes take queued walks.
      store_lanes(lanes, tx, ty, tz, dtx, dty, dtz, dx, dy, dz, s, ex, ey, ez, r, src);
      for (unsigned m = ended; m != 0; m &= m - 1) {
        visits += finish(std::countr_zero(m));
      }
      const int k = q.next;
      q.next += n_ended;
      tx = _mm512_mask_expandloadu_pd(tx, ended, &q.t[0][k]);
      ty = _mm512_mask_expandloadu_pd(ty, ended, &q.t[1][k]);
      tz = _mm512_mask_expandloadu_pd(tz, ended, &q.t[2][k]);
      dtx = _mm512_mask_expandloadu_pd(dtx, ended, &q.dt[0][k]);
      dty = _mm512_mask_expandloadu_pd(dty, ended, &q.dt[1][k]);
      dtz = _mm512_mask_expandloadu_pd(dtz, ended, &q.dt[2][k]);
      dx = _mm512_mask_expandloadu_epi64(dx, ended, &q.delta[0][k]);
      dy = _mm512_mask_expandloadu_epi64(dy, ended, &q.delta[1][k]);
      dz = _mm512_mask_expandloadu_epi64(dz, ended, &q.delta[2][k]);
      ex = _mm512_mask_expandloadu_epi64(ex, ended, &q.events[0][k]);
      ey = _mm512_mask_expandloadu_epi64(ey, ended, &q.events[1][k]);
      ez = _mm512_mask_expandloadu_epi64(ez, ended, &q.events[2][k]);
      r = _mm512_mask_expandloadu_epi64(r, ended, &q.steps[k]);
      src = _mm512_mask_expandloadu_epi64(src, ended, &q.id[k]);
      s = _mm512_mask_mov_epi64(s, ended, start_slot);
    }
    store_lanes(lanes, tx, ty, tz, dtx, dty, dtz, dx, dy, dz, s, ex, ey, ez, r, src);
    for (unsigned m = static_cast<unsigned>(event | ended); m != 0; m &= m - 1) {
      const int l = std::countr_zero(m);
      bool done = false;
      if (((event >> l) & 1) != 0) {
        // The stepped axis's event, as AxisWalk::advance handles it (before the step count).
        scalar(l);
        for (int a = 0; a < 3; ++a) {
          if (lanes.events[a][l] != 0) continue;
          if (!lane_axes[l][a].on_event(lanes.slot[l])) {  // left the window
            add_walk_box<kFlagWords>(start, lane_axes[l][0], lane_axes[l][1], lane_axes[l][2], box);
            visits +=
                static_cast<std::uint64_t>(lane_steps[static_cast<std::size_t>(l)] - lanes.left[l]);
            done = true;
          } else {
            lanes.events[a][l] = lane_axes[l][a].events;
          }
        }
      }
      if (!done && ((ended >> l) & 1) != 0) {
        visits += finish(l);  // no step left: the end voxel, if marked, and the box
        done = true;
      }
      if (done) lanes.source[l] = -2;
    }
  }
}

}  // namespace

std::uint64_t walk_rays_lanes8(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                               FreeMarks marks, MarkBox& box) {
  return marks.dirty != nullptr ? walk_lanes8<true>(w, start, rays, marks, box)
                                : walk_lanes8<false>(w, start, rays, marks, box);
}

bool lanes8_walk_supported() {
  static const bool supported =
      __builtin_cpu_supports("avx512f") != 0 && __builtin_cpu_supports("avx512dq") != 0;
  return supported;
}

}  // namespace tarmac::core::occupancy
#endif
