#pragma once
/// @file Writing triangle meshes for QC viewers (MeshLab, CloudCompare, Blender): binary PLY.

#include <filesystem>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_mesh.hpp"

namespace tarmac::tools {

/// Binary little-endian PLY 1.0: float x, y, z per vertex; uchar count + int indices per face.
core::Status write_ply(const std::filesystem::path& file, const core::TriangleMesh& mesh);

}  // namespace tarmac::tools
