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

/// The wide walk's lanes between vector loops, per axis where it applies: parameters, parameter
/// steps, slot steps, event counters; slot, steps left, and `source`: the queue index of the
/// lane's walk, or −1 once its scalar state lives in WideWalk (after an event or a new batch),
/// −2 when idle.
struct WideLanes {
  static constexpr int kLanes = 8;
  alignas(64) double t[3][kLanes], dt[3][kLanes];
  alignas(64) std::int64_t delta[3][kLanes], events[3][kLanes], slot[kLanes], left[kLanes];
  alignas(64) std::int64_t source[kLanes];
};

/// The wide walk's helpers are inlined into walk_lanes8: GCC inlines intrinsics-using code only
/// into a function of the same target, and a call per step would cost more than the step.
#define TARMAC_LANES8_INLINE __attribute__((target("avx512f,avx512dq"), always_inline)) inline

/// WideLanes in registers, as the vector loop holds them, per axis (t, dt, delta, events) and
/// per lane (s: slot, r: steps left, src: source). The axis loops below have constant bounds and
/// unroll: the arrays stay in registers.
struct LaneRegisters {
  __m512d t[3], dt[3];
  __m512i d[3], e[3], s, r, src;
};

/// The lanes that leave the vector loop: a stepped axis's counter reached 0 (`event`: the ring
/// wraps or the walk leaves the window), or the walk took its last step (`ended`).
struct LaneStops {
  __mmask8 event = 0, ended = 0;
};

/// The lanes' state into registers, for a vector loop.
TARMAC_LANES8_INLINE LaneRegisters load_lanes(const WideLanes& lanes) {
  LaneRegisters v;
  for (int a = 0; a < 3; ++a) {
    v.t[a] = _mm512_load_pd(lanes.t[a]);
    v.dt[a] = _mm512_load_pd(lanes.dt[a]);
    v.d[a] = _mm512_load_si512(lanes.delta[a]);
    v.e[a] = _mm512_load_si512(lanes.events[a]);
  }
  v.s = _mm512_load_si512(lanes.slot);
  v.r = _mm512_load_si512(lanes.left);
  v.src = _mm512_load_si512(lanes.source);
  return v;
}

/// The lanes' vector state back into `lanes` (for finish() and the event path).
TARMAC_LANES8_INLINE void store_lanes(WideLanes& lanes, const LaneRegisters& v) {
  for (int a = 0; a < 3; ++a) {
    _mm512_store_pd(lanes.t[a], v.t[a]);
    _mm512_store_pd(lanes.dt[a], v.dt[a]);
    _mm512_store_si512(lanes.delta[a], v.d[a]);
    _mm512_store_si512(lanes.events[a], v.e[a]);
  }
  _mm512_store_si512(lanes.slot, v.s);
  _mm512_store_si512(lanes.left, v.r);
  _mm512_store_si512(lanes.source, v.src);
}

/// Every lane one step: the stepped axis's parameter, slot and event counter, and the steps
/// left. Masked arithmetic where the one-at-a-time step branches; the same comparisons of the
/// same sums, so the same steps. Returns the lanes that must leave the loop, if any.
TARMAC_LANES8_INLINE LaneStops step_lanes(LaneRegisters& v) {
  const __m512i one = _mm512_set1_epi64(1);
  const __m512i zero = _mm512_setzero_si512();
  // The scalar step's comparisons: x if x < y and x < z, else y if y < z, else z.
  const __mmask8 x_lt_y = _mm512_cmp_pd_mask(v.t[0], v.t[1], _CMP_LT_OQ);
  const __mmask8 x_lt_z = _mm512_cmp_pd_mask(v.t[0], v.t[2], _CMP_LT_OQ);
  const __mmask8 y_lt_z = _mm512_cmp_pd_mask(v.t[1], v.t[2], _CMP_LT_OQ);
  __mmask8 k[3];
  k[0] = static_cast<__mmask8>(x_lt_y & x_lt_z);
  k[1] = static_cast<__mmask8>(~x_lt_y & y_lt_z);
  k[2] = static_cast<__mmask8>(~(k[0] | k[1]));
  __mmask8 event = 0;
  for (int a = 0; a < 3; ++a) {
    v.t[a] = _mm512_mask_add_pd(v.t[a], k[a], v.t[a], v.dt[a]);
    v.s = _mm512_mask_add_epi64(v.s, k[a], v.s, v.d[a]);
    v.e[a] = _mm512_mask_sub_epi64(v.e[a], k[a], v.e[a], one);
    event = static_cast<__mmask8>(event | _mm512_cmpeq_epi64_mask(v.e[a], zero));
  }
  v.r = _mm512_sub_epi64(v.r, one);
  LaneStops stops;
  stops.event = event;
  stops.ended = _mm512_cmpeq_epi64_mask(v.r, zero);
  return stops;
}

/// The lanes in `ended` take the queue's walks from entry `k` on, in lane order, as take() does,
/// without the registers going through memory.
TARMAC_LANES8_INLINE void load_queued(LaneRegisters& v, __mmask8 ended, const WideQueue& q, int k,
                                      __m512i start_slot) {
  for (int a = 0; a < 3; ++a) {
    v.t[a] = _mm512_mask_expandloadu_pd(v.t[a], ended, &q.t[a][k]);
    v.dt[a] = _mm512_mask_expandloadu_pd(v.dt[a], ended, &q.dt[a][k]);
    v.d[a] = _mm512_mask_expandloadu_epi64(v.d[a], ended, &q.delta[a][k]);
    v.e[a] = _mm512_mask_expandloadu_epi64(v.e[a], ended, &q.events[a][k]);
  }
  v.r = _mm512_mask_expandloadu_epi64(v.r, ended, &q.steps[k]);
  v.src = _mm512_mask_expandloadu_epi64(v.src, ended, &q.id[k]);
  v.s = _mm512_mask_mov_epi64(v.s, ended, start_slot);
}

/// One task's wide walk: the cursor and the queue its walks come from, the lanes, the scalar
/// state of walks that left the queue, and what the walks book (visits, marks, box). Its public
/// members are the steps of walk_lanes8.
template <bool kFlagWords>
class WideWalk {
 public:
  static constexpr int kLanes = WideLanes::kLanes;

  TARMAC_LANES8_INLINE WideWalk(const WindowGeometry& w, const RayStart& start,
                                const TaskRays& rays, FreeMarks marks, MarkBox& box)
      : w_(w), start_(start), cursor_(rays), marks_(marks), box_(box) {
    for (int l = 0; l < kLanes; ++l) lanes_.source[l] = -2;
  }

  /// Idle lanes take walks, from the queue, refilled as it runs dry. False when the task has
  /// fewer walks left than there are idle lanes: the lanes then finish one at a time.
  TARMAC_LANES8_INLINE bool fill_idle_lanes() {
    for (int l = 0; l < kLanes; ++l) {
      if (lanes_.source[l] != -2) continue;
      if (q_.next == q_.len && !refill_queue()) return false;
      take(l);
    }
    return true;
  }

  /// The lanes' walks, a step of all eight at a time, until a lane meets an event or walks end
  /// that the queue cannot replace; returns those lanes. Walks that end without an event are
  /// booked (finish() with no step left) and their lanes take queued walks without leaving
  /// the loop.
  TARMAC_LANES8_INLINE LaneStops run_lanes() {
    // Locals: the marks are 64-bit stores, which may alias the lanes' 64-bit state.
    std::uint64_t* const bits = marks_.bits;
    std::uint64_t* const dirty = marks_.dirty;
    const __m512i start_slot = _mm512_set1_epi64(start_.slot);
    LaneRegisters v = load_lanes(lanes_);
    LaneStops stops;
    while (true) {
      _mm512_store_si512(lanes_.slot, v.s);
      for (int l = 0; l < kLanes; ++l) mark_voxel<kFlagWords>(bits, dirty, lanes_.slot[l]);
      stops = step_lanes(v);
      if ((stops.ended | stops.event) == 0) continue;
      const int n_ended = std::popcount(static_cast<unsigned>(stops.ended));
      if (stops.event != 0 || q_.len - q_.next < n_ended) break;
      store_lanes(lanes_, v);
      for (unsigned m = stops.ended; m != 0; m &= m - 1) {
        visits_ += finish(std::countr_zero(m));
      }
      const int k = q_.next;
      q_.next += n_ended;
      load_queued(v, stops.ended, q_, k, start_slot);
    }
    store_lanes(lanes_, v);
    return stops;
  }

  /// The lanes that left the vector loop, one at a time: their events, then the end of their
  /// walks. A lane whose walk is done (ended, or left the window) becomes idle.
  TARMAC_LANES8_INLINE void settle(LaneStops stops) {
    for (unsigned m = static_cast<unsigned>(stops.event | stops.ended); m != 0; m &= m - 1) {
      const int l = std::countr_zero(m);
      bool done = ((stops.event >> l) & 1) != 0 && take_events(l);
      if (!done && ((stops.ended >> l) & 1) != 0) {
        visits_ += finish(l);  // no step left: the end voxel, if marked, and the box
        done = true;
      }
      if (done) lanes_.source[l] = -2;
    }
  }

  /// The walks still in lanes, each to its end one step at a time; the task's visits in all.
  TARMAC_LANES8_INLINE std::uint64_t finish_busy_lanes() {
    for (int l = 0; l < kLanes; ++l) {
      if (lanes_.source[l] != -2) visits_ += finish(l);
    }
    return visits_;
  }

 private:
  /// The lane's walk's scalar state moves out of the queue (which is about to change, or whose
  /// entry the lane's events will modify).
  TARMAC_LANES8_INLINE void own(int l) {
    const auto k = static_cast<std::size_t>(lanes_.source[l]);
    if (lanes_.source[l] < 0) return;
    for (int a = 0; a < 3; ++a) {
      lane_axes_[l][a] = start_.axis_walk[a][static_cast<std::size_t>(q_.sign[a][k])];
      lane_axes_[l][a].t_delta = q_.dt[a][k];
    }
    lane_steps_[static_cast<std::size_t>(l)] = q_.steps[k];
    lane_inc_[static_cast<std::size_t>(l)] = q_.inc[k];
    lanes_.source[l] = -1;
  }

  /// The next batch of walks into the queue (walks of no step are done on the spot); false
  /// when the task has none left.
  TARMAC_LANES8_INLINE bool refill_queue() {
    for (int l = 0; l < kLanes; ++l) own(l);
    q_.len = 0;
    q_.next = 0;
    set_up_walks<kFlagWords>(w_, start_, cursor_, q_, visits_, marks_, box_);
    return q_.len > 0;
  }

  /// Lane l's scalar state with its vector state written in.
  TARMAC_LANES8_INLINE void scalar(int l) {
    own(l);
    for (int a = 0; a < 3; ++a) {
      lane_axes_[l][a].t_max = lanes_.t[a][l];
      lane_axes_[l][a].events = static_cast<int>(lanes_.events[a][l]);
    }
  }

  /// The rest of lane l's walk one step at a time; its visits in all.
  TARMAC_LANES8_INLINE std::uint64_t finish(int l) {
    scalar(l);
    return finish_walk<kFlagWords>(start_, lane_axes_[l][0], lane_axes_[l][1], lane_axes_[l][2],
                                   lanes_.slot[l], lanes_.left[l],
                                   lane_steps_[static_cast<std::size_t>(l)],
                                   lane_inc_[static_cast<std::size_t>(l)], marks_, box_);
  }

  /// Lane l takes the queue's next walk (stored lanes; the vector loop takes them by itself).
  TARMAC_LANES8_INLINE void take(int l) {
    const auto k = static_cast<std::size_t>(q_.next++);
    for (int a = 0; a < 3; ++a) {
      lanes_.t[a][l] = q_.t[a][k];
      lanes_.dt[a][l] = q_.dt[a][k];
      lanes_.delta[a][l] = q_.delta[a][k];
      lanes_.events[a][l] = q_.events[a][k];
    }
    lanes_.slot[l] = start_.slot;
    lanes_.left[l] = q_.steps[k];
    lanes_.source[l] = q_.id[k];
  }

  /// Lane l's events (the axes whose counters reached 0), as AxisWalk::advance handles them
  /// (before the step count); true when the walk left the window, booked here.
  TARMAC_LANES8_INLINE bool take_events(int l) {
    scalar(l);
    bool left_window = false;
    for (int a = 0; a < 3; ++a) {
      if (lanes_.events[a][l] != 0) continue;
      if (!lane_axes_[l][a].on_event(lanes_.slot[l])) {
        add_walk_box<kFlagWords>(start_, lane_axes_[l][0], lane_axes_[l][1], lane_axes_[l][2],
                                 box_);
        visits_ +=
            static_cast<std::uint64_t>(lane_steps_[static_cast<std::size_t>(l)] - lanes_.left[l]);
        left_window = true;
      } else {
        lanes_.events[a][l] = lane_axes_[l][a].events;
      }
    }
    return left_window;
  }

  const WindowGeometry& w_;
  const RayStart& start_;
  TaskRayCursor cursor_;
  FreeMarks marks_;
  MarkBox& box_;
  std::uint64_t visits_ = 0;
  // The queue: walks set up and not yet in a lane. The lanes between vector loops, and the
  // scalar state of the walks that left the queue.
  WideQueue q_;
  WideLanes lanes_;
  AxisWalk lane_axes_[kLanes][3];
  std::array<std::int64_t, kLanes> lane_steps_{};
  std::array<bool, kLanes> lane_inc_{};
};

/// The same walks, eight at a time in the lanes of AVX-512 registers (x86-64 processors that
/// have it; the caller checks). A lane takes the same steps as the one-at-a-time walk, decided
/// by the same comparisons of the same sums, so the marks are the same bits. The step, which
/// one at a time is an unpredictable branch per visit, becomes masked arithmetic. Walks are set
/// up a batch at a time into a queue; a lane whose walk ends is booked (visits, box, end voxel)
/// and takes the next walk from the queue without leaving the vector loop. The loop is left
/// only for an event (ring wrap, window exit), which the scalar state handles one lane at a
/// time, and to set up the next batch.
/// `tarmac-bench --walk-lanes 1|4|8` compares the walks (docs/performance.md).
template <bool kFlagWords>
__attribute__((target("avx512f,avx512dq"))) std::uint64_t walk_lanes8(const WindowGeometry& w,
                                                                      const RayStart& start,
                                                                      const TaskRays& rays,
                                                                      FreeMarks marks,
                                                                      MarkBox& box) {
  if (!start.inside) return 0;
  WideWalk<kFlagWords> walk(w, start, rays, marks, box);
  while (walk.fill_idle_lanes()) walk.settle(walk.run_lanes());
  return walk.finish_busy_lanes();
}

#undef TARMAC_LANES8_INLINE

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
