#pragma once
/// @file The OpenVDB side of TsdfLayer, for the core's own TSDF .cpp files only (never include it
/// from a public header: an OpenVDB translation unit costs ~12 s and ~650 MB to compile).

#include <openvdb/openvdb.h>

#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

struct TsdfLayer::Grids {
  /// Signed distance, m; background (never observed) +truncation.
  openvdb::FloatGrid::Ptr distance;
  /// Weight (scans that observed the voxel, capped); background 0. Same topology as distance.
  openvdb::FloatGrid::Ptr weight;
};

/// Index-to-world transform of the lattice: index i ↦ centre (i + ½)·v of voxel [i·v, (i+1)·v).
openvdb::math::Transform::Ptr tsdf_transform(float voxel_size_m);

/// Empty grids named "tsdf" and "weight" with the lattice transform.
void make_tsdf_grids(float voxel_size_m, float truncation_m, TsdfLayer::Grids& grids);

}  // namespace tarmac::core
