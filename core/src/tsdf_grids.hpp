#pragma once
/// @file The OpenVDB side of TsdfLayer, for the core's own TSDF .cpp files only (never include it
/// from a public header: an OpenVDB translation unit costs ~12 s and ~650 MB to compile).

#include <algorithm>
#include <cstdint>
#include <unordered_set>
#include <vector>

#include <openvdb/openvdb.h>

#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

/// One grid of (signed distance m, weight) pairs: a voxel's two values share a cache line, which
/// halves the memory traffic of integration against two grids (in files: two float grids,
/// tsdf_io.cpp). Background (never observed):
/// (+truncation, 0).
using TsdfTree = openvdb::Vec2STree;
using TsdfGrid = openvdb::Grid<TsdfTree>;

/// Leaf pointers by packed block key (open addressing, at most half full), so that integration
/// finds a block's leaf without walking the tree. One table per integration partition: the task
/// of partition p is the only user of table p. Emptied whenever the tree may change outside the
/// integrator (TsdfLayer::grids(), clear()), keeping their memory.
struct TsdfLeafCache {
  struct Entry {
    std::uint64_t key;  // ~0: empty
    TsdfTree::LeafNodeType* leaf;
    TsdfTree::ValueType* values;
  };
  std::vector<Entry> table;
  std::size_t size = 0;

  /// Empties the table, keeping its memory (a table is sized for the map and faulted in once).
  void drop() {
    if (size == 0) return;
    std::fill(table.begin(), table.end(), Entry{~std::uint64_t{0}, nullptr, nullptr});
    size = 0;
  }
};

struct TsdfLayer::Grids {
  TsdfGrid::Ptr tsdf;
  std::vector<TsdfLeafCache> leaf_cache;
  /// Tiles paged out (pack_tile keys): read by the integrator's tasks, changed between scans.
  std::unordered_set<std::uint64_t> absent;
  /// Tiles changed since TsdfLayer::take_touched_tiles() (kept only when tracking is on).
  bool track_touched = false;
  std::unordered_set<std::uint64_t> touched;
  void touch(int bx, int by, int bz);
};

/// A tile's key in Grids::absent (21 bits per axis, like the integrator's block keys).
inline std::uint64_t pack_tile(int tx, int ty, int tz) {
  constexpr int kBias = 1 << 20;
  return (static_cast<std::uint64_t>(tx + kBias) << 42) |
         (static_cast<std::uint64_t>(ty + kBias) << 21) | static_cast<std::uint64_t>(tz + kBias);
}

inline void TsdfLayer::Grids::touch(int bx, int by, int bz) {
  if (track_touched) touched.insert(pack_tile(bx >> 4, by >> 4, bz >> 4));
}

/// OpenVDB's nodes of the TSDF tree: a tile is a Node.
using TsdfLeaf = TsdfTree::LeafNodeType;
using TsdfTopNode = TsdfTree::RootNodeType::ChildNodeType;  // 32³ tiles
using TsdfNode = TsdfTopNode::ChildNodeType;                // 16³ blocks: a tile

/// Index-to-world transform of the lattice: index i ↦ centre (i + ½)·v of voxel [i·v, (i+1)·v).
openvdb::math::Transform::Ptr tsdf_transform(float voxel_size_m);

/// An empty grid with the lattice transform.
void make_tsdf_grids(float voxel_size_m, float truncation_m, TsdfLayer::Grids& grids);

}  // namespace tarmac::core
