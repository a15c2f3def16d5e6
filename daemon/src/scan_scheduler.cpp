#include "tarmac/daemon/scan_scheduler.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tarmac::daemon {

ScanScheduler::ScanScheduler(const SchedulerParams& params)
    : params_(params), slots_(params.max_pending + 1), newest_(params.max_age_ns.size(), 0) {
  order_.reserve(slots_.size());
  // Every channel a parsed cloud may carry, written once so its pages are faulted in now: the
  // slots rotate, so without this each of the first max_pending + 1 scans grows its own.
  const auto touch = [n = params.reserve_points](auto& v) {
    v.resize(n);
    v.clear();  // capacity kept
  };
  for (auto& s : slots_) {
    touch(s.cloud.points_S);
    touch(s.cloud.intensity);
    touch(s.cloud.ring);
    touch(s.cloud.time_offset_s);
    touch(s.cloud.no_return_S);
  }
}

bool ScanScheduler::before(std::uint32_t a, std::uint32_t b) const {
  const auto& sa = slots_[a];
  const auto& sb = slots_[b];
  if (sa.cloud.stamp_ns != sb.cloud.stamp_ns) return sa.cloud.stamp_ns < sb.cloud.stamp_ns;
  return sa.sensor < sb.sensor;
}

core::PointCloud& ScanScheduler::slot(ReasonCounters& drops) {
  std::uint32_t oldest = 0;
  bool any_pending = false;
  for (std::uint32_t i = 0; i < slots_.size(); ++i) {
    if (slots_[i].state == State::kFree || slots_[i].state == State::kStaged) {
      staged_ = i;
      slots_[i].state = State::kStaged;
      return slots_[i].cloud;
    }
    if (slots_[i].state == State::kPending && (!any_pending || before(i, oldest))) {
      oldest = i;
      any_pending = true;
    }
  }
  TARMAC_ASSERT(any_pending, "scan slots exhausted by selected scans");
  drops.add("scan.shed_pending_full");
  staged_ = oldest;
  slots_[oldest].state = State::kStaged;
  return slots_[oldest].cloud;
}

void ScanScheduler::commit(std::uint32_t sensor, std::int64_t tick_ns, ReasonCounters& rejections) {
  Slot& s = slots_[staged_];
  TARMAC_ASSERT(s.state == State::kStaged, "commit without slot()");
  s.state = State::kFree;
  const std::int64_t stamp = s.cloud.stamp_ns;
  if (stamp > tick_ns + params_.max_future_ns) {
    rejections.add("scan.future");
    return;
  }
  if (stamp < tick_ns - params_.max_age_ns[sensor]) {
    rejections.add("scan.stale");
    return;
  }
  if (have_last_ && (stamp < last_stamp_ || (stamp == last_stamp_ && sensor <= last_sensor_))) {
    rejections.add("scan.late");  // its place in the order has already been integrated
    return;
  }
  for (const auto& other : slots_) {
    if (other.state == State::kPending && other.sensor == sensor && other.cloud.stamp_ns == stamp) {
      rejections.add("scan.duplicate_stamp");
      return;
    }
  }
  s.sensor = sensor;
  s.state = State::kPending;
  newest_[sensor] = std::max(newest_[sensor], stamp);
}

std::size_t ScanScheduler::on_clock_step(std::int64_t tick_ns, ReasonCounters& rejections) {
  std::size_t rejected = 0;
  for (Slot& s : slots_) {
    if (s.state != State::kPending) continue;
    const std::int64_t stamp = s.cloud.stamp_ns;
    const char* reason = stamp > tick_ns + params_.max_future_ns          ? "scan.future"
                         : stamp < tick_ns - params_.max_age_ns[s.sensor] ? "scan.stale"
                                                                          : nullptr;
    if (reason == nullptr) continue;
    rejections.add(reason);
    s.state = State::kFree;
    ++rejected;
  }
  const std::int64_t future = tick_ns + params_.max_future_ns;
  if (have_last_ && last_stamp_ > future) have_last_ = false;
  for (auto& newest : newest_) {
    if (newest > future) newest = 0;
  }
  return rejected;
}

std::size_t ScanScheduler::pending() const {
  return static_cast<std::size_t>(std::count_if(
      slots_.begin(), slots_.end(), [](const Slot& s) { return s.state == State::kPending; }));
}

std::int64_t ScanScheduler::oldest_pending_stamp() const {
  std::int64_t oldest = std::numeric_limits<std::int64_t>::max();
  for (const Slot& s : slots_) {
    if (s.state == State::kPending) oldest = std::min(oldest, s.cloud.stamp_ns);
  }
  return oldest;
}

void ScanScheduler::decimate(core::PointCloud& cloud, TickStats& stats) const {
  // The quota counts rays: returns and beams without return (both are cast).
  const std::size_t n = cloud.size();
  const std::size_t m = cloud.no_return_S.size();
  if (n + m <= params_.points_per_scan) return;
  // Every k-th point and every k-th beam without return, k the smallest stride that fits the
  // quota: deterministic by index.
  const std::size_t q = params_.points_per_scan;
  const auto kept = [n, m](std::size_t stride) {
    return (n + stride - 1) / stride + (m + stride - 1) / stride;
  };
  std::size_t k = (n + m + q - 1) / q;
  // Each part rounds up: at most two more steps (a quota of 1 keeps one of each).
  while (kept(k) > q && k < n + m) ++k;
  std::size_t w = 0;
  for (std::size_t r = 0; r < n; r += k, ++w) {
    cloud.points_S[w] = cloud.points_S[r];
    if (cloud.has_intensity()) cloud.intensity[w] = cloud.intensity[r];
    if (cloud.has_ring()) cloud.ring[w] = cloud.ring[r];
    if (cloud.has_time()) cloud.time_offset_s[w] = cloud.time_offset_s[r];
  }
  cloud.points_S.resize(w);
  if (cloud.has_intensity()) cloud.intensity.resize(w);
  if (cloud.has_ring()) cloud.ring.resize(w);
  if (cloud.has_time()) cloud.time_offset_s.resize(w);
  std::size_t v = 0;
  for (std::size_t r = 0; r < m; r += k, ++v) cloud.no_return_S[v] = cloud.no_return_S[r];
  cloud.no_return_S.resize(v);
  stats.decimated_points += (n - w) + (m - v);
}

namespace {

/// Earliest and latest finite point time of `cloud` (s from its stamp); false when the sweep has
/// no extent (all equal, or none finite): nothing to compensate.
bool time_span(const core::PointCloud& cloud, double& t0_s, double& t1_s) {
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (const float t : cloud.time_offset_s) {
    if (!std::isfinite(t)) continue;
    lo = std::min(lo, t);
    hi = std::max(hi, t);
  }
  if (!(hi > lo)) return false;
  t0_s = lo;
  t1_s = hi;
  return true;
}

}  // namespace

ScanScheduler::TickStats ScanScheduler::select(std::int64_t tick_ns, const PoseBuffer& poses,
                                               std::vector<Selected>& out, ReasonCounters& drops) {
  TickStats stats;
  out.clear();
  order_.clear();
  for (std::uint32_t i = 0; i < slots_.size(); ++i) {
    if (slots_[i].state == State::kPending) order_.push_back(i);
  }
  std::sort(order_.begin(), order_.end(),
            [this](std::uint32_t a, std::uint32_t b) { return before(a, b); });
  const std::int64_t eligible_until = tick_ns - params_.input_delay_ns;
  std::uint64_t points = 0;
  for (std::size_t k = 0; k < order_.size(); ++k) {
    const std::uint32_t i = order_[k];
    Slot& s = slots_[i];
    const std::int64_t stamp = s.cloud.stamp_ns;
    if (stamp > eligible_until) break;  // the rest are later still
    Selected sel;
    sel.slot = i;
    sel.sensor = s.sensor;
    // The pose at the stamp, then (deskew) at the sweep's first and last point time; the first
    // lookup that fails decides, with the same rules for all three.
    PoseBuffer::Lookup found = poses.lookup(stamp, sel.T_W_B);
    double t0_s = 0.0, t1_s = 0.0;
    if (found == PoseBuffer::Lookup::kOk && s.sensor < params_.deskew.size() &&
        params_.deskew[s.sensor] && s.cloud.has_time() && time_span(s.cloud, t0_s, t1_s)) {
      // Compared as doubles: a time field in the wrong unit (e.g. absolute nanoseconds read as
      // seconds) would overflow an integer. Points far from the stamp are as bad as a long span.
      const double max_sweep_s = static_cast<double>(params_.max_sweep_ns) * 1e-9;
      if (t1_s - t0_s > max_sweep_s || std::max(std::abs(t0_s), std::abs(t1_s)) > max_sweep_s) {
        drops.add("scan.deskew_span");
      } else {
        sel.deskew = true;
        sel.motion.t0_s = t0_s;
        sel.motion.t1_s = t1_s;
        found = poses.lookup(stamp + static_cast<std::int64_t>(std::llround(t0_s * 1e9)),
                             sel.motion.T_W_B_0);
        if (found == PoseBuffer::Lookup::kOk) {
          found = poses.lookup(stamp + static_cast<std::int64_t>(std::llround(t1_s * 1e9)),
                               sel.motion.T_W_B_1);
        }
      }
    }
    if (found == PoseBuffer::Lookup::kNotYet) {
      if (eligible_until - stamp < params_.pose_wait_ns) break;  // wait, keep the order
      drops.add("scan.pose_timeout");
      s.state = State::kFree;
      continue;
    }
    if (found == PoseBuffer::Lookup::kTooOld) {
      drops.add("scan.pose_before_buffer");
      s.state = State::kFree;
      continue;
    }
    if (found == PoseBuffer::Lookup::kGap) {
      drops.add("scan.pose_gap");
      s.state = State::kFree;
      continue;
    }
    decimate(s.cloud, stats);
    const std::size_t rays = s.cloud.size() + s.cloud.no_return_S.size();
    if (!out.empty() && points + rays > params_.points_per_cycle) {
      stats.deferred_scans = order_.size() - k;  // this one and every later one wait
      break;
    }
    points += rays;
    s.state = State::kSelected;
    have_last_ = true;
    last_stamp_ = stamp;
    last_sensor_ = s.sensor;
    out.push_back(sel);
  }
  return stats;
}

}  // namespace tarmac::daemon
