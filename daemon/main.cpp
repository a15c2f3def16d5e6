// tarmacd: the mapping daemon's entry point (composition root).
//
// This build validates its config and brings up the DDS participant; the fixed-rate executor,
// the stages and the systemd integration land with issue 5 ("tarmacd: deterministic fixed-rate
// executor"). Until then running without --check-config says so and exits with code 3.

#include <cstdio>
#include <cstring>
#include <string>

#include <spdlog/spdlog.h>

#include "tarmac/config/config.hpp"
#include "tarmac/transport/participant.hpp"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitUsage = 64;   // EX_USAGE
constexpr int kExitConfig = 78;  // EX_CONFIG
constexpr int kExitDds = 69;     // EX_UNAVAILABLE
constexpr int kExitNotYet = 3;

void usage(std::FILE* out) {
  std::fprintf(out,
               "usage: tarmacd --config FILE        run the daemon\n"
               "       tarmacd --check-config FILE  validate FILE and exit (0 valid, %d invalid)\n"
               "       tarmacd --version\n",
               kExitConfig);
}

}  // namespace

int main(int argc, char** argv) {
  std::string config_path;
  bool check_only = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if ((arg == "--config" || arg == "--check-config") && i + 1 < argc) {
      check_only = check_only || arg == "--check-config";
      config_path = argv[++i];
    } else if (arg == "--version") {
      std::printf("tarmacd %s\n", TARMAC_VERSION);
      return kExitOk;
    } else if (arg == "--help" || arg == "-h") {
      usage(stdout);
      return kExitOk;
    } else {
      std::fprintf(stderr, "tarmacd: unexpected argument '%s'\n", arg.c_str());
      usage(stderr);
      return kExitUsage;
    }
  }
  if (config_path.empty()) {
    usage(stderr);
    return kExitUsage;
  }

  auto config = tarmac::config::load_config_file(config_path);
  if (!config) {
    std::fprintf(stderr, "tarmacd: invalid config: %s [%s]\n", config.error().message.c_str(),
                 config.error().code.c_str());
    return kExitConfig;
  }
  const std::string hash = tarmac::config::config_hash(config.value());
  if (check_only) {
    std::printf("%s: valid (config hash %s)\n", config_path.c_str(), hash.c_str());
    return kExitOk;
  }

  spdlog::info("tarmacd {} starting, config {} (hash {})", TARMAC_VERSION, config_path, hash);
  spdlog::info("effective config:\n{}", tarmac::config::to_yaml(config.value()));
  auto participant = tarmac::transport::Participant::create(config.value().dds.participant);
  if (!participant) {
    spdlog::error("DDS: {} [{}]", participant.error().message, participant.error().code);
    return kExitDds;
  }
  spdlog::info("DDS participant up on domain {} (transport {})",
               config.value().dds.participant.domain_id,
               tarmac::transport::to_string(config.value().dds.participant.transport));
  spdlog::error("the executor is not built yet (issue 5); exiting");
  return kExitNotYet;
}
