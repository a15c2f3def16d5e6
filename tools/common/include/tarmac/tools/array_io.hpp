#pragma once
/// @file Writing results for analysis: NumPy .npy v1.0 (C order), 8-bit RGB PNG and JSON.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/result.hpp"

namespace tarmac::tools {

/// Writes a C-order array of float32 ('<f4'), int8 ('|i1') or uint8 ('|u1') with the given
/// shape.
core::Status write_npy(const std::filesystem::path& file, std::span<const float> data,
                       const std::vector<std::size_t>& shape);
core::Status write_npy(const std::filesystem::path& file, std::span<const std::int8_t> data,
                       const std::vector<std::size_t>& shape);
core::Status write_npy(const std::filesystem::path& file, std::span<const std::uint8_t> data,
                       const std::vector<std::size_t>& shape);

/// The pictures' colour for what was not observed (slate blue), the same in every image.
inline constexpr std::uint8_t kUnobservedRgb[3] = {70, 80, 110};

/// Writes an RGB image, rows top to bottom, 3 bytes per pixel.
core::Status write_png(const std::filesystem::path& file, std::span<const std::uint8_t> rgb,
                       std::uint32_t width, std::uint32_t height);

/// A float32 .npy of shape (rows, cols) too large to hold, written in bands of whole rows, in
/// any order (the file is sized at open()).
class NpyBands {
 public:
  core::Status open(const std::filesystem::path& file, std::size_t rows, std::size_t cols);
  /// Rows row0 .. row0 + cells.size() / cols - 1.
  core::Status band(std::size_t row0, std::span<const float> cells);
  core::Status finish();

 private:
  std::filesystem::path file_;
  std::ofstream out_;
  std::size_t cols_ = 0;
  std::size_t data_at_ = 0;
};

/// An RGB PNG too large to hold, written row by row, top to bottom.
class PngRows {
 public:
  PngRows();
  ~PngRows();
  PngRows(const PngRows&) = delete;
  PngRows& operator=(const PngRows&) = delete;
  core::Status open(const std::filesystem::path& file, std::uint32_t width, std::uint32_t height);
  /// The next row: 3 bytes per pixel.
  core::Status row(std::span<const std::uint8_t> rgb);
  core::Status finish();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::uint32_t width_ = 0;
};

/// Writes `value` as JSON, indented by two spaces, keys in their insertion order.
core::Status write_json(const std::filesystem::path& file, const nlohmann::ordered_json& value);

/// FNV-1a 64 over bytes, as 16 hex digits (map digests for determinism checks).
std::string digest(std::span<const std::uint8_t> bytes,
                   std::uint64_t seed = 1469598103934665603ull);

}  // namespace tarmac::tools
