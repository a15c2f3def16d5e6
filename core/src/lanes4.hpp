#pragma once
/// @file Four-lane helpers shared by the core's vector code (internal): GCC/Clang vector
/// extensions, so any target (SSE on x86-64, NEON on ARM); comparisons give −1 (all bits) or 0
/// per lane.

#include <cstdint>
#include <cstring>

#include <Eigen/Core>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tarmac::core {

using Float4 = float __attribute__((vector_size(16)));
using Int4 = std::int32_t __attribute__((vector_size(16)));

/// Bit k set when lane k of a comparison mask is set (one instruction with SSE).
inline unsigned lane_bits(Int4 mask) {
#if defined(__SSE2__)
  return static_cast<unsigned>(_mm_movemask_ps(reinterpret_cast<__m128>(mask)));
#else
  return static_cast<unsigned>((mask[0] & 1) | (mask[1] & 2) | (mask[2] & 4) | (mask[3] & 8));
#endif
}

/// Set bits of a word. (std::popcount is a library call on x86-64 builds without POPCNT.)
inline int bit_count(std::uint64_t x) {
  x -= (x >> 1) & 0x5555555555555555ull;
  x = (x & 0x3333333333333333ull) + ((x >> 2) & 0x3333333333333333ull);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0full;
  return static_cast<int>((x * 0x0101010101010101ull) >> 56);
}

/// Four consecutive points p[0..4) as lanes of x, y and z: three loads and six shuffles
/// (x0 y0 z0 x1 | y1 z1 x2 y2 | z2 x3 y3 z3), instead of twelve scalar inserts.
inline void load_xyz4(const Eigen::Vector3f* p, Float4& x, Float4& y, Float4& z) {
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float));
  const auto* const raw = reinterpret_cast<const unsigned char*>(p);
  Float4 a, b, c;
  std::memcpy(&a, raw, sizeof a);
  std::memcpy(&b, raw + sizeof a, sizeof b);
  std::memcpy(&c, raw + 2 * sizeof a, sizeof c);
  x = __builtin_shufflevector(__builtin_shufflevector(a, b, 0, 3, 6, 7), c, 0, 1, 2, 5);
  y = __builtin_shufflevector(__builtin_shufflevector(a, b, 1, 4, 7, 7), c, 0, 1, 2, 6);
  z = __builtin_shufflevector(__builtin_shufflevector(a, b, 2, 5, 5, 5), c, 0, 1, 4, 7);
}

}  // namespace tarmac::core
