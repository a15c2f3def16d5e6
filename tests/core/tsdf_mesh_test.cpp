#include "tarmac/core/tsdf_mesh.hpp"

#include <cmath>

#include <gtest/gtest.h>

namespace tarmac::core {
namespace {

// A sphere of radius R around the sensor, seen from its centre: the mesh of the zero crossing
// must lie on the sphere. Dual contouring places each vertex inside its cell on the linear
// interpolation of exact distances; the sphere's curvature over one 0.1 m cell at R = 3 m
// bends it by at most (√3·v)²/(8R) ≈ 1.3 mm, so 5 mm is a safe bound; no vertex may come from the
// band's back edge (0.3 m behind) next to never-observed space.
TEST(TsdfMesh, Sphere_VerticesLieOnTheSphere) {
  TsdfParams params;
  TsdfIntegrator integrator(params);
  TsdfLayer layer = integrator.make_layer();
  const Eigen::Vector3d o(0.537, -1.213, 0.771);
  const double R = 3.0;
  std::vector<Eigen::Vector3f> pts;
  const int n = 60000;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - z * z);
    pts.push_back((o + R * Eigen::Vector3d(r * std::cos(golden * i), r * std::sin(golden * i), z))
                      .cast<float>());
  }
  SerialRunner runner;
  integrator.integrate(o, pts, layer, runner);
  TriangleMesh mesh;
  ASSERT_TRUE(extract_mesh(layer, 1.0f, mesh).ok());
  // Area of the sphere / area per vertex (about one vertex per 0.1 m × 0.1 m of surface).
  ASSERT_GT(mesh.vertices_W.size(), 4 * M_PI * R * R / 0.01 * 0.8);
  ASSERT_GT(mesh.triangles.size(), mesh.vertices_W.size());
  double max_err = 0.0;
  for (const auto& p : mesh.vertices_W) {
    max_err = std::max(max_err, std::abs((p.cast<double>() - o).norm() - R));
  }
  EXPECT_LT(max_err, 0.005);
  for (const auto& t : mesh.triangles) {
    for (int a = 0; a < 3; ++a) {
      ASSERT_GE(t[a], 0);
      ASSERT_LT(static_cast<std::size_t>(t[a]), mesh.vertices_W.size());
    }
  }
}

TEST(TsdfMesh, Empty_GivesNoTriangles) {
  TsdfLayer layer(0.1f, 0.3f);
  TriangleMesh mesh;
  ASSERT_TRUE(extract_mesh(layer, 1.0f, mesh).ok());
  EXPECT_TRUE(mesh.vertices_W.empty());
  EXPECT_TRUE(mesh.triangles.empty());
  EXPECT_FALSE(extract_mesh(layer, -1.0f, mesh).ok());
}

}  // namespace
}  // namespace tarmac::core
