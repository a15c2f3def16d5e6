#include "tarmac/core/deskew.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

Eigen::Isometry3d interpolate_pose(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b,
                                   double f) {
  const Eigen::Quaterniond qa(a.linear()), qb(b.linear());
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = qa.slerp(f, qb).toRotationMatrix();
  T.translation() = (1.0 - f) * a.translation() + f * b.translation();
  return T;
}

void deskew_points(const PointCloud& cloud, const ScanMotion& motion,
                   const Eigen::Isometry3d& T_W_B_stamp, const Eigen::Isometry3d& T_B_S,
                   std::vector<Eigen::Vector3f>& out_S) {
  TARMAC_ASSERT(cloud.has_time() && cloud.consistent(), "deskew needs per-point times");
  TARMAC_ASSERT(motion.t1_s > motion.t0_s, "deskew needs t1 > t0");
  // Per bin edge: sensor at that time → sensor at the stamp, S_ref ← B_ref ← W ← B(t) ← S(t).
  const Eigen::Isometry3d T_Sref_W = (T_W_B_stamp * T_B_S).inverse();
  const double span = motion.t1_s - motion.t0_s;
  std::array<Eigen::Matrix3f, kDeskewBins + 1> R;
  std::array<Eigen::Vector3f, kDeskewBins + 1> t;
  for (int e = 0; e <= kDeskewBins; ++e) {
    const double f = static_cast<double>(e) / kDeskewBins;
    const Eigen::Isometry3d T =
        T_Sref_W * interpolate_pose(motion.T_W_B_0, motion.T_W_B_1, f) * T_B_S;
    R[static_cast<std::size_t>(e)] = T.linear().cast<float>();
    t[static_cast<std::size_t>(e)] = T.translation().cast<float>();
  }
  const float scale = static_cast<float>(kDeskewBins / span);
  const float t0 = static_cast<float>(motion.t0_s);
  const float u_stamp =
      std::clamp(static_cast<float>(-motion.t0_s) * scale, 0.0f, static_cast<float>(kDeskewBins));
  out_S.resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float time = cloud.time_offset_s[i];
    const float u = std::isfinite(time)
                        ? std::clamp((time - t0) * scale, 0.0f, static_cast<float>(kDeskewBins))
                        : u_stamp;
    // Within a bin, the point is blended between the transforms of its two edges.
    const int b = std::min(static_cast<int>(u), kDeskewBins - 1);
    const float w = u - static_cast<float>(b);
    const auto k = static_cast<std::size_t>(b);
    const Eigen::Vector3f& p = cloud.points_S[i];
    out_S[i] = (1.0f - w) * (R[k] * p + t[k]) + w * (R[k + 1] * p + t[k + 1]);
  }
}

}  // namespace tarmac::core
