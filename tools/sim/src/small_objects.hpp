#pragma once
/// @file tarmac-sim's small_objects.txt: the small static objects of a scene (cones, debris,
/// poles, landing gear) and the returns each gave per scan, for a score per object (issue 39:
/// first scan with two returns, first lethal, cycles held).

#include <map>
#include <string>
#include <utility>

#include <Eigen/Geometry>

#include "tarmac/sim/scene.hpp"

namespace tarmac::sim {

/// Whether `o` is a small static object whose own score the safety score keeps: not ground or a
/// curb, at most 1 m across in x and y.
bool small_object(const Object& o);

/// small_objects.txt's text: each small object's bounds in the poses' world frame (the box round
/// its scene-frame box's corners, T_O_W), then per scan the returns each gave (`returns`: (scan,
/// object id) -> count; scans without any left out). "" when the scene has none.
std::string small_objects_file(const Scene& scene, const Eigen::Isometry3d& T_O_W,
                               const std::map<std::pair<int, int>, int>& returns);

}  // namespace tarmac::sim
