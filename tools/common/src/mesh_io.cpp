#include "tarmac/tools/mesh_io.hpp"

#include <bit>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace tarmac::tools {

core::Status write_ply(const std::filesystem::path& file, const core::TriangleMesh& mesh) {
  static_assert(std::endian::native == std::endian::little, "PLY writer assumes little endian");
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (!out) return core::Error{"io.open", file.string() + ": cannot be written"};
  out << "ply\nformat binary_little_endian 1.0\ncomment tarmac TSDF zero level set, world "
         "frame, m\nelement vertex "
      << mesh.vertices_W.size()
      << "\nproperty float x\nproperty float y\nproperty float z\nelement face "
      << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  out.write(reinterpret_cast<const char*>(mesh.vertices_W.data()),
            static_cast<std::streamsize>(mesh.vertices_W.size() * sizeof(float) * 3));
  static_assert(sizeof(Eigen::Vector3f) == 12 && sizeof(Eigen::Vector3i) == 12);
  std::vector<char> faces(mesh.triangles.size() * 13);
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i) {
    faces[i * 13] = 3;
    std::memcpy(&faces[i * 13 + 1], mesh.triangles[i].data(), 12);
  }
  out.write(faces.data(), static_cast<std::streamsize>(faces.size()));
  out.close();
  if (!out) return core::Error{"io.write", file.string() + ": write failed"};
  return core::Ok{};
}

}  // namespace tarmac::tools
