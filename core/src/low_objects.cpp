#include "tarmac/core/low_objects.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>

namespace tarmac::core {

Status LowObjectParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) {
    return Error{"config.range", "low_objects." + key + ": " + why};
  };
  if (!(min_rise_m > 0.0 && min_rise_m <= 2.5)) return bad("min_rise_m", "must be in (0, 2.5]");
  if (!(max_rise_m >= min_rise_m && max_rise_m <= 2.55)) {
    return bad("max_rise_m", "must be in [min_rise_m, 2.55]");
  }
  if (!(match_radius_m > 0.0 && match_radius_m <= 1.0)) {
    return bad("match_radius_m", "must be in (0, 1]");
  }
  if (!(clear_radius_m > 0.0 && clear_radius_m <= match_radius_m)) {
    return bad("clear_radius_m", "must be in (0, match_radius_m]");
  }
  if (confirm_returns < 1 || confirm_returns > 1000) {
    return bad("confirm_returns", "must be in [1, 1000]");
  }
  if (lethal_returns < 1 || lethal_returns > confirm_returns) {
    return bad("lethal_returns", "must be in [1, confirm_returns]");
  }
  if (clear_scans < 1 || clear_scans > 100) return bad("clear_scans", "must be in [1, 100]");
  if (candidate_scans < 1 || candidate_scans > 1000) {
    return bad("candidate_scans", "must be in [1, 1000]");
  }
  if (capacity < 0 || capacity > 1'000'000) return bad("capacity", "must be in [0, 1e6]");
  return Ok{};
}

LowObjects::LowObjects(const LowObjectParams& params, int nx, int ny, double voxel_m)
    : params_(params), nx_(nx), ny_(ny), v_(static_cast<float>(voxel_m)) {
  const auto columns = static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny);
  head_.assign(columns, kNone);
  near_.assign(columns, 0);
  const auto cap = static_cast<std::size_t>(params.capacity);
  objects_.reserve(cap);
  next_.reserve(cap);
  indexed_column_.reserve(cap);
  touched_.reserve(cap);
  saw_through_.reserve(cap);
  // A scan's rising returns: room for a 64 × 1024 sweep of which every return rose, so the
  // update never grows it on the executor's threads for such sensors (256 KiB).
  rising_.reserve(std::size_t{64} * 1024);
}

std::size_t LowObjects::memory_bytes() const {
  return objects_.capacity() * sizeof(LowObject) +
         (head_.capacity() + next_.capacity() + indexed_column_.capacity()) *
             sizeof(std::uint32_t) +
         near_.capacity() + touched_.capacity() + saw_through_.capacity() +
         rising_.capacity() * sizeof(std::uint32_t);
}

void LowObjects::clear() {
  objects_.clear();
  min_x_ = min_y_ = 0;
}

std::int64_t LowObjects::column_of(const Eigen::Vector2f& xy) const {
  const auto x = static_cast<std::int64_t>(std::floor(xy.x() / v_)) - min_x_;
  const auto y = static_cast<std::int64_t>(std::floor(xy.y() / v_)) - min_y_;
  if (x < 0 || y < 0 || x >= nx_ || y >= ny_) return -1;
  return y * nx_ + x;
}

void LowObjects::place(int min_x, int min_y) {
  min_x_ = min_x;
  min_y_ = min_y;
  std::erase_if(objects_, [this](const LowObject& o) { return column_of(o.xy_W) < 0; });
}

void LowObjects::add_to_index(std::uint32_t k) {
  // The column is kept: evidence() moves the centre, possibly into the next column.
  const auto c = static_cast<std::size_t>(column_of(objects_[k].xy_W));
  indexed_column_[k] = static_cast<std::uint32_t>(c);
  next_[k] = head_[c];
  head_[c] = k;
  flag_reach(c, 1);
}

void LowObjects::flag_reach(std::size_t c, std::uint8_t value) {
  const int cx = static_cast<int>(c % static_cast<std::size_t>(nx_));
  const int cy = static_cast<int>(c / static_cast<std::size_t>(nx_));
  for (int y = std::max(0, cy - kReach); y <= std::min(ny_ - 1, cy + kReach); ++y) {
    for (int x = std::max(0, cx - kReach); x <= std::min(nx_ - 1, cx + kReach); ++x) {
      near_[static_cast<std::size_t>(y) * nx_ + x] = value;
    }
  }
}

void LowObjects::index() {
  const std::size_t n = objects_.size();
  next_.assign(n, kNone);
  indexed_column_.assign(n, 0);
  touched_.assign(n, 0);
  saw_through_.assign(n, 0);
  for (std::uint32_t k = 0; k < n; ++k) add_to_index(k);
}

void LowObjects::unindex() {
  for (const std::uint32_t col : indexed_column_) {
    const auto c = static_cast<std::size_t>(col);
    head_[c] = kNone;
    flag_reach(c, 0);
  }
}

std::uint32_t LowObjects::nearest(const Eigen::Vector2f& xy, std::int64_t column) const {
  const int cx = static_cast<int>(column % nx_);
  const int cy = static_cast<int>(column / nx_);
  const float r2 = static_cast<float>(params_.match_radius_m * params_.match_radius_m);
  std::uint32_t best = kNone;
  float best_d2 = r2;
  for (int y = std::max(0, cy - 1); y <= std::min(ny_ - 1, cy + 1); ++y) {
    for (int x = std::max(0, cx - 1); x <= std::min(nx_ - 1, cx + 1); ++x) {
      for (std::uint32_t k = head_[static_cast<std::size_t>(y) * nx_ + x]; k != kNone;
           k = next_[k]) {
        const float d2 = (objects_[k].xy_W - xy).squaredNorm();
        // Ties go to the lower index: the result does not depend on the lists' order.
        if (d2 < best_d2 || (d2 == best_d2 && k < best)) {
          best = k;
          best_d2 = d2;
        }
      }
    }
  }
  return best;
}

void LowObjects::evidence(std::uint32_t k, const Eigen::Vector3f& p, float rise_m,
                          const Scan& scan) {
  LowObject& o = objects_[k];
  // The centre follows the returns, each weighing as much as the (at most 15) before it.
  const float w = 1.0f / static_cast<float>(std::min<std::uint32_t>(o.returns, 15) + 1);
  o.xy_W += w * (p.head<2>() - o.xy_W);
  if (rise_m > o.rise_m) {
    o.rise_m = rise_m;
    o.top_z_W = p.z();
  }
  if (o.returns == 0 || o.last_scan != scan.number) ++o.scans;
  ++o.returns;
  o.last_scan = scan.number;
  o.last_ns = scan.stamp_ns;
  o.seen_through = 0;
  touched_[k] = 1;
}

bool LowObjects::sees_through(const LowObject& o, const Eigen::Vector3f& origin,
                              const Eigen::Vector3f& q, const Eigen::Vector3f& up) const {
  const Eigen::Vector2f a = origin.head<2>();
  const Eigen::Vector2f d = q.head<2>() - a;
  const float len2 = d.squaredNorm();
  if (len2 <= 0.0f) return false;
  const float t = (o.xy_W - a).dot(d) / len2;
  // It went on past the centre (its rising returns: the face or top the beams met) by more
  // than range noise; a beam just under the front edge ends in front of it.
  constexpr float kRangeNoise = 0.03f;
  const float len = std::sqrt(len2);
  if (t <= 0.0f || (1.0f - t) * len < kRangeNoise) return false;
  const Eigen::Vector3f p = origin + t * (q - origin);
  if ((p.head<2>() - o.xy_W).squaredNorm() >
      static_cast<float>(params_.clear_radius_m * params_.clear_radius_m)) {
    return false;
  }
  // Under its top by a margin (range noise), measured along the scan's up axis.
  const Eigen::Vector3f top(o.xy_W.x(), o.xy_W.y(), o.top_z_W);
  return up.dot(p - top) < -0.02f;
}

bool LowObjects::ground_at_top(const LowObject& o, const Scan& scan, std::size_t i) const {
  // A return on the ground (rising at most kOnGroundCm above it), on the object's spot and as
  // high as its top less kTopBandM: the ground here lies within min_rise of its top, so nothing
  // stands on it that rises min_rise. A glossy floor's mirror returns under the floor lower one
  // scan's ground and make the floor itself rise; the next scans find the floor where those
  // tops are. A return on a real object's face lies above the ground, and one on its top
  // rises (touched: no clearing this scan). The ground is the lower of the scan's and the one
  // remembered round the spot: a kerb's top seen from behind, its road not returned, lies on
  // the scan's ground alone.
  constexpr int kOnGroundCm = 3;
  constexpr float kTopBandM = 0.04f;
  constexpr float kSpotM = 0.08f;
  const Eigen::Vector3f& p = scan.points_W[i];
  if (scan.rise_cm[i] > kOnGroundCm || (p.head<2>() - o.xy_W).squaredNorm() > kSpotM * kSpotM) {
    return false;
  }
  const Eigen::Vector3f top(o.xy_W.x(), o.xy_W.y(), o.top_z_W);
  if (scan.up_W.dot(p - top) < -kTopBandM) return false;
  return scan.ground == nullptr || scan.up_W.dot(p) - scan.ground->ground_z(scan.column[i]) <
                                       static_cast<float>(kOnGroundCm + 1) * 0.01f;
}

void LowObjects::expire(const Scan& scan) {
  std::size_t out = 0;
  for (std::size_t k = 0; k < objects_.size(); ++k) {
    LowObject o = objects_[k];
    // A scan that neither saw through it nor returned from it keeps the count: a run is broken
    // only by a rising return (evidence()).
    if (saw_through_[k] != 0 && touched_[k] == 0) ++o.seen_through;
    const bool gone = o.seen_through >= params_.clear_scans;
    const bool lapsed = !confirmed(o) && scan.number - o.last_scan >=
                                             static_cast<std::uint32_t>(params_.candidate_scans);
    if (!gone && !lapsed) objects_[out++] = o;
  }
  objects_.resize(out);
}

void LowObjects::update(const Scan& scan) {
  index();
  const float min_rise = static_cast<float>(params_.min_rise_m);
  const float max_rise = static_cast<float>(params_.max_rise_m);
  const auto min_cm = static_cast<int>(std::ceil(params_.min_rise_m * 100.0 - 1e-6));
  const auto max_cm = static_cast<int>(std::floor(params_.max_rise_m * 100.0 + 1e-6));
  const auto rising = [&](std::size_t i) {
    const int rise = scan.rise_cm[i];
    return scan.voxel[i] != Scan::kNoColumn && rise >= min_cm && rise <= max_cm;
  };
  // 1. The rising returns, in an order of their own (by x, y, z): which object a return joins
  //    and where it moves the centre depend on the order they come in, and a driver's layout
  //    (rows by beam or by firing, or a list) must not change the map.
  rising_.clear();
  for (std::size_t i = 0; i < scan.points_W.size(); ++i) {
    if (rising(i)) rising_.push_back(static_cast<std::uint32_t>(i));
  }
  std::sort(rising_.begin(), rising_.end(), [&](std::uint32_t a, std::uint32_t b) {
    const Eigen::Vector3f &p = scan.points_W[a], &q = scan.points_W[b];
    return std::tie(p.x(), p.y(), p.z()) < std::tie(q.x(), q.y(), q.z());
  });
  for (const std::uint32_t i : rising_) {
    const Eigen::Vector3f& p = scan.points_W[i];
    const Eigen::Vector2f xy = p.head<2>();
    const std::int64_t column = column_of(xy);
    if (column < 0) continue;
    const float rise_m = static_cast<float>(scan.rise_cm[i]) * 0.01f;
    std::uint32_t k = nearest(xy, column);
    if (k == kNone) {
      if (objects_.size() >= static_cast<std::size_t>(params_.capacity)) {
        ++refused_;
        continue;
      }
      k = static_cast<std::uint32_t>(objects_.size());
      LowObject o;
      o.id = next_id_++;
      o.xy_W = xy;
      o.top_z_W = p.z();
      o.rise_m = rise_m;
      o.first_scan = scan.number;
      o.first_ns = scan.stamp_ns;
      objects_.push_back(o);
      next_.push_back(kNone);
      indexed_column_.push_back(0);
      touched_.push_back(0);
      saw_through_.push_back(0);
      add_to_index(k);
    }
    evidence(k, p, std::clamp(rise_m, min_rise, max_rise), scan);
  }
  // 2. The other returns near an object: does its ray show the object gone? Only an object no
  //    rising return touched this scan can be seen through (expire()), and its centre did not
  //    move in step 1, so their order does not matter.
  for (std::size_t i = 0; i < scan.points_W.size(); ++i) {
    if (scan.voxel[i] == Scan::kNoColumn || rising(i) || near_[scan.column[i]] == 0) continue;
    const Eigen::Vector3f& p = scan.points_W[i];
    const std::int64_t column = column_of(p.head<2>());
    if (column < 0) continue;
    const int cx = static_cast<int>(column % nx_), cy = static_cast<int>(column / nx_);
    for (int y = std::max(0, cy - kReach); y <= std::min(ny_ - 1, cy + kReach); ++y) {
      for (int x = std::max(0, cx - kReach); x <= std::min(nx_ - 1, cx + kReach); ++x) {
        for (std::uint32_t k = head_[static_cast<std::size_t>(y) * nx_ + x]; k != kNone;
             k = next_[k]) {
          if (saw_through_[k] == 0 && (sees_through(objects_[k], scan.origin_W, p, scan.up_W) ||
                                       ground_at_top(objects_[k], scan, i))) {
            saw_through_[k] = 1;
          }
        }
      }
    }
  }
  unindex();
  expire(scan);
}

}  // namespace tarmac::core
