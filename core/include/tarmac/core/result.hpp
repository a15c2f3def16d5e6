#pragma once
/// @file Errors as values for startup, config and I/O boundaries (STYLE.md rule 4).

#include <string>
#include <utility>
#include <variant>

#include "tarmac/core/assert.hpp"

namespace tarmac::core {

/// A failure with a stable machine-readable code (e.g. "pointcloud.missing_field") and a
/// human-readable message that names the offending key, field or value.
struct Error {
  std::string code;
  std::string message;
};

/// Either a value or an Error. Accessing the wrong alternative is a broken invariant.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value)
      : v_(std::move(value)) {}  // NOLINT(google-explicit-constructor): value-or-error sugar
  Result(Error error)
      : v_(std::move(error)) {}  // NOLINT(google-explicit-constructor): value-or-error sugar

  [[nodiscard]] bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & {
    TARMAC_ASSERT(ok(), "Result::value() on an error");
    return std::get<0>(v_);
  }
  const T& value() const& {
    TARMAC_ASSERT(ok(), "Result::value() on an error");
    return std::get<0>(v_);
  }
  T&& value() && {
    TARMAC_ASSERT(ok(), "Result::value() on an error");
    return std::get<0>(std::move(v_));
  }
  [[nodiscard]] const Error& error() const {
    TARMAC_ASSERT(!ok(), "Result::error() on a value");
    return std::get<1>(v_);
  }

 private:
  std::variant<T, Error> v_;
};

/// Result of an operation that yields nothing but may fail.
struct Ok {};
using Status = Result<Ok>;

}  // namespace tarmac::core
