#pragma once
/// @file Writing arrays for analysis: NumPy .npy v1.0 (C order) and 8-bit RGB PNG.

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

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

/// FNV-1a 64 over bytes, as 16 hex digits (map digests for determinism checks).
std::string digest(std::span<const std::uint8_t> bytes,
                   std::uint64_t seed = 1469598103934665603ull);

}  // namespace tarmac::tools
