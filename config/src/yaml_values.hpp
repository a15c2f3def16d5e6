#pragma once
/// @file Reading YAML values for the config loader (config.cpp): typed, bounded values with
/// messages that name the key and what was found, the structure checks yaml-cpp does not do,
/// and "did you mean" for unknown keys. Internal to config/src. Errors are thrown as
/// ConfigError and caught once in load_config (exceptions never leave the config library).

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace tarmac::config::detail {

/// A config error from deep inside the walk: `reason` is the error code's tail
/// ("config.<reason>"), `message` names the key.
struct ConfigError {
  std::string reason;
  std::string message;
};

[[noreturn]] void fail(const std::string& reason, const std::string& path, const std::string& why);

/// Why a DDS topic name is not the wire form of a ROS 2 topic (`rt/` + a fully qualified ROS
/// name: tokens of [A-Za-z0-9_] not starting with a digit, separated by single '/'), or "".
std::string ros_topic_problem(const std::string& name);
/// `key` appended to `path` ("executor" + "rate_hz" -> "executor.rate_hz").
std::string join_path(const std::string& path, const std::string& key);
/// `path`, or "<root>" for the document itself.
std::string path_or_root(const std::string& path);
/// The YAML line and column of a node, 1-based, for messages.
std::string where(const YAML::Mark& mark, bool with_column);
/// What a node holds, for type errors: "a map", "a list", "a bool 'yes'", "a number '2.5'",
/// "a string 'abc'" (a quoted scalar is always a string).
std::string describe(const YAML::Node& node);
/// Refuses what yaml-cpp accepts silently, at every depth: a key given twice in one map, a key
/// that is not a plain scalar, nesting too deep or too many nodes (aliases). `nodes` counts the
/// visits.
void check_structure(const YAML::Node& node, const std::string& path, int depth,
                     std::size_t& nodes);
/// A YAML bool (true/false, yes/no, on/off).
bool parse_bool(const YAML::Node& node, const std::string& path);
/// " (did you mean 'inflation_radius_m'?)" for the known key nearest to `key`, when one is near
/// enough to be a typo, else "".
std::string did_you_mean(const std::string& key, const std::vector<std::string>& known);
/// A topic key's value: `/ns/name` mapped to `rt/ns/name`, refused unless a ROS 2 topic's wire
/// form ("" allowed: an output switched off).
void read_topic(const YAML::Node& node, const std::string& path, std::string& value);

template <typename T>
[[noreturn]] void fail_range(const std::string& path, T min, T max, const std::string& got) {
  std::ostringstream os;
  os << "must be in [" << min << ", " << max << "], got " << got;
  fail("range", path, os.str());
}

/// A decimal integer within [min, max]. "2.5", "1e3", "0x10" are type errors (an integer key
/// takes an integer written as one); `.nan` and `.inf` are refused as not finite, as for reals.
template <typename T>
T parse_integer(const YAML::Node& node, const std::string& path, T min, T max) {
  static_assert(std::is_integral_v<T> && !std::is_same_v<T, bool>);
  if (!node.IsScalar()) fail("type", path, "expected an integer, got " + describe(node));
  const std::string& text = node.Scalar();
  const char* first = text.data();
  const char* last = text.data() + text.size();
  if (first != last && *first == '+') ++first;
  long long parsed = 0;
  const auto [end, ec] = std::from_chars(first, last, parsed, 10);
  if (ec == std::errc::result_out_of_range) fail_range(path, min, max, text);
  if (ec != std::errc() || end != last || first == last) {
    double real = 0.0;
    if (YAML::convert<double>::decode(node, real) && !std::isfinite(real)) {
      fail("not_finite", path, "must be a finite number, got " + text);
    }
    fail("type", path, "expected an integer, got " + describe(node));
  }
  if (std::cmp_less(parsed, min) || std::cmp_greater(parsed, max)) {
    fail_range(path, min, max, std::to_string(parsed));
  }
  return static_cast<T>(parsed);
}

/// A finite real number within [min, max] (compared in T, so a float key's bounds mean what
/// they say in float). `.nan`, `.inf`, `-.inf` and numbers beyond the range of a double (1e400)
/// are refused as not finite.
template <typename T>
T parse_real(const YAML::Node& node, const std::string& path, T min, T max) {
  static_assert(std::is_floating_point_v<T>);
  if (!node.IsScalar()) fail("type", path, "expected a number, got " + describe(node));
  const std::string& text = node.Scalar();
  double parsed = 0.0;
  if (!YAML::convert<double>::decode(node, parsed)) {
    // yaml-cpp refuses a number that overflows a double; say why instead of "not a number".
    errno = 0;
    char* end = nullptr;
    const double huge = std::strtod(text.c_str(), &end);
    if (!text.empty() && end == text.c_str() + text.size() && errno == ERANGE && std::isinf(huge)) {
      fail("not_finite", path, "must be a finite number, got " + text);
    }
    fail("type", path, "expected a number, got " + describe(node));
  }
  if (!std::isfinite(parsed)) fail("not_finite", path, "must be a finite number, got " + text);
  if (std::abs(parsed) > static_cast<double>(std::numeric_limits<T>::max())) {
    fail_range(path, min, max, text);
  }
  const auto value = static_cast<T>(parsed);
  if (value < min || value > max) {
    std::ostringstream got;
    got << value;
    fail_range(path, min, max, got.str());
  }
  return value;
}

}  // namespace tarmac::config::detail
