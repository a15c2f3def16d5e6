#pragma once
/// @file The per-voxel update of the occupancy map (internal to core/src/occupancy): log-odds
/// with clamping (Hornung et al., "OctoMap", Autonomous Robots 2013, eq. 2–3), the static-layer
/// state byte and the lowest return inside a voxel. The passes in integrate.cpp apply these to
/// every voxel a scan touches; the lane code there does the same arithmetic four at a time.

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "tarmac/core/occupancy_map.hpp"

namespace tarmac::core::occupancy {

/// A hit: L ← clamp(L + l_hit, l_min, l_max); unknown counts as 0 (probability 0.5).
inline float after_hit(float l, float l_hit, float l_min, float l_max) {
  return std::clamp((l == OccupancyMap::kUnknown ? 0.0f : l) + l_hit, l_min, l_max);
}

/// A miss of a voxel reading free or unknown: L ← max(L + l_miss, l_min) (the upper clamp
/// cannot apply: a miss only lowers).
inline float after_miss(float l, float l_miss, float l_min) {
  return std::max((l == OccupancyMap::kUnknown ? 0.0f : l) + l_miss, l_min);
}

/// The state byte per voxel (OccupancyMap::state_): the static flag, and a count — of scans
/// in a row with a return while not static (promotion), of scans in a row without one while
/// static (demotion).
constexpr std::uint8_t kStatic = 0x80;
constexpr std::uint8_t kCount = 0x7f;

/// Scans (with a return, the voxel reading occupied since) that a voxel leaving the window
/// needs to join the static layer: one return alone may be noise.
constexpr std::uint8_t kKeepHits = 2;

/// OccupancyMap::hit_floor_: the lowest return inside a voxel, in 32nds of the voxel's height.
constexpr int kFloorSteps = 32;
constexpr std::uint8_t kNoHitFloor = 0xff;

/// Where coordinate c (m) lies inside its voxel of size v (m), in 32nds: 0..31.
inline std::uint8_t sub_voxel(float c, double v) {
  const double u = static_cast<double>(c) / v;
  return static_cast<std::uint8_t>(
      std::clamp(static_cast<int>((u - std::floor(u)) * kFloorSteps), 0, kFloorSteps - 1));
}

}  // namespace tarmac::core::occupancy
