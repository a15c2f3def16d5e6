#pragma once
/// @file Tiles of the TSDF: the site cut on the voxel lattice into cubes of 128³ voxels (16³
/// blocks, 12.8 m at 0.1 m; OpenVDB's first-level internal node), which can leave a TsdfLayer as
/// a whole, be encoded to bytes (compact, checksummed) and come back bit for bit. Which tiles
/// stay resident is tile_residency.hpp's to decide (the daemon's TsdfPager carries it out); this
/// file only moves and encodes them.
///
/// A tile that left the layer is *absent*: the layer remembers it, and the integrator never
/// builds a block inside an absent tile (its samples there are refused and counted), so a tile
/// written to disk can never be shadowed by a half-observed copy in memory.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

/// Blocks per tile edge, voxels per tile edge.
inline constexpr int kTsdfTileBlocks = 16;
inline constexpr int kTsdfTileEdge = kTsdfTileBlocks * kTsdfBlockEdge;  // 128 voxels

/// Tile t holds voxels [128·t, 128·t + 128) along each axis.
using TileIndex = Eigen::Vector3i;

/// The tile holding block b.
inline TileIndex tile_of_block(const BlockIndex& b) {
  return {b.x() >> 4, b.y() >> 4, b.z() >> 4};
}
/// A tile's key: orders tiles as OpenVDB iterates them (by the 4096³-voxel top node, then by
/// tile, each x, then y, then z), so that blocks visited tile by tile in key order are the
/// blocks TsdfLayer::for_each_block visits, in the same order.
struct TileKey {
  std::int32_t top[3];
  std::int32_t tile[3];
  static TileKey of(const TileIndex& t) {
    return TileKey{{t.x() >> 5, t.y() >> 5, t.z() >> 5}, {t.x(), t.y(), t.z()}};
  }
  friend auto operator<=>(const TileKey&, const TileKey&) = default;
};

/// Bytes a resident block costs (leaf, its voxel buffer, allocator overhead) and a resident
/// tile's own node: the unit of TsdfLayer::resident_bytes().
inline constexpr std::size_t kTsdfBlockBytes = 4096 + 128;
inline constexpr std::size_t kTsdfTileNodeBytes = 33'792;

/// A resident tile and its blocks.
struct TsdfTileInfo {
  TileIndex tile;
  std::size_t blocks = 0;
};

/// A tile taken out of a layer (it owns its blocks): encode it on any thread, or put it back.
/// Move-only.
class TsdfTile {
 public:
  TsdfTile();
  ~TsdfTile();
  TsdfTile(TsdfTile&&) noexcept;
  TsdfTile& operator=(TsdfTile&&) noexcept;
  TsdfTile(const TsdfTile&) = delete;
  TsdfTile& operator=(const TsdfTile&) = delete;

  [[nodiscard]] const TileIndex& index() const { return index_; }
  [[nodiscard]] std::size_t block_count() const;
  /// Calls fn for each block in OpenVDB's order (as TsdfLayer::for_each_block within the tile).
  void for_each_block(const std::function<void(const TsdfBlockView&)>& fn) const;
  /// A deep copy (for a save while the layer keeps the original).
  [[nodiscard]] TsdfTile clone() const;

  /// The tile as bytes: a header (magic, version, lattice, tile, truncation, counts, FNV-1a 64
  /// of the payload), then per block its place in the tile, its active mask, a mask of the
  /// voxels that differ from the background and their values (distance as float32; weight as
  /// uint8 or uint16 when every weight of the block is such an integer, else float32). Lossless:
  /// decode gives back every bit.
  [[nodiscard]] std::vector<std::uint8_t> encode(float voxel_size_m, float truncation_m) const;
  /// Bytes back to a tile; refuses (tsdf_tile.corrupt / tsdf_tile.mismatch) a truncated or
  /// altered file, or one of another lattice, truncation or tile.
  static Result<TsdfTile> decode(std::span<const std::uint8_t> bytes, float voxel_size_m,
                                 float truncation_m, const TileIndex& expected);

 private:
  friend class TsdfLayer;
  struct Impl;
  TileIndex index_ = TileIndex::Zero();
  std::unique_ptr<Impl> impl_;
};

/// Streams FNV-1a 64 over blocks exactly as TsdfLayer::digest() does, so that a digest taken
/// tile by tile (resident tiles and tiles read back from disk, in TileKey order) equals the
/// digest of the same map held whole.
class TsdfDigest {
 public:
  void add(const TsdfBlockView& block);
  [[nodiscard]] std::uint64_t value() const { return h_; }

 private:
  std::uint64_t h_ = 1469598103934665603ull;
};

/// Columns of the occupancy map's static layer (OccupancyMap::take_static_columns): the site cut
/// in (x, y) into squares of 64 × 64 occupancy voxels (12.8 m at 0.2 m), every height, paged
/// with the TSDF's tiles. Static tile t holds voxels [64·t, 64·t + 64) in x and y.
inline constexpr int kStaticTileEdge = 64;
using StaticTileIndex = Eigen::Vector2i;

/// FNV-1a 64 over the voxels' coordinates (32-bit words, x y z) in the given order: of a static
/// layer sorted by (z, y, x), a digest independent of how it was held (whole or in tiles).
[[nodiscard]] std::uint64_t static_voxels_digest(std::span<const Eigen::Vector3i> voxels);

/// The static voxels of one column tile, sorted by (z, y, x): encoded to bytes (compact,
/// checksummed) and back.
struct StaticTile {
  StaticTileIndex index = StaticTileIndex::Zero();
  std::vector<Eigen::Vector3i> voxels;

  /// A header (magic, version, voxel size, tile, count, FNV-1a 64 of the payload), then per voxel
  /// its x and y in the tile (uint8 each) and its z (int32).
  [[nodiscard]] std::vector<std::uint8_t> encode(float voxel_size_m) const;
  /// Refuses (static_tile.corrupt / static_tile.mismatch) a truncated or altered file, one of
  /// another voxel size or tile, or voxels out of the tile or out of order.
  static Result<StaticTile> decode(std::span<const std::uint8_t> bytes, float voxel_size_m,
                                   const StaticTileIndex& expected);
};

}  // namespace tarmac::core
