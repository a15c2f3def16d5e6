#include "tarmac/tools/array_io.hpp"

#include <png.h>

#include <cstdio>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

namespace tarmac::tools {

namespace {

core::Status write_npy_raw(const std::filesystem::path& file, const char* descr, const void* data,
                           std::size_t bytes, const std::vector<std::size_t>& shape) {
  std::string dims;
  for (std::size_t i = 0; i < shape.size(); ++i)
    dims += std::to_string(shape[i]) + (shape.size() == 1 || i + 1 < shape.size() ? "," : "");
  std::string header =
      std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (" + dims + "), }";
  // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64.
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header += '\n';
  std::ofstream out(file, std::ios::binary);
  if (!out) return core::Error{"io.write", file.string() + ": cannot be written"};
  const auto len = static_cast<std::uint16_t>(header.size());
  out.write("\x93NUMPY\x01\x00", 8);
  const char len_le[2] = {static_cast<char>(len & 0xff), static_cast<char>(len >> 8)};
  out.write(len_le, 2);
  out.write(header.data(), static_cast<std::streamsize>(header.size()));
  out.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
  if (!out) return core::Error{"io.write", file.string() + ": write failed"};
  return core::Ok{};
}

}  // namespace

core::Status write_npy(const std::filesystem::path& file, std::span<const float> data,
                       const std::vector<std::size_t>& shape) {
  return write_npy_raw(file, "<f4", data.data(), data.size_bytes(), shape);
}

core::Status write_npy(const std::filesystem::path& file, std::span<const std::int8_t> data,
                       const std::vector<std::size_t>& shape) {
  return write_npy_raw(file, "|i1", data.data(), data.size_bytes(), shape);
}

core::Status write_png(const std::filesystem::path& file, std::span<const std::uint8_t> rgb,
                       std::uint32_t width, std::uint32_t height) {
  if (rgb.size() != std::size_t{width} * height * 3) return core::Error{"io.png", "size mismatch"};
  std::FILE* fp = std::fopen(file.c_str(), "wb");
  if (fp == nullptr) return core::Error{"io.write", file.string() + ": cannot be written"};
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png != nullptr ? png_create_info_struct(png) : nullptr;
  if (png == nullptr || info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(fp);
    return core::Error{"io.png", file.string() + ": libpng failed"};
  }
  png_init_io(png, fp);
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (std::uint32_t y = 0; y < height; ++y) {
    png_write_row(png, const_cast<png_bytep>(
                           rgb.data() + std::size_t{y} * width *
                                            3));  // NOLINT(cppcoreguidelines-pro-type-const-cast):
                                                  // libpng API is not const-correct
  }
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  std::fclose(fp);
  return core::Ok{};
}

core::Status write_json(const std::filesystem::path& file, const nlohmann::ordered_json& value) {
  std::ofstream out(file);
  if (!out) return core::Error{"io.write", file.string() + ": cannot be written"};
  // Text that is not UTF-8 (a path, a message) is replaced rather than stopping the write.
  out << value.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) << '\n';
  if (!out) return core::Error{"io.write", file.string() + ": write failed"};
  return core::Ok{};
}

std::string digest(std::span<const std::uint8_t> bytes, std::uint64_t h) {
  for (const auto b : bytes) {
    h ^= b;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

}  // namespace tarmac::tools
