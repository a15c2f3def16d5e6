#pragma once
/// @file Writing triangle meshes for QC viewers (MeshLab, CloudCompare, Blender): binary PLY.

#include <filesystem>
#include <fstream>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_mesh.hpp"

namespace tarmac::tools {

/// Binary little-endian PLY 1.0: float x, y, z per vertex; uchar count + int indices per face.
core::Status write_ply(const std::filesystem::path& file, const core::TriangleMesh& mesh);

/// A binary PLY written piece by piece (a mesh too big to hold: the site's, tile by tile): the
/// pieces' vertices and faces go to two files beside `file`, joined under the header by finish().
class PlyPieces {
 public:
  explicit PlyPieces(std::filesystem::path file);
  ~PlyPieces();
  PlyPieces(const PlyPieces&) = delete;
  PlyPieces& operator=(const PlyPieces&) = delete;
  /// Appends a piece (its indices shifted past the vertices written so far).
  core::Status add(const core::TriangleMesh& piece);
  /// Writes `file` and removes the two part files.
  core::Status finish();
  [[nodiscard]] std::size_t vertices() const { return vertices_; }
  [[nodiscard]] std::size_t triangles() const { return triangles_; }

 private:
  std::filesystem::path file_;
  std::ofstream vertex_part_, face_part_;
  std::size_t vertices_ = 0, triangles_ = 0;
};

}  // namespace tarmac::tools
