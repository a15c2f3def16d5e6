#pragma once
/// @file scan_filter.cpp's per-point tests four points at a time (PointLanes) and the region of
/// cells its outlier test reads (OutlierRegion). Internal to core/src: included by
/// scan_filter.cpp only; the one-point reference they must agree with is there
/// (PointTests::test_point).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

#include <Eigen/Geometry>

#include "lanes4.hpp"
#include "tarmac/core/scan_filter.hpp"

namespace tarmac::core::scan_filter_detail {

constexpr std::uint64_t kField = 0x1fffff;

/// Cell coordinates are taken for |coordinate / cell| up to this (the largest float below 2^31);
/// a point beyond is outside any region the outlier test reads (OutlierRegion).
constexpr float kCellLimit = 2147483520.0f;

/// The cells the outlier test can read: a near candidate's cell and the 26 around it lie within
/// `reach` cells of the sensor's on every axis (each coordinate of a near point is below the
/// outlier range; 3 cells more for the floors' float rounding). Candidates outside it are not
/// counted: no near candidate can be their neighbour. When the region has few enough cells
/// (side³ ≤ FilterScratch::grid_cell_limit: 2 MB at the defaults) they are counted in a grid
/// of bytes, an index instead of a hash lookup per count and per neighbour.
struct OutlierRegion {
  /// Cells of outlier range at most (validated parameters give at most 20 000).
  static constexpr double kMaxCells = 1e5;

  OutlierRegion(const FilterParams& params, std::size_t limit)
      : OutlierRegion(params.outlier_max_range_m / params.outlier_cell_m, limit) {}

  /// The outlier range, or for unvalidated parameters (beyond kMaxCells cells, negative, not a
  /// number) the range the region covers: near points must have their cells and neighbours in
  /// it.
  [[nodiscard]] double near_range_m(const FilterParams& params) const {
    return capped ? (reach - 3) * params.outlier_cell_m : params.outlier_max_range_m;
  }

  /// Whether a cell lies in the region.
  [[nodiscard]] bool holds(const std::array<std::int64_t, 3>& c) const {
    return std::abs(c[0]) <= reach && std::abs(c[1]) <= reach && std::abs(c[2]) <= reach;
  }

  /// The grid index (x fastest) of a cell in the region, from its key's three 21-bit fields
  /// (x, y, z). Computed once per candidate, when the candidate is tested.
  [[nodiscard]] std::uint32_t index(std::uint64_t fx, std::uint64_t fy, std::uint64_t fz) const {
    const std::uint64_t lo = (1u << 20) - static_cast<std::uint64_t>(reach);
    return static_cast<std::uint32_t>(((fz - lo) * side + (fy - lo)) * side + (fx - lo));
  }

  int reach;
  std::size_t side;
  bool grid;
  bool capped;

 private:
  /// `cells`: outlier range over cell size.
  OutlierRegion(double cells, std::size_t limit)
      : reach(static_cast<int>(cells >= 0.0 ? std::min(std::ceil(cells), kMaxCells) : 0.0) + 3),
        side(2 * static_cast<std::size_t>(reach) + 1),
        // Cell indices are 32-bit (the touched lists).
        grid(side * side * side <= std::min(limit, std::size_t{1} << 31)),
        capped(!(cells >= 0.0 && cells <= kMaxCells)) {}  // NaN: capped, reach 3
};

/// filter_scan's per-point tests four points at a time, with the same float arithmetic as the
/// one-point reference (PointTests::test_point), so the same decisions: the squared norm
/// summed in Eigen's order (x² + (y² + z²)), its comparison with min range² in double done in
/// float against the smallest float not below it, the cell key's floors in 32-bit lanes (a
/// lane whose cell coordinate is out of their range takes the reference's 64-bit one).
/// The ego box test, in double, is left to the reference for the few points that a float test
/// with a wide margin does not put surely outside the box (within ~1e-5 of the box's size and
/// of the point's distance: those near or in the vehicle).
class PointLanes {
 public:
  /// What test() finds for four points: lane masks (bit l: point l) and, for the lanes whose
  /// keys are in `keyed`, the three 21-bit fields of the cell key.
  struct Found {
    unsigned finite = 0, close = 0, maybe_ego = 0, keyed = 0, near = 0, region = 0;
    alignas(16) std::uint32_t field[3][4];
    /// The cell's grid index (OutlierRegion::index) for the lanes in `region`.
    alignas(16) std::uint32_t index[4];
  };

  PointLanes(const FilterParams& params, const Eigen::Isometry3d& T_B_S, float inv_cell,
             float near_sq, const OutlierRegion& region)
      : ego_(params.ego_box_enabled),
        inv_cell_(inv_cell),
        near_sq_(near_sq),
        reach_(region.reach),
        side_(static_cast<std::uint32_t>(region.side)),
        lo_field_((1u << 20) - static_cast<std::uint32_t>(region.reach)) {
    const double min_sq = params.min_range_m * params.min_range_m;
    float f = static_cast<float>(min_sq);
    if (static_cast<double>(f) < min_sq)
      f = std::nextafter(f, std::numeric_limits<float>::infinity());
    min_sq_ = f;
    double row_sum = 0.0, bound = 1.0;
    for (int a = 0; a < 3; ++a) {
      double sum = 0.0;
      for (int b = 0; b < 3; ++b) {
        R_[a][b] = static_cast<float>(T_B_S.linear()(a, b));
        sum += std::abs(T_B_S.linear()(a, b));
      }
      row_sum = std::max(row_sum, sum);
      t_[a] = static_cast<float>(T_B_S.translation()[a]);
      lo_[a] = static_cast<float>(params.ego_box_min_B[a]);
      hi_[a] = static_cast<float>(params.ego_box_max_B[a]);
      bound += std::abs(T_B_S.translation()[a]) + std::abs(params.ego_box_min_B[a]) +
               std::abs(params.ego_box_max_B[a]);
    }
    // The float test's error is a few float roundings of sums bounded by these: a margin a
    // hundred times that.
    margin_ = static_cast<float>(1e-5 * bound);
    margin_per_m_ = static_cast<float>(1e-5 * row_sum);
    // Extrinsics or a box beyond float's range: every lane takes the reference's test.
    bool finite = std::isfinite(margin_) && std::isfinite(margin_per_m_);
    for (int a = 0; a < 3; ++a) {
      finite = finite && std::isfinite(t_[a]) && std::isfinite(lo_[a]) && std::isfinite(hi_[a]);
      for (int b = 0; b < 3; ++b) finite = finite && std::isfinite(R_[a][b]);
    }
    all_maybe_ego_ = ego_ && !finite;
  }

  [[nodiscard]] Found test(const Eigen::Vector3f* p) const {
    Float4 x, y, z;
    load_xyz4(p, x, y, z);
    const Float4 zero = {};
    const Int4 finite = (x - x == zero) & (y - y == zero) & (z - z == zero);
    const Float4 sq = x * x + (y * y + z * z);
    const Int4 close = finite & (sq < min_sq_);
    Found f;
    f.finite = lane_bits(finite);
    f.close = lane_bits(close);
    f.near = lane_bits(sq < near_sq_);
    if (all_maybe_ego_) {
      f.maybe_ego = 0xf;
    } else if (ego_) {
      const Float4 ax = x < zero ? -x : x, ay = y < zero ? -y : y, az = z < zero ? -z : z;
      const Float4 m = margin_ + margin_per_m_ * (ax + ay + az);
      Int4 outside = {};
      for (int r = 0; r < 3; ++r) {
        const Float4 v = R_[r][0] * x + R_[r][1] * y + R_[r][2] * z + t_[r];
        // A sum that overflowed (not finite) says nothing: the reference decides.
        outside |= (v - v == zero) & ((v < lo_[r] - m) | (v > hi_[r] + m));
      }
      f.maybe_ego = lane_bits(~outside);
    }
    // Cell fields: floor as the reference's floor_to_int, in 32 bits while that is exact.
    const Float4 limit = zero + kCellLimit;
    Int4 keyed = finite;
    Int4 region = finite;
    const Float4 q[3] = {x * inv_cell_, y * inv_cell_, z * inv_cell_};
    using UInt4 = std::uint32_t __attribute__((vector_size(16)));
    UInt4 fields[3];
    for (int k = 0; k < 3; ++k) {
      const Float4 abs_q = q[k] < zero ? -q[k] : q[k];
      keyed &= abs_q <= limit;
      const Float4 safe = abs_q <= limit ? q[k] : zero;
      const Int4 i = __builtin_convertvector(safe, Int4);           // truncates toward zero
      const Int4 down = __builtin_convertvector(i, Float4) > safe;  // −1 where it rounded up
      const Int4 cell = i + down;  // no overflow: |safe| < 2^31, so i > −2^31 where down is −1
      region &= (cell >= -reach_) & (cell <= reach_);
      const UInt4 field =
          (reinterpret_cast<const UInt4&>(i) + reinterpret_cast<const UInt4&>(down) + (1u << 20)) &
          static_cast<std::uint32_t>(kField);
      std::memcpy(f.field[k], &field, sizeof field);
      fields[k] = field - lo_field_;
    }
    // The grid index in 32 bits (the region has at most 2^31 cells); lanes out of the region
    // wrap around and are not read.
    const UInt4 index = (fields[2] * side_ + fields[1]) * side_ + fields[0];
    std::memcpy(f.index, &index, sizeof index);
    f.keyed = lane_bits(keyed);
    f.region = lane_bits(region & keyed);
    return f;
  }

 private:
  bool ego_, all_maybe_ego_ = false;
  float inv_cell_, near_sq_, min_sq_ = 0.0f;
  int reach_;
  std::uint32_t side_, lo_field_;
  float R_[3][3] = {}, t_[3] = {}, lo_[3] = {}, hi_[3] = {};
  float margin_ = 0.0f, margin_per_m_ = 0.0f;
};

}  // namespace tarmac::core::scan_filter_detail
