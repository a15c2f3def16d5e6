#include "tarmac/core/distance_field.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr std::size_t kTasksPerPass = 16;
/// Lines along y and z are processed this many adjacent ones at a time: their cells are
/// contiguous in memory (64 bytes of floats), so the gathers and scatters read and write whole
/// cache lines instead of one float per line.
constexpr int kBlock = 16;

/// 1D squared distance transform of f (FH Algorithm 1) with the argmin of each output.
/// f[q] = +inf means "no site here". Writes d[q] = min_p (q − p)² + f[p] and arg[q] = p
/// (−1 when every f is infinite). Ties go to the parabola added last (the larger p), a fixed rule.
void edt_1d(const float* f, int n, float* d, std::int32_t* arg, std::int32_t* v, float* z) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kInf) continue;
    if (k < 0) {
      k = 0;
      v[0] = q;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    float s;
    while (true) {
      const int p = v[k];
      // Intersection of the parabolas rooted at q and p. Values are integers well below 2^24,
      // so float is exact enough to order breakpoints between integer positions.
      s = ((f[q] + static_cast<float>(q) * q) - (f[p] + static_cast<float>(p) * p)) /
          (2.0f * static_cast<float>(q - p));
      if (s <= z[k] && k > 0) {
        --k;
        continue;
      }
      break;
    }
    if (s <= z[k]) {  // k == 0 and the new parabola dominates everywhere
      v[0] = q;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kInf;
  }
  if (k < 0) {
    std::fill(d, d + n, kInf);
    std::fill(arg, arg + n, -1);
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < static_cast<float>(q)) ++j;
    const float dq = static_cast<float>(q - v[j]);
    d[q] = dq * dq + f[v[j]];
    arg[q] = v[j];
  }
}

/// edt_1d for an input that is 0 at sites and +inf elsewhere (the first pass), without
/// parabolas: the envelope of zero-height parabolas breaks exactly at the midpoints between
/// consecutive sites, and edt_1d keeps a midpoint cell with the left site. So each cell takes
/// its nearest site, the left one on a tie. Same d and arg as edt_1d, bit for bit.
void nearest_site_1d(const std::uint8_t* site, int n, float* d, std::int32_t* arg) {
  int left = -1;
  for (int q = 0; q < n; ++q) {
    if (site[q] != 0) left = q;
    arg[q] = left;
  }
  int right = -1;
  for (int q = n - 1; q >= 0; --q) {
    if (site[q] != 0) right = q;
    const int l = arg[q];
    const int p = l < 0 || (right >= 0 && right - q < q - l) ? right : l;
    arg[q] = p;
    const float dq = static_cast<float>(q - p);
    d[q] = p < 0 ? kInf : dq * dq;
  }
}

}  // namespace

void compute_distance_field(const std::vector<CellState>& states, const Eigen::Vector3i& dims,
                            double cell_size_m, UnknownPolicy policy, DistanceField& out,
                            DistanceFieldScratch& s, TaskRunner& runner) {
  const int nx = dims.x(), ny = dims.y(), nz = dims.z();
  const std::size_t n = static_cast<std::size_t>(nx) * ny * nz;
  TARMAC_ASSERT(states.size() == n, "states must match dims");
  out.dims = dims;
  out.cell_size_m = cell_size_m;
  out.distance_m.resize(n);
  out.gradient_x.resize(n);
  out.gradient_y.resize(n);
  out.gradient_z.resize(n);
  const int passes = nz == 1 ? 2 : 3;
  // The last pass writes the output directly; it needs no squared distances or sites stored.
  s.sq.resize(n);
  for (int a = 0; a < 3; ++a) s.site[a].resize(a < passes - 1 ? n : 0);
  const int longest = std::max({nx, ny, nz});
  const std::size_t line_len = static_cast<std::size_t>(longest) + 1;
  const auto ensure = [&](auto& lines, std::size_t size) {
    lines.resize(kTasksPerPass);
    for (auto& l : lines) l.resize(size);
  };
  ensure(s.line_f, line_len * kBlock);
  ensure(s.line_v, line_len);
  ensure(s.line_arg, line_len * kBlock);
  ensure(s.line_z, line_len);
  ensure(s.line_d, line_len * kBlock);
  ensure(s.line_s[0], line_len * kBlock);
  ensure(s.line_s[1], line_len * kBlock);

  const bool unknown_is_site = policy == UnknownPolicy::kUnknownIsOccupied;
  const bool report_unknown = policy == UnknownPolicy::kReportUnknown;

  // Metres and gradient of cell i at (x, y, z) from its squared distance and nearest site.
  const auto finish = [&](std::size_t i, int x, int y, int zz, float sq, std::int32_t sx,
                          std::int32_t sy, std::int32_t sz) {
    float& dist = out.distance_m[i];
    float& gx = out.gradient_x[i];
    float& gy = out.gradient_y[i];
    float& gz = out.gradient_z[i];
    gx = gy = gz = 0.0f;
    if (report_unknown && states[i] == CellState::kUnknown) {
      dist = std::nanf("");
      return;
    }
    if (sq == kInf) {
      dist = kInf;
      return;
    }
    const double r = std::sqrt(static_cast<double>(sq));
    dist = static_cast<float>(r * cell_size_m);
    if (r > 0.0) {
      gx = static_cast<float>((x - sx) / r);
      gy = static_cast<float>((y - sy) / r);
      if (passes == 3) gz = static_cast<float>((zz - sz) / r);
    }
  };

  // Pass along x builds, per cell, the squared distance to the nearest site in its row and that
  // site's x. The pass along y takes the lower envelope of each column: the winner's x is copied
  // from the cell it came from, its y is the argmin. The pass along z does the same for x and y.
  // So each pass carries only the coordinates of the axes before it.
  const std::size_t plane = static_cast<std::size_t>(nx) * ny;
  const std::size_t rows = static_cast<std::size_t>(ny) * nz;
  runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
    auto* site = reinterpret_cast<std::uint8_t*>(s.line_v[task].data());
    const std::size_t first = rows * task / kTasksPerPass;
    const std::size_t last = rows * (task + 1) / kTasksPerPass;
    for (std::size_t row = first; row < last; ++row) {
      const std::size_t base = row * static_cast<std::size_t>(nx);
      const CellState* st = states.data() + base;
      for (int q = 0; q < nx; ++q) {
        site[q] = static_cast<std::uint8_t>((st[q] == CellState::kOccupied) |
                                            (unknown_is_site & (st[q] == CellState::kUnknown)));
      }
      nearest_site_1d(site, nx, s.sq.data() + base, s.site[0].data() + base);
    }
  });

  // Passes along y and z: kBlock adjacent lines at a time (adjacent along x for y, along the
  // xy plane for z), gathered into per-task line buffers, transformed, scattered back.
  for (int axis = 1; axis < passes; ++axis) {
    const bool last_pass = axis == passes - 1;
    const int len = axis == 1 ? ny : nz;
    const std::size_t stride = axis == 1 ? static_cast<std::size_t>(nx) : plane;
    // Groups of lines: along y, kBlock columns of one z plane (a plane's columns are split into
    // ceil(nx / kBlock) groups); along z, kBlock xy cells.
    const std::size_t groups_per_plane = axis == 1
                                             ? (static_cast<std::size_t>(nx) + kBlock - 1) / kBlock
                                             : (plane + kBlock - 1) / kBlock;
    const std::size_t line_span = axis == 1 ? static_cast<std::size_t>(nx) : plane;
    const std::size_t groups = groups_per_plane * (axis == 1 ? static_cast<std::size_t>(nz) : 1);
    runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
      float* f = s.line_f[task].data();
      float* d = s.line_d[task].data();
      std::int32_t* arg = s.line_arg[task].data();
      std::int32_t* v = s.line_v[task].data();
      float* z = s.line_z[task].data();
      std::int32_t* carried[2] = {s.line_s[0][task].data(), s.line_s[1][task].data()};
      const std::size_t first = groups * task / kTasksPerPass;
      const std::size_t last = groups * (task + 1) / kTasksPerPass;
      for (std::size_t group = first; group < last; ++group) {
        const std::size_t outer = group / groups_per_plane;  // z plane for axis 1, 0 for axis 2
        const std::size_t start = (group % groups_per_plane) * kBlock;
        const int width = static_cast<int>(std::min<std::size_t>(kBlock, line_span - start));
        const std::size_t base = outer * plane + start;  // first cell of the group's first line
        // Gather: line b of the group into f[b * len ...], carried sites likewise.
        for (int q = 0; q < len; ++q) {
          const std::size_t i = base + q * stride;
          for (int b = 0; b < width; ++b) f[b * len + q] = s.sq[i + b];
          for (int a = 0; a < axis; ++a) {
            for (int b = 0; b < width; ++b) carried[a][b * len + q] = s.site[a][i + b];
          }
        }
        for (int b = 0; b < width; ++b) {
          edt_1d(f + b * len, len, d + b * len, arg + b * len, v, z);
        }
        for (int q = 0; q < len; ++q) {
          const std::size_t i = base + q * stride;
          if (!last_pass) {
            for (int b = 0; b < width; ++b) {
              const std::int32_t from = arg[b * len + q];
              s.sq[i + b] = d[b * len + q];
              s.site[0][i + b] = from < 0 ? -1 : carried[0][b * len + from];
              s.site[1][i + b] = from;
            }
            continue;
          }
          for (int b = 0; b < width; ++b) {
            const std::int32_t from = arg[b * len + q];
            const std::int32_t sx = from < 0 ? -1 : carried[0][b * len + from];
            const std::int32_t sy = axis == 1 ? from : (from < 0 ? -1 : carried[1][b * len + from]);
            const std::int32_t sz = axis == 2 ? from : 0;
            // Cell coordinates: the group's line b at position q along the axis.
            const std::size_t cell = start + b;  // index within the plane (axis 2) or row (1)
            const int x = axis == 1 ? static_cast<int>(cell) : static_cast<int>(cell % nx);
            const int y = axis == 1 ? q : static_cast<int>(cell / nx);
            const int zz = axis == 1 ? static_cast<int>(outer) : q;
            finish(i + b, x, y, zz, d[b * len + q], sx, sy, sz);
          }
        }
      }
    });
  }
}

}  // namespace tarmac::core
