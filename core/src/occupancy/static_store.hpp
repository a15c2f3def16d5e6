#pragma once
/// @file The occupancy map's site-wide static layer (internal to core/src/occupancy).

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "tarmac/core/occupancy_map.hpp"

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
  static std::size_t home(std::uint64_t k, std::size_t mask) {
    return static_cast<std::size_t>((k * 0x9E3779B97F4A7C15ull) >> 20) & mask;
  }
  [[nodiscard]] std::size_t probe(std::uint64_t k) const {
    const std::size_t mask = keys.size() - 1;
    std::size_t i = home(k, mask);
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
  /// Removes block `k` and its voxels (a tile paged out). Backward-shift deletion keeps every
  /// other key reachable from its home slot without tombstones.
  void erase_block(std::uint64_t k) {
    std::size_t i = probe(k);
    if (keys[i] != k) return;
    for (const std::uint64_t w : masks[i]) count -= static_cast<std::size_t>(std::popcount(w));
    const std::size_t mask = keys.size() - 1;
    for (std::size_t j = (i + 1) & mask; keys[j] != kEmpty; j = (j + 1) & mask) {
      // Key j may fill the hole at i unless its home lies cyclically in (i, j].
      if (((j - home(keys[j], mask)) & mask) >= ((j - i) & mask)) {
        keys[i] = keys[j];
        masks[i] = masks[j];
        i = j;
      }
    }
    keys[i] = kEmpty;
    masks[i] = Mask{};
    --used;
  }
  static int block_x(std::uint64_t k) { return field(k, 0); }
  static int block_y(std::uint64_t k) { return field(k, 21); }
  static int block_z(std::uint64_t k) { return field(k, 42); }
  static int field(std::uint64_t k, int shift) {
    return static_cast<int>(static_cast<std::int64_t>((k >> shift) & ((1u << 21) - 1)) -
                            (std::int64_t{1} << 20));
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

namespace occupancy {

/// Blocks of the static layer two windows hold (the table's initial reservation).
inline std::size_t static_reservation(const Eigen::Vector3i& dims) {
  std::size_t blocks = 1;
  for (int a = 0; a < 3; ++a) blocks *= static_cast<std::size_t>((dims[a] + 7) / 8 + 1);
  return 2 * blocks;
}

}  // namespace occupancy
}  // namespace tarmac::core
