#include "pose_corrections.hpp"

#include <algorithm>
#include <cmath>

#include <spdlog/spdlog.h>

namespace tarmac::daemon {

PoseCorrections::PoseCorrections(const core::CorrectionParams& params, PoseBuffer& poses,
                                 core::Mapper& mapper)
    : enabled_(params.enabled), poses_(poses), mapper_(mapper), jumps_(params) {
  scratch_.reserve(1024);
  jumps_found_.reserve(8);
}

void PoseCorrections::on_pose(const transport::PoseSample& sample) {
  if (!enabled_) return;
  const auto delta = jumps_.feed({sample.stamp_ns, sample.T_W_B});
  if (!delta) return;
  const std::size_t rebased = poses_.rebase_before(sample.stamp_ns, *delta);
  jumps_found_.push_back({*delta, sample.stamp_ns, rebased});
}

void PoseCorrections::apply_jumps() {
  for (const Jump& j : jumps_found_) {
    const std::uint64_t revised = mapper_.correct_rigid(j.delta, j.stamp_ns);
    ++pose_jumps_;
    // Rare (a loop closure or a GPS fix), so one log line each.
    spdlog::warn(
        "corrections: pose jump at stamp {} ns ({:.3f} m, {:.2f} deg from the prediction): {} "
        "pose samples and {} retained scans re-expressed, rebuilding",
        j.stamp_ns, j.delta.translation().norm(),
        Eigen::AngleAxisd(j.delta.linear()).angle() * 180.0 / M_PI, j.rebased, revised);
  }
  jumps_found_.clear();
}

void PoseCorrections::apply(std::int64_t made_ns, std::span<const transport::PoseSample> samples) {
  scratch_.clear();
  for (const auto& p : samples) scratch_.push_back({p.stamp_ns, p.T_W_B});
  const std::size_t replaced = poses_.apply_trajectory(scratch_, made_ns);
  const std::uint64_t revised = mapper_.correct_trajectory(scratch_);
  // Later live samples are predicted from the corrected ones.
  reset_prediction();
  ++trajectories_;
  spdlog::warn(
      "corrections: corrected trajectory of {} poses ({} .. {} ns): {} pose samples and {} "
      "retained scans revised{}",
      samples.size(), samples.front().stamp_ns, samples.back().stamp_ns, replaced, revised,
      revised > 0 ? ", rebuilding" : " (none retained in its span: nothing to rebuild)");
}

void PoseCorrections::queue_trajectory(std::int64_t stamp_ns,
                                       std::span<const transport::PoseSample> samples,
                                       std::int64_t newest_integrated_ns) {
  if (newest_integrated_ns > stamp_ns) {
    spdlog::warn(
        "corrections: trajectory made at stamp {} ns arrived after scan {} ns was integrated: "
        "applied now, out of stamp order",
        stamp_ns, newest_integrated_ns);
    ++late_;
    apply(stamp_ns, samples);
    return;
  }
  auto at = std::upper_bound(pending_.begin(), pending_.end(), stamp_ns,
                             [](std::int64_t t, const Pending& c) { return t < c.stamp_ns; });
  pending_.insert(at, Pending{stamp_ns, {samples.begin(), samples.end()}});
}

void PoseCorrections::apply_before(std::int64_t stamp_ns) {
  std::size_t n = 0;
  while (n < pending_.size() && pending_[n].stamp_ns < stamp_ns) {
    apply(pending_[n].stamp_ns, pending_[n].samples);
    ++n;
  }
  if (n > 0) pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(n));
}

std::size_t PoseCorrections::drop_after(std::int64_t stamp_ns) {
  std::size_t dropped = 0;
  while (!pending_.empty() && pending_.back().stamp_ns > stamp_ns) {
    pending_.pop_back();  // sorted by stamp
    ++dropped;
  }
  return dropped;
}

void PoseCorrections::reset_prediction() {
  core::StampedPose tail[2];
  jumps_.reset(std::span<const core::StampedPose>(tail, poses_.newest_two(tail)));
}

PoseCorrections::Counts PoseCorrections::counts() const {
  return {pose_jumps_.load(), trajectories_.load(), late_.load()};
}

}  // namespace tarmac::daemon
