#include "tarmac/core/distance_field.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr std::size_t kTasksPerPass = 16;
/// Offset (cell − site, cells) meaning "no site on this line"; larger than any real offset.
constexpr std::int32_t kNone = 1 << 14;

/// Bit of a CellState that makes it a site: occupied (1), or occupied and unknown (1 | 2).
std::uint8_t site_mask(UnknownPolicy policy) {
  return policy == UnknownPolicy::kUnknownIsOccupied ? 3 : 1;
}

/// Largest grid side: every value of the envelopes below stays under 2^25 (see kRecip).
constexpr int kMaxSide = 4096;

/// floor(num / (2 d)) = (num · kRecip[d]) >> 40 for 0 <= num < 2^25 and 1 <= d <= kMaxSide
/// (Granlund & Montgomery 1994): with M = ceil(2^40 / D), D = 2d <= 2^13, and e = M·D − 2^40 < D,
/// num·M / 2^40 = num / D + num·e / (D·2^40), and num·e / (D·2^40) < 2^−15 < 1/D, so the
/// fraction never carries into the quotient; num·M < 2^25 · 2^39 fits 64 bits.
constexpr auto kRecip = [] {
  std::array<std::uint64_t, kMaxSide + 1> r{};
  for (std::uint64_t d = 1; d <= kMaxSide; ++d)
    r[d] = ((std::uint64_t{1} << 40) + 2 * d - 1) / (2 * d);
  return r;
}();

/// Columns compared on each side when pruning envelope candidates (see transform_rows), and
/// the padding value for "no site": above every squared distance, and + kPrune² fits int32.
constexpr int kPrune = 6;
constexpr std::int32_t kFar = std::int32_t{1} << 29;

/// One parabola x ↦ (x − s)² + g of a lower envelope, lowest from x = t on; v is its value at t.
struct Parabola {
  std::int32_t s, t, v, g;
};

/// Lower envelope of the parabolas x ↦ (x − u)² + f[u] over the u with f[u] >= 0 (f[u] < 0:
/// no site), restricted to the integers [0, n) (Meijster, Roerdink & Hesselink 2000; the
/// envelope of Felzenszwalb & Huttenlocher): parabola j is lowest on [e[j].t, e[j + 1].t).
/// Returns their number k, with e[k].t = n. Exact int32 arithmetic: n <= kMaxSide and
/// f <= (kMaxSide − 1)², so every value is below 2^25. The last parabola is dropped when the
/// new one is strictly lower at its first cell; a tie at a cell goes to the one added first.
inline int lower_envelope(const std::int32_t* __restrict f, int n, Parabola* __restrict e) {
  // The last parabola lives in registers (top); e[0 .. k − 2] hold the ones below it.
  int k = 0;
  Parabola top{0, 0, 0, 0};
  for (int u = 0; u < n; ++u) {
    const std::int32_t fu = f[u];
    if (fu < 0) continue;
    while (k > 0) {
      const std::int32_t b = top.t - u;
      if (top.v <= b * b + fu) break;
      if (--k > 0) top = e[k - 1];
    }
    if (k == 0) {
      top = Parabola{u, 0, u * u + fu, fu};
      k = 1;
      continue;
    }
    // The new parabola is not lower at top.t, so it takes over strictly after the crossing
    // x* = num / (2 (u − p)) >= top.t >= 0: from floor(x*) + 1.
    const std::int32_t p = top.s;
    const std::int32_t num = (u - p) * (u + p) + fu - top.g;
    const auto w = static_cast<std::int32_t>(
        (static_cast<std::uint64_t>(num) * kRecip[static_cast<std::size_t>(u - p)]) >> 40);
    if (w + 1 < n) {
      e[k - 1] = top;
      top = Parabola{u, w + 1, (w + 1 - u) * (w + 1 - u) + fu, fu};
      ++k;
    }
  }
  if (k > 0) e[k - 1] = top;
  e[k].t = n;
  return k;
}

/// Per-cell result of one row's envelope, packed in one int32: the x offset to the site (low
/// 16 bits) and the site's carried y offset (high 16 bits); in 3D also the key
/// (squared 2D distance) · 2^zb + z of each cell.
template <bool kKeys, typename Key>
inline void fill_row(const std::int16_t* __restrict oy_in, int k, const Parabola* __restrict e,
                     std::int32_t* __restrict oxy, Key* __restrict key, int zb, int z) {
  for (int j = 0; j < k; ++j) {
    const std::int32_t site = e[j].s, g = e[j].g;
    const std::int32_t carried = static_cast<std::int32_t>(
        static_cast<std::uint32_t>(static_cast<std::uint16_t>(oy_in[site])) << 16);
    const int x1 = e[j + 1].t;
    for (int x = e[j].t; x < x1; ++x) {
      const std::int32_t dx = x - site;
      oxy[x] = carried | static_cast<std::uint16_t>(dx);
      if constexpr (kKeys) key[x] = (static_cast<Key>(dx * dx + g) << zb) | z;
    }
  }
}

/// Where x86-64 CPUs have AVX2, the hot loops run in an AVX2 build of the same source
/// (8-lane integer min, 4-lane double sqrt and division), picked once at load time; the
/// baseline build (SSE2) stays for other CPUs. Integer and IEEE float operations give the same
/// bits in both (no FMA contraction: the file builds with -ffp-contract=off).
/// Not under ThreadSanitizer: GCC instruments the ifunc resolver that target_clones generates,
/// the dynamic loader runs it before TSan's runtime is up, and the process crashes at load.
#if defined(__x86_64__) && defined(__linux__) && defined(__GNUC__) && !defined(__SANITIZE_THREAD__)
#define TARMAC_ESDF_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define TARMAC_ESDF_CLONES
#endif

/// Pass 1, along y in each layer, for the (layer, x) lanes [l0, l1): the nearest site on each
/// column, by a sweep up and a sweep down across contiguous x lanes. off = cell − site (y),
/// kNone when the column has no site; a tie between the site below and above goes below.
TARMAC_ESDF_CLONES
void sweep_columns(const std::uint8_t* states, std::int16_t* off_all, int nx, int ny,
                   std::uint8_t mask, std::size_t l0, std::size_t l1, std::int32_t* last) {
  const std::size_t plane = static_cast<std::size_t>(nx) * ny;
  for (std::size_t l = l0; l < l1;) {
    const std::size_t z = l / nx, c0 = l % nx;
    const std::size_t c1 = std::min<std::size_t>(nx, c0 + (l1 - l));
    l += c1 - c0;
    const std::uint8_t* layer = states + z * plane;
    std::int16_t* off = off_all + z * plane;
    for (std::size_t c = c0; c < c1; ++c) last[c] = -kNone;
    for (int p = 0; p < ny; ++p) {
      const std::uint8_t* __restrict st = layer + static_cast<std::size_t>(p) * nx;
      std::int16_t* __restrict o = off + static_cast<std::size_t>(p) * nx;
      for (std::size_t c = c0; c < c1; ++c) {
        last[c] = (st[c] & mask) != 0 ? p : last[c];
        o[c] = static_cast<std::int16_t>(std::min(p - last[c], kNone));
      }
    }
    for (std::size_t c = c0; c < c1; ++c) last[c] = ny + kNone;  // now "next"
    for (int p = ny - 1; p >= 0; --p) {
      const std::uint8_t* __restrict st = layer + static_cast<std::size_t>(p) * nx;
      std::int16_t* __restrict o = off + static_cast<std::size_t>(p) * nx;
      for (std::size_t c = c0; c < c1; ++c) {
        last[c] = (st[c] & mask) != 0 ? p : last[c];
        const std::int32_t down = std::min(last[c] - p, kNone);
        const std::int32_t up = o[c];
        o[c] = static_cast<std::int16_t>(down < up ? -down : up);
      }
    }
  }
}

/// What pass 2 reads and writes; per-task buffers come separately.
struct RowsJob {
  const std::uint8_t* states;
  const std::int16_t* off;  // pass 1's y offsets
  int nx, ny, nz, zb;
  bool report_unknown;
  double cell;
  float* dist;
  float* gx;
  float* gy;
  float* gz;
};

/// One task's buffers for pass 2; Key holds d2 · 2^zb + z (int32 when it fits, else int64).
template <typename Key>
struct RowsBuffers {
  std::int32_t* f;       // nx: envelope input
  Parabola* env;         // nx + 1: the envelope
  std::int32_t* e;       // 3 · nx: final offsets x, y, z
  Key* best;             // nx (3D): the best key per cell of a row
  std::int32_t* oxy;     // nz · nx: packed x / carried y offsets per layer row
  Key* keys;             // nz · nx (3D): keys per layer row
  std::int32_t* layers;  // nz: the layers whose row has a site
  std::int32_t* fp;      // nx + 2 kPrune: the envelope input before pruning
};

/// Pass 2 for the rows y0 ≤ y < y1 of every layer: the envelope along x of each layer's row
/// gives each cell its nearest site within its layer; in 3D the nearest site over all layers
/// is then the minimum over the layers z' of d2(z') + (z − z')² (ties to the lowest z'), taken
/// exactly by brute force across contiguous x lanes (bands and windows have few layers); then
/// metres and gradient.
template <typename Key>
[[gnu::always_inline]] inline void transform_rows(const RowsJob& job, const RowsBuffers<Key>& b,
                                                  int y0, int y1) {
  const int nx = job.nx, ny = job.ny, nz = job.nz, zb = job.zb;
  const bool three_d = nz > 1;
  const std::uint8_t unknown_state =
      job.report_unknown ? static_cast<std::uint8_t>(CellState::kUnknown) : 0xff;
  const Key no_key = Key{1} << (sizeof(Key) * 8 - 2);  // above every real key, room to add
  std::int32_t* __restrict f = b.f;
  std::int32_t* __restrict fp = b.fp;  // kPrune + nx + kPrune: f padded, kFar for no site
  for (int j = 0; j < kPrune; ++j) fp[j] = fp[kPrune + nx + j] = kFar;
  std::int32_t* __restrict ex = b.e;
  std::int32_t* __restrict ey = ex + nx;
  std::int32_t* __restrict ez = ey + nx;
  Key* __restrict best = b.best;
  const double cell = job.cell;
  std::int32_t* __restrict layers = b.layers;  // the layers whose row has a site
  for (int y = y0; y < y1; ++y) {
    int n_layers = 0;
    for (int z = 0; z < nz; ++z) {
      const std::size_t base = (static_cast<std::size_t>(z) * ny + y) * nx;
      const std::int16_t* __restrict a0 = job.off + base;
      // Envelope input: the squared y distance per column, −1 where the column has no site or
      // where its parabola is dominated on both sides, so never strictly lowest: by a column p
      // left of it with f[p] + (x − p)² <= f[x] (then p is at most as low as x's parabola at
      // every cell left of x) and by one right of it likewise; kPrune columns each side.
      for (int x = 0; x < nx; ++x) {
        const std::int32_t u = a0[x];
        fp[kPrune + x] = u == kNone ? kFar : u * u;
      }
      for (int x = 0; x < nx; ++x) {
        const std::int32_t c = fp[kPrune + x];
        std::int32_t left = kFar, right = kFar;
        for (int j = 1; j <= kPrune; ++j) {
          left = std::min(left, fp[kPrune + x - j] + j * j);
          right = std::min(right, fp[kPrune + x + j] + j * j);
        }
        f[x] = c == kFar || (c >= left && c >= right) ? -1 : c;
      }
      // 2D: straight into the final stage's input (packed, unpacked there).
      std::int32_t* oxy = three_d ? b.oxy + static_cast<std::size_t>(z) * nx : ey;
      Key* kz = b.keys + static_cast<std::size_t>(z) * nx;
      const int k = lower_envelope(f, nx, b.env);
      if (k == 0) {
        if (three_d) std::fill(kz, kz + nx, no_key);
        continue;
      }
      layers[n_layers++] = z;
      if (three_d) {
        fill_row<true>(a0, k, b.env, oxy, kz, zb, z);
      } else {
        fill_row<false, Key>(a0, k, b.env, oxy, nullptr, 0, 0);
      }
    }
    for (int z = 0; z < nz; ++z) {
      const std::size_t base = (static_cast<std::size_t>(z) * ny + y) * nx;
      const std::uint8_t* __restrict st = job.states + base;
      float* __restrict dist = job.dist + base;
      float* __restrict gx = job.gx + base;
      float* __restrict gy = job.gy + base;
      float* __restrict gz = job.gz + base;
      if (n_layers == 0) {  // no obstacle in the grid (every layer's row is empty only then)
        for (int x = 0; x < nx; ++x) {
          dist[x] = st[x] == unknown_state ? std::numeric_limits<float>::quiet_NaN() : kInf;
          gx[x] = gy[x] = gz[x] = 0.0f;
        }
        continue;
      }
      const std::int32_t* __restrict oxy = b.oxy;
      if (three_d) {
        const Key* __restrict k0 = b.keys + static_cast<std::size_t>(z) * nx;
        for (int x = 0; x < nx; ++x) best[x] = k0[x];
        for (int i = 0; i < n_layers; ++i) {
          const int zz = layers[i];
          if (zz == z) continue;
          const Key c = static_cast<Key>((z - zz) * (z - zz)) << zb;
          const Key* __restrict kk = b.keys + static_cast<std::size_t>(zz) * nx;
          for (int x = 0; x < nx; ++x) best[x] = std::min(best[x], kk[x] + c);
        }
        const Key zmask = (Key{1} << zb) - 1;
        for (int x = 0; x < nx; ++x) {
          const auto zz = static_cast<std::int32_t>(best[x] & zmask);
          ey[x] = oxy[zz * nx + x];  // packed, unpacked below (nz · nx < 2^31)
          ez[x] = z - zz;
        }
      } else {
        for (int x = 0; x < nx; ++x) ez[x] = 0;  // ey holds the packed offsets already
      }
      // Branch-free loops so each vectorises: unknown cells get zero offsets (so a zero
      // gradient), then metres and gradients (an obstacle, r = 0, multiplies 0 by 1), then NaN.
      for (int x = 0; x < nx; ++x) {
        const std::int32_t keep = -static_cast<std::int32_t>(st[x] != unknown_state);
        const std::int32_t packed = ey[x];
        ex[x] = static_cast<std::int16_t>(packed & 0xffff) & keep;
        ey[x] = (packed >> 16) & keep;
        ez[x] &= keep;
      }
      for (int x = 0; x < nx; ++x) {
        const double e0 = ex[x], e1 = ey[x], e2 = ez[x];
        const double r = std::sqrt(e0 * e0 + e1 * e1 + e2 * e2);
        const double inv = 1.0 / (r + (r == 0.0));  // 1 / r; 1 for an obstacle (r = 0)
        dist[x] = static_cast<float>(r * cell);
        gx[x] = static_cast<float>(e0 * inv);
        gy[x] = static_cast<float>(e1 * inv);
        gz[x] = static_cast<float>(e2 * inv);
      }
      if (job.report_unknown) {
        for (int x = 0; x < nx; ++x) {
          dist[x] = st[x] == unknown_state ? std::numeric_limits<float>::quiet_NaN() : dist[x];
        }
      }
    }
  }
}

/// Carves one task's buffers out of its scratch vector (64-byte aligned pieces).
template <typename Key>
RowsBuffers<Key> carve(std::vector<std::int64_t>& v, int nx, int nz) {
  const std::size_t row_cells = static_cast<std::size_t>(nx) * nz;
  const std::size_t sizes[] = {
      nx * sizeof(std::int32_t),        (nx + 1) * sizeof(Parabola),
      3 * nx * sizeof(std::int32_t),    nx * sizeof(Key),
      row_cells * sizeof(std::int32_t), row_cells * sizeof(Key),
      nz * sizeof(std::int32_t),        (nx + 2 * kPrune) * sizeof(std::int32_t)};
  std::size_t total = 64;
  for (const std::size_t sz : sizes) total += (sz + 63) / 64 * 64;
  v.resize(total / sizeof(std::int64_t));
  auto* p = reinterpret_cast<unsigned char*>(v.data());
  p += (64 - reinterpret_cast<std::uintptr_t>(p) % 64) % 64;
  unsigned char* piece[8];
  for (int i = 0; i < 8; ++i) {
    piece[i] = p;
    p += (sizes[i] + 63) / 64 * 64;
  }
  return RowsBuffers<Key>{
      reinterpret_cast<std::int32_t*>(piece[0]), reinterpret_cast<Parabola*>(piece[1]),
      reinterpret_cast<std::int32_t*>(piece[2]), reinterpret_cast<Key*>(piece[3]),
      reinterpret_cast<std::int32_t*>(piece[4]), reinterpret_cast<Key*>(piece[5]),
      reinterpret_cast<std::int32_t*>(piece[6]), reinterpret_cast<std::int32_t*>(piece[7])};
}

TARMAC_ESDF_CLONES
void transform_rows_32(const RowsJob& job, std::vector<std::int64_t>& v, int y0, int y1) {
  transform_rows(job, carve<std::int32_t>(v, job.nx, job.nz), y0, y1);
}

TARMAC_ESDF_CLONES
void transform_rows_64(const RowsJob& job, std::vector<std::int64_t>& v, int y0, int y1) {
  transform_rows(job, carve<std::int64_t>(v, job.nx, job.nz), y0, y1);
}

}  // namespace

void compute_distance_field(const std::vector<CellState>& states, const Eigen::Vector3i& dims,
                            double cell_size_m, UnknownPolicy policy, DistanceField& out,
                            DistanceFieldScratch& s, TaskRunner& runner) {
  const int nx = dims.x(), ny = dims.y(), nz = dims.z();
  const std::size_t n = static_cast<std::size_t>(nx) * ny * nz;
  TARMAC_ASSERT(states.size() == n, "states must match dims");
  TARMAC_ASSERT(nx >= 1 && ny >= 1 && nz >= 1 && nx <= kMaxSide && ny <= kMaxSide && nz <= kMaxSide,
                "dims must be in [1, 4096]");
  const bool three_d = nz > 1;
  const int zb = three_d ? std::bit_width(static_cast<unsigned>(nz - 1)) : 0;
  // Layer keys d2 · 2^zb + z in int32 when every one, plus (z − z')² · 2^zb, stays below 2^30.
  const std::int64_t max_d2 = std::int64_t{nx - 1} * (nx - 1) + std::int64_t{ny - 1} * (ny - 1) +
                              std::int64_t{nz - 1} * (nz - 1);
  const bool wide_keys = ((max_d2 + 1) << zb) >= (std::int64_t{1} << 30);
  out.dims = dims;
  out.cell_size_m = cell_size_m;
  out.distance_m.resize(n);
  out.gradient_x.resize(n);
  out.gradient_y.resize(n);
  out.gradient_z.resize(n);
  const auto* st_all = reinterpret_cast<const std::uint8_t*>(states.data());
  s.off.resize(n);
  s.task.resize(kTasksPerPass);
  for (auto& t : s.task) {
    if (wide_keys) {
      (void)carve<std::int64_t>(t, nx, nz);
    } else {
      (void)carve<std::int32_t>(t, nx, nz);
    }
  }

  // Pass 1: (layer, x) lanes split into tasks of at least 64 lanes (short runs of lanes do not
  // vectorise well); each cell's result is independent of the split.
  {
    const std::size_t lanes = static_cast<std::size_t>(nx) * nz;
    const std::size_t tasks = std::clamp<std::size_t>(lanes / 64, 1, kTasksPerPass);
    const std::uint8_t mask = site_mask(policy);
    runner.parallel_for(tasks, [&](std::size_t task) {
      auto* last = reinterpret_cast<std::int32_t*>(s.task[task].data());
      sweep_columns(st_all, s.off.data(), nx, ny, mask, lanes * task / tasks,
                    lanes * (task + 1) / tasks, last);
    });
  }

  // Pass 2: y rows (of all layers) split into fixed tasks.
  const RowsJob job{st_all,
                    s.off.data(),
                    nx,
                    ny,
                    nz,
                    zb,
                    policy == UnknownPolicy::kReportUnknown,
                    cell_size_m,
                    out.distance_m.data(),
                    out.gradient_x.data(),
                    out.gradient_y.data(),
                    out.gradient_z.data()};
  runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
    const int y0 = static_cast<int>(static_cast<std::size_t>(ny) * task / kTasksPerPass);
    const int y1 = static_cast<int>(static_cast<std::size_t>(ny) * (task + 1) / kTasksPerPass);
    if (wide_keys) {
      transform_rows_64(job, s.task[task], y0, y1);
    } else {
      transform_rows_32(job, s.task[task], y0, y1);
    }
  });
}

}  // namespace tarmac::core
