#include "tarmac/daemon/pose_buffer.hpp"

#include "tarmac/core/assert.hpp"
#include "tarmac/core/deskew.hpp"

namespace tarmac::daemon {

PoseBuffer::PoseBuffer(std::size_t capacity, std::int64_t max_gap_ns)
    : ring_(capacity), max_gap_ns_(max_gap_ns) {
  TARMAC_ASSERT(capacity >= 2 && max_gap_ns > 0, "PoseBuffer needs capacity >= 2 and a gap");
}

PoseBuffer::Insert PoseBuffer::insert(const transport::PoseSample& sample) {
  if (size_ > 0) {
    const std::int64_t newest = at(size_ - 1).stamp_ns;
    if (sample.stamp_ns == newest) return Insert::kDuplicate;
    if (sample.stamp_ns < newest) return Insert::kOutOfOrder;
  }
  if (size_ == ring_.size()) {
    ring_[head_] = sample;  // overwrite the oldest
    head_ = (head_ + 1) % ring_.size();
  } else {
    ring_[(head_ + size_) % ring_.size()] = sample;
    ++size_;
  }
  return Insert::kOk;
}

std::optional<std::int64_t> PoseBuffer::newest_stamp() const {
  if (size_ == 0) return std::nullopt;
  return at(size_ - 1).stamp_ns;
}

PoseBuffer::Lookup PoseBuffer::lookup(std::int64_t stamp_ns, Eigen::Isometry3d& T_W_B) const {
  if (size_ == 0 || at(size_ - 1).stamp_ns < stamp_ns) return Lookup::kNotYet;
  if (stamp_ns < at(0).stamp_ns) return Lookup::kTooOld;
  // First sample with stamp >= stamp_ns (binary search over the sorted ring).
  std::size_t lo = 0, hi = size_ - 1;
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (at(mid).stamp_ns < stamp_ns) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  const auto& b = at(lo);
  if (b.stamp_ns == stamp_ns) {
    T_W_B = b.T_W_B;  // exact: no arithmetic, so a pose sampled at the scan stamp is used as is
    return Lookup::kOk;
  }
  const auto& a = at(lo - 1);  // lo > 0: at(0).stamp_ns < stamp_ns here
  const std::int64_t span = b.stamp_ns - a.stamp_ns;
  if (span > max_gap_ns_) return Lookup::kGap;
  const double t = static_cast<double>(stamp_ns - a.stamp_ns) / static_cast<double>(span);
  T_W_B = core::interpolate_pose(a.T_W_B, b.T_W_B, t);
  return Lookup::kOk;
}

std::size_t PoseBuffer::rebase_before(std::int64_t before_stamp_ns,
                                      const Eigen::Isometry3d& delta) {
  std::size_t changed = 0;
  for (std::size_t i = 0; i < size_; ++i) {
    auto& s = ring_[(head_ + i) % ring_.size()];
    if (s.stamp_ns >= before_stamp_ns) break;  // sorted
    s.T_W_B = delta * s.T_W_B;
    ++changed;
  }
  return changed;
}

std::size_t PoseBuffer::apply_trajectory(std::span<const core::StampedPose> trajectory,
                                         std::int64_t made_ns) {
  if (trajectory.empty()) return 0;
  const core::StampedPose& end = trajectory.back();
  Eigen::Isometry3d T_old_end;
  const bool have_end = lookup(end.stamp_ns, T_old_end) == Lookup::kOk;
  const Eigen::Isometry3d delta_end =
      have_end ? end.T_W_B * T_old_end.inverse() : Eigen::Isometry3d::Identity();
  std::size_t changed = 0;
  for (std::size_t i = 0; i < size_; ++i) {
    auto& s = ring_[(head_ + i) % ring_.size()];
    if (s.stamp_ns < trajectory.front().stamp_ns) continue;
    if (s.stamp_ns <= end.stamp_ns) {
      s.T_W_B = *core::interpolate_pose(trajectory, s.stamp_ns);  // within the span: defined
    } else if (have_end && s.stamp_ns <= made_ns) {
      s.T_W_B = delta_end * s.T_W_B;
    } else {
      continue;
    }
    ++changed;
  }
  return changed;
}

std::size_t PoseBuffer::drop_after(std::int64_t stamp_ns) {
  std::size_t dropped = 0;
  while (size_ > 0 && at(size_ - 1).stamp_ns > stamp_ns) {  // sorted: the newest go first
    --size_;
    ++dropped;
  }
  return dropped;
}

std::size_t PoseBuffer::newest_two(core::StampedPose (&out)[2]) const {
  const std::size_t n = std::min<std::size_t>(size_, 2);
  for (std::size_t k = 0; k < n; ++k) {
    const auto& s = at(size_ - n + k);
    out[k] = {s.stamp_ns, s.T_W_B};
  }
  return n;
}

}  // namespace tarmac::daemon
