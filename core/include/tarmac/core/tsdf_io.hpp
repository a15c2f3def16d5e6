#pragma once
/// @file Persistence of the TSDF as an OpenVDB .vdb file (grids "tsdf" and "weight" plus a small
/// metadata header), saved atomically and refused with a clear error when truncated, corrupted
/// or made for another map. The one place in the core that touches files: OpenVDB's io::File
/// needs a path (DESIGN.md §2 exception, kept to this pair).
///
/// File layout: a standard .vdb (readable by vdb_print / vdb_view) followed by a 32-byte
/// trailer: "TARMACv1", the byte length of the .vdb part (u64 LE), its FNV-1a 64 (u64 LE),
/// "TSDF-END". The trailer is checked before OpenVDB parses anything, so damaged bytes are
/// refused before they reach the parser.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

/// Format version written to and required from the file's metadata.
inline constexpr int kTsdfFileVersion = 1;

/// The metadata header.
struct TsdfMapInfo {
  std::string frame_id = "world";  ///< frame of the voxel lattice
  float voxel_size_m = 0.0f;
  float truncation_m = 0.0f;
  std::string config_hash;    ///< of the config that built the map (informational)
  std::int64_t stamp_ns = 0;  ///< time of the save (the caller's clock), ns since the epoch
};

/// The static occupancy layer (OccupancyMap::export_static) on its own lattice: voxel i covers
/// [i·v, (i+1)·v). Stored as the active voxels of bool grid "static_occupancy" with metadata
/// "tarmac.static_voxel_size_m". voxel_size_m 0: absent.
struct StaticOccupancy {
  float voxel_size_m = 0.0f;
  std::vector<Eigen::Vector3i> voxels;  ///< sorted by (z, y, x) when loaded
};

/// Writes `layer` (and `occupancy`, when not null) to `file`: first to `file` + ".tmp", flushed
/// to disk, then renamed over `file`, so a crash mid-save leaves the previous file intact.
/// `info.voxel_size_m` and `truncation_m` are taken from the layer. Errors: "tsdf_io.write".
Status save_tsdf(const std::filesystem::path& file, const TsdfLayer& layer, TsdfMapInfo info,
                 const StaticOccupancy* occupancy = nullptr);

struct LoadedTsdf {
  TsdfLayer layer;
  TsdfMapInfo info;
  StaticOccupancy occupancy;  ///< empty (voxel_size_m 0) when the file holds none
};

/// Reads a file written by save_tsdf. Errors: "tsdf_io.open" (cannot be read),
/// "tsdf_io.truncated" (shorter than written), "tsdf_io.corrupt" (checksum, parse or content
/// failure), "tsdf_io.format" (not a tarmac TSDF, or another format version).
Result<LoadedTsdf> load_tsdf(const std::filesystem::path& file);

/// load_tsdf on a file's bytes already in memory; `name` prefixes the error messages. Every
/// error of load_tsdf except "tsdf_io.open".
Result<LoadedTsdf> parse_tsdf(std::string bytes, const std::string& name);

/// "tsdf_io.mismatch" unless the map was built in `frame_id` with these voxel size and
/// truncation (the caller refuses such a map and starts empty).
Status check_tsdf_matches(const TsdfMapInfo& info, const std::string& frame_id, float voxel_size_m,
                          float truncation_m);

/// "tsdf_io.mismatch" when the file holds a static occupancy layer of another voxel size.
Status check_static_occupancy_matches(const StaticOccupancy& occupancy, float voxel_size_m);

}  // namespace tarmac::core
