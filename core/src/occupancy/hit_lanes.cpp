#include "hit_lanes.hpp"

#include <algorithm>
#include <bit>

#include <immintrin.h>

#if defined(TARMAC_WIDE_WALK)
namespace tarmac::core::occupancy {
namespace {

/// Points [i, i + m) of `points` as three columns of doubles, for the hit pass's lanes (lanes
/// from m on stay 0).
template <int kLanes>
[[gnu::always_inline]] inline void point_columns(std::span<const Eigen::Vector3f> points,
                                                 std::size_t i, int m, double (&c)[3][kLanes]) {
  for (int j = 0; j < m; ++j) {
    for (int a = 0; a < 3; ++a) c[a][j] = static_cast<double>(points[i + j][a]);
  }
}

}  // namespace

/// integrate_hits' first pass in AVX-512 lanes, eight returns at a time: each return's slot
/// (kNoSlot when not finite, beyond max range or outside the window) and window column, with the
/// scalar pass's arithmetic (the same divisions and floors; the range's norm summed in the same
/// order, and a return within 1e-9 of max range decided by the scalar expression itself).
/// Returns how many returns fell outside the window.
__attribute__((target("avx512f,avx512dq"))) std::uint64_t hit_voxels_lanes8(const HitPass& h) {
  const auto& [points, origin_W, max_range, voxel_size, min, dims, ring_min, slot_out, column_out] =
      h;
  constexpr int kLanes = 8;
  const std::size_t n = points.size();
  std::uint64_t outside = 0;
  const __m512d voxel = _mm512_set1_pd(voxel_size);
  const __m512d range = _mm512_set1_pd(max_range);
  const __m512d near_edge = _mm512_set1_pd(h.near_edge());
  const __m512d abs_bits = _mm512_castsi512_pd(_mm512_set1_epi64(0x7fffffffffffffffLL));
  for (std::size_t i = 0; i < n; i += kLanes) {
    const int m = static_cast<int>(std::min<std::size_t>(kLanes, n - i));
    alignas(64) double c[3][kLanes] = {};
    point_columns<kLanes>(points, i, m, c);
    auto keep = static_cast<__mmask8>((1u << m) - 1u);
    __m512d sq = _mm512_setzero_pd();
    __m512i slot = _mm512_setzero_si512(), stride = _mm512_set1_epi64(1);
    __m512i rel[3];
    __mmask8 inside = 0xff;
    for (int a = 0; a < 3; ++a) {
      const __m512d x = _mm512_load_pd(c[a]);
      keep &= _mm512_cmp_pd_mask(_mm512_sub_pd(x, x), _mm512_setzero_pd(), _CMP_EQ_OQ);  // finite
      const __m512d d = _mm512_sub_pd(x, _mm512_set1_pd(origin_W[a]));
      sq = a == 0 ? _mm512_mul_pd(d, d) : _mm512_add_pd(sq, _mm512_mul_pd(d, d));
      const __m512d q = _mm512_div_pd(x, voxel);
      const __m512i cell = _mm512_cvtpd_epi64(
          _mm512_mask_roundscale_pd(q, 0xff, q, _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
      const __m512i size = _mm512_set1_epi64(dims[a]);
      rel[a] = _mm512_sub_epi64(cell, _mm512_set1_epi64(min[a]));
      inside &= _mm512_cmplt_epu64_mask(rel[a], size);
      __m512i ring = _mm512_add_epi64(rel[a], _mm512_set1_epi64(ring_min[a]));
      ring = _mm512_mask_sub_epi64(ring, _mm512_cmpge_epi64_mask(ring, size), ring, size);
      slot = _mm512_add_epi64(slot, _mm512_mullo_epi64(ring, stride));
      stride = _mm512_mullo_epi64(stride, size);
    }
    const __m512d norm = _mm512_mask_sqrt_pd(sq, 0xff, sq);
    keep &= _mm512_cmp_pd_mask(norm, range, _CMP_LE_OQ);
    // Within a hair of max range: the scalar expression decides (its summation order is
    // Eigen's; the lanes' is meant to be the same, this makes it so whatever it is).
    const __mmask8 edge = _mm512_cmp_pd_mask(_mm512_and_pd(_mm512_sub_pd(norm, range), abs_bits),
                                             near_edge, _CMP_LE_OQ);
    for (unsigned lanes = edge & ((1u << m) - 1u); lanes != 0; lanes &= lanes - 1) {
      const int j = std::countr_zero(lanes);
      const Eigen::Vector3f& p = points[i + static_cast<std::size_t>(j)];
      const bool in_range = p.allFinite() && !((p.cast<double>() - origin_W).norm() > max_range);
      keep = static_cast<__mmask8>(in_range ? (keep | (1u << j)) : (keep & ~(1u << j)));
    }
    outside += static_cast<std::uint64_t>(std::popcount(static_cast<unsigned>(keep & ~inside)));
    keep &= inside;
    alignas(64) std::int64_t slots[kLanes], columns[kLanes];
    _mm512_store_si512(slots, slot);
    _mm512_store_si512(
        columns, _mm512_add_epi64(_mm512_mullo_epi64(rel[1], _mm512_set1_epi64(dims[0])), rel[0]));
    for (int j = 0; j < m; ++j) {
      const bool k = ((keep >> j) & 1) != 0;
      slot_out[i + static_cast<std::size_t>(j)] =
          k ? static_cast<std::uint32_t>(slots[j]) : kNoSlot;
      if (k) column_out[i + static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(columns[j]);
    }
  }
  return outside;
}

/// integrate_hits' first pass in AVX2 lanes, four returns at a time, as hit_voxels_lanes8 (the
/// same divisions, floors and norm; a return within 1e-9 of max range decided by the scalar
/// expression). The window's indices in 32 bits: a window has fewer than 2^31 voxels
/// (OccupancyParams::validate) and every coordinate it holds is within ±2^31 voxels.
/// Returns how many returns fell outside the window.
__attribute__((target("avx2"))) std::uint64_t hit_voxels_lanes4(const HitPass& h) {
  const auto& [points, origin_W, max_range, voxel_size, min, dims, ring_min, slot_out, column_out] =
      h;
  constexpr int kLanes = 4;
  const std::size_t n = points.size();
  std::uint64_t outside = 0;
  const __m256d voxel = _mm256_set1_pd(voxel_size);
  const __m256d range = _mm256_set1_pd(max_range);
  const __m256d near_edge = _mm256_set1_pd(h.near_edge());
  const __m256d abs_bits = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
  for (std::size_t i = 0; i < n; i += kLanes) {
    const int m = static_cast<int>(std::min<std::size_t>(kLanes, n - i));
    alignas(32) double c[3][kLanes] = {};
    point_columns<kLanes>(points, i, m, c);
    __m256d keep = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    __m256d sq = _mm256_setzero_pd();
    __m128i slot = _mm_setzero_si128(), stride = _mm_set1_epi32(1), inside = _mm_set1_epi32(-1);
    __m128i rel[3];
    for (int a = 0; a < 3; ++a) {
      const __m256d x = _mm256_load_pd(c[a]);
      keep = _mm256_and_pd(keep, _mm256_cmp_pd(_mm256_sub_pd(x, x), _mm256_setzero_pd(),
                                               _CMP_EQ_OQ));  // finite
      const __m256d d = _mm256_sub_pd(x, _mm256_set1_pd(origin_W[a]));
      sq = a == 0 ? _mm256_mul_pd(d, d) : _mm256_add_pd(sq, _mm256_mul_pd(d, d));
      const __m128i cell = _mm256_cvttpd_epi32(
          _mm256_round_pd(_mm256_div_pd(x, voxel), _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
      const __m128i size = _mm_set1_epi32(dims[a]);
      rel[a] = _mm_sub_epi32(cell, _mm_set1_epi32(min[a]));
      inside = _mm_and_si128(inside, _mm_andnot_si128(_mm_cmpgt_epi32(_mm_setzero_si128(), rel[a]),
                                                      _mm_cmpgt_epi32(size, rel[a])));
      __m128i ring = _mm_add_epi32(rel[a], _mm_set1_epi32(ring_min[a]));
      ring = _mm_sub_epi32(ring, _mm_andnot_si128(_mm_cmpgt_epi32(size, ring), size));
      slot = _mm_add_epi32(slot, _mm_mullo_epi32(ring, stride));
      stride = _mm_mullo_epi32(stride, size);
    }
    const __m256d norm = _mm256_sqrt_pd(sq);
    keep = _mm256_and_pd(keep, _mm256_cmp_pd(norm, range, _CMP_LE_OQ));
    const int edge = _mm256_movemask_pd(
        _mm256_cmp_pd(_mm256_and_pd(_mm256_sub_pd(norm, range), abs_bits), near_edge, _CMP_LE_OQ));
    alignas(16) std::int32_t slots[kLanes], columns[kLanes], in[kLanes];
    _mm_store_si128(reinterpret_cast<__m128i*>(slots), slot);
    _mm_store_si128(reinterpret_cast<__m128i*>(columns),
                    _mm_add_epi32(_mm_mullo_epi32(rel[1], _mm_set1_epi32(dims[0])), rel[0]));
    _mm_store_si128(reinterpret_cast<__m128i*>(in), inside);
    const int kept = _mm256_movemask_pd(keep);
    for (int j = 0; j < m; ++j) {
      bool k = ((kept >> j) & 1) != 0;
      if (((edge >> j) & 1) != 0) {
        // Within a hair of max range: the scalar expression decides (its summation order is
        // Eigen's; the lanes' is meant to be the same, this makes it so whatever it is).
        const Eigen::Vector3f& p = points[i + static_cast<std::size_t>(j)];
        k = p.allFinite() && !((p.cast<double>() - origin_W).norm() > max_range);
      }
      if (k && in[j] == 0) ++outside;
      k = k && in[j] != 0;
      slot_out[i + static_cast<std::size_t>(j)] =
          k ? static_cast<std::uint32_t>(slots[j]) : kNoSlot;
      if (k) column_out[i + static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(columns[j]);
    }
  }
  return outside;
}

}  // namespace tarmac::core::occupancy
#endif
