// libFuzzer target: config::load_config_string, tarmacd's YAML loader (yaml-cpp underneath).
// The fuzz bytes are the file's text. Properties: a load either succeeds or fails with a
// "config.*" code and a message; an accepted config written back out (to_yaml) loads again and
// writes exactly the same text (so the same config hash).
// Seeds: the defaults as written by to_yaml, the shipped example files, and a few YAML shapes
// (anchors, merge keys, flow maps, duplicates, non-finite numbers, deep nesting). The
// dictionary holds every key the loader knows, taken from to_yaml, plus YAML syntax tokens.

#include <algorithm>
#include <cmath>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "fuzz_bytes.hpp"
#include "tarmac/config/config.hpp"

namespace tarmac::fuzz {
namespace {

Bytes text(const std::string& s) {
  return Bytes(s.begin(), s.end());
}

Bytes file(const std::string& relative) {
  std::ifstream in(std::string(TARMAC_SOURCE_DIR) + "/" + relative);
  std::ostringstream s;
  s << in.rdbuf();
  if (s.str().empty()) {
    std::fprintf(stderr, "seed source %s is missing or empty\n", relative.c_str());
    std::exit(1);
  }
  return text(s.str());
}

const std::vector<Bytes>& seeds() {
  static const std::vector<Bytes> all = [] {
    std::vector<Bytes> s;
    s.push_back(text(config::to_yaml(config::Config{})));
    s.push_back(file("config/tarmac.yaml"));
    s.push_back(file("config/four_lidars.yaml"));
    s.push_back(file("tests/config/bad_unknown_key.yaml"));
    s.push_back(text("version: 1\n"));
    s.push_back(text("version: 2\n"));
    s.push_back(text("version: 1\nexecutor: {rate_hz: .nan, input_delay_ms: -.inf}\n"));
    s.push_back(text("version: 1\nexecutor:\n  rate_hz: 10\n  rate_hz: 20\n"));
    s.push_back(text("version: 1\nbase: &b {voxel_size_m: 0.2}\nmapping:\n  occupancy: *b\n"));
    s.push_back(text("version: 1\nmapping:\n  occupancy:\n    <<: {voxel_size_m: 0.2}\n"));
    s.push_back(
        text("version: 1\nsensors:\n  - id: a\n    topic: /lidar/a\n"
             "    extrinsic: {translation: [1, 2, 0x10], rpy_deg: [0, 0, 1e400]}\n"));
    s.push_back(text("version: 1\n? [a, b]\n: 1\n"));
    s.push_back(text("version: !!str 1\ndds: {domain_id: ~}\n"));
    s.push_back(text(std::string(200, '[') + std::string(200, ']')));
    s.push_back(text("version: 1\n" + std::string(100, '{') + std::string(100, '}') + "\n"));
    return s;
  }();
  return all;
}

std::vector<std::string> dictionary() {
  std::set<std::string> words;
  const std::string yaml = config::to_yaml(config::Config{});
  const std::regex word("[A-Za-z_][A-Za-z0-9_]*");
  for (auto it = std::sregex_iterator(yaml.begin(), yaml.end(), word); it != std::sregex_iterator();
       ++it) {
    words.insert(it->str());
  }
  std::vector<std::string> dict(words.begin(), words.end());
  for (const char* token :
       {": ",   "- ",    "{",      "}",      "[",        "]",      ", ",    "&a ",     "*a",
        "<<: ", "? ",    "!!str ", "!!int ", "!!float ", "!!map ", "---\n", "...\n",   ".nan",
        ".inf", "-.inf", "~",      "0x",     "0o",       "1e999",  "|\n",   ">\n",     "'",
        "\"",   "#",     "\n  ",   "true",   "false",    "null",   "rt/",   "/tarmac/"}) {
    dict.emplace_back(token);
  }
  return dict;
}

}  // namespace
}  // namespace tarmac::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  tarmac::fuzz::handle_make_seeds(argc, argv, &tarmac::fuzz::seeds, tarmac::fuzz::dictionary());
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tarmac;
  const std::string text(reinterpret_cast<const char*>(data), size);
  const auto loaded = config::load_config_string(text);
  if (!loaded) {
    TARMAC_FUZZ_CHECK(loaded.error().code.rfind("config.", 0) == 0);
    TARMAC_FUZZ_CHECK(!loaded.error().message.empty());
    return 0;
  }
  const std::string written = config::to_yaml(loaded.value());
  const auto reloaded = config::load_config_string(written);
  if (!reloaded) {
    std::fprintf(stderr, "to_yaml output refused: %s: %s\n%s\n", reloaded.error().code.c_str(),
                 reloaded.error().message.c_str(), written.c_str());
  }
  TARMAC_FUZZ_CHECK(reloaded.ok());
  const std::string rewritten = config::to_yaml(reloaded.value());
  if (rewritten != written) {
    std::fprintf(stderr, "to_yaml changed on reload:\n--- first\n%s\n--- reloaded\n%s\n",
                 written.c_str(), rewritten.c_str());
    std::abort();
  }
  return 0;
}
