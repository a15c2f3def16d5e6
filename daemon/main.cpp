// tarmacd: the mapping daemon's entry point (composition root).
//
// Validates the config, creates every DDS entity, tells systemd READY=1, then runs the fixed-rate
// executor on this thread until SIGTERM or SIGINT: STOPPING=1, the occupancy window and the TSDF
// are saved to the state directory, exit 0. The saved TSDF is loaded before READY=1 (a file
// tsdf_io refuses is logged, moved aside, and the daemon starts with an empty TSDF).
//
// A stop signal ends tarmacd within one second whatever it is doing (StopSignals): during the
// startup it exits at once with 0 (nothing to save yet); in the loop the executor sees it within
// 100 ms while asleep or when the current tick completes (a stop never cuts a cycle in half),
// then the map is saved; a tick still running 900 ms after the signal is stuck, and the process
// exits 70 without saving.

#include <cstdio>
#include <cstring>
#include <string>

#include <spdlog/spdlog.h>

#include <systemd/sd-daemon.h>

#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/config/schema.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/daemon/stop_signals.hpp"
#include "tarmac/transport/participant.hpp"

namespace {

constexpr int kExitOk = 0;
constexpr int kExitConfig = 78;  // EX_CONFIG
constexpr int kExitDds = 69;     // EX_UNAVAILABLE

}  // namespace

int main(int argc, char** argv) {
  std::string config_path;
  bool print_reference = false;
  tarmac::cli::App app("tarmacd", "tarmac's real-time LiDAR mapping daemon.");
  auto* run =
      app.add_option("--config", config_path, "run the daemon with this config")->type_name("FILE");
  auto* check =
      app.add_option("--check-config", config_path, "validate FILE and exit (0 valid, 78 invalid)")
          ->type_name("FILE")
          ->excludes(run);
  auto* print = app.add_option("--print-config", config_path,
                               "print the effective config of FILE as YAML, every default filled "
                               "in, and exit (0 valid, 78 invalid)")
                    ->type_name("FILE")
                    ->excludes(run)
                    ->excludes(check);
  app.add_flag("--print-config-reference", print_reference,
               "print every config key (type, default, range, unit, doc) as a "
               "Markdown table and exit")
      ->excludes(run)
      ->excludes(check)
      ->excludes(print);
  app.footer(
      "Exit status: 0 stopped by SIGTERM/SIGINT (map saved) or config valid, 64 usage, 69 DDS "
      "unavailable, 70 a tick stuck at stop (map not saved), 78 config invalid.");
  if (auto exit = tarmac::cli::parse(app, argc, argv)) return *exit;
  if (print_reference) {
    std::fputs(tarmac::config::reference_markdown().c_str(), stdout);
    return kExitOk;
  }
  if (config_path.empty()) {
    return tarmac::cli::usage_error(
        app, "--config FILE, --check-config FILE or --print-config FILE is required");
  }
  const bool check_only = check->count() > 0 || print->count() > 0;

  // Running (not only checking): from here a stop signal is handled, not fatal. Before any
  // thread exists, so every thread inherits the blocked mask and only StopSignals' own thread
  // takes the signals. (Before main() runs, while the binary loads, a SIGTERM kills the process,
  // which systemd counts as a clean stop.)
  tarmac::daemon::StopSignals* stop = nullptr;
  if (!check_only) stop = &tarmac::daemon::StopSignals::install();

  auto config = tarmac::config::load_config_file(config_path);
  if (!config) {
    std::fprintf(stderr, "tarmacd: invalid config: %s [%s]\n", config.error().message.c_str(),
                 config.error().code.c_str());
    return kExitConfig;
  }
  const std::string hash = tarmac::config::config_hash(config.value());
  if (print->count() > 0) {
    std::printf("%s\n", tarmac::config::to_yaml(config.value()).c_str());
    return kExitOk;
  }
  if (check_only) {
    std::printf("%s: valid (config hash %s)\n", config_path.c_str(), hash.c_str());
    return kExitOk;
  }

  spdlog::info("tarmacd {} starting, config {} (hash {})", TARMAC_VERSION, config_path, hash);
  spdlog::info("effective config:\n{}", tarmac::config::to_yaml(config.value()));
  auto executor = tarmac::daemon::Executor::create(config.value());
  if (!executor) {
    spdlog::error("startup: {} [{}]", executor.error().message, executor.error().code);
    return executor.error().code.rfind("config.", 0) == 0 ? kExitConfig : kExitDds;
  }
  const auto& security = config.value().dds.participant.security;
  spdlog::info("DDS up on domain {} (transport {}, security {}); {} LiDAR input(s), poses on {}",
               config.value().dds.participant.domain_id,
               tarmac::transport::to_string(config.value().dds.participant.transport),
               security.enabled ? "on, identity " + security.identity_certificate : "off",
               config.value().sensors.size(), config.value().pose.topic);
  for (const auto& shortfall :
       tarmac::transport::udp_buffer_shortfalls(config.value().dds.participant)) {
    spdlog::warn("DDS: {}", shortfall);
  }
  executor.value()->load_tsdf();  // logs what it found; never fails the start
  executor.value()->prepare();    // memory locked, workers up: the first tick follows READY
  // Before READY=1: a stop from here on (systemd sends it as soon as it sees READY) reaches the
  // loop and the map is saved.
  stop->begin_loop();
  sd_notify(0, "READY=1");
  spdlog::info("tarmacd: ready (READY=1 sent), first tick within one period");

  tarmac::daemon::RunHooks hooks;
  hooks.on_loop_end = [stop] { stop->loop_ended(); };
  executor.value()->run([stop] { return stop->requested(); }, hooks);
  sd_notify(0, "STOPPING=1");
  spdlog::info("tarmacd: {} received, stopping ({})", strsignal(stop->signal()),
               executor.value()->status_line());
  if (config.value().state.save_on_exit) {
    if (auto saved = executor.value()->save_map(); !saved) {
      spdlog::error("state: map not saved: {} [{}]", saved.error().message, saved.error().code);
    } else {
      spdlog::info("state: occupancy window saved to {}/{}", config.value().state.dir,
                   config.value().state.map_file);
    }
    if (config.value().mapping.tsdf.enabled) {
      if (auto saved = executor.value()->save_tsdf(); !saved) {
        spdlog::error("state: TSDF not saved: {} [{}]", saved.error().message, saved.error().code);
      } else {
        spdlog::info("state: TSDF saved to {}/{} ({} voxels)", config.value().state.dir,
                     config.value().state.tsdf_file, executor.value()->tsdf().voxel_count());
      }
    }
  }
  return kExitOk;
}
