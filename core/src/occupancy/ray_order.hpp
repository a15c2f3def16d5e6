#pragma once
/// @file The order in which the one-at-a-time and four-lane walks take a scan's rays: by
/// direction (internal to core/src/occupancy).

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/task_runner.hpp"

namespace tarmac::core::occupancy {

/// The one-at-a-time walk takes the rays in order of direction, not in the order the scan lists
/// them (the wide walk does not need it, see integrate). The walk's step is a branch on which
/// axis crosses next, and a ray's run of steps resembles those of the
/// rays beside it: walked one after another, the processor predicts most of them, even for
/// scans that interleave distant directions. The marks are the
/// same whatever the order, so this changes speed only. The order: cube-map face of the
/// direction (dominant axis and sign), band of the second minor coordinate, bin of the first.
constexpr int kDirBands = 16;  ///< bands per cube face
constexpr int kDirBins = 128;  ///< bins per band
constexpr std::size_t kDirBuckets = std::size_t{6} * kDirBands * kDirBins;

/// Fixed ranges of rays whose direction buckets are computed side by side (the buckets are most
/// of the sort's time).
constexpr std::size_t kBucketTasks = 4;

/// The scan's rays (returns, then beams without one) in order of direction bucket, stable (a
/// counting sort): `order` receives the ray indices. `bucket` and `count` are scratch.
void sort_rays_by_direction(const Eigen::Vector3d& origin_W,
                            std::span<const Eigen::Vector3f> points,
                            std::span<const Eigen::Vector3f> dirs,
                            std::vector<std::uint16_t>& bucket, std::vector<std::uint32_t>& count,
                            std::vector<std::uint32_t>& order, TaskRunner& runner);

}  // namespace tarmac::core::occupancy
