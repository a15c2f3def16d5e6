#include "tarmac/core/occupancy_map.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif
#include <limits>
#include <tuple>
#include <utility>

#include "lanes4.hpp"

namespace tarmac::core {

/// The site-wide static layer: one 512-bit mask per 8×8×8 block of voxels that holds any.
/// Sparse and OpenVDB-free (this file stays cheap to compile); only promotions, demotions and the
/// window's entering slabs touch it, never the per-voxel hot loops. An open-addressing table
/// sized at construction (a few windows' worth of blocks), so promotions do not allocate in the
/// cycle; it doubles when half full (the static map grown over several windows of site). A block
/// whose last voxel is demoted keeps its slot with an empty mask.
struct StaticStore {
  static constexpr int kShift = 3;
  static constexpr int kSide = 1 << kShift;
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};
  using Mask = std::array<std::uint64_t, 8>;  // bit (z·64 + y·8 + x) of the block
  std::vector<std::uint64_t> keys;
  std::vector<Mask> masks;
  std::size_t used = 0;   ///< slots holding a key
  std::size_t count = 0;  ///< voxels in the layer

  explicit StaticStore(std::size_t min_blocks) {
    std::size_t capacity = 1024;
    while (capacity < 2 * min_blocks) capacity *= 2;
    keys.assign(capacity, kEmpty);
    masks.assign(capacity, Mask{});
  }
  static std::uint64_t key(int bx, int by, int bz) {
    constexpr std::uint64_t kBias = std::uint64_t{1} << 20;
    constexpr std::uint64_t kMask = (std::uint64_t{1} << 21) - 1;
    return ((static_cast<std::uint64_t>(bz) + kBias) & kMask) << 42 |
           ((static_cast<std::uint64_t>(by) + kBias) & kMask) << 21 |
           ((static_cast<std::uint64_t>(bx) + kBias) & kMask);
  }
  static int bit(const VoxelIndex& v) {
    return ((v.z() & (kSide - 1)) << 6) | ((v.y() & (kSide - 1)) << 3) | (v.x() & (kSide - 1));
  }
  static std::uint64_t key_of(const VoxelIndex& v) {
    return key(v.x() >> kShift, v.y() >> kShift, v.z() >> kShift);
  }
  [[nodiscard]] std::size_t probe(std::uint64_t k) const {
    const std::size_t mask = keys.size() - 1;
    std::size_t i = static_cast<std::size_t>((k * 0x9E3779B97F4A7C15ull) >> 20) & mask;
    while (keys[i] != kEmpty && keys[i] != k) i = (i + 1) & mask;
    return i;
  }
  [[nodiscard]] const Mask* find(std::uint64_t k) const {
    const std::size_t i = probe(k);
    return keys[i] == k ? &masks[i] : nullptr;
  }
  Mask& find_or_insert(std::uint64_t k) {
    std::size_t i = probe(k);
    if (keys[i] == k) return masks[i];
    if (2 * (used + 1) > keys.size()) {
      grow();
      i = probe(k);
    }
    keys[i] = k;
    masks[i] = Mask{};
    ++used;
    return masks[i];
  }
  void grow() {
    std::vector<std::uint64_t> old_keys(2 * keys.size(), kEmpty);
    std::vector<Mask> old_masks(2 * keys.size(), Mask{});
    old_keys.swap(keys);
    old_masks.swap(masks);
    for (std::size_t j = 0; j < old_keys.size(); ++j) {
      if (old_keys[j] == kEmpty) continue;
      const std::size_t i = probe(old_keys[j]);
      keys[i] = old_keys[j];
      masks[i] = old_masks[j];
    }
  }
  void clear() {
    std::fill(keys.begin(), keys.end(), kEmpty);
    used = 0;
    count = 0;
  }
  /// fn(key, mask) for every block with a voxel, in table order.
  template <typename Fn>
  void for_each(Fn&& fn) const {
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (keys[i] != kEmpty) fn(keys[i], masks[i]);
    }
  }
  [[nodiscard]] bool contains(const VoxelIndex& v) const {
    const Mask* m = find(key_of(v));
    if (m == nullptr) return false;
    const int b = bit(v);
    return (((*m)[b >> 6] >> (b & 63)) & 1) != 0;
  }
  void insert(const VoxelIndex& v) {
    Mask& m = find_or_insert(key_of(v));
    const int b = bit(v);
    const std::uint64_t one = std::uint64_t{1} << (b & 63);
    if ((m[b >> 6] & one) == 0) ++count;
    m[b >> 6] |= one;
  }
  void erase(const VoxelIndex& v) {
    const std::size_t i = probe(key_of(v));
    if (keys[i] != key_of(v)) return;
    const int b = bit(v);
    const std::uint64_t one = std::uint64_t{1} << (b & 63);
    if ((masks[i][b >> 6] & one) == 0) return;
    masks[i][b >> 6] &= ~one;
    --count;
  }
};

namespace {

/// Blocks of the static layer two windows hold (the table's initial reservation).
std::size_t static_reservation(const Eigen::Vector3i& dims) {
  std::size_t blocks = 1;
  for (int a = 0; a < 3; ++a) blocks *= static_cast<std::size_t>((dims[a] + 7) / 8 + 1);
  return 2 * blocks;
}

constexpr std::uint8_t kStatic = 0x80;
constexpr std::uint8_t kCount = 0x7f;

/// Scans (with a return, the voxel reading occupied since) that a voxel leaving the window
/// needs to join the static layer: one return alone may be noise.
constexpr std::uint8_t kKeepHits = 2;

/// OccupancyMap::hit_floor_: the lowest return inside a voxel, in 32nds of the voxel's height.
constexpr int kFloorSteps = 32;
constexpr std::uint8_t kNoHitFloor = 0xff;

/// Where coordinate c (m) lies inside its voxel of size v (m), in 32nds: 0..31.
std::uint8_t sub_voxel(float c, double v) {
  const double u = static_cast<double>(c) / v;
  return static_cast<std::uint8_t>(
      std::clamp(static_cast<int>((u - std::floor(u)) * kFloorSteps), 0, kFloorSteps - 1));
}

/// Non-negative remainder.
int wrap(int i, int n) {
  const int r = i % n;
  return r < 0 ? r + n : r;
}

/// Ray tasks, each marking its own bit set (the rays it walks: see TaskRays), beside the hit
/// pass's one task; the marks are applied in fixed ranges of the window. Three: a task more is
/// a mark set more for the apply pass to OR, and 4 or 5 measured no faster.
constexpr std::size_t kRayTasks = 3;
/// Rays are taken by the ray tasks in chunks of this many, in direction order, each chunk by the
/// first task to ask for it (see TaskRays).
constexpr std::size_t kRayChunk = 64;
/// Fixed ranges of the window the apply pass splits into. The marks crowd into the layers near
/// the sensor's height, so a few ranges hold most of them: with 8 on MulRan, the longest took
/// 1.44 of the 6.1 ms of all 8, and the pass 3.56 ms on 2 threads; finer ranges even it out.
constexpr std::size_t kApplyTasks = 32;
/// Fixed ranges of slots (cut at multiples of 64) in which the window's scroll clears the ring
/// slabs that the entering voxels take over.
constexpr std::size_t kSlabTasks = 8;
/// No slot: the return does not mark (beyond max range or outside the window).
constexpr std::uint32_t kNoSlot = ~std::uint32_t{0};

/// floor() to an integer for any finite double in int64 range, without a libm call.
std::int64_t floor_to_int(double v) {
  const auto i = static_cast<std::int64_t>(v);  // truncates toward zero
  return i - static_cast<std::int64_t>(static_cast<double>(i) > v);
}
/// Free-space marks are tracked per block of 64 bit words (4096 voxels).
constexpr int kBlockShift = 6;

/// Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing" (Eurographics 1987), on
/// the lattice [i·v, (i+1)·v), clipped to the window. Marks each voxel from the origin's voxel up
/// to the end point's voxel, excluding it unless `include_end`. Stops when the ray leaves the
/// window (a box: it cannot come back).
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

/// Windows up to this many voxels (2 MB of marks per ray task) skip the per-visit word flags: the
/// apply pass reads their marks inside the box the rays spanned, which costs less than a flag
/// on each of millions of visits. Larger windows (0.1 m voxels over 100 m: 10 MB of marks per
/// task) flag each mark word the rays touch, so the apply pass reads only those (a flag per
/// block of 64 words read 15 MB per scan of BALM hall). Either way the same voxels are marked
/// and updated.
constexpr std::size_t kUnflaggedVoxels = std::size_t{16} << 20;

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

template <bool kFlagWords>
std::uint64_t traverse(const WindowGeometry& w, const RayStart& start, const Eigen::Vector3d& end_W,
                       bool include_end, FreeMarks marks, MarkBox& box) {
  if (!start.inside) return 0;
  AxisWalk x, y, z;  // NOLINT(cppcoreguidelines-pro-type-member-init): begin_walk sets them
  std::int64_t steps = 0;
  begin_walk(w, start, end_W, x, y, z, steps);
  return finish_walk<kFlagWords>(start, x, y, z, start.slot, steps, steps, include_end, marks, box);
}

/// The one-at-a-time walk takes the rays in order of direction, not in the order the scan lists
/// them (the wide walk does not need it, see integrate). The walk's step is a branch on which
/// axis crosses next, and a ray's run of steps resembles those of the
/// rays beside it: walked one after another, the processor predicts most of them (BALM hall,
/// whose scans interleave distant directions: in a harness walking its rays, sorted per scan,
/// 0.83 of the time; docs/perf/archive/perf-occ5.md). The marks are the
/// same whatever the order, so this changes speed only. The order: cube-map face of the
/// direction (dominant axis and sign), band of the second minor coordinate, bin of the first.
constexpr int kDirBands = 16;  ///< bands per cube face
constexpr int kDirBins = 128;  ///< bins per band
constexpr std::size_t kDirBuckets = std::size_t{6} * kDirBands * kDirBins;

/// The direction buckets of four rays (x, y, z: four lanes each), without a branch: a scan's
/// directions are as good as random. Any input gives a bucket in range (NaN and infinities
/// land in a valid one; such rays are not walked anyway).
void direction_buckets(Float4 x, Float4 y, Float4 z, std::uint16_t* out) {
  const Float4 zero = {0.0f, 0.0f, 0.0f, 0.0f};
  const Float4 ax = x < zero ? -x : x, ay = y < zero ? -y : y, az = z < zero ? -z : z;
  const Int4 x_dom = (ax >= ay) & (ax >= az);
  const Int4 y_dom = ~x_dom & (ay >= az);
  const Int4 z_dom = ~x_dom & ~y_dom;
  const Float4 big = x_dom ? ax : (y_dom ? ay : az);
  const Float4 u = x_dom ? y : x;
  const Float4 v = z_dom ? y : z;
  // A comparison gives −1 where true: face 2·axis, +1 when the dominant coordinate is positive.
  const Int4 face = (x_dom & -(x > zero)) | (y_dom & (2 - (y > zero))) | (z_dom & (4 - (z > zero)));
  const Float4 one = {1.0f, 1.0f, 1.0f, 1.0f};
  // In [0, 2) on the face; anything else (a zero or non-finite direction) to 0.
  Float4 fu = u / big + one, fv = v / big + one;
  const Float4 two = one + one;
  fu = ((fu >= zero) & (fu < two)) ? fu : zero;
  fv = ((fv >= zero) & (fv < two)) ? fv : zero;
  const Float4 half_bins = one * (0.5f * kDirBins), half_bands = one * (0.5f * kDirBands);
  const Int4 bin = __builtin_convertvector(fu * half_bins, Int4);
  const Int4 band = __builtin_convertvector(fv * half_bands, Int4);
  const Int4 bucket = (face * kDirBands + band) * kDirBins + bin;
  for (int k = 0; k < 4; ++k) {
    out[k] =
        static_cast<std::uint16_t>(std::clamp(bucket[k], 0, static_cast<int>(kDirBuckets) - 1));
  }
}

/// Fixed ranges of rays whose direction buckets are computed side by side (most of the sort's
/// time: BALM hall, 0.15 of 0.23 ms).
constexpr std::size_t kBucketTasks = 4;

/// The scan's rays (returns, then beams without one) in order of direction bucket, stable (a
/// counting sort): `order` receives the ray indices. `bucket` and `count` are scratch.
void sort_rays_by_direction(const Eigen::Vector3d& origin_W,
                            std::span<const Eigen::Vector3f> points,
                            std::span<const Eigen::Vector3f> dirs,
                            std::vector<std::uint16_t>& bucket, std::vector<std::uint32_t>& count,
                            std::vector<std::uint32_t>& order, TaskRunner& runner) {
  const std::size_t n_points = points.size();
  const std::size_t n_rays = n_points + dirs.size();
  const std::size_t n_quads = (n_rays + 3) / 4;
  bucket.resize(4 * n_quads);
  order.resize(n_rays);
  count.resize(kBucketTasks * kDirBuckets);
  const Eigen::Vector3f o = origin_W.cast<float>();
  runner.parallel_for(kBucketTasks, [&](std::size_t task) {
    const std::size_t q0 = n_quads * task / kBucketTasks, q1 = n_quads * (task + 1) / kBucketTasks;
    for (std::size_t i = 4 * q0; i < 4 * q1; i += 4) {
      Float4 x{}, y{}, z{};
      if (i + 4 <= n_points) {  // four returns, contiguous
        load_xyz4(points.data() + i, x, y, z);
        const Float4 zero{};
        direction_buckets(x - (zero + o.x()), y - (zero + o.y()), z - (zero + o.z()),
                          bucket.data() + i);
        continue;
      }
      for (std::size_t k = 0; k < 4 && i + k < n_rays; ++k) {
        const std::size_t r = i + k;
        const Eigen::Vector3f q =
            r < n_points ? Eigen::Vector3f(points[r] - o) : dirs[r - n_points];
        x[k] = q.x();
        y[k] = q.y();
        z[k] = q.z();
      }
      direction_buckets(x, y, z, bucket.data() + i);
    }
    // The range's own histogram (a counting sort split by range: the order is the serial one).
    std::uint32_t* const c = count.data() + task * kDirBuckets;
    std::fill_n(c, kDirBuckets, 0u);
    for (std::size_t r = 4 * q0; r < std::min(4 * q1, n_rays); ++r) ++c[bucket[r]];
  });
  // Each range's first place per bucket: buckets in order, within a bucket the ranges in order,
  // so rays keep their scan order within a bucket (stable), as one serial pass would.
  std::uint32_t next = 0;
  for (std::size_t b = 0; b < kDirBuckets; ++b) {
    for (std::size_t t = 0; t < kBucketTasks; ++t) {
      std::uint32_t& c = count[t * kDirBuckets + b];
      const std::uint32_t n = c;
      c = next;
      next += n;
    }
  }
  runner.parallel_for(kBucketTasks, [&](std::size_t task) {
    const std::size_t q0 = n_quads * task / kBucketTasks, q1 = n_quads * (task + 1) / kBucketTasks;
    std::uint32_t* const c = count.data() + task * kDirBuckets;
    for (std::size_t r = 4 * q0; r < std::min(4 * q1, n_rays); ++r) {
      order[c[bucket[r]]++] = static_cast<std::uint32_t>(r);
    }
  });
}

/// The rays of one ray task: returns (within max range: walked to their voxel, not marked;
/// beyond: walked up to the clearing range, end voxel included) then beams without a return
/// (clearing range, end included). The scan's rays are taken in `order` (by direction), in
/// chunks of kRayChunk: a task takes the next chunk nobody has taken when it needs one
/// (`next_chunk`, shared by the scan's ray tasks), so the tasks end together however the
/// threads are shared with the hit pass. Which task walks which ray changes nothing: the
/// apply pass reads the union of the tasks' marks (an OR), the box is the union of their
/// boxes and the visits their sum, so the map is the same bit for bit (the digest tests).
/// On 2 threads the thread that ran the hit pass had to take one of three fixed thirds as
/// well, and the other two thirds waited for it (BALM hall: 1.4 ms hit pass, 1.9 ms a third).
struct TaskRays {
  std::span<const Eigen::Vector3f> points, dirs;
  /// The rays by direction (see sort_rays_by_direction); empty: in the scan's order.
  std::span<const std::uint32_t> order;
  Eigen::Vector3d origin;
  double max_range, clear_range;
  std::atomic<std::size_t>* next_chunk;
};

/// The rays of one ray task, one at a time, as walks to make: where each ends and whether its
/// end voxel is marked too (see TaskRays). Rays that mark nothing are passed over.
class TaskRayCursor {
 public:
  explicit TaskRayCursor(const TaskRays& rays)
      : rays_(rays),
        n_points_(rays.points.size()),
        n_rays_(rays.points.size() + rays.dirs.size()),
        first_(0),
        j_(0),
        end_(0) {}

  /// The next walk of the task; false when none is left.
  bool next(Eigen::Vector3d& end_W, bool& include_end) {
    const Eigen::Vector3d& origin_W = rays_.origin;
    while (true) {
      if (j_ >= end_) {
        first_ = kRayChunk * rays_.next_chunk->fetch_add(1, std::memory_order_relaxed);
        if (first_ >= n_rays_) return false;
        j_ = first_;
        end_ = std::min(n_rays_, first_ + kRayChunk);
      }
      const std::size_t j = j_++;
      const std::size_t i = rays_.order.empty() ? j : rays_.order[j];
      if (i < n_points_) {
        const Eigen::Vector3f& p = rays_.points[i];
        if (!p.allFinite()) continue;
        const Eigen::Vector3d pd = p.cast<double>();
        const double range = (pd - origin_W).norm();
        if (range <= rays_.max_range) {
          end_W = pd;
          include_end = false;
          return true;
        }
        if (rays_.clear_range > 0.0) {
          end_W = origin_W + (pd - origin_W) * (rays_.clear_range / range);
          include_end = true;
          return true;
        }
      } else {
        const Eigen::Vector3f& dir = rays_.dirs[i - n_points_];
        const double norm = dir.cast<double>().norm();
        if (!dir.allFinite() || norm == 0.0 || rays_.clear_range <= 0.0) continue;
        end_W = origin_W + dir.cast<double>() * (rays_.clear_range / norm);
        include_end = true;
        return true;
      }
    }
  }

 private:
  const TaskRays& rays_;
  std::size_t n_points_, n_rays_;
  std::size_t first_, j_, end_;  ///< the current chunk [first_, end_), the next ray (in `order`)
};

/// Walks every ray of a task one after the other; returns the voxel visits.
template <bool kFlagWords>
std::uint64_t walk_rays(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                        FreeMarks marks, MarkBox& box) {
  TaskRayCursor cursor(rays);
  Eigen::Vector3d end_W;
  bool include_end = false;
  std::uint64_t visits = 0;
  while (cursor.next(end_W, include_end)) {
    visits += traverse<kFlagWords>(w, start, end_W, include_end, marks, box);
  }
  return visits;
}

#if defined(__x86_64__) && defined(__GNUC__)
#define TARMAC_WIDE_WALK 1
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
/// Measurements: docs/perf/archive/perf-occ5.md; `tarmac-bench --narrow-walk` runs the walks one
/// at a time.
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
__attribute__((target("avx512f,avx512dq"))) std::uint64_t walk_rays_wide(const WindowGeometry& w,
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

/// Walks set up for the four-lane walk (walk_rays_lanes4), a batch at a time, each field in its
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
/// further along each axis it moves on, clamped to the window (see walk_rays_lanes4).
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
/// of 0 into word 0) until then. Neighbours in direction mostly end near each other (BALM hall:
/// 9 % of the lane steps idle); refilling a lane as its walk ends cost more than that without
/// AVX-512's expand-loads, and sorting each batch by length more still. The only branch per step
/// is to a rare path for ring wraps and window exits.
/// The box: each walk adds its start and its end voxel one step further along each axis it
/// moves on (the last steps may cross in another order than exact arithmetic would, by one
/// voxel at most), clamped to the window. A superset of the voxels marked: the apply pass
/// reads the marks inside it, so only its time changes.
/// Measurements: docs/perf/archive/perf-occ8.md.
template <bool kFlagWords>
__attribute__((target("avx2"))) std::uint64_t walk_rays_lanes4(const WindowGeometry& w,
                                                               const RayStart& start,
                                                               const TaskRays& rays,
                                                               FreeMarks marks, MarkBox& box) {
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
    // upper halves of the vector registers are in use (BALM hall, Zen 3, harness: 5.7 ns per
    // visit against 3.0 with this): they are cleared before every batch's end points.
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

/// Whether this processor runs walk_rays_lanes4 (checked once).
bool lanes4_walk_supported() {
  static const bool supported = __builtin_cpu_supports("avx2") != 0;
  return supported;
}

/// What integrate_hits' first pass in lanes reads and writes: the returns, the origin, max
/// range, the window; each return's slot and window column out.
struct HitPass {
  std::span<const Eigen::Vector3f> points;
  const Eigen::Vector3d& origin_W;
  double max_range, voxel_size;
  const VoxelIndex& min;
  const Eigen::Vector3i& dims;
  const std::array<int, 3>& ring_min;
  std::uint32_t *slot_out, *column_out;
  /// Within this of max range, the scalar expression decides whether a return is in range.
  [[nodiscard]] double near_edge() const { return 1e-9 * std::max(1.0, max_range); }
};

/// Points [i, i + m) of `points` as three columns of doubles, for the hit pass's lanes (lanes
/// from m on stay 0).
template <int kLanes>
[[gnu::always_inline]] inline void point_columns(std::span<const Eigen::Vector3f> points,
                                                 std::size_t i, int m, double (&c)[3][kLanes]) {
  for (int j = 0; j < m; ++j) {
    for (int a = 0; a < 3; ++a) c[a][j] = static_cast<double>(points[i + j][a]);
  }
}

/// integrate_hits' first pass in AVX-512 lanes, eight returns at a time: each return's slot
/// (kNoSlot when not finite, beyond max range or outside the window) and window column, with the
/// scalar pass's arithmetic (the same divisions and floors; the range's norm summed in the same
/// order, and a return within 1e-9 of max range decided by the scalar expression itself).
/// Returns how many returns fell outside the window.
__attribute__((target("avx512f,avx512dq"))) std::uint64_t hit_voxels_wide(const HitPass& h) {
  const auto& [points, origin_W, max_range, voxel_size, min, dims, ring_min, slot_out, column_out] =
      h;
  constexpr int kLanes = 8;
  const std::size_t n = points.size();
  std::uint64_t outside = 0;
  const __m512d voxel = _mm512_set1_pd(voxel_size);
  const __m512d range = _mm512_set1_pd(max_range);
  const __m512d near_edge = _mm512_set1_pd(h.near_edge());
  const __m512d abs_bits = _mm512_castsi512_pd(_mm512_set1_epi64(0x7fffffffffffffffLL));
  for (std::size_t i = 0; i < n; i += kLanes) {
    const int m = static_cast<int>(std::min<std::size_t>(kLanes, n - i));
    alignas(64) double c[3][kLanes] = {};
    point_columns<kLanes>(points, i, m, c);
    auto keep = static_cast<__mmask8>((1u << m) - 1u);
    __m512d sq = _mm512_setzero_pd();
    __m512i slot = _mm512_setzero_si512(), stride = _mm512_set1_epi64(1);
    __m512i rel[3];
    __mmask8 inside = 0xff;
    for (int a = 0; a < 3; ++a) {
      const __m512d x = _mm512_load_pd(c[a]);
      keep &= _mm512_cmp_pd_mask(_mm512_sub_pd(x, x), _mm512_setzero_pd(), _CMP_EQ_OQ);  // finite
      const __m512d d = _mm512_sub_pd(x, _mm512_set1_pd(origin_W[a]));
      sq = a == 0 ? _mm512_mul_pd(d, d) : _mm512_add_pd(sq, _mm512_mul_pd(d, d));
      const __m512d q = _mm512_div_pd(x, voxel);
      const __m512i cell = _mm512_cvtpd_epi64(
          _mm512_mask_roundscale_pd(q, 0xff, q, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
      const __m512i size = _mm512_set1_epi64(dims[a]);
      rel[a] = _mm512_sub_epi64(cell, _mm512_set1_epi64(min[a]));
      inside &= _mm512_cmplt_epu64_mask(rel[a], size);
      __m512i ring = _mm512_add_epi64(rel[a], _mm512_set1_epi64(ring_min[a]));
      ring = _mm512_mask_sub_epi64(ring, _mm512_cmpge_epi64_mask(ring, size), ring, size);
      slot = _mm512_add_epi64(slot, _mm512_mullo_epi64(ring, stride));
      stride = _mm512_mullo_epi64(stride, size);
    }
    const __m512d norm = _mm512_mask_sqrt_pd(sq, 0xff, sq);
    keep &= _mm512_cmp_pd_mask(norm, range, _CMP_LE_OQ);
    // Within a hair of max range: the scalar expression decides (its summation order is
    // Eigen's; the lanes' is meant to be the same, this makes it so whatever it is).
    const __mmask8 edge = _mm512_cmp_pd_mask(_mm512_and_pd(_mm512_sub_pd(norm, range), abs_bits),
                                             near_edge, _CMP_LE_OQ);
    for (unsigned lanes = edge & ((1u << m) - 1u); lanes != 0; lanes &= lanes - 1) {
      const int j = std::countr_zero(lanes);
      const Eigen::Vector3f& p = points[i + static_cast<std::size_t>(j)];
      const bool in_range = p.allFinite() && !((p.cast<double>() - origin_W).norm() > max_range);
      keep = static_cast<__mmask8>(in_range ? (keep | (1u << j)) : (keep & ~(1u << j)));
    }
    outside += static_cast<std::uint64_t>(std::popcount(static_cast<unsigned>(keep & ~inside)));
    keep &= inside;
    alignas(64) std::int64_t slots[kLanes], columns[kLanes];
    _mm512_store_si512(slots, slot);
    _mm512_store_si512(
        columns, _mm512_add_epi64(_mm512_mullo_epi64(rel[1], _mm512_set1_epi64(dims[0])), rel[0]));
    for (int j = 0; j < m; ++j) {
      const bool k = ((keep >> j) & 1) != 0;
      slot_out[i + static_cast<std::size_t>(j)] =
          k ? static_cast<std::uint32_t>(slots[j]) : kNoSlot;
      if (k) column_out[i + static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(columns[j]);
    }
  }
  return outside;
}

/// integrate_hits' first pass in AVX2 lanes, four returns at a time, as hit_voxels_wide (the
/// same divisions, floors and norm; a return within 1e-9 of max range decided by the scalar
/// expression). The window's indices in 32 bits: a window has fewer than 2^31 voxels
/// (OccupancyParams::validate) and every coordinate it holds is within ±2^31 voxels.
/// Returns how many returns fell outside the window.
__attribute__((target("avx2"))) std::uint64_t hit_voxels_lanes4(const HitPass& h) {
  const auto& [points, origin_W, max_range, voxel_size, min, dims, ring_min, slot_out, column_out] =
      h;
  constexpr int kLanes = 4;
  const std::size_t n = points.size();
  std::uint64_t outside = 0;
  const __m256d voxel = _mm256_set1_pd(voxel_size);
  const __m256d range = _mm256_set1_pd(max_range);
  const __m256d near_edge = _mm256_set1_pd(h.near_edge());
  const __m256d abs_bits = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
  for (std::size_t i = 0; i < n; i += kLanes) {
    const int m = static_cast<int>(std::min<std::size_t>(kLanes, n - i));
    alignas(32) double c[3][kLanes] = {};
    point_columns<kLanes>(points, i, m, c);
    __m256d keep = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    __m256d sq = _mm256_setzero_pd();
    __m128i slot = _mm_setzero_si128(), stride = _mm_set1_epi32(1), inside = _mm_set1_epi32(-1);
    __m128i rel[3];
    for (int a = 0; a < 3; ++a) {
      const __m256d x = _mm256_load_pd(c[a]);
      keep = _mm256_and_pd(keep, _mm256_cmp_pd(_mm256_sub_pd(x, x), _mm256_setzero_pd(),
                                               _CMP_EQ_OQ));  // finite
      const __m256d d = _mm256_sub_pd(x, _mm256_set1_pd(origin_W[a]));
      sq = a == 0 ? _mm256_mul_pd(d, d) : _mm256_add_pd(sq, _mm256_mul_pd(d, d));
      const __m128i cell = _mm256_cvttpd_epi32(
          _mm256_round_pd(_mm256_div_pd(x, voxel), _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
      const __m128i size = _mm_set1_epi32(dims[a]);
      rel[a] = _mm_sub_epi32(cell, _mm_set1_epi32(min[a]));
      inside = _mm_and_si128(inside, _mm_andnot_si128(_mm_cmpgt_epi32(_mm_setzero_si128(), rel[a]),
                                                      _mm_cmpgt_epi32(size, rel[a])));
      __m128i ring = _mm_add_epi32(rel[a], _mm_set1_epi32(ring_min[a]));
      ring = _mm_sub_epi32(ring, _mm_andnot_si128(_mm_cmpgt_epi32(size, ring), size));
      slot = _mm_add_epi32(slot, _mm_mullo_epi32(ring, stride));
      stride = _mm_mullo_epi32(stride, size);
    }
    const __m256d norm = _mm256_sqrt_pd(sq);
    keep = _mm256_and_pd(keep, _mm256_cmp_pd(norm, range, _CMP_LE_OQ));
    const int edge = _mm256_movemask_pd(
        _mm256_cmp_pd(_mm256_and_pd(_mm256_sub_pd(norm, range), abs_bits), near_edge, _CMP_LE_OQ));
    alignas(16) std::int32_t slots[kLanes], columns[kLanes], in[kLanes];
    _mm_store_si128(reinterpret_cast<__m128i*>(slots), slot);
    _mm_store_si128(reinterpret_cast<__m128i*>(columns),
                    _mm_add_epi32(_mm_mullo_epi32(rel[1], _mm_set1_epi32(dims[0])), rel[0]));
    _mm_store_si128(reinterpret_cast<__m128i*>(in), inside);
    const int kept = _mm256_movemask_pd(keep);
    for (int j = 0; j < m; ++j) {
      bool k = ((kept >> j) & 1) != 0;
      if (((edge >> j) & 1) != 0) {
        // Within a hair of max range: the scalar expression decides (its summation order is
        // Eigen's; the lanes' is meant to be the same, this makes it so whatever it is).
        const Eigen::Vector3f& p = points[i + static_cast<std::size_t>(j)];
        k = p.allFinite() && !((p.cast<double>() - origin_W).norm() > max_range);
      }
      if (k && in[j] == 0) ++outside;
      k = k && in[j] != 0;
      slot_out[i + static_cast<std::size_t>(j)] =
          k ? static_cast<std::uint32_t>(slots[j]) : kNoSlot;
      if (k) column_out[i + static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(columns[j]);
    }
  }
  return outside;
}

/// Whether this processor runs walk_rays_wide (checked once).
bool wide_walk_supported() {
  static const bool supported =
      __builtin_cpu_supports("avx512f") != 0 && __builtin_cpu_supports("avx512dq") != 0;
  return supported;
}
#endif

/// The walks of one task, `lanes` at a time (8, 4 or 1: see OccupancyMap::walk_lanes), with
/// per-word flags (large windows) or without.
std::uint64_t walk_task(const WindowGeometry& w, const RayStart& start, const TaskRays& rays,
                        FreeMarks marks, MarkBox& box, int lanes) {
  // The box grows at the end of every ray: it lives on this task's own stack until the task
  // is done. The tasks' boxes share a cache line, and updating them in place while another
  // task did the same cost the walks about a quarter of their time on 2 threads.
  MarkBox local;
  std::uint64_t visits = 0;
  const bool flags = marks.dirty != nullptr;
#if defined(TARMAC_WIDE_WALK)
  if (lanes == 8) {
    visits = flags ? walk_rays_wide<true>(w, start, rays, marks, local)
                   : walk_rays_wide<false>(w, start, rays, marks, local);
  } else if (lanes == 4) {
    visits = flags ? walk_rays_lanes4<true>(w, start, rays, marks, local)
                   : walk_rays_lanes4<false>(w, start, rays, marks, local);
  }
#endif
  if (lanes == 1) {
    visits = flags ? walk_rays<true>(w, start, rays, marks, local)
                   : walk_rays<false>(w, start, rays, marks, local);
  }
  box = local;
  return visits;
}

/// Words with at least this many voxels to miss take the four-lanes path.
constexpr int kDenseWord = 8;

/// The miss update's constants, four lanes each.
struct MissLanes {
  Float4 miss, min, zero, unknown;
  MissLanes(float l_miss, float l_min)
      : miss{l_miss, l_miss, l_miss, l_miss},
        min{l_min, l_min, l_min, l_min},
        zero{0.0f, 0.0f, 0.0f, 0.0f},
        unknown{OccupancyMap::kUnknown, OccupancyMap::kUnknown, OccupancyMap::kUnknown,
                OccupancyMap::kUnknown} {}
};

/// The miss of every voxel of one mark word (64 consecutive slots at `l`, bit k of `marks`
/// for slot k) that reads free or unknown, four lanes at a time: the same arithmetic as one at a
/// time (kUnknown counts as 0, then max(l + miss, min)); unmarked and occupied lanes are
/// written back unchanged. Sets in `occupied` the marked voxels reading occupied (left to the
/// caller's static-layer logic), in `void_heights` those that reach the lower clamp now and in
/// `at_floor` every free one that reads the lower clamp after the miss.
void miss_free_word(float* l, std::uint64_t marks, const MissLanes& c, std::uint64_t& occupied,
                    std::uint64_t& void_heights, std::uint64_t& at_floor) {
  const Int4 lane = {1, 2, 4, 8};
  for (int g = 0; g < 16; ++g) {
    const auto nibble = static_cast<std::int32_t>((marks >> (4 * g)) & 15);
    if (nibble == 0) continue;
    const Int4 marked = (lane & nibble) != 0;
    Float4 v;
    std::memcpy(&v, l + 4 * g, sizeof v);
    const Int4 free = marked & (v <= c.zero);
    const Float4 known = reinterpret_cast<Float4>(reinterpret_cast<Int4>(v) & ~(v == c.unknown));
    const Float4 sum = known + c.miss;
    const Int4 below = sum < c.min;
    const Float4 next = reinterpret_cast<Float4>((reinterpret_cast<Int4>(c.min) & below) |
                                                 (reinterpret_cast<Int4>(sum) & ~below));
    const Int4 voided = free & (next == c.min) & (v > c.min);
    const Float4 out = reinterpret_cast<Float4>((reinterpret_cast<Int4>(next) & free) |
                                                (reinterpret_cast<Int4>(v) & ~free));
    std::memcpy(l + 4 * g, &out, sizeof out);
    occupied |= std::uint64_t{lane_bits(marked & (v > c.zero))} << (4 * g);
    void_heights |= std::uint64_t{lane_bits(voided)} << (4 * g);
    at_floor |= std::uint64_t{lane_bits(free & (next == c.min))} << (4 * g);
  }
}

}  // namespace

float log_odds_of(float probability) {
  return std::log(probability / (1.0f - probability));
}
float probability_of(float log_odds) {
  return 1.0f / (1.0f + std::exp(-log_odds));
}

Status OccupancyParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) {
    return Error{"config.range", "occupancy." + key + ": " + why};
  };
  if (!(voxel_size_m >= 0.02 && voxel_size_m <= 2.0))
    return bad("voxel_size_m", "must be in [0.02, 2]");
  for (const int n : {window_x_vox, window_y_vox, window_z_vox}) {
    if (n < 4 || n > 4096) return bad("window_*_vox", "must be in [4, 4096]");
  }
  if (static_cast<double>(window_x_vox) * window_y_vox * window_z_vox > 512e6) {
    return bad("window_*_vox", "window larger than 512 M voxels");
  }
  if (!(prob_hit > 0.5f && prob_hit < 1.0f)) return bad("prob_hit", "must be in (0.5, 1)");
  if (!(prob_miss > 0.0f && prob_miss < 0.5f)) return bad("prob_miss", "must be in (0, 0.5)");
  if (!(clamp_min > 0.0f && clamp_min < 0.5f)) return bad("clamp_min", "must be in (0, 0.5)");
  if (!(clamp_max > 0.5f && clamp_max < 1.0f)) return bad("clamp_max", "must be in (0.5, 1)");
  // Bounded: a walk's voxel indices are 32-bit (the lanes' conversions, the scalar casts), which
  // holds for any world coordinate within about ±4e7 voxels of a voxel size's range: far beyond
  // any sensor.
  if (!(max_range_m > 0.0 && max_range_m <= 1000.0)) {
    return bad("max_range_m", "must be in (0, 1000]");
  }
  if (!(clearing_range_m >= 0.0 && clearing_range_m <= 1000.0)) {
    return bad("clearing_range_m", "must be in [0, 1000]");
  }
  if (!(ground_radius_m >= 0.0 && ground_radius_m <= 10.0)) {
    return bad("ground_radius_m", "must be in [0, 10]");
  }
  if (!(window_below_m >= 0.0 && window_below_m <= window_z_vox * voxel_size_m)) {
    return bad("window_below_m", "must be within the window height");
  }
  if (static_promote_scans < 0 || static_promote_scans > kCount) {
    return bad("static_promote_scans", "must be in [0, 127]");
  }
  if (static_demote_scans < 1 || static_demote_scans > kCount) {
    return bad("static_demote_scans", "must be in [1, 127]");
  }
  return Ok{};
}

namespace {
constexpr std::size_t kReservedHitSlots = std::size_t{1} << 17;
}  // namespace

OccupancyMap::OccupancyMap(const OccupancyParams& params)
    : params_(params),
      dims_(params.window_x_vox, params.window_y_vox, params.window_z_vox),
      min_(VoxelIndex::Zero()),
      l_hit_(log_odds_of(params.prob_hit)),
      l_miss_(log_odds_of(params.prob_miss)),
      l_min_(log_odds_of(params.clamp_min)),
      l_max_(log_odds_of(params.clamp_max)) {
  TARMAC_ASSERT(params.validate().ok(), "OccupancyParams must be validated first");
  const std::size_t n = static_cast<std::size_t>(dims_.x()) * dims_.y() * dims_.z();
  // Padded to whole 64-slot mark words (never marked, always kUnknown): miss_free_word reads and
  // writes a word's slots four at a time, and a window whose voxel count is not a multiple of 4
  // would otherwise have its last group reach past the end (ASan found it).
  log_odds_.assign((n + 63) / 64 * 64, kUnknown);
  rise_cm_.assign(n, 0);
  hit_floor_.assign(n, kNoHitFloor);
  state_.assign(n, 0);
  static_ = std::make_unique<StaticStore>(static_reservation(dims_));
  kept_.resize(kSlabTasks);
  for (auto& k : kept_) k.reserve(4096);
  candidates_.resize(kApplyTasks);
  for (auto& c : candidates_) c.reserve(4096);  // per scan and task; grows once if more
  scan_ground_z_.assign(static_cast<std::size_t>(dims_.x()) * dims_.y(),
                        std::numeric_limits<float>::infinity());
  scan_ground_near_z_.assign(scan_ground_z_.size(), std::numeric_limits<float>::infinity());
  const std::size_t words = (n + 63) / 64;
  hit_bits_.assign(words, 0);
  floor_bits_.assign(words, 0);
  free_bits_.assign(kRayTasks, std::vector<std::uint64_t>(words, 0));
  if (n > kUnflaggedVoxels) {
    dirty_words_.assign(kRayTasks, std::vector<std::uint64_t>((words >> kBlockShift) + 1, 0));
  }
  // Reserved up front so scans do not grow them in the cycle (DESIGN.md §3): every window column
  // can hold a ground return; the hit list takes a 64-beam scan's distinct return voxels (a
  // scan with more grows it once, then keeps the capacity). Written once here, so the first
  // scan does not pay their page faults either.
  const auto warm = [](auto& v, std::size_t n) {
    v.resize(n);
    v.clear();
  };
  // These two keep their size (their counts are n_ground_cols_, n_hit_slots_): growing them from
  // empty each scan zero-filled ~150 KB per scan.
  scan_ground_cols_.assign(static_cast<std::size_t>(dims_.x()) * dims_.y() + 1, 0);
  hit_slots_.assign(kReservedHitSlots, 0);
  warm(hit_slot_, kReservedHitSlots);
  warm(hit_column_, kReservedHitSlots);
  warm(hit_height_, kReservedHitSlots);
  warm(hit_rise_, kReservedHitSlots);
  warm(ray_order_, kReservedHitSlots);
  warm(ray_bucket_, kReservedHitSlots);
  ray_bucket_count_.assign(kBucketTasks * kDirBuckets, 0);
}

int OccupancyMap::walk_lanes() const {
#if defined(TARMAC_WIDE_WALK)
  if (walk_lanes_ >= 8 && wide_walk_supported()) return 8;
  if (walk_lanes_ >= 4 && lanes4_walk_supported()) return 4;
#endif
  return 1;
}

OccupancyMap::OccupancyMap(OccupancyMap&&) noexcept = default;
OccupancyMap& OccupancyMap::operator=(OccupancyMap&&) noexcept = default;
OccupancyMap::~OccupancyMap() = default;

std::size_t OccupancyMap::memory_bytes() const {
  std::size_t bytes =
      log_odds_.capacity() * sizeof(float) + rise_cm_.capacity() + state_.capacity() +
      hit_floor_.capacity() + scan_rays_.memory_bytes() +
      static_->keys.capacity() * (sizeof(StaticStore::Mask) + sizeof(std::uint64_t)) +
      (scan_ground_z_.capacity() + scan_ground_near_z_.capacity()) * sizeof(float) +
      scan_ground_cols_.capacity() * sizeof(std::uint32_t) +
      (hit_bits_.capacity() + floor_bits_.capacity()) * sizeof(std::uint64_t) +
      hit_slots_.capacity() * sizeof(std::uint32_t) +
      (hit_slot_.capacity() + hit_column_.capacity()) * sizeof(std::uint32_t) +
      hit_height_.capacity() * sizeof(float) + hit_rise_.capacity() +
      (ray_order_.capacity() + ray_bucket_count_.capacity()) * sizeof(std::uint32_t) +
      ray_bucket_.capacity() * sizeof(std::uint16_t);
  for (const auto& b : free_bits_) bytes += b.capacity() * sizeof(std::uint64_t);
  for (const auto& d : dirty_words_) bytes += d.capacity() * sizeof(std::uint64_t);
  for (const auto& c : candidates_) bytes += c.capacity() * sizeof(std::uint32_t);
  bytes += miss_decision_.capacity();
  return bytes;
}

VoxelIndex OccupancyMap::voxel_of(const Eigen::Vector3d& p_W) const {
  return (p_W / params_.voxel_size_m).array().floor().cast<int>();
}

bool OccupancyMap::in_window(const VoxelIndex& v) const {
  const Eigen::Vector3i r = v - min_;
  return (r.array() >= 0).all() && (r.array() < dims_.array()).all();
}

std::size_t OccupancyMap::slot(const VoxelIndex& v) const {
  return (static_cast<std::size_t>(wrap(v.z(), dims_.z())) * dims_.y() + wrap(v.y(), dims_.y())) *
             dims_.x() +
         wrap(v.x(), dims_.x());
}

float OccupancyMap::log_odds(const VoxelIndex& v) const {
  return in_window(v) ? log_odds_[slot(v)] : kUnknown;
}

void OccupancyMap::clear_slabs(int axis, int first, int count, TaskRunner& runner) {
  const int nx = dims_.x(), ny = dims_.y(), nz = dims_.z();
  const int n = dims_[axis];
  // The slabs' ring indices: one run, or two where the ring wraps.
  const int r0 = wrap(first, n);
  const std::array<std::array<int, 2>, 2> runs{
      {{r0, std::min(count, n - r0)}, {0, count - std::min(count, n - r0)}}};
  // The leaving voxels to keep (keep_leaving), collected per task, inserted in task order.
  for (auto& k : kept_) k.clear();
  const auto clear = [&](std::size_t s, std::size_t len, std::vector<std::uint32_t>& kept) {
    keep_leaving(s, len, kept);
    const auto at = static_cast<std::ptrdiff_t>(s);
    std::fill_n(log_odds_.begin() + at, len, kUnknown);
    std::fill_n(rise_cm_.begin() + at, len, std::uint8_t{0});
    std::fill_n(hit_floor_.begin() + at, len, kNoHitFloor);
    std::fill_n(state_.begin() + at, len, std::uint8_t{0});
    clear_floor_bits(s, len);
  };
  const std::size_t row_len = static_cast<std::size_t>(nx);
  const std::size_t layer_len = row_len * static_cast<std::size_t>(ny);
  const std::size_t total = layer_len * static_cast<std::size_t>(nz);
  // Each task clears what lies in its own range of slots, the ranges cut at multiples of 64,
  // so that no two tasks write a word of floor bits (and a voxel's clearing does not depend on
  // the split). The x slabs' short runs in every row are cache misses, which two threads
  // overlap better than one.
  runner.parallel_for(kSlabTasks, [&](std::size_t task) {
    const std::size_t lo = (total * task / kSlabTasks) & ~std::size_t{63};
    const std::size_t hi =
        task + 1 == kSlabTasks ? total : (total * (task + 1) / kSlabTasks) & ~std::size_t{63};
    const auto clip = [&](std::size_t s, std::size_t len) {
      const std::size_t a = std::max(s, lo), b = std::min(s + len, hi);
      if (a < b) clear(a, b - a, kept_[task]);
    };
    for (const auto& [r, len] : runs) {
      if (len == 0) continue;
      const auto ur = static_cast<std::size_t>(r), ulen = static_cast<std::size_t>(len);
      if (axis == 2) {
        clip(ur * layer_len, ulen * layer_len);  // whole layers
      } else if (axis == 1) {
        for (std::size_t z = 0; z < static_cast<std::size_t>(nz); ++z) {
          clip(z * layer_len + ur * row_len, ulen * row_len);  // whole rows of each layer
        }
      } else {
        // Along x the slabs cut every row: all of them in one pass, each row's run at once (a
        // pass per slab touched each row's lines again: 2.8 ms per scan driving on MulRan).
        for (std::size_t q = lo / row_len; q * row_len < hi; ++q) clip(q * row_len + ur, ulen);
      }
    }
  });
  for (const auto& kept : kept_) {
    for (const std::uint32_t q : kept) static_->insert(voxel_of_slot(q));
  }
}

void OccupancyMap::keep_leaving(std::size_t first, std::size_t count,
                                std::vector<std::uint32_t>& kept) const {
  if (params_.static_promote_scans == 0) return;
  for (std::size_t q = first; q < first + count; ++q) {
    if (log_odds_[q] > 0.0f && (state_[q] & kStatic) == 0 && state_[q] >= kKeepHits) {
      kept.push_back(static_cast<std::uint32_t>(q));
    }
  }
}

void OccupancyMap::recenter(const Eigen::Vector3d& position_W) {
  SerialRunner serial;
  recenter(position_W, serial);
}

void OccupancyMap::recenter(const Eigen::Vector3d& position_W, TaskRunner& runner) {
  const double v = params_.voxel_size_m;
  VoxelIndex target;
  target.x() = static_cast<int>(std::floor(position_W.x() / v)) - dims_.x() / 2;
  target.y() = static_cast<int>(std::floor(position_W.y() / v)) - dims_.y() / 2;
  target.z() = static_cast<int>(std::floor((position_W.z() - params_.window_below_m) / v));
  if (!placed_) {
    min_ = target;
    placed_ = true;
    restore_static(min_, min_ + dims_ - VoxelIndex::Ones());
    return;
  }
  // Axis by axis: the voxels entering along an axis occupy exactly the ring slabs of the voxels
  // leaving, so clearing those slabs forgets the old content and nothing else; the static layer's
  // voxels among the entering ones read static again.
  for (int a = 0; a < 3; ++a) {
    const int shift = target[a] - min_[a];
    if (shift == 0) continue;
    VoxelIndex lo = min_, hi = min_ + dims_ - VoxelIndex::Ones();
    if (std::abs(shift) >= dims_[a]) {
      keep_leaving(0, state_.size(), kept_[0]);
      for (const std::uint32_t q : kept_[0]) static_->insert(voxel_of_slot(q));
      kept_[0].clear();
      std::fill(log_odds_.begin(), log_odds_.end(), kUnknown);
      std::fill(rise_cm_.begin(), rise_cm_.end(), std::uint8_t{0});
      std::fill(hit_floor_.begin(), hit_floor_.end(), kNoHitFloor);
      std::fill(state_.begin(), state_.end(), std::uint8_t{0});
      std::fill(floor_bits_.begin(), floor_bits_.end(), std::uint64_t{0});
      lo[a] = target[a];
      hi[a] = target[a] + dims_[a] - 1;
    } else if (shift > 0) {
      clear_slabs(a, min_[a] + dims_[a], shift, runner);
      lo[a] = min_[a] + dims_[a];
      hi[a] = target[a] + dims_[a] - 1;
    } else {
      clear_slabs(a, target[a], -shift, runner);
      lo[a] = target[a];
      hi[a] = min_[a] - 1;
    }
    min_[a] = target[a];
    restore_static(lo, hi);
  }
}

void OccupancyMap::restore_static(const VoxelIndex& lo, const VoxelIndex& hi) {
  if (static_->count == 0) return;
  constexpr int kS = StaticStore::kShift;
  for (int bz = lo.z() >> kS; bz <= hi.z() >> kS; ++bz) {
    for (int by = lo.y() >> kS; by <= hi.y() >> kS; ++by) {
      for (int bx = lo.x() >> kS; bx <= hi.x() >> kS; ++bx) {
        const StaticStore::Mask* block = static_->find(StaticStore::key(bx, by, bz));
        if (block == nullptr) continue;
        for (int w = 0; w < 8; ++w) {
          for (std::uint64_t m = (*block)[w]; m != 0; m &= m - 1) {
            const int b = w * 64 + std::countr_zero(m);
            const VoxelIndex v((bx << kS) | (b & 7), (by << kS) | ((b >> 3) & 7),
                               (bz << kS) | (b >> 6));
            if ((v.array() < lo.array()).any() || (v.array() > hi.array()).any()) continue;
            const std::size_t s = slot(v);
            state_[s] = kStatic;
            log_odds_[s] = std::max(log_odds_[s], l_hit_);
            clear_floor_bits(s, 1);
          }
        }
      }
    }
  }
}

void OccupancyMap::clear_floor_bits(std::size_t first, std::size_t count) {
  for (std::size_t s = first; s < first + count;) {
    const std::size_t bit = s & 63;
    const std::size_t n = std::min<std::size_t>(64 - bit, first + count - s);
    const std::uint64_t run = n == 64 ? ~std::uint64_t{0} : ((std::uint64_t{1} << n) - 1) << bit;
    floor_bits_[s >> 6] &= ~run;
    s += n;
  }
}

VoxelIndex OccupancyMap::voxel_of_slot(std::size_t s) const {
  const auto nx = static_cast<std::size_t>(dims_.x()), ny = static_cast<std::size_t>(dims_.y());
  const int rings[3] = {static_cast<int>(s % nx), static_cast<int>((s / nx) % ny),
                        static_cast<int>(s / (nx * ny))};
  VoxelIndex v;
  for (int a = 0; a < 3; ++a) v[a] = min_[a] + wrap(rings[a] - wrap(min_[a], dims_[a]), dims_[a]);
  return v;
}

bool OccupancyMap::is_static(const VoxelIndex& v) const {
  return static_->contains(v);
}

std::size_t OccupancyMap::static_count() const {
  return static_->count;
}

void OccupancyMap::export_static(std::vector<VoxelIndex>& out) const {
  out.clear();
  out.reserve(static_->count);
  static_->for_each([&](std::uint64_t key, const StaticStore::Mask& mask) {
    const auto field = [&](int shift) {
      return static_cast<int>(static_cast<std::int64_t>((key >> shift) & ((1u << 21) - 1)) -
                              (std::int64_t{1} << 20));
    };
    const int bx = field(0), by = field(21), bz = field(42);
    for (int w = 0; w < 8; ++w) {
      for (std::uint64_t m = mask[w]; m != 0; m &= m - 1) {
        const int b = w * 64 + std::countr_zero(m);
        out.emplace_back((bx << 3) | (b & 7), (by << 3) | ((b >> 3) & 7), (bz << 3) | (b >> 6));
      }
    }
  });
  std::sort(out.begin(), out.end(), [](const VoxelIndex& a, const VoxelIndex& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
}

void OccupancyMap::import_static(std::span<const VoxelIndex> voxels) {
  // Window voxels that were static and are not any more fall back to unknown (their dynamic
  // content was the static floor, not an observation).
  for (std::size_t s = 0; s < state_.size(); ++s) {
    if ((state_[s] & kStatic) != 0) {
      state_[s] = 0;
      log_odds_[s] = kUnknown;  // static: never at the lower clamp
    }
  }
  static_ = std::make_unique<StaticStore>(static_reservation(dims_));
  for (const VoxelIndex& v : voxels) static_->insert(v);
  if (placed_) restore_static(min_, min_ + dims_ - VoxelIndex::Ones());
}

std::array<int, 3> OccupancyMap::ring_origin() const {
  return {wrap(min_.x(), dims_.x()), wrap(min_.y(), dims_.y()), wrap(min_.z(), dims_.z())};
}

void OccupancyMap::integrate_hits(const Eigen::Vector3d& origin_W,
                                  std::span<const Eigen::Vector3f> points_W,
                                  const Eigen::Vector3d& up_W, OccupancyUpdateStats& stats) {
  const int nx = dims_.x(), ny = dims_.y();
  const std::size_t n_points = points_W.size();
  const double max_range = params_.max_range_m;
  const std::array<int, 3> ring_min = ring_origin();
  // a) Per return: its slot and window column, or none (beyond max range or outside the
  //    window), and its height along up_W; and the scan's own ground: the lowest return
  //    per window column (only the columns this scan touched are reset next time).
  constexpr float kNone = std::numeric_limits<float>::infinity();
  // A zero or non-finite up axis is taken as +z: the heights must be numbers (a column's first
  // return is booked by its ground leaving +inf, below).
  const double up_norm = up_W.norm();
  const Eigen::Vector3f up = std::isfinite(up_norm) && up_norm > 0.0
                                 ? Eigen::Vector3f((up_W / up_norm).cast<float>())
                                 : Eigen::Vector3f::UnitZ();
  hit_slot_.resize(n_points);
  hit_column_.resize(n_points);
  hit_height_.resize(n_points);
  hit_rise_.resize(n_points);
  const double v_m = params_.voxel_size_m;
  for (std::size_t k = 0; k < n_ground_cols_; ++k) scan_ground_z_[scan_ground_cols_[k]] = kNone;
  n_ground_cols_ = 0;
  // The slot and column of each return (none: not finite, beyond max range or outside).
  bool in_lanes = false;
#if defined(TARMAC_WIDE_WALK)
  const int lanes = walk_lanes();
  in_lanes = lanes > 1;
  const HitPass pass{points_W, origin_W,         max_range,         v_m, min_, dims_,
                     ring_min, hit_slot_.data(), hit_column_.data()};
  if (lanes == 8) {
    stats.outside_window += hit_voxels_wide(pass);
  } else if (lanes == 4) {
    stats.outside_window += hit_voxels_lanes4(pass);
  }
#endif
  if (!in_lanes) {
    for (std::size_t i = 0; i < n_points; ++i) {
      const Eigen::Vector3f& p = points_W[i];
      hit_slot_[i] = kNoSlot;
      if (!p.allFinite() || (p.cast<double>() - origin_W).norm() > max_range) continue;
      std::int64_t slot = 0;
      std::int64_t stride = 1;
      bool inside = true;
      int rel[3];
      for (int a = 0; a < 3; ++a) {
        rel[a] = static_cast<int>(floor_to_int(static_cast<double>(p[a]) / v_m)) - min_[a];
        inside = inside && static_cast<unsigned>(rel[a]) < static_cast<unsigned>(dims_[a]);
        int ring = ring_min[a] + rel[a];
        if (ring >= dims_[a]) ring -= dims_[a];
        slot += ring * stride;
        stride *= dims_[a];
      }
      if (!inside) {
        ++stats.outside_window;
        continue;
      }
      hit_slot_[i] = static_cast<std::uint32_t>(slot);
      hit_column_[i] = static_cast<std::uint32_t>(rel[1] * nx + rel[0]);
    }
  }
  // Heights, and the lowest return per column, in point order. A column's first return books
  // it without a branch (whether a column was touched before is as good as random: the branch
  // was a fifth of integrate_hits' own time): every return writes its column at the list's
  // end, which moves on only for a first return, so the list has room for one entry more than
  // there can be columns.
  const std::uint32_t* const slot_of_hit = hit_slot_.data();
  {
    const std::size_t columns = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
    scan_ground_cols_.resize(std::max(scan_ground_cols_.size(), std::min(n_points, columns) + 1));
    std::uint32_t* const touched = scan_ground_cols_.data();
    std::size_t n_touched = 0;
    float* const ground = scan_ground_z_.data();
    float* const height_of_hit = hit_height_.data();
    const std::uint32_t* const column_of_hit = hit_column_.data();
    for (std::size_t i = 0; i < n_points; ++i) {
      if (slot_of_hit[i] == kNoSlot) continue;
      const std::uint32_t column = column_of_hit[i];
      const float height = up.dot(points_W[i]);
      height_of_hit[i] = height;
      const float g = ground[column];
      touched[n_touched] = column;
      n_touched += g == kNone ? 1 : 0;
      ground[column] = std::min(g, height);
    }
    n_ground_cols_ = n_touched;
  }
  // b) Rise above the lowest return of this scan within ground_radius_m (an object cannot
  //    hide the ground around it).
  //    Once per column the scan touched (returns stack up in columns: walls, poles), then
  //    per return; a return's own column is among them, so its ground is at most its height.
  const int r = static_cast<int>(std::lround(params_.ground_radius_m / params_.voxel_size_m));
  for (std::size_t k = 0; k < n_ground_cols_; ++k) {
    const std::uint32_t c = scan_ground_cols_[k];
    const int cx = static_cast<int>(c % static_cast<std::uint32_t>(nx));
    const int cy = static_cast<int>(c / static_cast<std::uint32_t>(nx));
    float ground_z = kNone;
    for (int y = std::max(0, cy - r); y <= std::min(ny - 1, cy + r); ++y) {
      const float* row = &scan_ground_z_[static_cast<std::size_t>(y) * nx];
      for (int x = std::max(0, cx - r); x <= std::min(nx - 1, cx + r); ++x) {
        ground_z = std::min(ground_z, row[x]);
      }
    }
    scan_ground_near_z_[c] = ground_z;
  }
  // The loops that store bytes read through locals: a byte store may alias anything, and the
  // compiler would reload every member after each (BALM hall: 0.1 ms of the 0.8 ms pass).
  std::uint8_t* const rise_of_hit = hit_rise_.data();
  {
    const float* const height = hit_height_.data();
    const std::uint32_t* const column = hit_column_.data();
    const float* const ground_near = scan_ground_near_z_.data();
    for (std::size_t i = 0; i < n_points; ++i) {
      if (slot_of_hit[i] == kNoSlot) continue;
      const float ground_z = ground_near[column[i]];
      rise_of_hit[i] = static_cast<std::uint8_t>(
          std::clamp(static_cast<int>((height[i] - ground_z) * 100.0f), 0, 255));
    }
  }
  // c) One hit per voxel, in point order (promotions enter the static layer in that order).
  const int promote = params_.static_promote_scans;
  hit_slots_.resize(std::max(hit_slots_.size(), n_points));
  std::uint32_t* const first_hits = hit_slots_.data();
  std::size_t n_first = 0;
  float* const log_odds = log_odds_.data();
  std::uint8_t* const state = state_.data();
  std::uint8_t* const rise_cm = rise_cm_.data();
  std::uint8_t* const hit_floor = hit_floor_.data();
  std::uint64_t* const hit_bits = hit_bits_.data();
  std::uint64_t* const floor_bits = floor_bits_.data();
  const float l_hit = l_hit_, l_min = l_min_, l_max = l_max_;
  std::uint64_t promotions = 0;
  // The voxels of a scan's returns are scattered over the window: their lines are requested a
  // few returns ahead, so that the misses overlap instead of stalling this loop one by one.
  constexpr std::size_t kAhead = 16;
  for (std::size_t i = 0; i < n_points; ++i) {
    if (i + kAhead < n_points && slot_of_hit[i + kAhead] != kNoSlot) {
      const std::uint32_t a = slot_of_hit[i + kAhead];
      __builtin_prefetch(log_odds + a, 1);
      __builtin_prefetch(state + a, 1);
      __builtin_prefetch(rise_cm + a, 1);
      __builtin_prefetch(hit_bits + (a >> 6), 1);
      __builtin_prefetch(floor_bits + (a >> 6), 1);
    }
    const std::uint32_t s = slot_of_hit[i];
    if (s == kNoSlot) continue;
    const std::uint8_t rise = rise_of_hit[i];
    std::uint64_t& word = hit_bits[s >> 6];
    const std::uint64_t bit = std::uint64_t{1} << (s & 63);
    const std::uint8_t here = sub_voxel(points_W[i].z(), v_m);
    if ((word & bit) == 0) {
      word |= bit;
      floor_bits[s >> 6] &= ~bit;  // a hit lifts it off the lower clamp
      first_hits[n_first++] = s;
      float& l = log_odds[s];
      // Reading free or unknown until now: its lowest return starts again from this one.
      hit_floor[s] = l > 0.0f ? std::min(hit_floor[s], here) : here;
      l = std::clamp((l == kUnknown ? 0.0f : l) + l_hit, l_min, l_max);
      std::uint8_t& st = state[s];
      if ((st & kStatic) != 0) {
        st = kStatic;  // a return: the run of free observations restarts
      } else if (l <= 0.0f || promote == 0) {
        st = 0;  // not reading occupied yet: no run
      } else if ((st & kCount) + 1 >= promote) {
        st = kStatic;
        static_->insert(voxel_of_slot(s));
        ++promotions;
      } else {
        ++st;
      }
      rise_cm[s] = rise;  // the latest scan's returns replace older ones
    } else {
      rise_cm[s] = std::max(rise_cm[s], rise);
      hit_floor[s] = std::min(hit_floor[s], here);
    }
  }
  n_hit_slots_ = n_first;
  stats.hit_updates += n_first;
  stats.promotions += promotions;
}

OccupancyUpdateStats OccupancyMap::integrate(const Eigen::Vector3d& origin_W,
                                             std::span<const Eigen::Vector3f> points_W,
                                             std::span<const Eigen::Vector3f> clearing_dirs_W,
                                             TaskRunner& runner, const Eigen::Vector3d& up_W) {
  OccupancyUpdateStats stats;
  if (!placed_) recenter(origin_W);
  const double max_range = params_.max_range_m;
  const double clear_range = params_.clearing_range_m;

  // 1. Hits (integrate_hits), in one task beside the ray walks of 2.: they touch disjoint data
  //    (the hit pass the per-return arrays, the hit bits and the hit voxels' state; the walks
  //    their own mark bit sets). Applied before any miss in 3., so that a voxel hit by any ray
  //    of this scan is never also cleared by it.
  const int nx = dims_.x(), ny = dims_.y();
  const std::size_t n_points = points_W.size();
  const std::array<int, 3> ring_min = ring_origin();
  // 2. Free space: each ray task marks the voxels its rays pass through in its own bit set
  //    (chunks of rays as the tasks ask for them; their union does not depend on who took
  //    which, see TaskRays).
  const std::size_t n_rays = n_points + clearing_dirs_W.size();
  const WindowGeometry w{dims_, min_, params_.voxel_size_m};
  const RayStart start(w, origin_W);
  std::array<std::uint64_t, kRayTasks> task_visits{};
  std::array<MarkBox, kRayTasks> task_boxes{};
  const bool flag_words = !dirty_words_.empty();
  // The order helps the one-at-a-time walk's branch prediction, and the four-lane walk's
  // lockstep (neighbours in direction end near each other). The eight-lane walk needs neither:
  // BALM hall at 1 thread, its occupancy stage took 4.01–4.09 ms without the sort against
  // 4.21–4.25 ms with it (the sort itself 0.11 ms, serial).
  std::atomic<std::size_t> next_chunk{0};
  const int lanes = walk_lanes();
  const bool wide = lanes == 8;
  if (!wide) {
    sort_rays_by_direction(origin_W, points_W, clearing_dirs_W, ray_bucket_, ray_bucket_count_,
                           ray_order_, runner);
  }
  const std::span<const std::uint32_t> order =
      wide ? std::span<const std::uint32_t>{} : std::span<const std::uint32_t>(ray_order_);
  has_no_returns_ = !clearing_dirs_W.empty();
  runner.parallel_for(1 + kRayTasks, [&](std::size_t job) {
    if (job == 0) {
      integrate_hits(origin_W, points_W, up_W, stats);
      scan_rays_.build(origin_W, points_W, clearing_dirs_W, max_range, clear_range);
      return;
    }
    const std::size_t task = job - 1;
    MarkBox& box = task_boxes[task];
    const FreeMarks marks{free_bits_[task].data(),
                          flag_words ? dirty_words_[task].data() : nullptr};
    const std::uint64_t visits = walk_task(
        w, start,
        TaskRays{points_W, clearing_dirs_W, order, origin_W, max_range, clear_range, &next_chunk},
        marks, box, lanes);
    task_visits[task] = visits;
  });

  // 3. Apply: fixed ranges of mark words, each voxel marked by any task and not hit gets one
  //    miss. Only the words inside the box of all marks are read (small windows) or only the
  //    blocks a ray flagged (large ones). The marks are cleared as they are read, ready for the
  //    next scan. Only voxels reading occupied carry static-layer state (free space costs no
  //    extra memory access). A word may be visited twice (rows share words); the second visit
  //    finds its marks cleared, so every marked voxel gets exactly one miss.
  MarkBox marked_box;
  for (const MarkBox& b : task_boxes) marked_box.add(b);
  const std::size_t n_words = hit_bits_.size();
  const std::size_t n_blocks = (n_words >> kBlockShift) + 1;
  std::array<std::uint64_t*, kRayTasks> task_bits{};
  for (std::size_t t = 0; t < kRayTasks; ++t) task_bits[t] = free_bits_[t].data();
  std::array<std::uint64_t, kApplyTasks> task_updates{};
  const MissLanes miss_lanes(l_miss_, l_min_);

  runner.parallel_for(kApplyTasks, [&](std::size_t task) {
    std::uint64_t updates = 0;
    std::vector<std::uint32_t>& candidates = candidates_[task];
    candidates.clear();
    // Words whose marks need an update (not hit, not at the lower clamp), collected with their
    // log-odds lines prefetched, then updated together: the voxels are scattered over the
    // window, and waiting for them one by one was most of this pass's time.
    constexpr std::size_t kPending = 256;
    std::array<std::pair<std::size_t, std::uint64_t>, kPending> pending;
    std::size_t n_pending = 0;
    const auto flush = [&] {
      for (std::size_t p = 0; p < n_pending; ++p) {
        const std::size_t wi = pending[p].first;
        std::uint64_t marks = pending[p].second;
        std::uint64_t& at_floor = floor_bits_[wi];
        const int count = bit_count(marks);
        const std::size_t base = wi << 6;
        std::uint64_t occupied = 0;  // marked voxels reading occupied: static-layer logic below
        if (count >= kDenseWord) {
          // Mostly free space near the sensor: the whole word's voxels four at a time.
          std::uint64_t void_heights = 0;
          miss_free_word(log_odds_.data() + base, marks, miss_lanes, occupied, void_heights,
                         at_floor);
          for (; void_heights != 0; void_heights &= void_heights - 1) {
            rise_cm_[base + static_cast<std::size_t>(std::countr_zero(void_heights))] = 0;
          }
        } else {
          for (; marks != 0; marks &= marks - 1) {
            const std::size_t s = base + static_cast<std::size_t>(std::countr_zero(marks));
            float& l = log_odds_[s];
            if (l > 0.0f) {
              occupied |= std::uint64_t{1} << (s & 63);
              continue;
            }
            // Free or unknown (kUnknown < 0): no static state.
            const float next = std::max((l == kUnknown ? 0.0f : l) + l_miss_, l_min_);
            // Reaching the lower clamp (observed free scan after scan): the sub-voxel heights
            // of older returns are void too (a tug's edge hit once leaves no ghost).
            if (next == l_min_) {
              if (l > l_min_) rise_cm_[s] = 0;
              at_floor |= std::uint64_t{1} << (s & 63);
            }
            l = next;  // a miss only lowers
          }
        }
        // Voxels reading occupied: decided after this pass (see below).
        for (; occupied != 0; occupied &= occupied - 1) {
          candidates.push_back(static_cast<std::uint32_t>(
              base + static_cast<std::size_t>(std::countr_zero(occupied))));
        }
      }
      n_pending = 0;
    };
    // The marks of words [w_begin, w_end): the tasks' marks ORed, then cleared. Voxels already
    // at the lower clamp stay there, their heights already void: a miss changes nothing, so
    // their log-odds are not even read.
    const auto gather = [&](std::size_t w_begin, std::size_t w_end) {
      for (std::size_t wi = w_begin; wi < w_end; ++wi) {
        std::uint64_t m = 0;
        for (std::size_t t = 0; t < kRayTasks; ++t) {
          m |= task_bits[t][wi];
          task_bits[t][wi] = 0;
        }
        if (m == 0) continue;
        m &= ~hit_bits_[wi];
        updates += static_cast<std::uint64_t>(bit_count(m));
        m &= ~floor_bits_[wi];
        if (m == 0) continue;
        for (int g = 0; g < 4; ++g) {  // 16 floats per 64-byte line
          if (((m >> (16 * g)) & 0xffff) != 0) {
            __builtin_prefetch(log_odds_.data() + (wi << 6) + 16 * g, 1);
          }
        }
        pending[n_pending++] = {wi, m};
        if (n_pending == kPending) flush();
      }
    };
    if (flag_words) {
      const std::size_t b_begin = n_blocks * task / kApplyTasks;
      const std::size_t b_end = n_blocks * (task + 1) / kApplyTasks;
      for (std::size_t b = b_begin; b < b_end; ++b) {
        std::uint64_t flags = 0;
        for (auto& d : dirty_words_) {
          flags |= d[b];
          d[b] = 0;
        }
        for (; flags != 0; flags &= flags - 1) {
          const std::size_t wi =
              (b << kBlockShift) + static_cast<std::size_t>(std::countr_zero(flags));
          gather(wi, wi + 1);
        }
      }
    } else if (!marked_box.empty()) {
      // This task's words, row by row (a row: the voxels of one ring z and ring y): the rows
      // of the box, each as one or two runs of x in ring order.
      const std::size_t w_begin = n_words * task / kApplyTasks;
      const std::size_t w_end = n_words * (task + 1) / kApplyTasks;
      const auto row_len = static_cast<std::size_t>(nx);
      const std::size_t r_first = (w_begin << 6) / row_len;
      const std::size_t r_last =
          std::min((w_end << 6) / row_len + 1, static_cast<std::size_t>(ny) * dims_.z());
      const int x_lo = marked_box.lo[0], x_hi = marked_box.hi[0];
      const int x0 = wrap(ring_min[0] + x_lo, nx);
      const int x_count = x_hi - x_lo + 1;
      const auto run = [&](std::size_t first_slot, std::size_t last_slot) {
        const std::size_t a = std::max(w_begin, first_slot >> 6);
        const std::size_t b = std::min(w_end, (last_slot >> 6) + 1);
        gather(a, b);
      };
      // The row's ring y and z, and where they sit in the window, are stepped along with it:
      // a division per row (tens of thousands of rows per task and scan) was most of this
      // pass's time.
      const int nz = dims_.z();
      auto ring_y = static_cast<int>(r_first % static_cast<std::size_t>(ny));
      int rel_y = wrap(ring_y - ring_min[1], ny);
      int rel_z = wrap(static_cast<int>(r_first / static_cast<std::size_t>(ny)) - ring_min[2], nz);
      for (std::size_t r = r_first; r < r_last; ++r) {
        if (marked_box.holds(1, rel_y) && marked_box.holds(2, rel_z)) {
          const std::size_t row = r * row_len;
          if (x0 + x_count <= nx) {
            run(row + static_cast<std::size_t>(x0),
                row + static_cast<std::size_t>(x0 + x_count - 1));
          } else {
            run(row + static_cast<std::size_t>(x0), row + row_len - 1);
            run(row, row + static_cast<std::size_t>(x0 + x_count - nx - 1));
          }
        }
        rel_y = rel_y + 1 == ny ? 0 : rel_y + 1;
        if (++ring_y == ny) {
          ring_y = 0;
          rel_z = rel_z + 1 == nz ? 0 : rel_z + 1;
        }
      }
    }
    flush();
    task_updates[task] = updates;
  });
  for (std::size_t k = 0; k < n_hit_slots_; ++k) hit_bits_[hit_slots_[k] >> 6] = 0;
  miss_occupied(runner, stats);

  stats.rays = n_rays;
  for (const auto v : task_visits) stats.voxel_visits += v;
  for (const auto u : task_updates) stats.miss_updates += u;
  return stats;
}

void OccupancyMap::miss_occupied(TaskRunner& runner, OccupancyUpdateStats& stats) {
  // a) Decide, reading only (so that no decision sees another's write): which of the occupied
  //    voxels a ray crossed this scan get a miss. A voxel with observed free space below it and
  //    none above (unknown, or occupied) is the underside of something: an aircraft's belly,
  //    an engine, a truck bed. Rays that cross such a voxel under its lowest return only pass
  //    under the surface; they miss it only when one passes through the voxel at or above its
  //    lowest return and goes on more than a voxel (ScanRays::any_passes). Every other
  //    occupied voxel a ray crossed gets its miss, as any free voxel does: the top of a tug
  //    that drove away has free space above it, and clears as fast as before.
  const std::size_t n_tasks = candidates_.size();
  std::array<std::size_t, kApplyTasks + 1> first{};
  for (std::size_t t = 0; t < n_tasks; ++t) first[t + 1] = first[t] + candidates_[t].size();
  const std::size_t n = first[n_tasks];
  miss_decision_.resize(std::max(miss_decision_.size(), n));
  const double v = params_.voxel_size_m;
  const int nz = dims_.z();
  const std::size_t layer = static_cast<std::size_t>(dims_.x()) * dims_.y();
  const int ring_z0 = wrap(min_.z(), nz);
  const auto reads_free = [&](std::size_t s) {
    const float l = log_odds_[s];
    return l != kUnknown && l <= 0.0f;
  };
  runner.parallel_for(n_tasks, [&](std::size_t task) {
    const std::vector<std::uint32_t>& list = candidates_[task];
    for (std::size_t k = 0; k < list.size(); ++k) {
      const std::size_t s = list[k];
      bool miss = true;
      const std::uint8_t floor32 = hit_floor_[s];
      const int rel_z = wrap(static_cast<int>(s / layer) - ring_z0, nz);
      const Eigen::Vector3d corner = voxel_of_slot(s).cast<double>() * v;
      if (floor32 != kNoHitFloor && rel_z > 0) {
        const std::size_t below = s >= layer ? s - layer : s + layer * (nz - 1);
        const bool above_free =
            rel_z + 1 < nz &&
            reads_free(s + layer < layer * nz ? s + layer : s + layer - layer * nz);
        if (reads_free(below) && !above_free) {
          const Eigen::Vector3d lo(corner.x(), corner.y(), corner.z() + floor32 * v / kFloorSteps);
          miss = scan_rays_.any_passes(lo, corner + Eigen::Vector3d::Constant(v), v, true);
        }
      }
      // Beams without a return never empty an occupied voxel: a black or mirror-like surface
      // returns nothing too. Only a ray that ended at a return shows it empty.
      if (miss && has_no_returns_) {
        miss = scan_rays_.any_passes(corner, corner + Eigen::Vector3d::Constant(v), 0.0, true);
      }
      miss_decision_[first[task] + k] = miss ? 1 : 0;
    }
  });
  // b) Apply, in the lists' order: the misses, and the static layer's runs of free
  //    observations (a static voxel leaves the layer after static_demote_scans in a row).
  const int demote = params_.static_demote_scans;
  for (std::size_t t = 0; t < n_tasks; ++t) {
    const std::vector<std::uint32_t>& list = candidates_[t];
    for (std::size_t k = 0; k < list.size(); ++k) {
      if (miss_decision_[first[t] + k] == 0) continue;
      const std::size_t s = list[k];
      float& l = log_odds_[s];
      std::uint8_t& st = state_[s];
      if ((st & kStatic) == 0) {
        l = std::max(l + l_miss_, l_min_);
        if (l <= 0.0f) {  // reads free: the run of hits is broken, the heights are void
          st = 0;
          rise_cm_[s] = 0;
        }
      } else if ((st & kCount) + 1 >= demote) {
        st = 0;  // strong free evidence: leaves the static layer and reads free
        l = std::max(l_miss_, l_min_);
        rise_cm_[s] = 0;
        static_->erase(voxel_of_slot(s));
        ++stats.demotions;
      } else {
        ++st;
        l = std::max(l + l_miss_, l_hit_);  // a static voxel reads at least one hit
      }
    }
  }
}

const float* OccupancyMap::ring_layer(int wz) const {
  return log_odds_.data() +
         static_cast<std::size_t>(wrap(min_.z() + wz, dims_.z())) * dims_.x() * dims_.y();
}
const std::uint8_t* OccupancyMap::ring_layer_rise_cm(int wz) const {
  return rise_cm_.data() +
         static_cast<std::size_t>(wrap(min_.z() + wz, dims_.z())) * dims_.x() * dims_.y();
}
int OccupancyMap::ring_x(int wx) const {
  return wrap(min_.x() + wx, dims_.x());
}
int OccupancyMap::ring_y(int wy) const {
  return wrap(min_.y() + wy, dims_.y());
}

void OccupancyMap::export_log_odds(std::vector<float>& out) const {
  out.resize(static_cast<std::size_t>(dims_.x()) * dims_.y() * dims_.z());
  std::size_t i = 0;
  for (int z = 0; z < dims_.z(); ++z) {
    for (int y = 0; y < dims_.y(); ++y) {
      for (int x = 0; x < dims_.x(); ++x) {
        out[i++] = log_odds_[slot(min_ + VoxelIndex(x, y, z))];
      }
    }
  }
}

void OccupancyMap::reset() {
  // Every per-voxel layer back to its constructed state (a layer added here must be reset too:
  // a rebuilt window must equal a fresh one).
  std::fill(log_odds_.begin(), log_odds_.end(), kUnknown);
  std::fill(rise_cm_.begin(), rise_cm_.end(), std::uint8_t{0});
  std::fill(hit_floor_.begin(), hit_floor_.end(), kNoHitFloor);
  std::fill(state_.begin(), state_.end(), std::uint8_t{0});
  std::fill(floor_bits_.begin(), floor_bits_.end(), std::uint64_t{0});
  // The static layer too: a rebuild re-derives it from the retained scans (what was static
  // before the correction sits in the uncorrected frame).
  static_->clear();
  for (auto& c : candidates_) c.clear();
  min_ = VoxelIndex::Zero();
  placed_ = false;
}

}  // namespace tarmac::core
