#include "small_objects.hpp"

#include <limits>

#include "text_number.hpp"

namespace tarmac::sim {

bool small_object(const Object& o) {
  if (o.dynamic() || o.kind == "ground" || o.kind == "curb") return false;
  const Aabb b = bounds(o.shape_W);
  return b.max_W.x() - b.min_W.x() <= 1.0 && b.max_W.y() - b.min_W.y() <= 1.0;
}

std::string small_objects_file(const Scene& scene, const Eigen::Isometry3d& T_O_W,
                               const std::map<std::pair<int, int>, int>& returns) {
  std::string text;
  for (const Object& o : scene.objects()) {
    if (!small_object(o)) continue;
    const Aabb b = bounds(o.shape_W);
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
    Eigen::Vector3d hi = -lo;
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d corner((c & 1) != 0 ? b.max_W.x() : b.min_W.x(),
                                   (c & 2) != 0 ? b.max_W.y() : b.min_W.y(),
                                   (c & 4) != 0 ? b.max_W.z() : b.min_W.z());
      lo = lo.cwiseMin(T_O_W * corner);
      hi = hi.cwiseMax(T_O_W * corner);
    }
    text += "object " + std::to_string(o.id) + ' ' + o.name + ' ' + o.kind;
    for (const Eigen::Vector3d* v : {&lo, &hi}) {
      for (int a = 0; a < 3; ++a) text += ' ' + number((*v)[a]);
    }
    text += '\n';
  }
  if (text.empty()) return text;
  text =
      "# small objects (at most 1 m across): 'object id name kind min_x min_y min_z max_x max_y "
      "max_z' (frame of poses.txt, m), then 'returns scan id count' per scan that returned "
      "points from it\n" +
      text;
  for (const auto& [scan_id, count] : returns) {
    text += "returns " + std::to_string(scan_id.first) + ' ' + std::to_string(scan_id.second) +
            ' ' + std::to_string(count) + '\n';
  }
  return text;
}

}  // namespace tarmac::sim
