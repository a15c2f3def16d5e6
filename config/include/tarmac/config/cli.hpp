// tarmac::cli: the command line all tarmac programs share, on CLI11. --help prints the usage on
// stdout and exits 0; --version prints "<program> <TARMAC_VERSION>" and exits 0; an error (unknown
// option, missing or malformed value, value out of range, required option missing) is named on
// stderr with a hint to run --help, exit 64 (EX_USAGE). `--opt value` and `--opt=value` both work.
//
// Header-only and free of DDS and YAML: programs link the tarmac_cli target, which defines
// TARMAC_VERSION.
#pragma once

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <system_error>
#include <type_traits>
#include <utility>

#include <CLI/CLI.hpp>

namespace tarmac::cli {

constexpr int kExitUsage = 64;  ///< EX_USAGE (sysexits.h)

/// `text` with line breaks between words so that no line is longer than `width` (a longer word
/// stays whole); its own line breaks are kept.
inline std::string wrap(const std::string& text, std::size_t width) {
  std::string out;
  for (std::size_t begin = 0;;) {
    const std::size_t end = std::min(text.find('\n', begin), text.size());
    std::istringstream words(text.substr(begin, end - begin));
    std::size_t column = 0;
    for (std::string word; words >> word;) {
      if (column > 0 && column + 1 + word.size() > width) {
        out += '\n';
        column = 0;
      } else if (column > 0) {
        out += ' ';
        ++column;
      }
      out += word;
      column += word.size();
    }
    if (end == text.size()) return out;
    out += '\n';
    begin = end + 1;
  }
}

/// CLI11's --help, its texts wrapped to fit in 100 columns (CLI11 does not wrap), so that each
/// description can be written as one string.
class Formatter : public CLI::Formatter {
 public:
  static constexpr std::size_t kWidth = 100;
  std::string make_description(const CLI::App* app) const override {
    return wrap(CLI::Formatter::make_description(app), kWidth);
  }
  std::string make_footer(const CLI::App* app) const override {
    return wrap(CLI::Formatter::make_footer(app), kWidth);
  }
  std::string make_option_desc(const CLI::Option* option) const override {
    return wrap(CLI::Formatter::make_option_desc(option), kWidth - get_column_width());
  }
};

/// A program's command line. `description` heads --help; a paragraph that belongs after the
/// options goes in footer().
class App : public CLI::App {
 public:
  App(std::string name, std::string description)
      : CLI::App(std::move(description), std::move(name)) {
    set_version_flag("--version", get_name() + " " + TARMAC_VERSION);
    formatter(std::make_shared<Formatter>());
    // --help shows each option's default, so descriptions need not repeat it. An option given
    // twice takes the last value, as the hand-written parsers did (scripts append overrides).
    option_defaults()->always_capture_default()->multi_option_policy(
        CLI::MultiOptionPolicy::TakeLast);
    failure_message([](const CLI::App* app, const CLI::Error& e) {
      return app->get_name() + ": " + CLI::FailureMessage::simple(app, e);
    });
  }
};

/// Parses the command line into `app`'s options. Empty: go on. Otherwise main returns the value:
/// 0 after --help or --version, kExitUsage after an error (already reported on stderr).
inline std::optional<int> parse(CLI::App& app, int argc, const char* const* argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : kExitUsage;
  }
  return std::nullopt;
}

/// A usage error only the program can see (e.g. two values that do not go together), reported
/// as CLI11's own are. Returns kExitUsage.
inline int usage_error(const CLI::App& app, const std::string& message) {
  std::fprintf(stderr, "%s: %s\nRun with --help for more information.\n", app.get_name().c_str(),
               message.c_str());
  return kExitUsage;
}

namespace detail {

/// A value of type T that `accept` takes, read as std::from_chars reads it: decimal, a float
/// correctly rounded and finite. CLI11 2.1 converts with strtoull/strtold in base 0 ("010" is 8,
/// "-1" a huge std::size_t, a double rounded twice through long double), so the value is handed
/// on in a form that conversion reads back exactly (a decimal integer, a hexadecimal float).
template <typename T>
CLI::Validator number(std::string description, std::string what, std::function<bool(T)> accept) {
  return CLI::Validator(
      [what = std::move(what), accept = std::move(accept)](std::string& text) -> std::string {
        T value{};
        const char* end = text.data() + text.size();
        const auto [ptr, ec] = std::from_chars(text.data(), end, value);
        bool ok = ec == std::errc{} && ptr == end;
        if constexpr (std::is_floating_point_v<T>) ok = ok && std::isfinite(value);
        if (!ok || !accept(value)) return "'" + text + "' is not " + what;
        if constexpr (std::is_floating_point_v<T>) {
          char hex[64];
          std::snprintf(hex, sizeof hex, "%a", static_cast<double>(value));
          text = hex;
        } else {
          text = std::to_string(value);
        }
        return {};
      },
      std::move(description));
}

template <typename T>
std::string kind() {
  if constexpr (std::is_unsigned_v<T>) return "a whole number";  // "-1" is not one
  return std::is_integral_v<T> ? "an integer" : "a number";
}

template <typename T>
std::string to_text(T value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

}  // namespace detail

// Typed values and their ranges, as transforms: add_option(...)->transform(positive<int>()).

/// Any (finite) number of type T.
template <typename T>
CLI::Validator number() {
  return detail::number<T>("", detail::kind<T>(), [](T) { return true; });
}

/// A T > 0.
template <typename T>
CLI::Validator positive() {
  return detail::number<T>("POSITIVE", detail::kind<T>() + " > 0", [](T v) { return v > T{0}; });
}

/// A T >= 0.
template <typename T>
CLI::Validator non_negative() {
  return detail::number<T>("NONNEGATIVE", detail::kind<T>() + " >= 0", [](T v) {
    if constexpr (std::is_unsigned_v<T>) {
      return true;  // (v >= 0 would warn: always true)
    } else {
      return v >= T{0};
    }
  });
}

/// A T in [min, max].
template <typename T>
CLI::Validator in_range(T min, T max) {
  const std::string range = "[" + detail::to_text(min) + ", " + detail::to_text(max) + "]";
  return detail::number<T>(range, detail::kind<T>() + " in " + range,
                           [min, max](T v) { return v >= min && v <= max; });
}

}  // namespace tarmac::cli
