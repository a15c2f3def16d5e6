#pragma once
/// @file A time-indexed ring of vehicle poses (T_map_base) with interpolation: linear in
/// translation, slerp in rotation. The executor looks up each scan's pose at the scan's stamp;
/// nothing is extrapolated. Fixed capacity, no allocation after construction (RT-safe).

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/pose_correction.hpp"
#include "tarmac/transport/inputs.hpp"

namespace tarmac::daemon {

class PoseBuffer {
 public:
  enum class Insert { kOk, kOutOfOrder, kDuplicate };
  enum class Lookup {
    kOk,      ///< T_W_B filled
    kNotYet,  ///< no pose at or after the stamp yet (it may still come)
    kTooOld,  ///< the stamp lies before the oldest pose kept
    kGap,     ///< the poses around the stamp are further apart than max_gap_ns
  };

  /// @pre capacity >= 2, max_gap_ns > 0
  PoseBuffer(std::size_t capacity, std::int64_t max_gap_ns);

  /// Appends a pose; stamps must increase strictly (older or equal ones are refused, so the
  /// buffer stays sorted and a replayed sample cannot change an earlier answer). RT-safe.
  Insert insert(const transport::PoseSample& sample);

  /// T_W_B at `stamp_ns`: the sample itself when a pose has exactly that stamp, otherwise
  /// interpolated between its neighbours. RT-safe.
  Lookup lookup(std::int64_t stamp_ns, Eigen::Isometry3d& T_W_B) const;

  /// Re-expresses every sample stamped before `before_stamp_ns` in a corrected frame
  /// (T ← delta · T): after a jump in the pose stream (a pose-graph correction), scans stamped
  /// before it are then looked up in the same frame as the rebuilt map. Returns the samples
  /// changed. RT-safe.
  std::size_t rebase_before(std::int64_t before_stamp_ns, const Eigen::Isometry3d& delta);

  /// A corrected trajectory (sorted by stamp) made at `made_ns`: every sample within its span
  /// takes the trajectory's pose at its stamp (interpolated), and the newer samples up to
  /// `made_ns` are re-expressed by the correction at the trajectory's end (delta =
  /// T_corrected · T_old⁻¹ there, T_old looked up in this buffer; when it cannot be looked up
  /// they are left alone). Samples after `made_ns` came from the corrected localiser and are
  /// kept. Returns the samples changed. RT-safe.
  std::size_t apply_trajectory(std::span<const core::StampedPose> trajectory, std::int64_t made_ns);
  /// Removes every sample stamped after `stamp_ns` (after a backward step of the stamp clock
  /// they come from the old clock, and would refuse every new sample as out of order). Returns
  /// how many. RT-safe.
  std::size_t drop_after(std::int64_t stamp_ns);
  /// The newest min(2, size()) samples, oldest first, into `out`; returns how many.
  std::size_t newest_two(core::StampedPose (&out)[2]) const;

  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] std::optional<std::int64_t> newest_stamp() const;

 private:
  [[nodiscard]] const transport::PoseSample& at(std::size_t i) const {  // 0 = oldest
    return ring_[(head_ + i) % ring_.size()];
  }

  std::vector<transport::PoseSample> ring_;
  std::size_t head_ = 0;  ///< index of the oldest sample
  std::size_t size_ = 0;
  std::int64_t max_gap_ns_;
};

}  // namespace tarmac::daemon
