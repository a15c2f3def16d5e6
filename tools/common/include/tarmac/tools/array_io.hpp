#pragma once
/// @file Writing results for analysis: NumPy .npy v1.0 (C order), 8-bit RGB PNG and JSON.

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/result.hpp"

namespace tarmac::tools {

/// Writes a C-order array of float32 ('<f4') or int8 ('|i1') with the given shape.
core::Status write_npy(const std::filesystem::path& file, std::span<const float> data,
                       const std::vector<std::size_t>& shape);
core::Status write_npy(const std::filesystem::path& file, std::span<const std::int8_t> data,
                       const std::vector<std::size_t>& shape);

/// Writes an RGB image, rows top to bottom, 3 bytes per pixel.
core::Status write_png(const std::filesystem::path& file, std::span<const std::uint8_t> rgb,
                       std::uint32_t width, std::uint32_t height);

/// Writes `value` as JSON, indented by two spaces, keys in their insertion order.
core::Status write_json(const std::filesystem::path& file, const nlohmann::ordered_json& value);

/// FNV-1a 64 over bytes, as 16 hex digits (map digests for determinism checks).
std::string digest(std::span<const std::uint8_t> bytes,
                   std::uint64_t seed = 1469598103934665603ull);

}  // namespace tarmac::tools
