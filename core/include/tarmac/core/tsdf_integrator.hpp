#pragma once
/// @file The TSDF: a sparse truncated signed distance field on OpenVDB, covering the whole site,
/// and its integrator.
///
/// Curless & Levoy, "A Volumetric Method for Building Complex Models from Range Images",
/// SIGGRAPH 1996: each voxel keeps a signed distance d and a weight w; an observation d_obs
/// with weight 1 updates them as d ← (w·d + d_obs)/(w + 1), w ← min(w + 1, max_weight).
/// The distance is projective, measured along each LiDAR ray: for a return at range r and a
/// voxel centre c, d_obs = r − |c − o| (o the sensor origin): positive in front of the surface,
/// negative behind it. Only voxels whose centre lies within ±truncation_m of a return are touched
/// (Vizzo et al., "VDBFusion", Sensors 22(3) 2022, §3: O(points · 2·trunc/voxel) voxels per scan).
///
/// Lattice: voxel i covers [i·v, (i+1)·v) along each axis of the world frame, centre (i + ½)·v,
/// the same lattice as the occupancy map. Blocks are OpenVDB leaves of 8³ voxels; block b covers
/// voxels [8·b, 8·b + 8).
///
/// OpenVDB stays inside core/src (pimpl): this header is cheap to include.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/result.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::core {

/// TSDF configuration (YAML section `tsdf`).
struct TsdfParams {
  bool enabled = true;         ///< false: the mapper skips the TSDF stage
  float voxel_size_m = 0.10f;  ///< edge of a voxel, m
  float truncation_m = 0.30f;  ///< half-width of the band around each return, m (>= voxel size)
  /// Weight cap: a voxel at the cap follows new observations as an exponential moving average
  /// with factor 1/(max_weight + 1), so a surface that moved is re-learnt (weights count scans).
  float max_weight = 64.f;
  float max_range_m = 50.0f;  ///< returns farther than this are not integrated, m
  /// Space carving: also update every voxel from the sensor to the band with +truncation_m
  /// (free space), at a cost proportional to range/voxel per ray. Off by default (VDBFusion's
  /// default too).
  bool space_carving = false;
  /// Blocks the integrator builds at construction (4 KB each, a 16th per partition) and hands
  /// out before it allocates one: such a new block costs integrate neither an allocation nor the
  /// page fault of its first touch (~4 µs per 4 KB page on the project's VMs: about a fifth of
  /// the integration time while the map grows). 0..1e7; 0: none.
  std::uint32_t reserve_blocks = 0;
  /// Resident memory of the TSDF's tiles above which the far ones are paged to disk, MiB
  /// (tsdf_tiles.hpp; the daemon's TsdfPager does the paging). 0..1e6; 0: no limit.
  std::uint32_t resident_limit_mb = 0;

  [[nodiscard]] Status validate() const;
};

class TsdfTile;
struct TsdfTileInfo;
using TileIndex = Eigen::Vector3i;

/// Integer voxel coordinates on the world lattice (same convention as VoxelIndex).
using TsdfVoxelIndex = Eigen::Vector3i;
/// Integer block (8³ voxels) coordinates: block b holds voxels [8·b, 8·b + 8).
using BlockIndex = Eigen::Vector3i;

/// Voxels per block edge and per block.
inline constexpr int kTsdfBlockEdge = 8;
inline constexpr int kTsdfBlockVoxels = 512;

/// One observed voxel.
struct TsdfVoxel {
  float distance_m = 0.0f;  ///< signed, in [−truncation, +truncation]
  float weight = 0.0f;      ///< > 0 for an observed voxel
};

/// Read-only view of one block's storage. Voxel (i, j, k) of the block (each 0..7, the voxel
/// 8·block + (i, j, k)) is voxels[(i·8 + j)·8 + k] (x slowest: OpenVDB's leaf order).
/// weight == 0 means never observed (its distance is then +truncation).
struct TsdfBlockView {
  BlockIndex block;
  const TsdfVoxel* voxels = nullptr;  ///< kTsdfBlockVoxels values
};

/// Offset of voxel (i, j, k) inside its block (see TsdfBlockView).
constexpr int tsdf_voxel_offset(int i, int j, int k) {
  return (i * kTsdfBlockEdge + j) * kTsdfBlockEdge + k;
}

/// The TSDF map: one OpenVDB grid of (distance, weight) pairs (Vec2SGrid).
/// Move-only. Not thread-safe: one writer, or any number of readers.
class TsdfLayer {
 public:
  /// @pre voxel_size_m > 0, truncation_m > 0.
  TsdfLayer(float voxel_size_m, float truncation_m);
  ~TsdfLayer();
  TsdfLayer(TsdfLayer&&) noexcept;
  TsdfLayer& operator=(TsdfLayer&&) noexcept;
  TsdfLayer(const TsdfLayer&) = delete;
  TsdfLayer& operator=(const TsdfLayer&) = delete;

  [[nodiscard]] float voxel_size_m() const { return voxel_size_m_; }
  [[nodiscard]] float truncation_m() const { return truncation_m_; }

  /// The observed voxel at `v`, or nothing when it was never observed.
  [[nodiscard]] std::optional<TsdfVoxel> voxel(const TsdfVoxelIndex& v) const;
  /// Voxel containing a world point.
  [[nodiscard]] TsdfVoxelIndex voxel_of(const Eigen::Vector3d& p_W) const;
  /// Centre of a voxel in the world frame, m.
  [[nodiscard]] Eigen::Vector3d center_of(const TsdfVoxelIndex& v) const;

  /// Blocks allocated, voxels observed, and the memory of the grid (OpenVDB's memUsage).
  [[nodiscard]] std::size_t block_count() const;
  [[nodiscard]] std::size_t voxel_count() const;
  [[nodiscard]] std::size_t memory_bytes() const;

  /// Calls fn for every block, in ascending (x, y, z) block order.
  void for_each_block(const std::function<void(const TsdfBlockView&)>& fn) const;
  /// The block at `b`, or nothing when it is not allocated.
  [[nodiscard]] std::optional<TsdfBlockView> find_block(const BlockIndex& b) const;

  /// FNV-1a 64 over every block in ascending order (coordinates, distances, weights): equal
  /// digests mean bit-identical maps.
  [[nodiscard]] std::uint64_t digest() const;

  /// Drops every voxel.
  void clear();
  /// Drops the given blocks (those not allocated are skipped; duplicates are fine), as if never
  /// observed: a pose-correction rebuild erases what the retained scans wrote before
  /// re-integrating them. Returns the blocks dropped.
  std::size_t erase_blocks(std::span<const BlockIndex> blocks);

  /// A deep copy (every block copied; the integrator's leaf cache is not): a snapshot another
  /// thread can save while this layer keeps integrating. Costs a copy of memory_bytes().
  [[nodiscard]] TsdfLayer clone() const;

  // Tiles (tsdf_tiles.hpp): a paged map holds some tiles; the others are absent (on disk).
  /// Resident tiles and their blocks, in TileKey order.
  [[nodiscard]] std::vector<TsdfTileInfo> resident_tiles() const;
  /// The same into `out` (cleared; its capacity is kept: no allocation once it has grown).
  void resident_tiles(std::vector<TsdfTileInfo>& out) const;
  /// What the resident tiles cost as counted against a paging limit: blocks · kTsdfBlockBytes +
  /// tiles · kTsdfTileNodeBytes (deterministic, unlike the allocator's figures).
  [[nodiscard]] std::size_t resident_bytes() const;
  /// Takes tile `t` out of the layer (nothing when it holds no block); it becomes absent.
  [[nodiscard]] std::optional<TsdfTile> detach_tile(const TileIndex& t);
  /// A copy of resident tile `t` (nothing when it holds no block); the layer keeps it.
  [[nodiscard]] std::optional<TsdfTile> copy_tile(const TileIndex& t) const;
  /// Puts a detached or decoded tile back; it is no longer absent.
  /// @pre no block of the tile is resident (true while it is absent: nothing builds there).
  void attach_tile(TsdfTile&& tile);
  /// Marks a tile absent (a layer started over a tile store), or forgets that it was (a tile
  /// whose file was lost: its ground is mapped afresh).
  void mark_absent(const TileIndex& t);
  void forget_absent(const TileIndex& t);
  [[nodiscard]] bool is_absent(const TileIndex& t) const;
  [[nodiscard]] std::size_t absent_count() const;
  /// Keeps (or stops keeping) the tiles that integration and erase_blocks change.
  void track_touched_tiles(bool on);
  /// The tiles changed since the last call, sorted, into `out` (cleared); empties the set.
  void take_touched_tiles(std::vector<TileIndex>& out);

  /// OpenVDB grids (defined in core/src/tsdf_grids.hpp, for the core's own .cpp files only).
  /// Mutable access drops the integrator's leaf-pointer cache (the tree may change).
  struct Grids;
  [[nodiscard]] Grids& grids();
  [[nodiscard]] const Grids& grids() const { return *grids_; }

 private:
  friend class TsdfIntegrator;  // writes voxels through its leaf cache, not through grids()
  float voxel_size_m_;
  float truncation_m_;
  std::unique_ptr<Grids> grids_;
};

/// What one scan changed.
struct TsdfUpdate {
  std::uint64_t rays = 0;           ///< returns integrated (within max range)
  std::uint64_t samples = 0;        ///< (ray, voxel) pairs inside the band, before merging
  std::uint64_t voxel_updates = 0;  ///< voxels updated (each at most once per scan)
  std::uint64_t blocks_created = 0;
  /// Blocks inside absent tiles (paged out, not back yet): their samples were not applied.
  std::uint64_t blocks_refused = 0;
  std::uint64_t samples_refused = 0;
  /// Every block this scan updated, in ascending (x, y, z) order.
  std::vector<BlockIndex> blocks;
};

/// A count of spare TSDF tree parts: blocks (leaves, 8³ voxels, 4 KB) and the tree nodes above
/// them (a node holds 16³ blocks, 32 KB; a top node 32³ nodes, 256 KB). A map that grows into
/// new ground needs new nodes too: 77 nodes and 8 top nodes for the first scan of an urban
/// street around the origin (every octant of the top level), whose page faults, built in the
/// scan, cost more than its thousands of new blocks.
struct TsdfSpareCount {
  std::size_t blocks = 0;
  std::size_t nodes = 0;
  std::size_t top_nodes = 0;

  /// Memory in blocks (4 KB) of a node and of a top node: the top-up budget's unit.
  static constexpr std::size_t kNodeBlocks = 8, kTopNodeBlocks = 64;
  [[nodiscard]] std::size_t block_equivalents() const {
    return blocks + kNodeBlocks * nodes + kTopNodeBlocks * top_nodes;
  }
  [[nodiscard]] bool empty() const { return blocks == 0 && nodes == 0 && top_nodes == 0; }
  friend bool operator==(const TsdfSpareCount&, const TsdfSpareCount&) = default;
};

/// Tree parts built ahead of integration (background value, every page touched), on any thread,
/// to be handed to an integrator between scans (TsdfIntegrator::add_spares): the map keeps
/// growing without the cycle paying for the allocation and first-touch page faults of its new
/// blocks and nodes. Move-only.
class TsdfSpareBlocks {
 public:
  TsdfSpareBlocks();
  ~TsdfSpareBlocks();
  TsdfSpareBlocks(TsdfSpareBlocks&&) noexcept;
  TsdfSpareBlocks& operator=(TsdfSpareBlocks&&) noexcept;
  TsdfSpareBlocks(const TsdfSpareBlocks&) = delete;
  TsdfSpareBlocks& operator=(const TsdfSpareBlocks&) = delete;

  /// `count` blocks and nodes for a TSDF with these params (their background value).
  /// Allocates: call it where the time does not matter (tarmacd: between ticks; the tools:
  /// between scans).
  static TsdfSpareBlocks build(const TsdfParams& params, const TsdfSpareCount& count);

  [[nodiscard]] TsdfSpareCount size() const;

 private:
  friend class TsdfIntegrator;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Integrates scans into a TsdfLayer. Holds only scratch buffers, reused across scans (after
/// warm-up nothing it owns allocates; OpenVDB allocates new blocks).
///
/// Determinism: rays are cut into a fixed number of chunks; their band samples are binned by
/// block into a fixed number of partitions (a hash of the block coordinates), each partition
/// owning disjoint blocks. Within a partition, the samples of a voxel are merged in ray order
/// (mean of the scan's observations of that voxel) and applied once. So the result is
/// bit-identical for any runner and any thread count.
class TsdfIntegrator {
 public:
  /// @pre params.validate().ok()
  explicit TsdfIntegrator(const TsdfParams& params);
  ~TsdfIntegrator();
  TsdfIntegrator(TsdfIntegrator&&) noexcept;
  TsdfIntegrator& operator=(TsdfIntegrator&&) noexcept;
  TsdfIntegrator(const TsdfIntegrator&) = delete;
  TsdfIntegrator& operator=(const TsdfIntegrator&) = delete;

  /// Integrates one scan: returns `points_W` (world frame) seen from `origin_W`. Non-finite
  /// points and returns beyond max_range_m are skipped.
  /// @pre layer.voxel_size_m() and truncation_m() equal the params'.
  /// @return what changed; valid until the next call.
  const TsdfUpdate& integrate(const Eigen::Vector3d& origin_W,
                              std::span<const Eigen::Vector3f> points_W, TsdfLayer& layer,
                              TaskRunner& runner);

  [[nodiscard]] const TsdfParams& params() const { return params_; }

  /// Tops the spare blocks up to at least `blocks` (rounded up to a multiple of 16), and the
  /// spare nodes to their share of it (spare_target): built and touched now, so that integrate
  /// takes them instead of allocating. Not RT-safe (allocates); for start-up or a moment the
  /// cycle has slack. Spares are not part of any layer's memory_bytes().
  void reserve_blocks(std::size_t blocks);
  /// The spares kept for a reserve of `blocks` blocks: the blocks, a node per 64 of them (a
  /// first scan builds one per ~110 new blocks) and 8 top nodes (the 8 around a corner of the
  /// top level, where a map that starts at the origin sits); none when `blocks` is 0.
  [[nodiscard]] static TsdfSpareCount spare_target(std::size_t blocks);
  /// Sizes and touches the per-scan scratch (band samples, grouping, block tables) for scans of
  /// up to `rays` returns, so that the first scans cost what later ones do: without it the
  /// scratch grows and takes its first-touch page faults in the first scan. A larger scan grows
  /// it once. Not RT-safe (allocates); for start-up.
  void reserve_scan(std::size_t rays);
  /// Spare blocks left.
  [[nodiscard]] std::size_t spare_blocks() const { return spares().blocks; }
  /// Spare blocks and nodes left.
  [[nodiscard]] TsdfSpareCount spares() const;
  /// Spares missing to spare_target(params.reserve_blocks): what a top-up should build.
  [[nodiscard]] TsdfSpareCount spare_shortfall() const;
  /// Takes `spares` (moves pointers: RT-safe once the spare lists have grown to reserve_blocks,
  /// which the constructor does), topping up the partitions that are shortest first.
  /// @pre the spares were built for params with the same truncation_m.
  void add_spares(TsdfSpareBlocks&& spares);

  /// A layer matching the params.
  [[nodiscard]] TsdfLayer make_layer() const;
  /// Sizes (and touches) the layer's block lookup tables for the spare blocks and a scan of the
  /// reserved size (reserve_scan), which the first scans would otherwise grow. Not RT-safe
  /// (allocates); for start-up, after reserve_scan.
  void reserve_layer(TsdfLayer& layer) const;

 private:
  struct Scratch;
  TsdfParams params_;
  std::unique_ptr<Scratch> scratch_;
  TsdfUpdate update_;
};

}  // namespace tarmac::core
