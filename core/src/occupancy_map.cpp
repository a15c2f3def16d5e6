#include "tarmac/core/occupancy_map.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <tuple>
#include <utility>

#include "occupancy/log_odds.hpp"
#include "occupancy/ray_order.hpp"
#include "occupancy/ray_tasks.hpp"
#include "occupancy/static_store.hpp"
#include "occupancy/window.hpp"

namespace tarmac::core {

using namespace occupancy;  // NOLINT(google-build-using-namespace): the map's own internals

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
  if (const Status s = low_objects.validate(); !s.ok()) return s;
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
      l_max_(log_odds_of(params.clamp_max)),
      low_objects_(params.low_objects, params.window_x_vox, params.window_y_vox,
                   params.voxel_size_m) {
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
  scan_ground2_z_.assign(scan_ground_z_.size(), std::numeric_limits<float>::infinity());
  scan_ground_near_z_.assign(scan_ground_z_.size(), std::numeric_limits<float>::infinity());
  ground_memory_z_.assign(scan_ground_z_.size(), 0.0f);
  ground_memory_scan_.assign(scan_ground_z_.size(), 0);
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
  hit_before_.assign(kReservedHitSlots, 0.0f);
  hit_rise_before_.assign(kReservedHitSlots, 0);
  changed_columns_.assign((static_cast<std::size_t>(dims_.x()) * dims_.y() + 63) / 64, 0);
  bricks_ = (dims_.array() + ((1 << kBrickShift) - 1)) / (1 << kBrickShift);
  brick_bits_.assign((static_cast<std::size_t>(bricks_.prod()) + 63) / 64, 0);
  brick_skip_.assign(static_cast<std::size_t>(bricks_.prod()), 0);
  brick_run_up_.assign(brick_skip_.size(), 0);
  brick_run_down_.assign(brick_skip_.size(), 0);
  update_brick_skips();
  warm(hit_slot_, kReservedHitSlots);
  warm(hit_column_, kReservedHitSlots);
  warm(hit_height_, kReservedHitSlots);
  warm(hit_rise_, kReservedHitSlots);
  warm(ray_order_, kReservedHitSlots);
  warm(ray_bucket_, kReservedHitSlots);
  ray_bucket_count_.assign(kBucketTasks * kDirBuckets, 0);
}

bool ChangedColumns::contains(int x, int y) const {
  if (x < 0 || y < 0 || x >= width_ || y >= height_ || bits_.empty()) return false;
  const auto col = static_cast<std::size_t>(wrap(ring_y0_ + y, height_)) * width_ +
                   static_cast<std::size_t>(wrap(ring_x0_ + x, width_));
  return ((bits_[col >> 6] >> (col & 63)) & 1) != 0;
}

std::size_t ChangedColumns::count() const {
  std::size_t n = 0;
  for (const std::uint64_t w : bits_) n += static_cast<std::size_t>(std::popcount(w));
  return n;
}

int OccupancyMap::walk_lanes() const {
#if defined(TARMAC_WIDE_WALK)
  if (walk_lanes_ >= 8 && lanes8_walk_supported()) return 8;
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
      hit_floor_.capacity() + scan_rays_.memory_bytes() + static_bytes() +
      (scan_ground_z_.capacity() + scan_ground2_z_.capacity() + scan_ground_near_z_.capacity()) *
          sizeof(float) +
      scan_ground_cols_.capacity() * sizeof(std::uint32_t) +
      (hit_bits_.capacity() + floor_bits_.capacity() + changed_columns_.capacity()) *
          sizeof(std::uint64_t) +
      hit_before_.capacity() * sizeof(float) + hit_rise_before_.capacity() +
      hit_slots_.capacity() * sizeof(std::uint32_t) +
      (hit_slot_.capacity() + hit_column_.capacity()) * sizeof(std::uint32_t) +
      hit_height_.capacity() * sizeof(float) + hit_rise_.capacity() +
      ground_memory_z_.capacity() * sizeof(float) +
      ground_memory_scan_.capacity() * sizeof(std::uint32_t) +
      (ray_order_.capacity() + ray_bucket_count_.capacity()) * sizeof(std::uint32_t) +
      ray_bucket_.capacity() * sizeof(std::uint16_t) +
      brick_bits_.capacity() * sizeof(std::uint64_t) + brick_skip_.capacity() +
      brick_run_up_.capacity() + brick_run_down_.capacity();
  for (const auto& b : free_bits_) bytes += b.capacity() * sizeof(std::uint64_t);
  for (const auto& d : dirty_words_) bytes += d.capacity() * sizeof(std::uint64_t);
  for (const auto& c : candidates_) bytes += c.capacity() * sizeof(std::uint32_t);
  bytes += miss_decision_.capacity() + low_objects_.memory_bytes();
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
        // pass per slab would read each row's lines again).
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

VoxelIndex OccupancyMap::window_min_at(const Eigen::Vector3d& position_W) const {
  const double v = params_.voxel_size_m;
  VoxelIndex target;
  target.x() = static_cast<int>(std::floor(position_W.x() / v)) - dims_.x() / 2;
  target.y() = static_cast<int>(std::floor(position_W.y() / v)) - dims_.y() / 2;
  target.z() = static_cast<int>(std::floor((position_W.z() - params_.window_below_m) / v));
  return target;
}

void OccupancyMap::recenter(const Eigen::Vector3d& position_W) {
  SerialRunner serial;
  recenter(position_W, serial);
}

void OccupancyMap::recenter(const Eigen::Vector3d& position_W, TaskRunner& runner) {
  const VoxelIndex target = window_min_at(position_W);
  if (!placed_) {
    min_ = target;
    placed_ = true;
    restore_static(min_, min_ + dims_ - VoxelIndex::Ones());
    update_band();
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
    if (a < 2) {
      // The columns leaving: never observed, no ground remembered, when they come back in.
      const int first =
          std::abs(shift) >= dims_[a] ? 0 : (shift > 0 ? min_[a] + dims_[a] : target[a]);
      const int count = std::min(std::abs(shift), dims_[a]);
      const int nx = dims_.x(), ny = dims_.y();
      const bool observed = !column_observed_ns_.empty();
      for (int k = 0; k < count; ++k) {
        const int r = wrap(first + k, dims_[a]);
        for (int o = 0; o < (a == 0 ? ny : nx); ++o) {
          const auto q = static_cast<std::size_t>(a == 0 ? o * nx + r : r * nx + o);
          ground_memory_scan_[q] = 0;
          if (observed) column_observed_ns_[q] = 0;
        }
      }
    }
    min_[a] = target[a];
    restore_static(lo, hi);
  }
  update_band();
}

void OccupancyMap::track_column_observations(int band_lo, int band_hi) {
  band_lo_ = std::max(0, band_lo);
  band_hi_ = std::min(dims_.z() - 1, band_hi);
  column_observed_ns_.assign(static_cast<std::size_t>(dims_.x()) * dims_.y(), 0);
  in_band_.assign(static_cast<std::size_t>(dims_.z()), 0);
  update_band();
}

void OccupancyMap::update_band() {
  if (in_band_.empty()) return;
  std::fill(in_band_.begin(), in_band_.end(), std::uint8_t{0});
  for (int z = band_lo_; z <= band_hi_; ++z) {
    in_band_[static_cast<std::size_t>(wrap(min_.z() + z, dims_.z()))] = 1;
  }
}

void OccupancyMap::export_column_observed(std::vector<std::int64_t>& out) const {
  const int nx = dims_.x(), ny = dims_.y();
  out.assign(static_cast<std::size_t>(nx) * ny, 0);
  if (column_observed_ns_.empty()) return;
  for (int y = 0; y < ny; ++y) {
    const std::size_t ring_row = static_cast<std::size_t>(ring_y(y)) * nx;
    for (int x = 0; x < nx; ++x) {
      out[static_cast<std::size_t>(y) * nx + x] =
          column_observed_ns_[ring_row + static_cast<std::size_t>(ring_x(x))];
    }
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
            flag_brick(s);
          }
        }
      }
    }
  }
  if (bricks_dirty_) update_brick_skips();
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
  const std::array<int, 3> seam = ring_origin();
  VoxelIndex v;
  for (int a = 0; a < 3; ++a) v[a] = world_of_ring(a, rings[a], seam[a]);
  return v;
}

int OccupancyMap::world_of_ring(int a, int r, int seam) const {
  return min_[a] + wrap(r - seam, dims_[a]);
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
    const int bx = StaticStore::block_x(key), by = StaticStore::block_y(key),
              bz = StaticStore::block_z(key);
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

bool OccupancyMap::take_static_columns(int lo_x, int lo_y, int hi_x, int hi_y,
                                       std::vector<VoxelIndex>& out) {
  return static_columns(lo_x, lo_y, hi_x, hi_y, out, true);
}

void OccupancyMap::copy_static_columns(int lo_x, int lo_y, int hi_x, int hi_y,
                                       std::vector<VoxelIndex>& out) {
  static_columns(lo_x, lo_y, hi_x, hi_y, out, false);
}

void OccupancyMap::static_tiles(int edge, std::vector<Eigen::Vector2i>& out) const {
  TARMAC_ASSERT(edge > 0 && edge % StaticStore::kSide == 0, "static tiles are whole blocks");
  const int per = edge / StaticStore::kSide;
  const auto tile = [per](int b) { return b >= 0 ? b / per : -((-b + per - 1) / per); };
  out.clear();
  static_->for_each([&](std::uint64_t key, const StaticStore::Mask&) {
    out.emplace_back(tile(StaticStore::block_x(key)), tile(StaticStore::block_y(key)));
  });
  const auto order = [](const Eigen::Vector2i& a, const Eigen::Vector2i& b) {
    return std::tie(a.y(), a.x()) < std::tie(b.y(), b.x());
  };
  std::sort(out.begin(), out.end(), order);
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

bool OccupancyMap::static_columns(int lo_x, int lo_y, int hi_x, int hi_y,
                                  std::vector<VoxelIndex>& out, bool take) {
  constexpr int kS = StaticStore::kShift;
  TARMAC_ASSERT(((lo_x | lo_y) & (StaticStore::kSide - 1)) == 0 &&
                    ((hi_x + 1) & (StaticStore::kSide - 1)) == 0 &&
                    ((hi_y + 1) & (StaticStore::kSide - 1)) == 0,
                "take_static_columns takes whole blocks");
  if (take && placed_) {
    const VoxelIndex top = min_ + dims_ - VoxelIndex::Ones();
    const bool meets = lo_x <= top.x() && hi_x >= min_.x() && lo_y <= top.y() && hi_y >= min_.y();
    if (meets) return false;  // the window's voxels carry the static state too
  }
  const std::size_t first = out.size();
  taken_keys_.clear();
  static_->for_each([&](std::uint64_t key, const StaticStore::Mask& mask) {
    const int bx = StaticStore::block_x(key), by = StaticStore::block_y(key);
    if (bx < (lo_x >> kS) || bx > (hi_x >> kS) || by < (lo_y >> kS) || by > (hi_y >> kS)) return;
    taken_keys_.push_back(key);
    const int bz = StaticStore::block_z(key);
    for (int w = 0; w < 8; ++w) {
      for (std::uint64_t m = mask[w]; m != 0; m &= m - 1) {
        const int b = w * 64 + std::countr_zero(m);
        out.emplace_back((bx << kS) | (b & 7), (by << kS) | ((b >> 3) & 7), (bz << kS) | (b >> 6));
      }
    }
  });
  if (take) {
    for (const std::uint64_t key : taken_keys_) static_->erase_block(key);
  }
  std::sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end(),
            [](const VoxelIndex& a, const VoxelIndex& b) {
              return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
            });
  return true;
}

void OccupancyMap::put_static(std::span<const VoxelIndex> voxels) {
  if (voxels.empty()) return;
  VoxelIndex lo = voxels.front(), hi = voxels.front();
  for (const VoxelIndex& v : voxels) {
    static_->insert(v);
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  if (!placed_) return;
  // Those inside the window read static now (a tile that came back after the window reached it).
  lo = lo.cwiseMax(min_);
  hi = hi.cwiseMin(min_ + dims_ - VoxelIndex::Ones());
  if ((lo.array() <= hi.array()).all()) restore_static(lo, hi);
}

std::size_t OccupancyMap::static_bytes() const {
  return static_->keys.capacity() * (sizeof(StaticStore::Mask) + sizeof(std::uint64_t));
}

std::array<int, 3> OccupancyMap::ring_origin() const {
  return {wrap(min_.x(), dims_.x()), wrap(min_.y(), dims_.y()), wrap(min_.z(), dims_.z())};
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
  std::fill(changed_columns_.begin(), changed_columns_.end(), std::uint64_t{0});
  // The static layer too: a rebuild re-derives it from the retained scans (what was static
  // before the correction sits in the uncorrected frame).
  static_->clear();
  for (auto& c : candidates_) c.clear();
  std::fill(column_observed_ns_.begin(), column_observed_ns_.end(), std::int64_t{0});
  std::fill(ground_memory_scan_.begin(), ground_memory_scan_.end(), std::uint32_t{0});
  low_objects_.clear();
  std::fill(brick_bits_.begin(), brick_bits_.end(), std::uint64_t{0});
  brick_refresh_row_ = 0;
  update_brick_skips();
  min_ = VoxelIndex::Zero();
  placed_ = false;
}

}  // namespace tarmac::core
