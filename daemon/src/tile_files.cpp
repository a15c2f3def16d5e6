// The tile store's files (tile_files.hpp): names, atomic writes, reads.

#include "tile_files.hpp"

#include <cstdio>
#include <fstream>
#include <iterator>

#include <fcntl.h>
#include <unistd.h>

namespace tarmac::daemon {

namespace {

bool sync_fd_path(const std::filesystem::path& p, bool dir) {
  const int fd = ::open(p.c_str(), (dir ? O_RDONLY | O_DIRECTORY : O_RDWR) | O_CLOEXEC);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
}

std::optional<std::vector<std::uint8_t>> read_bytes(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)),
                                   std::istreambuf_iterator<char>());
}

}  // namespace

std::string tsdf_file_name(const core::TileIndex& t) {
  return "tile_" + std::to_string(t.x()) + "_" + std::to_string(t.y()) + "_" +
         std::to_string(t.z()) + ".tsdft";
}

std::optional<core::TileIndex> parse_tsdf_file_name(const std::string& name) {
  int x = 0, y = 0, z = 0, n = 0;
  if (std::sscanf(name.c_str(), "tile_%d_%d_%d.tsdft%n", &x, &y, &z, &n) != 3) return std::nullopt;
  if (static_cast<std::size_t>(n) != name.size()) return std::nullopt;
  if (tsdf_file_name(core::TileIndex(x, y, z)) != name) return std::nullopt;
  return core::TileIndex(x, y, z);
}

std::string static_file_name(const core::StaticTileIndex& t) {
  return "static_" + std::to_string(t.x()) + "_" + std::to_string(t.y()) + ".occs";
}

std::optional<core::StaticTileIndex> parse_static_file_name(const std::string& name) {
  int x = 0, y = 0, n = 0;
  if (std::sscanf(name.c_str(), "static_%d_%d.occs%n", &x, &y, &n) != 2) return std::nullopt;
  if (static_cast<std::size_t>(n) != name.size()) return std::nullopt;
  if (static_file_name(core::StaticTileIndex(x, y)) != name) return std::nullopt;
  return core::StaticTileIndex(x, y);
}

core::Status write_file_atomic(const std::filesystem::path& file,
                               const std::vector<std::uint8_t>& bytes) {
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()),
              static_cast<std::streamsize>(bytes.size()));
    if (!out) return core::Error{"tsdf_tile.write", tmp.string() + ": write failed"};
  }
  if (!sync_fd_path(tmp, false))
    return core::Error{"tsdf_tile.write", tmp.string() + ": fsync failed"};
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) return core::Error{"tsdf_tile.write", file.string() + ": rename failed: " + ec.message()};
  sync_fd_path(file.parent_path(), true);  // best effort: the rename is atomic either way
  return core::Ok{};
}

std::filesystem::path TileFiles::tsdf_file(const core::TileIndex& t) const {
  return dir / tsdf_file_name(t);
}

std::filesystem::path TileFiles::static_file(const core::StaticTileIndex& t) const {
  return dir / static_file_name(t);
}

core::Result<core::TsdfTile> TileFiles::read_tsdf(const core::TileIndex& t) const {
  const std::filesystem::path file = tsdf_file(t);
  const auto bytes = read_bytes(file);
  if (!bytes) return core::Error{"tsdf_tile.open", file.string() + ": cannot open"};
  core::Result<core::TsdfTile> tile = core::TsdfTile::decode(*bytes, voxel_size_m, truncation_m, t);
  if (!tile) return core::Error{tile.error().code, file.string() + ": " + tile.error().message};
  return tile;
}

core::Result<core::StaticTile> TileFiles::read_static(const core::StaticTileIndex& t) const {
  const std::filesystem::path file = static_file(t);
  const auto bytes = read_bytes(file);
  if (!bytes) return core::Error{"static_tile.open", file.string() + ": cannot open"};
  core::Result<core::StaticTile> tile = core::StaticTile::decode(*bytes, occupancy_voxel_m, t);
  if (!tile) return core::Error{tile.error().code, file.string() + ": " + tile.error().message};
  return tile;
}

}  // namespace tarmac::daemon
