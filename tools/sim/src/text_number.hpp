#pragma once
/// @file How tarmac-sim writes a number into its text files (lidar.cpp, small_objects.cpp).

#include <charconv>
#include <string>

namespace tarmac::sim {

/// Shortest decimal that reads back as the same double (deterministic, locale-independent).
inline std::string number(double value) {
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof(buf), value);
  return std::string(buf, res.ptr);
}

}  // namespace tarmac::sim
