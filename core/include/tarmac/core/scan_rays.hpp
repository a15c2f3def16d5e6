#pragma once
/// @file The rays of one scan, binned by direction from the scan's origin, to answer one
/// question fast: does any ray of this scan pass through a given box and go on beyond it?
/// OccupancyMap asks it for occupied voxels that a ray walk marked: a miss counts only when a
/// ray passed through the part of the voxel its returns came from (the "returns' extent"), not
/// when it only crossed the voxel's empty part (a ray grazing under an aircraft's belly crosses
/// the bottom of the voxel that holds the belly surface).

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace tarmac::core {

/// Built once per scan (RT-safe after the first scans: storage is kept), then queried from any
/// number of threads (the queries are const).
class ScanRays {
 public:
  /// Rays from `origin_W`: every finite return within `max_range_m` (a segment ending at it),
  /// every finite return beyond it and every beam without a return in `dirs_W` (segments of
  /// `clear_range_m`; none when that is 0), as OccupancyMap walks them.
  void build(const Eigen::Vector3d& origin_W, std::span<const Eigen::Vector3f> points_W,
             std::span<const Eigen::Vector3f> dirs_W, double max_range_m, double clear_range_m);

  /// True when some ray passes through the box [lo_W, hi_W] (closed) and goes on beyond it: a
  /// return's ray must end more than `behind_m` past the point where it leaves the box (a ray
  /// that hits the same surface just after the box has not shown the box empty); a beam without
  /// a return must leave the box before its clearing range ends. Exact per ray (a slab test in
  /// the origin's frame); the binning only selects which rays are tested.
  /// With `measured_only`, beams without a return (dirs_W) are left out: only rays that ended
  /// at a return, within range or beyond it, count.
  [[nodiscard]] bool any_passes(const Eigen::Vector3d& lo_W, const Eigen::Vector3d& hi_W,
                                double behind_m, bool measured_only = false) const;

  [[nodiscard]] std::size_t size() const { return rays_.size(); }
  [[nodiscard]] std::size_t memory_bytes() const;

  /// Bins: pseudo-azimuth (the "diamond angle" of x, y: monotonic in the angle, no trigonometry)
  /// by the sine of the elevation (z / range).
  static constexpr int kAzBins = 1024;
  static constexpr int kElBins = 256;

 private:
  struct Ray {
    Eigen::Vector3f end;  ///< end point relative to the origin
    float length_m;       ///< |end|
    bool returned;        ///< ends at a return (else a clearing segment)
    bool measured;        ///< from a return (within range or beyond), not a beam without one
  };
  [[nodiscard]] bool ray_passes(const Ray& r, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                                double behind_m) const;

  Eigen::Vector3d origin_W_ = Eigen::Vector3d::Zero();
  std::vector<Ray> rays_;                 ///< in bin order
  std::vector<std::uint32_t> bin_first_;  ///< rays_[bin_first_[b] .. bin_first_[b + 1])
  std::vector<std::uint32_t> ray_bin_;    ///< scratch: each candidate ray's bin
  std::vector<Ray> unsorted_;             ///< scratch
};

}  // namespace tarmac::core
