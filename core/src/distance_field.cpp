#include "tarmac/core/distance_field.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr std::size_t kTasksPerPass = 16;

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
  s.sq.resize(n);
  for (int a = 0; a < 3; ++a) s.site[a].resize(a < 2 || nz > 1 ? n : 0);
  const int longest = std::max({nx, ny, nz});
  const auto ensure = [&](auto& lines) {
    lines.resize(kTasksPerPass);
    for (auto& l : lines) l.resize(static_cast<std::size_t>(longest) + 1);
  };
  ensure(s.line_f);
  ensure(s.line_v);
  ensure(s.line_arg);
  ensure(s.line_z);
  ensure(s.line_d);
  ensure(s.line_s[0]);
  ensure(s.line_s[1]);

  const auto is_site = [&](CellState c) {
    return c == CellState::kOccupied ||
           (c == CellState::kUnknown && policy == UnknownPolicy::kUnknownIsOccupied);
  };

  // Pass along x builds, per cell, the squared distance to the nearest site in its row and that
  // site's x. The pass along y takes the lower envelope of each column: the winner's x is copied
  // from the cell it came from, its y is the argmin. The pass along z does the same for x and y.
  // So each pass carries only the coordinates of the axes before it.
  const std::size_t plane = static_cast<std::size_t>(nx) * ny;
  const int lens[3] = {nx, ny, nz};
  const std::size_t strides[3] = {1, static_cast<std::size_t>(nx), plane};
  const int passes = nz == 1 ? 2 : 3;
  for (int axis = 0; axis < passes; ++axis) {
    const int len = lens[axis];
    const std::size_t stride = strides[axis];
    const std::size_t lines = n / static_cast<std::size_t>(len);
    runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
      float* f = s.line_f[task].data();
      float* d = s.line_d[task].data();
      std::int32_t* arg = s.line_arg[task].data();
      std::int32_t* v = s.line_v[task].data();
      float* z = s.line_z[task].data();
      std::int32_t* carried[2] = {s.line_s[0][task].data(), s.line_s[1][task].data()};
      const std::size_t first = lines * task / kTasksPerPass;
      const std::size_t last = lines * (task + 1) / kTasksPerPass;
      for (std::size_t line = first; line < last; ++line) {
        // The line's first cell: line enumerates the other two axes.
        const std::size_t base = axis == 0   ? line * static_cast<std::size_t>(nx)
                                 : axis == 1 ? (line / nx) * plane + (line % nx)
                                             : line;
        if (axis == 0) {
          for (int q = 0; q < len; ++q) f[q] = is_site(states[base + q]) ? 0.0f : kInf;
        } else {
          for (int q = 0; q < len; ++q) {
            const std::size_t i = base + q * stride;
            f[q] = s.sq[i];
            for (int a = 0; a < axis; ++a) carried[a][q] = s.site[a][i];
          }
        }
        edt_1d(f, len, d, arg, v, z);
        for (int q = 0; q < len; ++q) {
          const std::size_t i = base + q * stride;
          s.sq[i] = d[q];
          const std::int32_t from = arg[q];
          for (int a = 0; a < axis; ++a) s.site[a][i] = from < 0 ? -1 : carried[a][from];
          s.site[axis][i] = from;
        }
      }
    });
  }

  // Metres and gradients from the nearest site, row by row.
  const std::size_t rows = static_cast<std::size_t>(ny) * nz;
  runner.parallel_for(kTasksPerPass, [&](std::size_t task) {
    const std::size_t first = rows * task / kTasksPerPass;
    const std::size_t last = rows * (task + 1) / kTasksPerPass;
    for (std::size_t row = first; row < last; ++row) {
      const int y = static_cast<int>(row % ny);
      const int zz = static_cast<int>(row / ny);
      const std::size_t base = row * static_cast<std::size_t>(nx);
      for (int x = 0; x < nx; ++x) {
        const std::size_t i = base + x;
        float& dist = out.distance_m[i];
        float& gx = out.gradient_x[i];
        float& gy = out.gradient_y[i];
        float& gz = out.gradient_z[i];
        gx = gy = gz = 0.0f;
        if (states[i] == CellState::kUnknown && policy == UnknownPolicy::kReportUnknown) {
          dist = std::nanf("");
          continue;
        }
        if (s.sq[i] == kInf) {
          dist = kInf;
          continue;
        }
        const double r = std::sqrt(static_cast<double>(s.sq[i]));
        dist = static_cast<float>(r * cell_size_m);
        if (r > 0.0) {
          gx = static_cast<float>((x - s.site[0][i]) / r);
          gy = static_cast<float>((y - s.site[1][i]) / r);
          if (passes == 3) gz = static_cast<float>((zz - s.site[2][i]) / r);
        }
      }
    }
  });
}

}  // namespace tarmac::core
