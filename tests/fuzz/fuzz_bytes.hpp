#pragma once
/// @file Shared by the libFuzzer targets in tests/fuzz: ByteReader turns fuzz bytes into message
/// fields (zeros once the bytes run out, so every input decodes to something), ByteWriter encodes
/// seeds in the same layout, and `--make-seeds DIR` writes a target's generated seeds.
///
/// Each target defines its input layout once, as a `decode(ByteReader&)` that builds the message
/// and an `encode(ByteWriter&, ...)` used only for seeds; the two read and write the same fields
/// in the same order.

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

namespace tarmac::fuzz {

using Bytes = std::vector<std::uint8_t>;

class ByteReader {
 public:
  ByteReader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}

  /// The next sizeof(T) bytes (host order); zero bytes past the end.
  template <typename T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value{};
    const std::size_t n = std::min(sizeof(T), size_ - pos_);
    if (n > 0) std::memcpy(&value, data_ + pos_, n);
    pos_ += n;
    return value;
  }
  /// A u8 length, then that many bytes.
  std::string string() {
    const std::size_t n = std::min<std::size_t>(get<std::uint8_t>(), size_ - pos_);
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }
  /// Everything not read yet.
  std::span<const std::uint8_t> rest() {
    const std::span<const std::uint8_t> r(data_ + pos_, size_ - pos_);
    pos_ = size_;
    return r;
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
};

class ByteWriter {
 public:
  template <typename T>
  void put(T value) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* p = reinterpret_cast<const std::uint8_t*>(&value);
    bytes_.insert(bytes_.end(), p, p + sizeof(T));
  }
  void string(std::string_view s) {
    const std::size_t n = std::min<std::size_t>(s.size(), 255);
    put<std::uint8_t>(static_cast<std::uint8_t>(n));
    bytes_.insert(bytes_.end(), s.begin(), s.begin() + static_cast<std::ptrdiff_t>(n));
  }
  void bytes(std::span<const std::uint8_t> b) { bytes_.insert(bytes_.end(), b.begin(), b.end()); }
  [[nodiscard]] Bytes take() { return std::move(bytes_); }

 private:
  Bytes bytes_;
};

/// A property the target checks failed: abort, so libFuzzer saves the input as a crash.
#define TARMAC_FUZZ_CHECK(cond)                                                             \
  do {                                                                                      \
    if (!(cond)) {                                                                          \
      std::fprintf(stderr, "%s:%d: fuzz property failed: %s\n", __FILE__, __LINE__, #cond); \
      std::abort();                                                                         \
    }                                                                                       \
  } while (false)

/// For LLVMFuzzerInitialize: when the arguments are `--make-seeds DIR`, writes `seeds` as
/// DIR/seed-NNN (and `dictionary`, libFuzzer -dict format, as DIR.dict when not empty), then
/// exits 0. Otherwise returns and libFuzzer runs as usual.
inline void handle_make_seeds(int* argc, char*** argv, const std::vector<Bytes>& (*seeds)(),
                              const std::vector<std::string>& dictionary = {}) {
  if (*argc != 3 || std::string_view((*argv)[1]) != "--make-seeds") return;
  const std::filesystem::path dir = (*argv)[2];
  std::filesystem::create_directories(dir);
  int i = 0;
  for (const Bytes& seed : seeds()) {
    char name[32];
    std::snprintf(name, sizeof name, "seed-%03d", i++);
    std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(seed.data()),
              static_cast<std::streamsize>(seed.size()));
    if (!out) {
      std::fprintf(stderr, "cannot write %s\n", (dir / name).c_str());
      std::exit(1);
    }
  }
  if (!dictionary.empty()) {
    std::ofstream dict(dir.string() + ".dict", std::ios::trunc);
    for (const std::string& entry : dictionary) {
      dict << '"';
      for (const char c : entry) {
        if (c == '"' || c == '\\') {
          dict << '\\' << c;
        } else if (c < 0x20 || c > 0x7e) {
          char hex[8];
          std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned char>(c));
          dict << hex;
        } else {
          dict << c;
        }
      }
      dict << "\"\n";
    }
  }
  std::printf("%d seeds in %s\n", i, dir.c_str());
  std::exit(0);
}

}  // namespace tarmac::fuzz
