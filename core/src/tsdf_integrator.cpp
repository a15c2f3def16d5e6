#include "tarmac/core/tsdf_integrator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "tsdf_grids.hpp"

namespace tarmac::core {

namespace {

using FloatTree = openvdb::FloatTree;
using FloatLeaf = FloatTree::LeafNodeType;
/// Unregistered accessor: used only within one integration phase, during which the tree's
/// structure does not change.
using FastAccessor = openvdb::tree::ValueAccessor<FloatTree, false>;

static_assert(FloatLeaf::DIM == kTsdfBlockEdge, "TSDF blocks are OpenVDB leaves");
static_assert(FloatLeaf::SIZE == kTsdfBlockVoxels, "TSDF blocks are OpenVDB leaves");

/// Ray chunks and block partitions: fixed, independent of the thread count (determinism).
constexpr std::size_t kRayChunks = 32;
constexpr std::size_t kPartitions = 16;
/// Block coordinates are packed in 21 bits each: voxel indices must stay within ±2^23.
constexpr int kBlockBias = 1 << 20;
constexpr double kMaxVoxelIndex = static_cast<double>((1 << 23) - 16);
constexpr std::uint64_t kEmptyKey = ~std::uint64_t{0};

std::uint64_t pack_block(int bx, int by, int bz) {
  return (static_cast<std::uint64_t>(bx + kBlockBias) << 42) |
         (static_cast<std::uint64_t>(by + kBlockBias) << 21) |
         static_cast<std::uint64_t>(bz + kBlockBias);
}
BlockIndex unpack_block(std::uint64_t key) {
  constexpr std::uint64_t m = (std::uint64_t{1} << 21) - 1;
  return {static_cast<int>((key >> 42) & m) - kBlockBias,
          static_cast<int>((key >> 21) & m) - kBlockBias, static_cast<int>(key & m) - kBlockBias};
}
std::uint64_t mix(std::uint64_t key) {
  return key * 0x9E3779B97F4A7C15ull;
}
std::size_t partition_of(std::uint64_t key) {
  return static_cast<std::size_t>(mix(key) >> 60);
}
static_assert(kPartitions == 16, "partition_of takes the top 4 bits");

/// One (ray, voxel) pair inside the band.
struct Sample {
  std::uint64_t block_key;
  std::uint32_t offset;  // voxel inside the block, OpenVDB leaf order
  float sdf_m;
};

/// One sample after grouping by block.
struct GroupedSample {
  std::uint32_t offset;
  float sdf_m;
};

/// Per-partition state: blocks met this scan (open addressing), grouped samples, new leaves.
struct Partition {
  std::vector<std::uint64_t> table_keys;  // kEmptyKey = free
  std::vector<std::uint32_t> table_slots;
  std::vector<std::uint64_t> slot_keys;
  std::vector<std::uint32_t> slot_hash_pos;
  std::vector<std::uint32_t> slot_count;
  std::vector<std::uint32_t> slot_start;
  std::vector<std::uint32_t> sample_slot;
  std::vector<GroupedSample> grouped;
  std::vector<std::unique_ptr<FloatLeaf>> new_distance, new_weight;
  std::array<float, kTsdfBlockVoxels> sum{};
  std::array<std::uint32_t, kTsdfBlockVoxels> count{};
  std::vector<std::uint32_t> touched;
  std::uint64_t voxel_updates = 0;

  void reserve_table(std::size_t blocks) {
    std::size_t cap = 1024;
    while (cap < 2 * blocks) cap *= 2;
    if (table_keys.size() >= cap) return;
    table_keys.assign(cap, kEmptyKey);
    table_slots.assign(cap, 0);
  }

  std::uint32_t slot_for(std::uint64_t key) {
    const std::size_t mask = table_keys.size() - 1;
    std::size_t h = static_cast<std::size_t>(mix(key) >> 20) & mask;
    while (true) {
      if (table_keys[h] == key) return table_slots[h];
      if (table_keys[h] == kEmptyKey) {
        const auto slot = static_cast<std::uint32_t>(slot_keys.size());
        table_keys[h] = key;
        table_slots[h] = slot;
        slot_keys.push_back(key);
        slot_hash_pos.push_back(static_cast<std::uint32_t>(h));
        slot_count.push_back(0);
        return slot;
      }
      h = (h + 1) & mask;
    }
  }

  void reset_table() {
    for (const std::uint32_t h : slot_hash_pos) table_keys[h] = kEmptyKey;
    slot_keys.clear();
    slot_hash_pos.clear();
    slot_count.clear();
  }
};

}  // namespace

struct TsdfIntegrator::Scratch {
  std::vector<std::vector<Sample>> bins =
      std::vector<std::vector<Sample>>(kRayChunks * kPartitions);
  std::vector<std::uint64_t> chunk_rays = std::vector<std::uint64_t>(kRayChunks);
  std::vector<Partition> partitions = std::vector<Partition>(kPartitions);
};

// ---------------------------------------------------------------------------------------------
// Params and layer

Status TsdfParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) -> Status {
    return Error{"tsdf.invalid", "tsdf." + key + ": " + why};
  };
  if (!(voxel_size_m >= 0.01f && voxel_size_m <= 2.0f)) {
    return bad("voxel_size_m", "must be in [0.01, 2] m");
  }
  if (!(truncation_m >= voxel_size_m && truncation_m <= 32.0f * voxel_size_m)) {
    return bad("truncation_m", "must be in [voxel_size_m, 32 * voxel_size_m]");
  }
  if (!(max_weight >= 1.0f && max_weight <= 1e6f)) return bad("max_weight", "must be in [1, 1e6]");
  if (!(max_range_m > 0.0f && max_range_m <= 1000.0f)) {
    return bad("max_range_m", "must be in (0, 1000] m");
  }
  return Ok{};
}

openvdb::math::Transform::Ptr tsdf_transform(float voxel_size_m) {
  auto xform = openvdb::math::Transform::createLinearTransform(static_cast<double>(voxel_size_m));
  xform->postTranslate(openvdb::Vec3d(0.5 * static_cast<double>(voxel_size_m)));
  return xform;
}

void make_tsdf_grids(float voxel_size_m, float truncation_m, TsdfLayer::Grids& grids) {
  grids.distance = openvdb::FloatGrid::create(truncation_m);
  grids.distance->setName("tsdf");
  grids.distance->setGridClass(openvdb::GRID_LEVEL_SET);
  grids.distance->setTransform(tsdf_transform(voxel_size_m));
  grids.weight = openvdb::FloatGrid::create(0.0f);
  grids.weight->setName("weight");
  grids.weight->setTransform(tsdf_transform(voxel_size_m));
}

TsdfLayer::TsdfLayer(float voxel_size_m, float truncation_m)
    : voxel_size_m_(voxel_size_m), truncation_m_(truncation_m), grids_(std::make_unique<Grids>()) {
  TARMAC_ASSERT(voxel_size_m > 0.0f && truncation_m > 0.0f, "TsdfLayer needs positive sizes");
  make_tsdf_grids(voxel_size_m, truncation_m, *grids_);
}
TsdfLayer::~TsdfLayer() = default;
TsdfLayer::TsdfLayer(TsdfLayer&&) noexcept = default;
TsdfLayer& TsdfLayer::operator=(TsdfLayer&&) noexcept = default;

std::optional<TsdfVoxel> TsdfLayer::voxel(const TsdfVoxelIndex& v) const {
  const openvdb::Coord c(v.x(), v.y(), v.z());
  const float w = grids_->weight->tree().getValue(c);
  if (!(w > 0.0f)) return std::nullopt;
  return TsdfVoxel{grids_->distance->tree().getValue(c), w};
}

TsdfVoxelIndex TsdfLayer::voxel_of(const Eigen::Vector3d& p_W) const {
  return (p_W / static_cast<double>(voxel_size_m_)).array().floor().cast<int>();
}

Eigen::Vector3d TsdfLayer::center_of(const TsdfVoxelIndex& v) const {
  return (v.cast<double>().array() + 0.5) * static_cast<double>(voxel_size_m_);
}

std::size_t TsdfLayer::block_count() const {
  return grids_->distance->tree().leafCount();
}

std::size_t TsdfLayer::voxel_count() const {
  return grids_->distance->tree().activeLeafVoxelCount();
}

std::size_t TsdfLayer::memory_bytes() const {
  return grids_->distance->memUsage() + grids_->weight->memUsage();
}

void TsdfLayer::for_each_block(const std::function<void(const TsdfBlockView&)>& fn) const {
  openvdb::tree::ValueAccessor<const FloatTree> weights(grids_->weight->tree());
  for (auto it = grids_->distance->tree().cbeginLeaf(); it; ++it) {
    const openvdb::Coord o = it->origin();
    const FloatLeaf* w = weights.probeConstLeaf(o);
    TARMAC_ASSERT(w != nullptr, "TSDF distance and weight grids share one topology");
    fn(TsdfBlockView{BlockIndex(o.x() >> 3, o.y() >> 3, o.z() >> 3), it->buffer().data(),
                     w->buffer().data()});
  }
}

std::optional<TsdfBlockView> TsdfLayer::find_block(const BlockIndex& b) const {
  const openvdb::Coord o(b.x() * kTsdfBlockEdge, b.y() * kTsdfBlockEdge, b.z() * kTsdfBlockEdge);
  const FloatLeaf* d = grids_->distance->tree().probeConstLeaf(o);
  if (d == nullptr) return std::nullopt;
  const FloatLeaf* w = grids_->weight->tree().probeConstLeaf(o);
  TARMAC_ASSERT(w != nullptr, "TSDF distance and weight grids share one topology");
  return TsdfBlockView{b, d->buffer().data(), w->buffer().data()};
}

std::uint64_t TsdfLayer::digest() const {
  // FNV-1a 64 over 32-bit words (coordinates, then distances and weights of every voxel).
  std::uint64_t h = 1469598103934665603ull;
  const auto word = [&h](std::uint32_t x) {
    h ^= x;
    h *= 1099511628211ull;
  };
  for_each_block([&](const TsdfBlockView& b) {
    for (int a = 0; a < 3; ++a) word(static_cast<std::uint32_t>(b.block[a]));
    for (int n = 0; n < kTsdfBlockVoxels; ++n) {
      std::uint32_t d, w;
      std::memcpy(&d, &b.distance_m[n], 4);
      std::memcpy(&w, &b.weight[n], 4);
      word(d);
      word(w);
    }
  });
  return h;
}

void TsdfLayer::clear() {
  make_tsdf_grids(voxel_size_m_, truncation_m_, *grids_);
}

// ---------------------------------------------------------------------------------------------
// Integrator

TsdfIntegrator::TsdfIntegrator(const TsdfParams& params)
    : params_(params), scratch_(std::make_unique<Scratch>()) {
  TARMAC_ASSERT(params.validate().ok(), "TsdfParams must be validated first");
}
TsdfIntegrator::~TsdfIntegrator() = default;
TsdfIntegrator::TsdfIntegrator(TsdfIntegrator&&) noexcept = default;
TsdfIntegrator& TsdfIntegrator::operator=(TsdfIntegrator&&) noexcept = default;

TsdfLayer TsdfIntegrator::make_layer() const {
  return TsdfLayer(params_.voxel_size_m, params_.truncation_m);
}

namespace {

/// Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing", Eurographics 1987:
/// every voxel the segment origin + t·dir, t in [t0, t1], passes through, in order. For each,
/// the projective signed distance r − |c − o| of its centre c; kept when within the band
/// (carving: in front of the band clamped to +truncation).
void band_samples(const Eigen::Vector3d& o, const Eigen::Vector3d& dir, double range, double t0,
                  double t1, double v, double trunc, bool carve,
                  std::vector<Sample>* bins /* kPartitions */) {
  const Eigen::Vector3d q0 = (o + t0 * dir) / v;  // voxel units
  Eigen::Vector3i idx = q0.array().floor().cast<int>();
  int step[3];
  double t_max[3], t_delta[3];
  for (int a = 0; a < 3; ++a) {
    if (dir[a] > 0.0) {
      step[a] = 1;
      t_delta[a] = v / dir[a];
      t_max[a] = t0 + (idx[a] + 1 - q0[a]) * t_delta[a];
    } else if (dir[a] < 0.0) {
      step[a] = -1;
      t_delta[a] = -v / dir[a];
      t_max[a] = t0 + (q0[a] - idx[a]) * t_delta[a];
    } else {
      step[a] = 0;
      t_delta[a] = std::numeric_limits<double>::infinity();
      t_max[a] = std::numeric_limits<double>::infinity();
    }
  }
  const double half = 0.5 * v;
  std::uint64_t last_key = kEmptyKey;
  std::vector<Sample>* bin = nullptr;
  while (true) {
    const double cx = idx.x() * v + half - o.x(), cy = idx.y() * v + half - o.y(),
                 cz = idx.z() * v + half - o.z();
    double sdf = range - std::sqrt(cx * cx + cy * cy + cz * cz);
    if (carve && sdf > trunc) sdf = trunc;
    if (sdf <= trunc && sdf >= -trunc) {
      const std::uint64_t key = pack_block(idx.x() >> 3, idx.y() >> 3, idx.z() >> 3);
      if (key != last_key) {
        last_key = key;
        bin = &bins[partition_of(key)];
      }
      const auto offset =
          static_cast<std::uint32_t>(tsdf_voxel_offset(idx.x() & 7, idx.y() & 7, idx.z() & 7));
      bin->push_back(Sample{key, offset, static_cast<float>(sdf)});
    }
    const int a =
        t_max[0] < t_max[1] ? (t_max[0] < t_max[2] ? 0 : 2) : (t_max[1] < t_max[2] ? 1 : 2);
    if (t_max[a] > t1) break;
    idx[a] += step[a];
    t_max[a] += t_delta[a];
  }
}

}  // namespace

const TsdfUpdate& TsdfIntegrator::integrate(const Eigen::Vector3d& origin_W,
                                            std::span<const Eigen::Vector3f> points_W,
                                            TsdfLayer& layer, TaskRunner& runner) {
  TARMAC_ASSERT(
      layer.voxel_size_m() == params_.voxel_size_m && layer.truncation_m() == params_.truncation_m,
      "TSDF layer and integrator must share voxel size and truncation");
  Scratch& s = *scratch_;
  {
    std::vector<BlockIndex> keep = std::move(update_.blocks);  // keeps its capacity
    keep.clear();
    update_ = TsdfUpdate{};
    update_.blocks = std::move(keep);
  }
  const double v = params_.voxel_size_m;
  const double trunc = params_.truncation_m;
  const double max_range = params_.max_range_m;
  const bool carve = params_.space_carving;
  const Eigen::Vector3d o = origin_W;
  if (!o.allFinite() || (o.array().abs() / v).maxCoeff() > kMaxVoxelIndex / 2) return update_;

  // 1. Band samples per ray chunk, binned by the partition owning their block.
  const std::size_t n = points_W.size();
  const std::size_t per_chunk = (n + kRayChunks - 1) / kRayChunks;
  runner.parallel_for(kRayChunks, [&](std::size_t c) {
    std::vector<Sample>* bins = &s.bins[c * kPartitions];
    for (std::size_t p = 0; p < kPartitions; ++p) bins[p].clear();
    std::uint64_t rays = 0;
    const std::size_t end = std::min(n, (c + 1) * per_chunk);
    for (std::size_t i = c * per_chunk; i < end; ++i) {
      const Eigen::Vector3d p = points_W[i].cast<double>();
      const Eigen::Vector3d d = p - o;
      const double r = d.norm();
      if (!std::isfinite(r) || r > max_range || r <= 0.0) continue;
      ++rays;
      const Eigen::Vector3d dir = d / r;
      const double t0 = carve ? 0.0 : std::max(0.0, r - trunc);
      band_samples(o, dir, r, t0, r + trunc, v, trunc, carve, bins);
    }
    s.chunk_rays[c] = rays;
  });

  // 2. Per partition: group samples by block (first-touch order, samples in ray order), merge
  //    each voxel's samples (mean) and apply one running-average update. Existing leaves are
  //    found read-only; new ones are built aside and added to the trees in step 3.
  const float max_w = params_.max_weight;
  const float background = params_.truncation_m;
  auto& grids = layer.grids();
  FloatTree& dist_tree = grids.distance->tree();
  FloatTree& weight_tree = grids.weight->tree();
  runner.parallel_for(kPartitions, [&](std::size_t p) {
    Partition& part = s.partitions[p];
    std::size_t total = 0;
    for (std::size_t c = 0; c < kRayChunks; ++c) total += s.bins[c * kPartitions + p].size();
    // Worst case every sample is its own block: the table never fills beyond half.
    part.reserve_table(total);
    part.sample_slot.resize(total);
    part.grouped.resize(total);
    part.new_distance.clear();
    part.new_weight.clear();
    part.voxel_updates = 0;
    std::size_t k = 0;
    for (std::size_t c = 0; c < kRayChunks; ++c) {
      const auto& bin = s.bins[c * kPartitions + p];
      std::uint64_t last = kEmptyKey;
      std::uint32_t slot = 0;
      for (const Sample& smp : bin) {
        if (smp.block_key != last) {
          last = smp.block_key;
          slot = part.slot_for(last);
        }
        part.slot_count[slot]++;
        part.sample_slot[k++] = slot;
      }
    }
    const std::size_t slots = part.slot_keys.size();
    part.slot_start.resize(slots + 1);
    std::uint32_t acc = 0;
    for (std::size_t sl = 0; sl < slots; ++sl) {
      part.slot_start[sl] = acc;
      acc += part.slot_count[sl];
    }
    part.slot_start[slots] = acc;
    // Scatter (stable: ray order within each block).
    k = 0;
    for (std::size_t sl = 0; sl < slots; ++sl) part.slot_count[sl] = part.slot_start[sl];
    for (std::size_t c = 0; c < kRayChunks; ++c) {
      for (const Sample& smp : s.bins[c * kPartitions + p]) {
        part.grouped[part.slot_count[part.sample_slot[k++]]++] = {smp.offset, smp.sdf_m};
      }
    }
    FastAccessor dist_acc(dist_tree), weight_acc(weight_tree);
    for (std::size_t sl = 0; sl < slots; ++sl) {
      const BlockIndex b = unpack_block(part.slot_keys[sl]);
      const openvdb::Coord origin(b.x() * kTsdfBlockEdge, b.y() * kTsdfBlockEdge,
                                  b.z() * kTsdfBlockEdge);
      FloatLeaf* dl = dist_acc.probeLeaf(origin);
      FloatLeaf* wl = nullptr;
      if (dl != nullptr) {
        wl = weight_acc.probeLeaf(origin);
      } else {
        part.new_distance.push_back(std::make_unique<FloatLeaf>(origin, background, false));
        part.new_weight.push_back(std::make_unique<FloatLeaf>(origin, 0.0f, false));
        dl = part.new_distance.back().get();
        wl = part.new_weight.back().get();
      }
      TARMAC_ASSERT(wl != nullptr, "TSDF distance and weight grids share one topology");
      float* dv = dl->buffer().data();
      float* wv = wl->buffer().data();
      for (std::uint32_t g = part.slot_start[sl]; g < part.slot_start[sl + 1]; ++g) {
        const GroupedSample gs = part.grouped[g];
        if (part.count[gs.offset] == 0) part.touched.push_back(gs.offset);
        part.sum[gs.offset] += gs.sdf_m;
        part.count[gs.offset]++;
      }
      for (const std::uint32_t off : part.touched) {
        const float obs = part.sum[off] / static_cast<float>(part.count[off]);
        const float w = wv[off];
        dv[off] = (dv[off] * w + obs) / (w + 1.0f);
        wv[off] = std::min(w + 1.0f, max_w);
        dl->setActiveState(off, true);
        wl->setActiveState(off, true);
        part.sum[off] = 0.0f;
        part.count[off] = 0;
      }
      part.voxel_updates += part.touched.size();
      part.touched.clear();
    }
  });

  // 3. Serial: hand the new leaves to the trees, collect the changed blocks in partition order.
  FastAccessor dist_acc(dist_tree), weight_acc(weight_tree);
  for (std::size_t p = 0; p < kPartitions; ++p) {
    Partition& part = s.partitions[p];
    for (std::size_t i = 0; i < part.new_distance.size(); ++i) {
      dist_acc.addLeaf(part.new_distance[i].release());
      weight_acc.addLeaf(part.new_weight[i].release());
    }
    update_.blocks_created += part.new_distance.size();
    update_.voxel_updates += part.voxel_updates;
    for (const std::uint64_t key : part.slot_keys) update_.blocks.push_back(unpack_block(key));
    update_.samples += part.grouped.size();
    part.reset_table();
  }
  for (const std::uint64_t r : s.chunk_rays) update_.rays += r;
  return update_;
}

}  // namespace tarmac::core
