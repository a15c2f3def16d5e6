// Reading YAML values for the config loader (yaml_values.hpp).

#include "yaml_values.hpp"

#include <algorithm>

namespace tarmac::config::detail {

void fail(const std::string& reason, const std::string& path, const std::string& why) {
  throw ConfigError{reason, path + ": " + why};
}

namespace {
bool decodes_as_number(const YAML::Node& node) {
  double d = 0.0;
  return YAML::convert<double>::decode(node, d);
}

/// A YAML nesting deeper than this, or with more nodes than that, is refused: no config comes
/// near either, and aliases can make a node contain itself (`a: &x [*x]`) or expand
/// exponentially (each level a list of two aliases of the one before), which a walk would
/// follow forever.
constexpr int kMaxDepth = 32;
constexpr std::size_t kMaxNodes = 100000;

/// Edit distance between two keys (optimal string alignment: insertions, deletions,
/// substitutions and swaps of neighbours each cost 1), for "did you mean".
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    }
  }
  return d[a.size()][b.size()];
}

}  // namespace

/// Why a DDS topic name is not the wire form of a ROS 2 topic (`rt/` + a fully qualified ROS
/// name: tokens of [A-Za-z0-9_] not starting with a digit, separated by single '/'), or "".
std::string ros_topic_problem(const std::string& name) {
  if (name.rfind("rt/", 0) != 0) return "is not a ROS 2 topic: ROS 2 nodes could not see it";
  const std::string ros = name.substr(2);  // "/ns/name"
  if (ros.size() < 2) return "has no name after the namespace";
  if (ros.back() == '/') return "ends with '/'";
  bool token_start = false;
  for (const char c : ros) {
    if (c == '/') {
      if (token_start) return "has an empty token ('//')";
      token_start = true;
      continue;
    }
    const bool alnum = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9');
    if (!alnum && c != '_') return std::string("has a character ROS 2 names refuse: '") + c + "'";
    if (token_start && c >= '0' && c <= '9') return "has a token starting with a digit";
    token_start = false;
  }
  return {};
}

/// `key` appended to `path` ("executor" + "rate_hz" -> "executor.rate_hz").
std::string join_path(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

std::string path_or_root(const std::string& path) {
  return path.empty() ? "<root>" : path;
}

/// The YAML line and column of a node, 1-based, for messages.
std::string where(const YAML::Mark& mark, bool with_column) {
  std::string s = "line " + std::to_string(mark.line + 1);
  if (with_column) s += " column " + std::to_string(mark.column + 1);
  return s;
}

/// What a node holds, for type errors: "a map", "a list", "a bool 'yes'", "a number '2.5'",
/// "a string 'abc'" (a quoted scalar is always a string).
std::string describe(const YAML::Node& node) {
  if (node.IsMap()) return "a map";
  if (node.IsSequence()) return "a list";
  if (!node.IsScalar()) return "nothing";
  const std::string quoted = "'" + node.Scalar() + "'";
  if (node.Tag() == "!") return "a string " + quoted;
  bool b = false;
  if (YAML::convert<bool>::decode(node, b)) return "a bool " + quoted;
  if (decodes_as_number(node)) return "a number " + quoted;
  return "a string " + quoted;
}

/// Refuses what yaml-cpp accepts silently, at every depth (maps inside lists included): a key
/// given twice in one map (yaml-cpp would keep the first and drop the other), a key that is
/// not a plain scalar, and nesting beyond kMaxDepth or kMaxNodes. `nodes` counts the visits.
void check_structure(const YAML::Node& node, const std::string& path, int depth,
                     std::size_t& nodes) {
  if (depth > kMaxDepth || ++nodes > kMaxNodes) {
    fail("structure", path_or_root(path),
         depth > kMaxDepth
             ? "nested deeper than " + std::to_string(kMaxDepth) +
                   " levels (an alias that contains itself?)"
             : "more than " + std::to_string(kMaxNodes) + " nodes (aliases that expand?)");
  }
  if (node.IsMap()) {
    std::vector<std::pair<std::string, YAML::Mark>> seen;
    for (const auto& kv : node) {
      if (!kv.first.IsScalar()) {
        fail("type", path_or_root(path),
             "keys must be strings, got " + describe(kv.first) + " at " +
                 where(kv.first.Mark(), true));
      }
      const std::string& key = kv.first.Scalar();
      const std::string key_path = join_path(path, key);
      for (const auto& [other, mark] : seen) {
        if (other != key) continue;
        const YAML::Mark again = kv.first.Mark();
        const bool same_line = mark.line == again.line;
        fail("duplicate_key", key_path,
             "duplicate key (" + where(mark, same_line) + " and " + where(again, same_line) + ")");
      }
      seen.emplace_back(key, kv.first.Mark());
      check_structure(kv.second, key_path, depth + 1, nodes);
    }
  } else if (node.IsSequence()) {
    std::size_t i = 0;
    for (const auto& item : node) {
      check_structure(item, path + "[" + std::to_string(i++) + "]", depth + 1, nodes);
    }
  }
}

/// A YAML bool (true/false, yes/no, on/off).
bool parse_bool(const YAML::Node& node, const std::string& path) {
  bool value = false;
  if (!node.IsScalar() || !YAML::convert<bool>::decode(node, value)) {
    fail("type", path, "expected a bool (true or false), got " + describe(node));
  }
  return value;
}

/// " (did you mean 'inflation_radius_m'?)" for the known key nearest to `key`, when one is near
/// enough to be a typo (a third of the key's length, 1 to 3 edits), else "".
std::string did_you_mean(const std::string& key, const std::vector<std::string>& known) {
  const std::size_t near = std::clamp<std::size_t>(key.size() / 3, 1, 3);
  std::string best;
  std::size_t best_distance = near + 1;
  for (const auto& candidate : known) {
    const std::size_t distance = edit_distance(key, candidate);
    if (distance < best_distance) {
      best = candidate;
      best_distance = distance;
    }
  }
  return best.empty() ? "" : " (did you mean '" + best + "'?)";
}

/// Why a topic key's value is refused, or "" (after mapping `/ns/name` to `rt/ns/name`).
void read_topic(const YAML::Node& node, const std::string& path, std::string& value) {
  const std::string given = node.Scalar();
  value = given;
  if (value.empty()) return;  // an output switched off, where the key allows it
  if (value.front() == '/') value = "rt" + value;
  const auto why = ros_topic_problem(value);
  if (!why.empty()) {
    fail("value", path,
         "'" + given + "' " + why + " (give a ROS 2 name such as /tarmac/costmap, or its DDS " +
             "form rt/tarmac/costmap)");
  }
}

}  // namespace tarmac::config::detail
