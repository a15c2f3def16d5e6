#pragma once
// The tile store's files (docs/mapping.md, "Site-scale maps"): one file a tile in one directory,
// tile_X_Y_Z.tsdft for the TSDF's tiles and static_X_Y.occs for the static occupancy's column
// tiles, each written whole or not at all.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_tiles.hpp"

namespace tarmac::daemon {

/// What the store's files are of: the lattice their tiles were encoded for.
struct TileFiles {
  std::filesystem::path dir;
  float voxel_size_m = 0.1f;
  float truncation_m = 0.3f;
  float occupancy_voxel_m = 0.2f;  ///< the static tiles' voxel

  [[nodiscard]] std::filesystem::path tsdf_file(const core::TileIndex& t) const;
  [[nodiscard]] std::filesystem::path static_file(const core::StaticTileIndex& t) const;
  /// Reads and decodes a TSDF tile (`t` from this store, or from another one at `dir`).
  [[nodiscard]] core::Result<core::TsdfTile> read_tsdf(const core::TileIndex& t) const;
  [[nodiscard]] core::Result<core::StaticTile> read_static(const core::StaticTileIndex& t) const;
};

[[nodiscard]] std::string tsdf_file_name(const core::TileIndex& t);
/// The tile a file name spells (one spelling a tile), or none.
[[nodiscard]] std::optional<core::TileIndex> parse_tsdf_file_name(const std::string& name);
[[nodiscard]] std::string static_file_name(const core::StaticTileIndex& t);
[[nodiscard]] std::optional<core::StaticTileIndex> parse_static_file_name(const std::string& name);

/// Writes `bytes` to `file` atomically: a temporary beside it, fsync, rename.
core::Status write_file_atomic(const std::filesystem::path& file,
                               const std::vector<std::uint8_t>& bytes);

}  // namespace tarmac::daemon
