#pragma once
/// @file What tarmac-map writes at the end of a run: the window's arrays and images with
/// map.json, and the TSDF's products with tsdf.json. Formats in docs/tools.md.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "tarmac/core/distance_field.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/task_runner.hpp"
#include "tarmac/core/tsdf_changes.hpp"
#include "tarmac/core/tsdf_integrator.hpp"
#include "tarmac/daemon/site_store.hpp"

namespace tarmac::map_tool {

/// Frame of the TSDF lattice written by this tool: the dataset's pose frame.
inline constexpr const char* kTsdfFrame = "world";

/// What write_window_outputs computed on the way (the digests are printed from it).
struct WindowOutputs {
  std::vector<float> log_odds;  ///< the window's log-odds, x fastest
  core::DistanceField esdf3d;   ///< 3D ESDF of the window, ground layer excluded
  double esdf3d_ms = 0.0;
  bool have_band = false;  ///< esdf_band.npy written
};

/// occupancy.npy, esdf.npy, esdf_slice.npy (and esdf_band.npy), costmap.npy / .png,
/// esdf_slice.png and map.json, from the mapper's window and layers after `scans` scans.
core::Status write_window_outputs(const std::filesystem::path& out, const core::Mapper& mapper,
                                  std::size_t scans, core::TaskRunner& runner,
                                  WindowOutputs& result);

struct TsdfOutputs {
  double mesh_ms = 0.0, save_ms = 0.0, changes_ms = 0.0;
  std::size_t vertices = 0, triangles = 0;
  core::ChangeMap changes;
  bool paged = false;  ///< tsdf.resident_limit_mb > 0: the TSDF is the tile store, no products
};

/// tsdf.vdb, tsdf.json, mesh.ply and, with a prior, changes.npy + changes.png.
core::Status write_tsdf_outputs(const std::filesystem::path& out, const core::TsdfLayer& tsdf,
                                const std::string& config_hash, std::int64_t stamp_ns,
                                const core::TsdfLayer* prior, TsdfOutputs& result);

/// Tile columns per side of a part of the .vdb export with a limit (51.2 m at 0.1 m).
inline constexpr int kVdbRegionTiles = 4;

/// With tsdf.resident_limit_mb: tsdf_vdb/ (the site's .vdb in parts of kVdbRegionTiles² tile
/// columns), mesh.ply tile by tile, tsdf.json and, with `prior_dir` (a tile
/// store of an earlier run), changes.npy + changes.png strip by strip
/// (daemon::SiteStore::changes): the same files as write_tsdf_outputs gives for the maps held
/// whole. result.changes gets the geometry and counts; its raster stays empty.
core::Status write_tsdf_site_outputs(const std::filesystem::path& out,
                                     const daemon::SiteStore& site, const core::TsdfLayer& layer,
                                     const std::string& config_hash, std::int64_t stamp_ns,
                                     const std::filesystem::path* prior_dir, TsdfOutputs& result);

}  // namespace tarmac::map_tool
