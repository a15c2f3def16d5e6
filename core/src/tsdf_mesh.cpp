#include "tarmac/core/tsdf_mesh.hpp"

#include <algorithm>
#include <limits>

#include <openvdb/tools/VolumeToMesh.h>

#include "tsdf_grids.hpp"

namespace tarmac::core {

Status extract_mesh(const TsdfLayer& layer, float min_weight, TriangleMesh& out) {
  constexpr int kMin = std::numeric_limits<int>::min(), kMax = std::numeric_limits<int>::max();
  return extract_mesh(layer, min_weight, Eigen::Vector3i::Constant(kMin),
                      Eigen::Vector3i::Constant(kMax), out);
}

Status extract_mesh(const TsdfLayer& layer, float min_weight, const Eigen::Vector3i& lo,
                    const Eigen::Vector3i& hi, TriangleMesh& out) {
  out.vertices_W.clear();
  out.triangles.clear();
  if (!(min_weight >= 0.0f)) return Error{"tsdf_mesh.invalid", "min_weight must be >= 0"};
  const TsdfTree& tree = layer.grids().tsdf->tree();
  const auto& xform = layer.grids().tsdf->transform();
  // The mesher wants a scalar grid: the distances, with the same topology.
  auto distance = openvdb::FloatGrid::create(layer.truncation_m());
  distance->setTransform(xform.copy());
  // Cells (voxel i up to i + (1, 1, 1)) whose eight corners are observed: the region to mesh.
  auto mask = openvdb::BoolGrid::create(false);
  mask->setTransform(xform.copy());
  {
    openvdb::tree::ValueAccessor<const TsdfTree> acc(tree);
    openvdb::tree::ValueAccessor<openvdb::FloatTree> d(distance->tree());
    openvdb::tree::ValueAccessor<openvdb::BoolTree> m(mask->tree());
    const auto observed = [&](const openvdb::Coord& c) {
      const float w = acc.getValue(c)[1];
      return w > 0.0f && w >= min_weight;
    };
    // The distances the region's cells and edges read: the region and a margin of two voxels
    // (a cell reads its corners up to +1; an edge's polygon joins the cells around it, down to
    // −1). Saturated, so the whole map's region is every int.
    const auto widen = [](int x, int by) {
      const long long w = static_cast<long long>(x) + by;
      return static_cast<int>(std::clamp<long long>(w, std::numeric_limits<int>::min(),
                                                    std::numeric_limits<int>::max()));
    };
    const openvdb::CoordBBox needed(
        openvdb::Coord(widen(lo.x(), -2), widen(lo.y(), -2), widen(lo.z(), -2)),
        openvdb::Coord(widen(hi.x(), 1), widen(hi.y(), 1), widen(hi.z(), 1)));
    for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) {
      if (!needed.hasOverlap(leaf->getNodeBoundingBox())) continue;
      for (auto it = leaf->cbeginValueOn(); it; ++it) {
        const openvdb::Coord c = it.getCoord();
        if (!needed.isInside(c)) continue;
        d.setValue(c, (*it)[0]);
        if (c.x() < lo.x() || c.y() < lo.y() || c.z() < lo.z() || c.x() >= hi.x() ||
            c.y() >= hi.y() || c.z() >= hi.z()) {
          continue;  // a neighbour's voxel: its distance is there, its cell is not meshed here
        }
        bool all = true;
        for (int corner = 0; corner < 8 && all; ++corner) {
          all = observed(c.offsetBy(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1));
        }
        if (all) m.setValueOn(c, true);
      }
    }
  }
  try {
    openvdb::tools::VolumeToMesh mesher(/*isovalue=*/0.0, /*adaptivity=*/0.0);
    mesher.setSurfaceMask(mask);
    mesher(*distance);
    out.vertices_W.reserve(mesher.pointListSize());
    for (std::size_t i = 0; i < mesher.pointListSize(); ++i) {
      const openvdb::Vec3s& p = mesher.pointList()[i];
      out.vertices_W.emplace_back(p.x(), p.y(), p.z());
    }
    auto& pools = mesher.polygonPoolList();
    for (std::size_t n = 0; n < mesher.polygonPoolListSize(); ++n) {
      const openvdb::tools::PolygonPool& pool = pools[n];
      for (std::size_t i = 0; i < pool.numQuads(); ++i) {
        const openvdb::Vec4I& q = pool.quad(i);
        out.triangles.emplace_back(q[0], q[1], q[2]);
        out.triangles.emplace_back(q[0], q[2], q[3]);
      }
      for (std::size_t i = 0; i < pool.numTriangles(); ++i) {
        const openvdb::Vec3I& t = pool.triangle(i);
        out.triangles.emplace_back(t[0], t[1], t[2]);
      }
    }
  } catch (const std::exception& e) {
    return Error{"tsdf_mesh.openvdb", std::string("OpenVDB mesher failed: ") + e.what()};
  }
  return Ok{};
}

}  // namespace tarmac::core
