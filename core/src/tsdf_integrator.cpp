// TsdfIntegrator (tsdf_integrator.hpp): one scan into the TSDF, in three steps (band samples
// binned by ray chunk and partition; per partition, group by block, find leaves, apply; hand the
// new leaves to the tree) and the spare blocks and nodes they take. Over 600 lines because the
// steps' scratch (sample bins, per-partition block tables) lives with them; the layer is in
// tsdf_layer.cpp.

#include "tarmac/core/tsdf_integrator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "tsdf_band_walk.hpp"
#include "tsdf_grids.hpp"

namespace tarmac::core {

namespace {

using Tree = TsdfTree;
using Leaf = Tree::LeafNodeType;
using Value = Tree::ValueType;                      // (distance, weight)
using TopNode = Tree::RootNodeType::ChildNodeType;  // 32³ nodes
using Node = TopNode::ChildNodeType;                // 16³ leaves
/// Unregistered accessor: used only within one integration phase, during which the tree's
/// structure does not change.
using FastAccessor = openvdb::tree::ValueAccessor<Tree, false>;

static_assert(Leaf::DIM == kTsdfBlockEdge, "TSDF blocks are OpenVDB leaves");
static_assert(Leaf::SIZE == kTsdfBlockVoxels, "TSDF blocks are OpenVDB leaves");
static_assert(sizeof(Value) == sizeof(TsdfVoxel) && sizeof(TsdfVoxel) == 2 * sizeof(float),
              "a leaf buffer is an array of TsdfVoxel");

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

/// Samples each bin has room for when a scan starts: a 16th of its chunk's bound on samples
/// (3·(L/v + 1) + 1 per ray, L <= 2·trunc without carving), ~3.5x a bin's mean share on MulRan,
/// so that bins stop growing (allocating) instead of whenever one meets a new maximum. Carving
/// has no bound (the segment starts at the sensor): bins grow as they fill.
std::size_t bin_share(const TsdfParams& params, std::size_t rays_per_chunk) {
  if (params.space_carving) return 0;
  const auto voxels_per_ray =
      3 * static_cast<std::size_t>(2.0 * params.truncation_m / params.voxel_size_m) + 7;
  return rays_per_chunk * voxels_per_ray / kPartitions;
}

/// Writes every page of [p, p + n): the first-touch page faults are taken now, not in a scan.
template <typename T>
void prefault(T* p, std::size_t n) {
  std::memset(static_cast<void*>(p), 0, n * sizeof(T));
}

/// One (ray, voxel) pair inside the band; its block is that of the run holding it.
struct Sample {
  std::uint32_t offset;  // voxel inside the block, OpenVDB leaf order
  float sdf_m;
};

/// Consecutive samples of one bin in one block (a ray crosses a block in one run; consecutive
/// rays in the same block extend it): samples [begin, next run's begin) of the bin.
struct Run {
  std::uint64_t block_key;
  std::uint32_t begin;
};

/// Band samples of one (ray chunk, partition) and their runs, stored without initialisation (a
/// vector would zero what it grows into) and read back in order. Every run holds at least one
/// sample, so `runs` needs no more room than `samples`: both share one capacity.
struct SampleBin {
  std::unique_ptr<Sample[]> samples;
  std::unique_ptr<Run[]> runs;
  std::size_t capacity = 0;
  std::size_t count = 0;  // samples
  std::size_t run_count = 0;

  std::size_t size() const { return count; }
  std::uint32_t run_end(std::size_t r) const {
    return r + 1 < run_count ? runs[r + 1].begin : static_cast<std::uint32_t>(count);
  }
  void grow(std::size_t min_capacity) {
    const std::size_t cap = std::max({min_capacity, 2 * capacity, std::size_t{1024}});
    auto more_samples = std::make_unique_for_overwrite<Sample[]>(cap);
    auto more_runs = std::make_unique_for_overwrite<Run[]>(cap);
    std::copy(samples.get(), samples.get() + count, more_samples.get());
    std::copy(runs.get(), runs.get() + run_count, more_runs.get());
    samples = std::move(more_samples);
    runs = std::move(more_runs);
    capacity = cap;
  }
};

/// Per-partition state: blocks met this scan (open addressing), grouped samples, new leaves.
struct Partition {
  std::vector<std::uint64_t> table_keys;  // kEmptyKey = free
  std::vector<std::uint32_t> table_slots;
  std::vector<std::uint64_t> slot_keys;
  std::vector<std::uint32_t> slot_hash_pos;
  std::vector<std::uint32_t> slot_count;
  std::vector<std::uint32_t> slot_start;
  /// The slot of each run (bins in chunk order): slot lookups are per run, not per sample.
  std::vector<std::uint32_t> run_slot;
  std::vector<Sample> grouped;
  std::vector<std::uint64_t> slot_lines;  // cache lines (8 voxels) of the block touched
  std::vector<TsdfLeafCache::Entry> slot_entry;
  std::vector<std::unique_ptr<Leaf>> new_leaves;
  std::array<float, kTsdfBlockVoxels> sum{};
  std::array<std::uint32_t, kTsdfBlockVoxels> count{};
  std::array<std::uint32_t, kTsdfBlockVoxels> touched{};
  std::uint64_t voxel_updates = 0;
  std::uint64_t blocks_refused = 0, samples_refused = 0;

  std::size_t home(std::uint64_t key) const {
    return static_cast<std::size_t>(mix(key) >> 20) & (table_keys.size() - 1);
  }

  /// Slot of a block, numbered in first-touch order (independent of the table's size).
  std::uint32_t slot_for(std::uint64_t key) {
    const std::size_t mask = table_keys.size() - 1;
    std::size_t h = home(key);
    while (true) {
      if (table_keys[h] == key) return table_slots[h];
      if (table_keys[h] == kEmptyKey) break;
      h = (h + 1) & mask;
    }
    const auto slot = static_cast<std::uint32_t>(slot_keys.size());
    table_keys[h] = key;
    table_slots[h] = slot;
    slot_keys.push_back(key);
    slot_hash_pos.push_back(static_cast<std::uint32_t>(h));
    slot_count.push_back(0);
    slot_lines.push_back(0);
    if (2 * slot_keys.size() > table_keys.size()) grow();  // at most half full
    return slot;
  }

  /// Doubles the table (warm-up only: capacity is kept across scans).
  void grow() {
    const std::size_t cap = std::max<std::size_t>(1024, 2 * table_keys.size());
    table_keys.assign(cap, kEmptyKey);
    table_slots.assign(cap, 0);
    for (std::uint32_t sl = 0; sl < slot_keys.size(); ++sl) {
      std::size_t h = home(slot_keys[sl]);
      while (table_keys[h] != kEmptyKey) h = (h + 1) & (cap - 1);
      table_keys[h] = slot_keys[sl];
      table_slots[h] = sl;
      slot_hash_pos[sl] = static_cast<std::uint32_t>(h);
    }
  }

  void reset_table() {
    for (const std::uint32_t h : slot_hash_pos) table_keys[h] = kEmptyKey;
    slot_keys.clear();
    slot_hash_pos.clear();
    slot_count.clear();
    slot_lines.clear();
  }
};

}  // namespace

struct TsdfIntegrator::Scratch {
  std::vector<SampleBin> bins = std::vector<SampleBin>(kRayChunks * kPartitions);
  std::vector<std::uint64_t> chunk_rays = std::vector<std::uint64_t>(kRayChunks);
  std::vector<Partition> partitions = std::vector<Partition>(kPartitions);
  /// Spare leaves per partition (taken in slot order by that partition's task only).
  std::vector<std::vector<std::unique_ptr<Leaf>>> spares =
      std::vector<std::vector<std::unique_ptr<Leaf>>>(kPartitions);
  /// Blocks per partition a scan of the reserved size touches (reserve_scan).
  std::size_t reserved_slots = 0;
  /// Spare nodes, taken by the serial hand-over of new leaves (graft_nodes).
  std::vector<std::unique_ptr<Node>> spare_nodes;
  std::vector<std::unique_ptr<TopNode>> spare_top_nodes;
};

namespace {

/// Puts spare nodes on the path from the root to the leaf at `xyz` where the tree has none, so
/// that adding the leaf builds no node. A spare goes only where the parent holds the background,
/// inactive (what OpenVDB would build the node from); elsewhere, or without spares, the tree
/// builds its node as usual. The result is the same tree either way.
void graft_nodes(Tree& tree, const openvdb::Coord& xyz, const Value& background,
                 std::vector<std::unique_ptr<Node>>& nodes,
                 std::vector<std::unique_ptr<TopNode>>& top_nodes) {
  auto& root = tree.root();
  TopNode* top = root.probeNode<TopNode>(xyz);
  if (top == nullptr) {
    if (top_nodes.empty() || root.isValueOn(xyz) || root.getValue(xyz) != background) return;
    top = top_nodes.back().release();
    top_nodes.pop_back();
    top->setOrigin(xyz & ~(TopNode::DIM - 1));
    root.addChild(top);
  }
  const openvdb::Index n = TopNode::coordToOffset(xyz);
  if (top->isChildMaskOn(n) || nodes.empty()) return;
  if (top->isValueMaskOn(n) || top->getValue(xyz) != background) return;
  Node* node = nodes.back().release();
  nodes.pop_back();
  node->setOrigin(xyz & ~(Node::DIM - 1));
  top->addChild(node);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Integrator

TsdfIntegrator::TsdfIntegrator(const TsdfParams& params)
    : params_(params), scratch_(std::make_unique<Scratch>()) {
  TARMAC_ASSERT(params.validate().ok(), "TsdfParams must be validated first");
  reserve_blocks(params.reserve_blocks);
}
TsdfIntegrator::~TsdfIntegrator() = default;
TsdfIntegrator::TsdfIntegrator(TsdfIntegrator&&) noexcept = default;
TsdfIntegrator& TsdfIntegrator::operator=(TsdfIntegrator&&) noexcept = default;

TsdfSpareCount TsdfIntegrator::spare_target(std::size_t blocks) {
  if (blocks == 0) return {};
  return TsdfSpareCount{blocks, (blocks + 63) / 64, 8};
}

void TsdfIntegrator::reserve_blocks(std::size_t blocks) {
  const std::size_t per_partition = (blocks + kPartitions - 1) / kPartitions;
  const TsdfSpareCount target = spare_target(blocks);
  Scratch& s = *scratch_;
  TsdfSpareCount missing;
  for (auto& spares : s.spares) {
    // Room for top-ups too (add_spares then only moves pointers).
    spares.reserve(2 * per_partition);
    missing.blocks += per_partition - std::min(per_partition, spares.size());
  }
  s.spare_nodes.reserve(2 * target.nodes);
  s.spare_top_nodes.reserve(2 * target.top_nodes);
  missing.nodes = target.nodes - std::min(target.nodes, s.spare_nodes.size());
  missing.top_nodes = target.top_nodes - std::min(target.top_nodes, s.spare_top_nodes.size());
  add_spares(TsdfSpareBlocks::build(params_, missing));
}

void TsdfIntegrator::reserve_scan(std::size_t rays) {
  Scratch& s = *scratch_;
  const std::size_t per_chunk = (rays + kRayChunks - 1) / kRayChunks;
  const std::size_t share = bin_share(params_, per_chunk);
  // Room for the bound; touched up to half of it (a bin fills to ~0.3 of its share on average:
  // the rest is headroom a scan rarely reaches, not worth faulting in at start).
  for (SampleBin& bin : s.bins) {
    if (bin.capacity < share) bin.grow(share);
    prefault(bin.samples.get(), std::min(bin.capacity, share / 2));
    prefault(bin.runs.get(), std::min(bin.capacity, share / 2));
  }
  // A partition receives a 16th of the scan's samples: on average 0.3 of its bins' bound.
  const std::size_t samples = share * kRayChunks / 2;
  // Blocks per partition and scan: a ray's band crosses one or two blocks, and neighbouring rays
  // share them; the first scan of a 64-beam street at 0.1 m touches one block per ~4 rays.
  const std::size_t slots = std::max<std::size_t>(64, rays / kPartitions / 4);
  s.reserved_slots = std::max(s.reserved_slots, slots);
  for (Partition& part : s.partitions) {
    const auto touch = [](auto& v, std::size_t n) {
      if (v.size() < n) v.resize(n);  // written: faulted now
      v.clear();                      // capacity kept
    };
    touch(part.grouped, samples);
    touch(part.run_slot, samples);
    touch(part.slot_keys, slots);
    touch(part.slot_hash_pos, slots);
    touch(part.slot_count, slots);
    touch(part.slot_start, slots + 1);
    touch(part.slot_lines, slots);
    touch(part.slot_entry, slots);
    part.new_leaves.reserve(slots);
    while (part.table_keys.size() < 2 * slots) part.grow();
  }
}

struct TsdfSpareBlocks::Impl {
  float background_distance_m = 0.0f;
  std::vector<std::unique_ptr<Leaf>> leaves;
  std::vector<std::unique_ptr<Node>> nodes;
  std::vector<std::unique_ptr<TopNode>> top_nodes;
};

TsdfSpareBlocks::TsdfSpareBlocks() : impl_(std::make_unique<Impl>()) {}
TsdfSpareBlocks::~TsdfSpareBlocks() = default;
TsdfSpareBlocks::TsdfSpareBlocks(TsdfSpareBlocks&&) noexcept = default;
TsdfSpareBlocks& TsdfSpareBlocks::operator=(TsdfSpareBlocks&&) noexcept = default;

TsdfSpareBlocks TsdfSpareBlocks::build(const TsdfParams& params, const TsdfSpareCount& count) {
  TsdfSpareBlocks out;
  Impl& impl = *out.impl_;
  impl.background_distance_m = params.truncation_m;
  // Built with the background value, inactive, as the tree builds a new leaf or node: every
  // page is written here. Their origins are set where they are used.
  const Value background(params.truncation_m, 0.0f);
  const openvdb::Coord zero(0, 0, 0);
  impl.leaves.reserve(count.blocks);
  for (std::size_t i = 0; i < count.blocks; ++i) {
    impl.leaves.push_back(std::make_unique<Leaf>(zero, background, false));
  }
  impl.nodes.reserve(count.nodes);
  for (std::size_t i = 0; i < count.nodes; ++i) {
    impl.nodes.push_back(std::make_unique<Node>(zero, background, false));
  }
  impl.top_nodes.reserve(count.top_nodes);
  for (std::size_t i = 0; i < count.top_nodes; ++i) {
    impl.top_nodes.push_back(std::make_unique<TopNode>(zero, background, false));
  }
  return out;
}

TsdfSpareCount TsdfSpareBlocks::size() const {
  if (!impl_) return {};
  return TsdfSpareCount{impl_->leaves.size(), impl_->nodes.size(), impl_->top_nodes.size()};
}

void TsdfIntegrator::add_spares(TsdfSpareBlocks&& spares) {
  if (!spares.impl_) return;
  auto& leaves = spares.impl_->leaves;
  TARMAC_ASSERT(
      spares.size().empty() || spares.impl_->background_distance_m == params_.truncation_m,
      "spare TSDF blocks must have the layer's background value");
  Scratch& s = *scratch_;
  for (auto& node : spares.impl_->nodes) s.spare_nodes.push_back(std::move(node));
  for (auto& top : spares.impl_->top_nodes) s.spare_top_nodes.push_back(std::move(top));
  spares.impl_->nodes.clear();
  spares.impl_->top_nodes.clear();
  auto& pools = s.spares;
  while (!leaves.empty()) {
    // The shortest pool first, so the partitions that have used the most are refilled first.
    auto& pool = *std::min_element(pools.begin(), pools.end(), [](const auto& a, const auto& b) {
      return a.size() < b.size();
    });
    pool.push_back(std::move(leaves.back()));
    leaves.pop_back();
  }
}

TsdfSpareCount TsdfIntegrator::spare_shortfall() const {
  const TsdfSpareCount have = spares();
  const TsdfSpareCount want = spare_target(params_.reserve_blocks);
  const auto missing = [](std::size_t w, std::size_t h) { return w > h ? w - h : 0; };
  return TsdfSpareCount{missing(want.blocks, have.blocks), missing(want.nodes, have.nodes),
                        missing(want.top_nodes, have.top_nodes)};
}

TsdfSpareCount TsdfIntegrator::spares() const {
  const Scratch& s = *scratch_;
  TsdfSpareCount n{0, s.spare_nodes.size(), s.spare_top_nodes.size()};
  for (const auto& spares : s.spares) n.blocks += spares.size();
  return n;
}

TsdfLayer TsdfIntegrator::make_layer() const {
  return TsdfLayer(params_.voxel_size_m, params_.truncation_m);
}

void TsdfIntegrator::reserve_layer(TsdfLayer& layer) const {
  const Scratch& s = *scratch_;
  std::size_t spares = 0;
  for (const auto& pool : s.spares) spares = std::max(spares, pool.size());
  // As integrate sizes a table: at most half full with this partition's blocks and a scan's.
  std::size_t cap = 1024;
  while (cap < 2 * (spares + s.reserved_slots)) cap *= 2;
  auto& caches = layer.grids_->leaf_cache;
  caches.resize(kPartitions);
  for (TsdfLeafCache& cache : caches) {
    if (cache.table.size() >= cap || cache.size > 0) continue;
    cache.table.assign(cap, TsdfLeafCache::Entry{kEmptyKey, nullptr, nullptr});
  }
}

namespace {

/// The bins of one ray chunk (one per partition). `room` is a lower bound of the free samples of
/// every bin, so a ray checks capacity once instead of once per sample.
struct ChunkBins {
  SampleBin* bins;  // kPartitions
  std::size_t room = 0;

  /// Empties the bins, each with room for at least `share` samples.
  void begin(std::size_t share) {
    room = std::numeric_limits<std::size_t>::max();
    for (std::size_t p = 0; p < kPartitions; ++p) {
      bins[p].count = 0;
      bins[p].run_count = 0;
      if (bins[p].capacity < share) bins[p].grow(share);
      room = std::min(room, bins[p].capacity);
    }
  }
  /// Makes room for `need` more samples in every bin.
  void reserve(std::size_t need) {
    if (room >= need) return;
    room = std::numeric_limits<std::size_t>::max();
    for (std::size_t p = 0; p < kPartitions; ++p) {
      SampleBin& bin = bins[p];
      if (bin.capacity - bin.count < need) bin.grow(bin.count + need);
      room = std::min(room, bin.capacity - bin.count);
    }
  }
};

/// The band samples of one ray (tsdf_band_walk.hpp), binned by the partition of their block.
/// @return the samples written.
/// kCarve: the segment may be long (sensor to band), so each sample checks its bin's capacity;
/// otherwise the caller has reserved room for the whole segment.
template <bool kCarve>
std::size_t band_samples(const Eigen::Vector3d& o, const Eigen::Vector3d& dir, double range,
                         double t0, double t1, double v, double trunc, ChunkBins& out) {
  // The block of the last sample and its bin, state of the walk's loop (kept in registers).
  auto bin_sample = [&out, last_key = kEmptyKey, bin = static_cast<SampleBin*>(nullptr)](
                        int ix, int iy, int iz, float sdf) mutable {
    const std::uint64_t key = pack_block(ix >> 3, iy >> 3, iz >> 3);
    if (key != last_key) {
      last_key = key;
      bin = &out.bins[partition_of(key)];
      if (kCarve && bin->count == bin->capacity) bin->grow(bin->count + 1);
      // Room: run_count <= count < capacity (every run holds a sample).
      if (bin->run_count == 0 || bin->runs[bin->run_count - 1].block_key != key) {
        bin->runs[bin->run_count++] = Run{key, static_cast<std::uint32_t>(bin->count)};
      }
    }
    if (kCarve && bin->count == bin->capacity) bin->grow(bin->count + 1);
    const auto offset = static_cast<std::uint32_t>(tsdf_voxel_offset(ix & 7, iy & 7, iz & 7));
    bin->samples[bin->count++] = Sample{offset, sdf};
  };
  return walk_band<kCarve>(o, dir, range, t0, t1, v, trunc, std::move(bin_sample));
}

}  // namespace

namespace {

/// Step 2a of integrate: partition `p`'s samples, from the bins of every ray chunk, grouped by
/// block (blocks in first-touch order, each block's samples in ray order): part.grouped, with
/// part.slot_start / slot_lines per block (slot).
void group_by_block(Partition& part, const std::vector<SampleBin>& bins, std::size_t p) {
  std::size_t total = 0, total_runs = 0;
  for (std::size_t c = 0; c < kRayChunks; ++c) {
    total += bins[c * kPartitions + p].size();
    total_runs += bins[c * kPartitions + p].run_count;
  }
  if (part.table_keys.empty()) part.grow();
  part.run_slot.resize(total_runs);
  part.grouped.resize(total);
  // Count the samples of each block, run by run (the samples themselves are not read here).
  std::size_t runs = 0;
  for (std::size_t c = 0; c < kRayChunks; ++c) {
    const SampleBin& bin = bins[c * kPartitions + p];
    for (std::size_t r = 0; r < bin.run_count; ++r) {
      const Run& run = bin.runs[r];
      const std::uint32_t slot = part.slot_for(run.block_key);
      part.slot_count[slot] += bin.run_end(r) - run.begin;
      part.run_slot[runs++] = slot;
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
  // Scatter (stable: ray order within each block), run by run in the order counted.
  for (std::size_t sl = 0; sl < slots; ++sl) part.slot_count[sl] = part.slot_start[sl];
  {
    std::size_t k = 0;
    for (std::size_t c = 0; c < kRayChunks; ++c) {
      const SampleBin& bin = bins[c * kPartitions + p];
      for (std::size_t r = 0; r < bin.run_count; ++r) {
        const std::uint32_t slot = part.run_slot[k++];
        const std::uint32_t begin = bin.runs[r].begin, len = bin.run_end(r) - begin;
        Sample* dst = &part.grouped[part.slot_count[slot]];
        std::uint64_t lines = 0;
        for (std::uint32_t i = begin; i < begin + len; ++i) {
          *dst++ = bin.samples[i];
          lines |= std::uint64_t{1} << (bin.samples[i].offset >> 3);
        }
        part.slot_count[slot] += len;
        part.slot_lines[slot] |= lines;
      }
    }
  }
}

/// Step 2b: the leaf of every block of the partition: from the leaf cache, else found in the
/// tree read-only (its structure does not change in this step), else a spare or a new leaf built
/// aside and handed to the tree in step 3 (part.new_leaves). The cache spares a walk down the
/// tree (several dependent cache misses) per block.
void find_leaves(Partition& part, TsdfLeafCache& cache, Tree& tree,
                 const std::unordered_set<std::uint64_t>& absent,
                 std::vector<std::unique_ptr<Leaf>>& spares, const Value& background) {
  const std::size_t slots = part.slot_keys.size();
  // The leaf of every block: from the leaf cache, else found in the tree read-only (its
  // structure does not change in this step), else built aside and handed to the tree in
  // step 3. The cache spares a walk down the tree (several dependent cache misses) per block.
  part.slot_entry.resize(slots);
  {
    if (cache.table.size() < 2 * (cache.size + slots)) {
      std::size_t cap = std::max<std::size_t>(1024, cache.table.size());
      while (cap < 2 * (cache.size + slots)) cap *= 2;
      std::vector<TsdfLeafCache::Entry> old = std::move(cache.table);
      cache.table.assign(cap, TsdfLeafCache::Entry{kEmptyKey, nullptr, nullptr});
      for (const auto& e : old) {
        if (e.key == kEmptyKey) continue;
        std::size_t h = static_cast<std::size_t>(mix(e.key) >> 24) & (cap - 1);
        while (cache.table[h].key != kEmptyKey) h = (h + 1) & (cap - 1);
        cache.table[h] = e;
      }
    }
    const std::size_t mask = cache.table.size() - 1;
    FastAccessor acc_tree(tree);
    // The table is larger than the L2 cache and probed at random: prefetch a few slots ahead.
    constexpr std::size_t kProbeAhead = 8;
    const auto home = [&](std::size_t sl) {
      return static_cast<std::size_t>(mix(part.slot_keys[sl]) >> 24) & mask;
    };
    for (std::size_t sl = 0; sl < std::min(slots, kProbeAhead); ++sl) {
      __builtin_prefetch(&cache.table[home(sl)]);
    }
    for (std::size_t sl = 0; sl < slots; ++sl) {
      if (sl + kProbeAhead < slots) __builtin_prefetch(&cache.table[home(sl + kProbeAhead)]);
      const std::uint64_t key = part.slot_keys[sl];
      std::size_t h = home(sl);
      while (cache.table[h].key != key && cache.table[h].key != kEmptyKey) h = (h + 1) & mask;
      if (cache.table[h].key != key) {
        const BlockIndex b = unpack_block(key);
        const openvdb::Coord origin(b.x() * kTsdfBlockEdge, b.y() * kTsdfBlockEdge,
                                    b.z() * kTsdfBlockEdge);
        Leaf* leaf = acc_tree.probeLeaf(origin);
        if (leaf == nullptr && !absent.empty() &&
            absent.contains(pack_tile(b.x() >> 4, b.y() >> 4, b.z() >> 4))) {
          // Its tile is paged out: building the block would shadow the tile's stored values.
          part.slot_entry[sl] = TsdfLeafCache::Entry{key, nullptr, nullptr};
          part.slot_lines[sl] = 0;
          ++part.blocks_refused;
          continue;
        }
        if (leaf == nullptr) {
          // A spare (all background, inactive, as a new leaf) when there is one.
          if (spares.empty()) {
            part.new_leaves.push_back(std::make_unique<Leaf>(origin, background, false));
          } else {
            part.new_leaves.push_back(std::move(spares.back()));
            spares.pop_back();
            part.new_leaves.back()->setOrigin(origin);
          }
          leaf = part.new_leaves.back().get();
        }
        cache.table[h] = TsdfLeafCache::Entry{key, leaf, leaf->buffer().data()};
        ++cache.size;
      }
      part.slot_entry[sl] = cache.table[h];
    }
  }
}

/// Step 2c: each touched voxel of the partition updated once, with the mean of the scan's
/// samples of it (weighted running average, weight capped at `max_w`).
void apply_samples(Partition& part, float max_w) {
  const std::size_t slots = part.slot_keys.size();
  // Apply, prefetching the touched cache lines of the blocks ahead: leaves are scattered in
  // memory, so this step is bound by cache misses, not arithmetic. The prefetch runs a fixed
  // number of cache lines ahead (not slots: a slot touches 1 to 64 lines, and prefetching
  // more lines than the core can keep in flight drops them).
  constexpr std::size_t kLinesAhead = 24;
  std::size_t pf_slot = 0, issued = 0, consumed = 0;
  std::uint64_t pf_lines = 0;
  const auto prefetch_mask = [&](std::size_t sl) {
    if (part.slot_entry[sl].leaf != nullptr) {
      __builtin_prefetch(&part.slot_entry[sl].leaf->getValueMask(), 1);
    }
  };
  if (slots > 0) {
    pf_lines = part.slot_lines[0];
    prefetch_mask(0);
  }
  const auto prefetch_until = [&](std::size_t target) {
    while (issued < target) {
      if (pf_lines == 0) {
        if (++pf_slot >= slots) return;
        pf_lines = part.slot_lines[pf_slot];
        prefetch_mask(pf_slot);
        continue;
      }
      const int l = __builtin_ctzll(pf_lines);
      pf_lines &= pf_lines - 1;
      __builtin_prefetch(part.slot_entry[pf_slot].values + 8 * l, 1);
      ++issued;
    }
  };
  std::uint32_t* touched = part.touched.data();
  for (std::size_t sl = 0; sl < slots; ++sl) {
    consumed += static_cast<std::size_t>(__builtin_popcountll(part.slot_lines[sl]));
    prefetch_until(consumed + kLinesAhead);
    Leaf* leaf = part.slot_entry[sl].leaf;
    Value* values = part.slot_entry[sl].values;
    if (leaf == nullptr) {  // refused: its tile is paged out
      part.samples_refused += part.slot_start[sl + 1] - part.slot_start[sl];
      continue;
    }
    std::size_t nt = 0;
    // The voxels of the block, each once in first-touch order (branch-free: whether a sample
    // is a voxel's first is unpredictable).
    for (std::uint32_t g = part.slot_start[sl]; g < part.slot_start[sl + 1]; ++g) {
      const Sample gs = part.grouped[g];
      const std::uint32_t c = part.count[gs.offset];
      touched[nt] = gs.offset;
      nt += c == 0;
      part.sum[gs.offset] += gs.sdf_m;
      part.count[gs.offset] = c + 1;
    }
    for (std::size_t t = 0; t < nt; ++t) {
      const std::uint32_t off = touched[t];
      const float obs = part.sum[off] / static_cast<float>(part.count[off]);
      Value& x = values[off];
      const float w = x[1];
      // Weighted running average; the cap lets an old surface be re-learnt.
      x[0] = (x[0] * w + obs) / (w + 1.0f);
      x[1] = std::min(w + 1.0f, max_w);
      leaf->setActiveState(off, true);
      part.sum[off] = 0.0f;
      part.count[off] = 0;
    }
    part.voxel_updates += nt;
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
  const std::size_t share = bin_share(params_, per_chunk);
  runner.parallel_for(kRayChunks, [&](std::size_t c) {
    ChunkBins out{&s.bins[c * kPartitions]};
    out.begin(share);
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
      const double t1 = r + trunc;
      if (carve) {
        band_samples<true>(o, dir, r, t0, t1, v, trunc, out);
        out.room = 0;  // unknown: the next reserve() recomputes it
      } else {
        // A segment of length L crosses at most L/v + 1 boundaries per axis: at most
        // 3·(L/v + 1) + 1 voxels.
        out.reserve(3 * static_cast<std::size_t>((t1 - t0) / v) + 7);
        out.room -= band_samples<false>(o, dir, r, t0, t1, v, trunc, out);
      }
    }
    s.chunk_rays[c] = rays;
  });

  // 2. Per partition: group samples by block (first-touch order, samples in ray order), merge
  //    each voxel's samples (their mean) and apply one running-average update.
  const float max_w = params_.max_weight;
  const Value background(params_.truncation_m, 0.0f);
  TsdfLayer::Grids& grids = *layer.grids_;
  Tree& tree = grids.tsdf->tree();
  grids.leaf_cache.resize(kPartitions);
  runner.parallel_for(kPartitions, [&](std::size_t p) {
    Partition& part = s.partitions[p];
    part.new_leaves.clear();
    part.voxel_updates = 0;
    part.blocks_refused = 0;
    part.samples_refused = 0;
    group_by_block(part, s.bins, p);
    find_leaves(part, grids.leaf_cache[p], tree, grids.absent, s.spares[p], background);
    apply_samples(part, max_w);
  });

  // 3. Serial: hand the new leaves to the tree (on spare nodes where it has none), collect the
  //    changed blocks in partition order.
  FastAccessor acc_tree(tree);
  for (std::size_t p = 0; p < kPartitions; ++p) {
    Partition& part = s.partitions[p];
    for (auto& leaf : part.new_leaves) {
      if (acc_tree.probeConstNode<Node>(leaf->origin()) == nullptr) {
        graft_nodes(tree, leaf->origin(), background, s.spare_nodes, s.spare_top_nodes);
        acc_tree.clear();  // the tree's structure changed above the accessor's cached nodes
      }
      acc_tree.addLeaf(leaf.release());
    }
    update_.blocks_created += part.new_leaves.size();
    update_.voxel_updates += part.voxel_updates;
    update_.blocks_refused += part.blocks_refused;
    update_.samples_refused += part.samples_refused;
    for (std::size_t sl = 0; sl < part.slot_keys.size(); ++sl) {
      if (part.blocks_refused > 0 && part.slot_entry[sl].leaf == nullptr) continue;
      update_.blocks.push_back(unpack_block(part.slot_keys[sl]));
      const BlockIndex& b = update_.blocks.back();
      grids.touch(b.x(), b.y(), b.z());
    }
    update_.samples += part.grouped.size();
    part.reset_table();
  }
  for (const std::uint64_t r : s.chunk_rays) update_.rays += r;
  return update_;
}

}  // namespace tarmac::core
