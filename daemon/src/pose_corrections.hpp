#pragma once
/// @file The executor's side of pose corrections (DESIGN.md §4, docs/pose_corrections.md): a
/// jump in the live pose stream is taken as a rigid correction, applied to the map before the
/// tick's first scan; a corrected trajectory waits for its place in the stamp order. Either
/// revises the pose buffer and the mapper's retained scans, and the mapper rebuilds its window
/// (the tick's rebuild stage). The drain step only detects and queues: the map changes in the
/// mapping step.

#include <atomic>
#include <cstdint>
#include <span>
#include <vector>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/pose_correction.hpp"
#include "tarmac/daemon/pose_buffer.hpp"
#include "tarmac/transport/inputs.hpp"

namespace tarmac::daemon {

class PoseCorrections {
 public:
  struct Counts {
    std::uint64_t pose_jumps = 0;
    std::uint64_t trajectories = 0;  ///< corrected trajectories applied
    std::uint64_t late = 0;          ///< of those, applied out of stamp order
  };

  /// `poses` and `mapper` are revised by the corrections and must outlive this.
  PoseCorrections(const core::CorrectionParams& params, PoseBuffer& poses, core::Mapper& mapper);

  /// A sample just taken into the pose buffer: one farther than the thresholds from the
  /// prediction is a jump. The samples before it are re-expressed in the corrected frame
  /// (T ← Δ · T) at once, so the scans selected this tick take poses in that frame; the
  /// mapper's retained scans by apply_jumps(). Nothing when corrections are disabled.
  void on_pose(const transport::PoseSample& sample);
  /// The jumps found since the last call, applied to the mapper's retained scans in the order
  /// found. Before the tick's first scan: every scan integrated after it has its pose in the
  /// corrected frame.
  void apply_jumps();

  /// A corrected trajectory made at `stamp_ns` waits for its place in the stamp order
  /// (DESIGN.md §3): it is applied after every scan stamped up to `stamp_ns` and before any
  /// later one, whenever it arrived within the input delay. One that arrives after a later scan
  /// was integrated (`newest_integrated_ns` > `stamp_ns`) is applied at once (still a full
  /// rebuild) and counted as late.
  void queue_trajectory(std::int64_t stamp_ns, std::span<const transport::PoseSample> samples,
                        std::int64_t newest_integrated_ns);
  [[nodiscard]] bool pending() const { return !pending_.empty(); }
  /// Applies, in stamp order, the queued corrections stamped before `stamp_ns`.
  void apply_before(std::int64_t stamp_ns);

  /// After a backward step of the stamp clock: forgets the queued corrections stamped after
  /// `stamp_ns` (by the old clock); returns how many.
  std::size_t drop_after(std::int64_t stamp_ns);
  /// The pose buffer's newest samples changed other than by a jump: later live samples are
  /// predicted from the buffer's two newest.
  void reset_prediction();

  /// Thread-safe.
  [[nodiscard]] Counts counts() const;

 private:
  struct Jump {
    Eigen::Isometry3d delta;
    std::int64_t stamp_ns = 0;
    std::size_t rebased = 0;  ///< pose samples re-expressed
  };
  /// The pose samples `samples` covers are replaced (newer ones re-expressed by the correction
  /// at its end), the mapper's retained scans within it take the revised poses and the rebuild
  /// starts.
  void apply(std::int64_t made_ns, std::span<const transport::PoseSample> samples);

  struct Pending {
    std::int64_t stamp_ns = 0;
    std::vector<transport::PoseSample> samples;
  };

  bool enabled_;
  PoseBuffer& poses_;
  core::Mapper& mapper_;
  core::PoseJumpDetector jumps_;
  std::vector<core::StampedPose> scratch_;
  std::vector<Pending> pending_;   ///< by stamp; corrections are rare
  std::vector<Jump> jumps_found_;  ///< since the last apply_jumps()
  std::atomic<std::uint64_t> pose_jumps_{0}, trajectories_{0}, late_{0};
};

}  // namespace tarmac::daemon
