#include "tarmac/tools/array_io.hpp"

#include <png.h>

#include <cstdio>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

namespace tarmac::tools {

namespace {

/// The .npy v1.0 preamble: magic, version, header length, header padded to a multiple of 64.
std::string npy_preamble(const char* descr, const std::vector<std::size_t>& shape) {
  std::string dims;
  for (std::size_t i = 0; i < shape.size(); ++i)
    dims += std::to_string(shape[i]) + (shape.size() == 1 || i + 1 < shape.size() ? "," : "");
  std::string header =
      std::string("{'descr': '") + descr + "', 'fortran_order': False, 'shape': (" + dims + "), }";
  // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64.
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header += '\n';
  const auto len = static_cast<std::uint16_t>(header.size());
  std::string out("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>(len & 0xff);
  out += static_cast<char>(len >> 8);
  return out + header;
}

core::Status write_npy_raw(const std::filesystem::path& file, const char* descr, const void* data,
                           std::size_t bytes, const std::vector<std::size_t>& shape) {
  const std::string preamble = npy_preamble(descr, shape);
  std::ofstream out(file, std::ios::binary);
  if (!out) return core::Error{"io.write", file.string() + ": cannot be written"};
  out.write(preamble.data(), static_cast<std::streamsize>(preamble.size()));
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

core::Status write_npy(const std::filesystem::path& file, std::span<const std::uint8_t> data,
                       const std::vector<std::size_t>& shape) {
  return write_npy_raw(file, "|u1", data.data(), data.size_bytes(), shape);
}

core::Status NpyBands::open(const std::filesystem::path& file, std::size_t rows, std::size_t cols) {
  file_ = file;
  cols_ = cols;
  const std::string preamble = npy_preamble("<f4", {rows, cols});
  data_at_ = preamble.size();
  out_.open(file, std::ios::binary | std::ios::trunc);
  out_.write(preamble.data(), static_cast<std::streamsize>(preamble.size()));
  // Sized up front: bands may come in any order.
  if (rows * cols > 0) {
    out_.seekp(static_cast<std::streamoff>(data_at_ + rows * cols * sizeof(float) - 1));
    out_.put('\0');
  }
  if (!out_) return core::Error{"io.write", file.string() + ": cannot be written"};
  return core::Ok{};
}

core::Status NpyBands::band(std::size_t row0, std::span<const float> cells) {
  out_.seekp(static_cast<std::streamoff>(data_at_ + row0 * cols_ * sizeof(float)));
  out_.write(reinterpret_cast<const char*>(cells.data()),
             static_cast<std::streamsize>(cells.size_bytes()));
  if (!out_) return core::Error{"io.write", file_.string() + ": write failed"};
  return core::Ok{};
}

core::Status NpyBands::finish() {
  out_.close();
  if (!out_) return core::Error{"io.write", file_.string() + ": write failed"};
  return core::Ok{};
}

struct PngRows::Impl {
  std::FILE* fp = nullptr;
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::filesystem::path file;
  ~Impl() {
    if (png != nullptr) png_destroy_write_struct(&png, &info);
    if (fp != nullptr) std::fclose(fp);
  }
};

PngRows::PngRows() : impl_(std::make_unique<Impl>()) {}
PngRows::~PngRows() = default;

core::Status PngRows::open(const std::filesystem::path& file, std::uint32_t width,
                           std::uint32_t height) {
  Impl& d = *impl_;
  d.file = file;
  width_ = width;
  d.fp = std::fopen(file.c_str(), "wb");
  if (d.fp == nullptr) return core::Error{"io.write", file.string() + ": cannot be written"};
  d.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  d.info = d.png != nullptr ? png_create_info_struct(d.png) : nullptr;
  if (d.png == nullptr || d.info == nullptr || setjmp(png_jmpbuf(d.png))) {
    return core::Error{"io.png", file.string() + ": libpng failed"};
  }
  png_init_io(d.png, d.fp);
  png_set_IHDR(d.png, d.info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(d.png, d.info);
  return core::Ok{};
}

core::Status PngRows::row(std::span<const std::uint8_t> rgb) {
  Impl& d = *impl_;
  if (rgb.size() != std::size_t{width_} * 3) return core::Error{"io.png", "row size mismatch"};
  if (setjmp(png_jmpbuf(d.png))) return core::Error{"io.png", d.file.string() + ": libpng failed"};
  // NOLINTNEXTLINE(cppcoreguidelines-pro-type-const-cast): libpng is not const-correct
  png_write_row(d.png, const_cast<png_bytep>(rgb.data()));
  return core::Ok{};
}

core::Status PngRows::finish() {
  Impl& d = *impl_;
  if (setjmp(png_jmpbuf(d.png))) return core::Error{"io.png", d.file.string() + ": libpng failed"};
  png_write_end(d.png, nullptr);
  png_destroy_write_struct(&d.png, &d.info);
  d.png = nullptr;
  const bool closed = std::fclose(d.fp) == 0;
  d.fp = nullptr;
  if (!closed) return core::Error{"io.write", d.file.string() + ": write failed"};
  return core::Ok{};
}

core::Status write_png(const std::filesystem::path& file, std::span<const std::uint8_t> rgb,
                       std::uint32_t width, std::uint32_t height) {
  if (rgb.size() != std::size_t{width} * height * 3) return core::Error{"io.png", "size mismatch"};
  PngRows png;
  if (auto s = png.open(file, width, height); !s) return s;
  for (std::uint32_t y = 0; y < height; ++y) {
    if (auto s = png.row(rgb.subspan(std::size_t{y} * width * 3, std::size_t{width} * 3)); !s) {
      return s;
    }
  }
  return png.finish();
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
