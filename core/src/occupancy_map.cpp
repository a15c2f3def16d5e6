#include "tarmac/core/occupancy_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tarmac::core {

namespace {

/// Non-negative remainder.
int wrap(int i, int n) {
  const int r = i % n;
  return r < 0 ? r + n : r;
}

/// Rays are cast in fixed chunks and their voxels applied in fixed bands of the window, so the
/// work splits the same way whatever the runner's thread count (determinism contract).
constexpr std::size_t kRaysPerChunk = 2048;
constexpr int kApplyBands = 8;

/// Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing" (Eurographics 1987), on
/// the lattice [i·v, (i+1)·v), clipped to the window. Calls visit(slot) for each voxel from the
/// origin's voxel up to the end point's voxel, excluding it unless `include_end`. Stops when the
/// ray leaves the window (a box: it cannot come back).
struct WindowGeometry {
  Eigen::Vector3i dims;
  Eigen::Vector3i min;
  double voxel_size_m;
};

template <typename Visit>
std::uint64_t traverse(const WindowGeometry& w, const Eigen::Vector3d& origin_W,
                       const Eigen::Vector3d& end_W, bool include_end, Visit&& visit) {
  const Eigen::Vector3d o = origin_W / w.voxel_size_m;
  const Eigen::Vector3d e = end_W / w.voxel_size_m;
  const Eigen::Vector3d d = e - o;
  int cur[3], rel[3], ring[3], step[3];  // NOLINT(cppcoreguidelines-init-variables): set below
  double t_max[3], t_delta[3];
  int remaining = 0;
  for (int a = 0; a < 3; ++a) {
    cur[a] = static_cast<int>(std::floor(o[a]));
    const int last = static_cast<int>(std::floor(e[a]));
    remaining += std::abs(last - cur[a]);
    rel[a] = cur[a] - w.min[a];
    ring[a] = wrap(cur[a], w.dims[a]);
    if (d[a] > 0) {
      step[a] = 1;
      t_delta[a] = 1.0 / d[a];
      t_max[a] = (cur[a] + 1 - o[a]) * t_delta[a];
    } else if (d[a] < 0) {
      step[a] = -1;
      t_delta[a] = -1.0 / d[a];
      t_max[a] = (o[a] - cur[a]) * t_delta[a];
    } else {
      step[a] = 0;
      t_delta[a] = std::numeric_limits<double>::infinity();
      t_max[a] = std::numeric_limits<double>::infinity();
    }
  }
  const int nx = w.dims[0], ny = w.dims[1], nz = w.dims[2];
  std::uint64_t visits = 0;
  const auto inside = [&] {
    return rel[0] >= 0 && rel[0] < nx && rel[1] >= 0 && rel[1] < ny && rel[2] >= 0 && rel[2] < nz;
  };
  for (;; --remaining) {
    if (remaining == 0 && !include_end) break;
    if (!inside()) break;
    visit(static_cast<std::uint32_t>((ring[2] * ny + ring[1]) * nx + ring[0]), ring[2]);
    ++visits;
    if (remaining == 0) break;
    const int a =
        t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
    cur[a] += step[a];
    rel[a] += step[a];
    ring[a] += step[a];
    if (ring[a] == w.dims[a]) ring[a] = 0;
    if (ring[a] < 0) ring[a] = w.dims[a] - 1;
    t_max[a] += t_delta[a];
  }
  return visits;
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
  if (!(max_range_m > 0.0)) return bad("max_range_m", "must be > 0");
  if (!(clearing_range_m >= 0.0)) return bad("clearing_range_m", "must be >= 0");
  if (!(window_below_m >= 0.0 && window_below_m <= window_z_vox * voxel_size_m)) {
    return bad("window_below_m", "must be within the window height");
  }
  return Ok{};
}

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
  log_odds_.assign(n, kUnknown);
  touched_.assign(n, 0);
}

std::size_t OccupancyMap::memory_bytes() const {
  return log_odds_.capacity() * sizeof(float) + touched_.capacity() * sizeof(std::uint32_t);
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

void OccupancyMap::clear_slab(int axis, int global_index) {
  const int r = wrap(global_index, dims_[axis]);
  const int nx = dims_.x(), ny = dims_.y(), nz = dims_.z();
  for (int z = 0; z < nz; ++z) {
    for (int y = 0; y < ny; ++y) {
      if ((axis == 2 && z != r) || (axis == 1 && y != r)) continue;
      const std::size_t row = (static_cast<std::size_t>(z) * ny + y) * nx;
      if (axis == 0) {
        log_odds_[row + r] = kUnknown;
      } else {
        std::fill_n(log_odds_.begin() + static_cast<std::ptrdiff_t>(row), nx, kUnknown);
      }
    }
  }
}

void OccupancyMap::recenter(const Eigen::Vector3d& position_W) {
  const double v = params_.voxel_size_m;
  VoxelIndex target;
  target.x() = static_cast<int>(std::floor(position_W.x() / v)) - dims_.x() / 2;
  target.y() = static_cast<int>(std::floor(position_W.y() / v)) - dims_.y() / 2;
  target.z() = static_cast<int>(std::floor((position_W.z() - params_.window_below_m) / v));
  if (!placed_) {
    min_ = target;
    placed_ = true;
    return;
  }
  // Axis by axis: the voxels entering along an axis occupy exactly the ring slabs of the voxels
  // leaving, so clearing those slabs forgets the old content and nothing else.
  for (int a = 0; a < 3; ++a) {
    const int shift = target[a] - min_[a];
    if (shift == 0) continue;
    if (std::abs(shift) >= dims_[a]) {
      std::fill(log_odds_.begin(), log_odds_.end(), kUnknown);
    } else if (shift > 0) {
      for (int g = min_[a] + dims_[a]; g < target[a] + dims_[a]; ++g) clear_slab(a, g);
    } else {
      for (int g = target[a]; g < min_[a]; ++g) clear_slab(a, g);
    }
    min_[a] = target[a];
  }
}

void OccupancyMap::update(std::size_t s, bool hit) {
  float& l = log_odds_[s];
  const float base = l == kUnknown ? 0.0f : l;
  l = std::clamp(base + (hit ? l_hit_ : l_miss_), l_min_, l_max_);
}

OccupancyUpdateStats OccupancyMap::integrate(const Eigen::Vector3d& origin_W,
                                             std::span<const Eigen::Vector3f> points_W,
                                             std::span<const Eigen::Vector3f> clearing_dirs_W,
                                             TaskRunner& runner) {
  OccupancyUpdateStats stats;
  if (!placed_) recenter(origin_W);
  // A new epoch per scan: touched_ == 2·epoch (+1 for a hit) means "updated in this scan".
  if (epoch_ >= std::numeric_limits<std::uint32_t>::max() / 2 - 1) {
    std::fill(touched_.begin(), touched_.end(), 0u);
    epoch_ = 0;
  }
  ++epoch_;
  const std::uint32_t free_mark = 2 * epoch_;
  const std::uint32_t hit_mark = free_mark + 1;
  const double max_range = params_.max_range_m;
  const double clear_range = params_.clearing_range_m;

  // 1. Hits first, so that a voxel hit by any ray of this scan is never also cleared by it.
  for (const auto& p : points_W) {
    if (!p.allFinite()) continue;
    const Eigen::Vector3d pd = p.cast<double>();
    if ((pd - origin_W).norm() > max_range) continue;
    const VoxelIndex v = voxel_of(pd);
    if (!in_window(v)) {
      ++stats.outside_window;
      continue;
    }
    const std::size_t s = slot(v);
    if (touched_[s] != hit_mark) {
      touched_[s] = hit_mark;
      update(s, true);
      ++stats.hit_updates;
    }
  }

  // 2. Free space: rays cast in fixed chunks (in parallel), their voxels binned by window band,
  //    then each band applied by one task in chunk order. Membership, not order, decides each
  //    voxel's update, so the result is the same for any thread count.
  const std::size_t n_rays = points_W.size() + clearing_dirs_W.size();
  const std::size_t n_chunks = (n_rays + kRaysPerChunk - 1) / kRaysPerChunk;
  bins_.resize(std::max(bins_.size(), n_chunks * kApplyBands));
  const WindowGeometry w{dims_, min_, params_.voxel_size_m};
  // Bands are ranges of ring layers, looked up per visit (no division in the inner loop).
  const int band_height = (dims_.z() + kApplyBands - 1) / kApplyBands;
  band_of_z_.resize(static_cast<std::size_t>(dims_.z()));
  for (int z = 0; z < dims_.z(); ++z)
    band_of_z_[static_cast<std::size_t>(z)] = static_cast<std::uint8_t>(z / band_height);
  const std::uint8_t* band_of_z = band_of_z_.data();
  std::vector<std::uint64_t> chunk_visits(n_chunks, 0);
  runner.parallel_for(n_chunks, [&](std::size_t chunk) {
    std::vector<std::uint32_t>* bins = &bins_[chunk * kApplyBands];
    for (int b = 0; b < kApplyBands; ++b) bins[b].clear();
    const auto visit = [&](std::uint32_t s, int ring_z) { bins[band_of_z[ring_z]].push_back(s); };
    const std::size_t begin = chunk * kRaysPerChunk;
    const std::size_t end = std::min(n_rays, begin + kRaysPerChunk);
    std::uint64_t visits = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if (i < points_W.size()) {
        const Eigen::Vector3f& p = points_W[i];
        if (!p.allFinite()) continue;
        const Eigen::Vector3d pd = p.cast<double>();
        const double range = (pd - origin_W).norm();
        if (range <= max_range) {
          visits += traverse(w, origin_W, pd, false, visit);
        } else if (clear_range > 0.0) {
          visits += traverse(w, origin_W, origin_W + (pd - origin_W) * (clear_range / range), true,
                             visit);
        }
      } else {
        const Eigen::Vector3f& dir = clearing_dirs_W[i - points_W.size()];
        const double norm = dir.cast<double>().norm();
        if (!dir.allFinite() || norm == 0.0 || clear_range <= 0.0) continue;
        visits += traverse(w, origin_W, origin_W + dir.cast<double>() * (clear_range / norm), true,
                           visit);
      }
    }
    chunk_visits[chunk] = visits;
  });
  std::vector<std::uint64_t> band_updates(kApplyBands, 0);
  runner.parallel_for(kApplyBands, [&](std::size_t band) {
    std::uint64_t updates = 0;
    for (std::size_t chunk = 0; chunk < n_chunks; ++chunk) {
      for (const std::uint32_t s : bins_[chunk * kApplyBands + band]) {
        std::uint32_t& t = touched_[s];
        if (t == hit_mark || t == free_mark) continue;
        t = free_mark;
        float& l = log_odds_[s];
        l = std::max((l == kUnknown ? 0.0f : l) + l_miss_, l_min_);  // a miss only lowers
        ++updates;
      }
    }
    band_updates[band] = updates;
  });
  stats.rays = n_rays;
  for (const auto v : chunk_visits) stats.voxel_visits += v;
  for (const auto u : band_updates) stats.miss_updates += u;
  return stats;
}

const float* OccupancyMap::ring_layer(int wz) const {
  return log_odds_.data() +
         static_cast<std::size_t>(wrap(min_.z() + wz, dims_.z())) * dims_.x() * dims_.y();
}
int OccupancyMap::ring_x(int wx) const {
  return wrap(min_.x() + wx, dims_.x());
}
int OccupancyMap::ring_y(int wy) const {
  return wrap(min_.y() + wy, dims_.y());
}

void OccupancyMap::export_log_odds(std::vector<float>& out) const {
  out.resize(log_odds_.size());
  std::size_t i = 0;
  for (int z = 0; z < dims_.z(); ++z) {
    for (int y = 0; y < dims_.y(); ++y) {
      for (int x = 0; x < dims_.x(); ++x) {
        out[i++] = log_odds_[slot(min_ + VoxelIndex(x, y, z))];
      }
    }
  }
}

}  // namespace tarmac::core
