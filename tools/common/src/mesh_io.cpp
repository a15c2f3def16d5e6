#include "tarmac/tools/mesh_io.hpp"

#include <bit>
#include <cstring>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace tarmac::tools {

namespace {

void write_header(std::ostream& out, std::size_t vertices, std::size_t faces) {
  out << "ply\nformat binary_little_endian 1.0\ncomment tarmac TSDF zero level set, world "
         "frame, m\nelement vertex "
      << vertices << "\nproperty float x\nproperty float y\nproperty float z\nelement face "
      << faces << "\nproperty list uchar int vertex_indices\nend_header\n";
}

/// The mesh's vertices, then its faces with their indices shifted by `offset`.
void write_body(std::ostream& vertices_out, std::ostream& faces_out, const core::TriangleMesh& mesh,
                std::size_t offset) {
  static_assert(std::endian::native == std::endian::little, "PLY writer assumes little endian");
  static_assert(sizeof(Eigen::Vector3f) == 12 && sizeof(Eigen::Vector3i) == 12);
  vertices_out.write(reinterpret_cast<const char*>(mesh.vertices_W.data()),
                     static_cast<std::streamsize>(mesh.vertices_W.size() * sizeof(float) * 3));
  std::vector<char> faces(mesh.triangles.size() * 13);
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    faces[i * 13] = 3;
    const Eigen::Vector3i t = mesh.triangles[i].array() + static_cast<int>(offset);
    std::memcpy(&faces[i * 13 + 1], t.data(), 12);
  }
  faces_out.write(faces.data(), static_cast<std::streamsize>(faces.size()));
}

}  // namespace

core::Status write_ply(const std::filesystem::path& file, const core::TriangleMesh& mesh) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (!out) return core::Error{"io.open", file.string() + ": cannot be written"};
  write_header(out, mesh.vertices_W.size(), mesh.triangles.size());
  write_body(out, out, mesh, 0);
  out.close();
  if (!out) return core::Error{"io.write", file.string() + ": write failed"};
  return core::Ok{};
}

PlyPieces::PlyPieces(std::filesystem::path file)
    : file_(std::move(file)),
      vertex_part_(file_.string() + ".vertices.part", std::ios::binary | std::ios::trunc),
      face_part_(file_.string() + ".faces.part", std::ios::binary | std::ios::trunc) {}

PlyPieces::~PlyPieces() {
  std::error_code ec;
  std::filesystem::remove(file_.string() + ".vertices.part", ec);
  std::filesystem::remove(file_.string() + ".faces.part", ec);
}

core::Status PlyPieces::add(const core::TriangleMesh& piece) {
  write_body(vertex_part_, face_part_, piece, vertices_);
  vertices_ += piece.vertices_W.size();
  triangles_ += piece.triangles.size();
  if (!vertex_part_ || !face_part_) {
    return core::Error{"io.write", file_.string() + ": writing its parts failed"};
  }
  return core::Ok{};
}

core::Status PlyPieces::finish() {
  vertex_part_.close();
  face_part_.close();
  std::ofstream out(file_, std::ios::binary | std::ios::trunc);
  if (!out) return core::Error{"io.open", file_.string() + ": cannot be written"};
  write_header(out, vertices_, triangles_);
  for (const char* part : {".vertices.part", ".faces.part"}) {
    std::ifstream in(file_.string() + part, std::ios::binary);
    out << in.rdbuf();
  }
  out.close();
  if (!out) return core::Error{"io.write", file_.string() + ": write failed"};
  return core::Ok{};
}

}  // namespace tarmac::tools
