#pragma once
/// @file A triangle mesh of the TSDF's zero level set for QC, by OpenVDB's mesher
/// (openvdb::tools::VolumeToMesh, dual contouring on the distance grid). Only cells whose eight
/// corner voxels were all observed (weight >= min_weight) are meshed: the edge of a truncation
/// band next to never-observed space is not a surface.

#include <vector>

#include <Eigen/Core>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices_W;  ///< world frame, m
  std::vector<Eigen::Vector3i> triangles;   ///< vertex indices, OpenVDB's winding
};

/// Extracts the zero crossing of `layer` into `out` (cleared first). Not RT-safe (allocates;
/// OpenVDB's mesher runs on TBB threads): for QC and on-demand export.
/// @param min_weight voxels with a lower weight count as unobserved (>= 0).
Status extract_mesh(const TsdfLayer& layer, float min_weight, TriangleMesh& out);

/// The same, restricted to the cells whose first corner (voxel index) lies in [lo, hi): a piece
/// of a larger map (the site mesh tile by tile, tsdf_tiles.hpp), meshed from a layer that also
/// holds the piece's neighbours, so that every cell and every edge of the piece sees the voxels
/// it would see in the whole map. The pieces of a partition of the map together hold the whole
/// map's triangles (their vertices are not shared across pieces).
Status extract_mesh(const TsdfLayer& layer, float min_weight, const Eigen::Vector3i& lo,
                    const Eigen::Vector3i& hi, TriangleMesh& out);

}  // namespace tarmac::core
