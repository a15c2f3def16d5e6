#pragma once
/// @file The config tests' shared helper: the message of a config that must be refused.

#include <string>

#include <gtest/gtest.h>

#include "tarmac/config/config.hpp"

namespace tarmac::config {

/// The error message of loading `yaml`; a failed expectation (and "") when it loads.
inline std::string error_of(const std::string& yaml) {
  auto result = load_config_string(yaml);
  EXPECT_FALSE(result.ok()) << yaml;
  return result.ok() ? "" : result.error().message;
}

}  // namespace tarmac::config
