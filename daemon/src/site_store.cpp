// The site of a paged TSDF, read-only (site_store.hpp): resident tiles from the layer, the others
// read back from the tile store one at a time.

#include "tarmac/daemon/site_store.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <tuple>
#include <utility>

#include "tile_files.hpp"

namespace tarmac::daemon {

namespace {

using core::TileIndex;
using core::TileKey;
using core::TsdfTile;

TileIndex tile_of_key(const TileKey& key) {
  return {key.tile[0], key.tile[1], key.tile[2]};
}

/// Floor division of a voxel or tile coordinate by `edge`.
int floor_div(int v, int edge) {
  return v >= 0 ? v / edge : -((-v + edge - 1) / edge);
}

TileFiles files_at(const SiteStoreParams& p, const std::filesystem::path& dir) {
  return TileFiles{dir, p.voxel_size_m, p.truncation_m, p.occupancy_voxel_m};
}

}  // namespace

/// The change raster being filled: its extent (voxels, x and y, [lo, hi)), geometry, the strip
/// in hand and the prior tile's blocks by index.
struct SiteStore::ChangeRaster {
  Eigen::Vector2i lo{std::numeric_limits<int>::max(), std::numeric_limits<int>::max()};
  Eigen::Vector2i hi{std::numeric_limits<int>::min(), std::numeric_limits<int>::min()};
  core::GridGeometry2D geometry;
  std::vector<float> cells;
  std::map<std::array<int, 3>, core::TsdfBlockView> before;
};

SiteStore::SiteStore(SiteStoreParams params, const core::TsdfLayer& layer, StoredTiles stored,
                     const core::OccupancyMap* occupancy)
    : params_(std::move(params)),
      layer_(layer),
      stored_(std::move(stored)),
      occupancy_(occupancy) {}

SiteStore::Tiles SiteStore::tiles() const {
  Tiles site;
  for (const core::TsdfTileInfo& info : layer_.resident_tiles()) {
    site[TileKey::of(info.tile)] = true;
  }
  for (const TileIndex& t : stored_.tsdf) site.emplace(TileKey::of(t), false);
  return site;
}

/// fn(view) for each block of a site tile, in the layer's order: found in the layer when
/// resident (for_each_block would walk the whole tree), else read back.
core::Status SiteStore::for_each_tile_block(
    const TileIndex& t, bool resident,
    const std::function<void(const core::TsdfBlockView&)>& fn) const {
  if (!resident) {
    core::Result<TsdfTile> tile = files_at(params_, params_.dir).read_tsdf(t);
    if (!tile) return tile.error();
    tile.value().for_each_block(fn);
    return core::Ok{};
  }
  const int b = core::kTsdfTileBlocks;
  for (int x = 0; x < b; ++x) {
    for (int y = 0; y < b; ++y) {
      for (int z = 0; z < b; ++z) {
        const core::BlockIndex bi(t.x() * b + x, t.y() * b + y, t.z() * b + z);
        if (const auto view = layer_.find_block(bi)) fn(*view);
      }
    }
  }
  return core::Ok{};
}

/// A copy of a site tile: of the resident one, or read back from the store.
core::Result<TsdfTile> SiteStore::tile(const TileIndex& t, bool resident) const {
  if (resident) return std::move(*layer_.copy_tile(t));
  return files_at(params_, params_.dir).read_tsdf(t);
}

bool SiteStore::for_each_block(const std::function<void(const core::TsdfBlockView&)>& fn) const {
  bool ok = true;
  for (const auto& [key, resident] : tiles()) {
    if (!for_each_tile_block(tile_of_key(key), resident, fn)) ok = false;
  }
  return ok;
}

std::uint64_t SiteStore::digest() const {
  core::TsdfDigest digest;
  for_each_block([&digest](const core::TsdfBlockView& b) { digest.add(b); });
  return digest.value();
}

core::Status SiteStore::mesh(
    float min_weight, const std::function<core::Status(const core::TriangleMesh&)>& piece) const {
  const Tiles site = tiles();
  core::TriangleMesh mesh;
  for (const auto& [key, resident] : site) {
    if (auto s = mesh_tile(site, tile_of_key(key), min_weight, mesh); !s) return s;
    if (auto s = piece(mesh); !s) return s;
  }
  return core::Ok{};
}

/// Tile t's triangles: meshed with its 26 neighbours present, restricted to its own cells.
core::Status SiteStore::mesh_tile(const Tiles& site, const TileIndex& t, float min_weight,
                                  core::TriangleMesh& mesh) const {
  core::TsdfLayer piece_layer(params_.voxel_size_m, params_.truncation_m);
  for (int dx = -1; dx <= 1; ++dx) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dz = -1; dz <= 1; ++dz) {
        const TileIndex n = t + TileIndex(dx, dy, dz);
        const auto it = site.find(TileKey::of(n));
        if (it == site.end()) continue;
        core::Result<TsdfTile> copy = tile(n, it->second);
        if (!copy) return copy.error();
        piece_layer.attach_tile(std::move(copy).value());
      }
    }
  }
  const Eigen::Vector3i lo = t * core::kTsdfTileEdge;
  const Eigen::Vector3i hi = lo + Eigen::Vector3i::Constant(core::kTsdfTileEdge);
  return core::extract_mesh(piece_layer, min_weight, lo, hi, mesh);
}

core::Status SiteStore::export_parts(
    int region_tiles,
    const std::function<core::Status(const Eigen::Vector2i& region, const core::TsdfLayer& part)>&
        part) const {
  if (region_tiles < 1) return core::Error{"tsdf_pager.config", "region_tiles must be >= 1"};
  // Every tile of the site, by region (y, x) then in key order.
  std::map<std::pair<int, int>, Tiles> regions;
  for (const auto& [key, resident] : tiles()) {
    regions[{floor_div(key.tile[1], region_tiles), floor_div(key.tile[0], region_tiles)}][key] =
        resident;
  }
  for (const auto& [r, region] : regions) {
    core::TsdfLayer piece(params_.voxel_size_m, params_.truncation_m);
    for (const auto& [key, resident] : region) {
      core::Result<TsdfTile> copy = tile(tile_of_key(key), resident);
      if (!copy) return copy.error();
      piece.attach_tile(std::move(copy).value());
    }
    if (auto s = part(Eigen::Vector2i(r.second, r.first), piece); !s) return s;
  }
  return core::Ok{};
}

core::Status SiteStore::changes(
    const std::filesystem::path& prior_dir, const core::ChangeParams& params,
    core::ChangeCounts& counts,
    const std::function<core::Status(const core::GridGeometry2D&)>& begin,
    const std::function<core::Status(int y0, int rows, std::span<const float> cells)>& strip)
    const {
  if (auto s = params.validate(); !s) return s;
  counts = core::ChangeCounts{};
  // Both sites' tiles: the current one's (resident or stored) and the prior store's.
  const Tiles site = tiles();
  std::map<TileKey, TileIndex> prior;
  std::error_code ec;
  for (const auto& f : std::filesystem::directory_iterator(prior_dir, ec)) {
    if (const auto t = parse_tsdf_file_name(f.path().filename().string())) {
      prior[TileKey::of(*t)] = *t;
    }
  }
  if (ec) return core::Error{"tsdf_changes.prior", prior_dir.string() + ": " + ec.message()};
  ChangeRaster raster;
  if (auto s = change_extent(site, prior, prior_dir, raster); !s) return s;
  const Eigen::Vector2i lo = raster.lo, hi = raster.hi;
  if (lo.x() >= hi.x()) return begin(raster.geometry);
  if (auto s = begin(raster.geometry); !s) return s;
  // Strip by strip, one tile row (ty) at a time from the top down.
  for (int ty = floor_div(hi.y() - 1, core::kTsdfTileEdge);
       ty >= floor_div(lo.y(), core::kTsdfTileEdge); --ty) {
    if (auto s = change_strip(site, prior, prior_dir, params, ty, raster, counts); !s) return s;
    const int y0 = std::max(lo.y(), ty * core::kTsdfTileEdge);
    const int y1 = std::min(hi.y(), (ty + 1) * core::kTsdfTileEdge);
    if (auto s = strip(y0 - lo.y(), y1 - y0, raster.cells); !s) return s;
  }
  return core::Ok{};
}

/// The raster's extent and geometry, as detect_changes takes it: the union of both maps'
/// blocks (x, y).
core::Status SiteStore::change_extent(const Tiles& site, const std::map<TileKey, TileIndex>& prior,
                                      const std::filesystem::path& prior_dir,
                                      ChangeRaster& raster) const {
  const auto extend = [&raster](const core::TsdfBlockView& b) {
    raster.lo = raster.lo.cwiseMin(b.block.head<2>() * core::kTsdfBlockEdge);
    raster.hi = raster.hi.cwiseMax(b.block.head<2>() * core::kTsdfBlockEdge +
                                   Eigen::Vector2i::Constant(core::kTsdfBlockEdge));
  };
  for (const auto& [key, resident] : site) {
    if (auto s = for_each_tile_block(tile_of_key(key), resident, extend); !s) return s;
  }
  const TileFiles prior_files = files_at(params_, prior_dir);
  for (const auto& [key, t] : prior) {
    core::Result<TsdfTile> tile = prior_files.read_tsdf(t);
    if (!tile) return tile.error();
    tile.value().for_each_block(extend);
  }
  if (raster.lo.x() >= raster.hi.x()) return core::Ok{};
  core::GridGeometry2D& g = raster.geometry;
  const double v = params_.voxel_size_m;
  g.origin_x_m = raster.lo.x() * v;
  g.origin_y_m = raster.lo.y() * v;
  g.resolution_m = v;
  g.width = static_cast<std::uint32_t>(raster.hi.x() - raster.lo.x());
  g.height = static_cast<std::uint32_t>(raster.hi.y() - raster.lo.y());
  return core::Ok{};
}

/// The strip of tile row ty into raster.cells: the current tiles of that row that the prior
/// also holds, compared block by block.
core::Status SiteStore::change_strip(const Tiles& site, const std::map<TileKey, TileIndex>& prior,
                                     const std::filesystem::path& prior_dir,
                                     const core::ChangeParams& params, int ty, ChangeRaster& raster,
                                     core::ChangeCounts& counts) const {
  const int y0 = std::max(raster.lo.y(), ty * core::kTsdfTileEdge);
  const int y1 = std::min(raster.hi.y(), (ty + 1) * core::kTsdfTileEdge);
  const core::GridGeometry2D& g = raster.geometry;
  raster.cells.assign(static_cast<std::size_t>(y1 - y0) * g.width, std::nanf(""));
  const Eigen::Vector2i origin(raster.lo.x(), y0);
  const TileFiles prior_files = files_at(params_, prior_dir);
  for (const auto& [key, resident] : site) {
    if (key.tile[1] != ty || !prior.contains(key)) continue;
    const TileIndex t = tile_of_key(key);
    core::Result<TsdfTile> prior_tile = prior_files.read_tsdf(t);
    if (!prior_tile) return prior_tile.error();
    raster.before.clear();
    prior_tile.value().for_each_block([&raster](const core::TsdfBlockView& b) {
      raster.before.emplace(std::array<int, 3>{b.block.x(), b.block.y(), b.block.z()}, b);
    });
    const auto compare = [&](const core::TsdfBlockView& now) {
      const auto it = raster.before.find({now.block.x(), now.block.y(), now.block.z()});
      if (it != raster.before.end()) {
        core::compare_blocks(it->second, now, params, params_.voxel_size_m, origin, g.width,
                             raster.cells, counts);
      }
    };
    if (auto s = for_each_tile_block(t, resident, compare); !s) return s;
  }
  return core::Ok{};
}

bool SiteStore::static_voxels(std::vector<Eigen::Vector3i>& out) const {
  out.clear();
  if (occupancy_ == nullptr) return true;
  occupancy_->export_static(out);
  bool ok = true;
  const TileFiles files = files_at(params_, params_.dir);
  for (const core::StaticTileIndex& t : stored_.statics) {
    core::Result<core::StaticTile> read = files.read_static(t);
    if (!read) {
      ok = false;
      continue;
    }
    out.insert(out.end(), read.value().voxels.begin(), read.value().voxels.end());
  }
  std::sort(out.begin(), out.end(), [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  return ok;
}

}  // namespace tarmac::daemon
