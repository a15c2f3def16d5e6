// tarmac-fleet: the site view for operations (docs/fleet.md "Site view"). Subscribes to every
// vehicle's fleet summaries (tarmac_msgs/FleetBev on fleet.topic) and writes the fused site-wide
// occupancy — site.npy, site.png in per-vehicle colours paling with age, site_vehicle.npy,
// site_age_s.npy, site.json — live (for --seconds, or until SIGINT/SIGTERM; --record keeps what
// it received) or from a recording (--play).

#include <signal.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "site_view.hpp"
#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/transport/fleet.hpp"

namespace {

using namespace tarmac;

std::atomic<bool> g_stop{false};

std::int64_t realtime_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

/// Applies summaries in stamp order (as tarmacd does), counting refusals by reason.
class Site final : public transport::FleetSink {
 public:
  Site(const config::Config& cfg, bool live)
      : peers_("", cfg.mapping.occupancy.voxel_size_m, std::llround(cfg.fleet.max_age_s * 1e9),
               live ? std::llround(cfg.executor.max_future_ms * 1e6) : INT64_MAX / 4) {}

  void summary(core::BevMessage&& m) override { batch_.push_back(std::move(m)); }
  void reject(std::string_view reason) override { refused_.emplace_back(reason); }

  /// Applies what was taken since the last call, at `now_ns` (a recording: each at its stamp).
  void apply(std::int64_t now_ns, fleet::Recorder* recorder) {
    core::sort_in_apply_order(batch_);
    for (const auto& m : batch_) {
      if (recorder != nullptr) {
        if (auto s = recorder->append(m); !s)
          std::fprintf(stderr, "tarmac-fleet: %s\n", s.error().message.c_str());
      }
      const std::int64_t at = now_ns != 0 ? now_ns : m.stamp_ns;
      if (auto s = peers_.apply(m, at); !s) refused_.push_back(s.error().code);
      newest_ns_ = std::max(newest_ns_, m.stamp_ns);
      ++taken_;
    }
    batch_.clear();
  }

  [[nodiscard]] const core::BevPeers& peers() const { return peers_; }
  [[nodiscard]] std::int64_t newest_ns() const { return newest_ns_; }
  [[nodiscard]] std::size_t taken() const { return taken_; }
  [[nodiscard]] const std::vector<std::string>& refused() const { return refused_; }

 private:
  core::BevPeers peers_;
  std::vector<core::BevMessage> batch_;
  std::vector<std::string> refused_;
  std::int64_t newest_ns_ = 0;
  std::size_t taken_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string config_path, out_dir, record, play, identity_dir;
  double seconds = 10.0;
  cli::App app("tarmac-fleet",
               "Site view: subscribes to every vehicle's fleet summaries (fleet.topic) and writes "
               "the fused site-wide occupancy as site.npy + site.png (per-vehicle colours, paler "
               "with age), site_vehicle.npy, site_age_s.npy and site.json; live, or from a "
               "recording.");
  app.add_option("--config", config_path,
                 "tarmacd config: DDS, fleet.topic, fleet.max_age_s "
                 "(default: the built-in defaults)")
      ->type_name("FILE");
  app.add_option("--out", out_dir, "output directory")->type_name("DIR")->required();
  app.add_option("--seconds", seconds, "live: listen this long (0: until SIGINT/SIGTERM)")
      ->transform(cli::in_range<double>(0.0, 86400.0));
  app.add_option("--record", record, "live: also append every summary received to FILE")
      ->type_name("FILE");
  app.add_option("--play", play, "read the summaries of a --record FILE instead of DDS")
      ->type_name("FILE")
      ->check(CLI::ExistingFile)
      ->excludes("--record");
  app.add_option("--identity", identity_dir,
                 "DDS Security identity DIR/cert.pem, DIR/key.pem instead of the config's (e.g. "
                 "make-dds-security.sh's 'monitor')")
      ->check(CLI::ExistingDirectory);
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  config::Config cfg;
  if (const int rc = config::load_tool_config("tarmac-fleet", config_path, cfg); rc != 0) return rc;

  Site site(cfg, play.empty());
  std::int64_t now_ns = 0;
  if (!play.empty()) {
    auto messages = fleet::read_recording(play);
    if (!messages) {
      std::fprintf(stderr, "tarmac-fleet: %s\n", messages.error().message.c_str());
      return 65;
    }
    for (auto& m : messages.value()) site.summary(std::move(m));
    site.apply(0, nullptr);
    now_ns = site.newest_ns();
  } else {
    cfg.dds.participant.name = "tarmac-fleet";
    if (!identity_dir.empty()) cfg.dds.participant.security.use_identity_dir(identity_dir);
    auto participant = transport::Participant::create(cfg.dds.participant);
    if (!participant) {
      std::fprintf(stderr, "tarmac-fleet: %s\n", participant.error().message.c_str());
      return 69;
    }
    transport::FleetLinkOptions options;
    options.topic = cfg.fleet.topic;
    options.frame_id = cfg.outputs.frame_id;
    options.queue_depth = 1024;
    auto link = transport::FleetLink::create(participant.value(), options);
    if (!link) {
      std::fprintf(stderr, "tarmac-fleet: %s\n", link.error().message.c_str());
      return 69;
    }
    std::optional<fleet::Recorder> recorder;
    if (!record.empty()) {
      auto opened = fleet::Recorder::open(record);
      if (!opened) {
        std::fprintf(stderr, "tarmac-fleet: %s\n", opened.error().message.c_str());
        return 73;
      }
      recorder = std::move(opened).value();
    }
    struct sigaction sa {};
    sa.sa_handler = [](int) { g_stop = true; };
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    std::printf("tarmac-fleet: listening on %s\n", options.topic.c_str());
    std::fflush(stdout);
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (!g_stop && (seconds == 0.0 || std::chrono::steady_clock::now() < end)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      link.value()->drain(site);
      site.apply(realtime_ns(), recorder ? &*recorder : nullptr);
    }
    link.value()->drain(site);
    site.apply(realtime_ns(), recorder ? &*recorder : nullptr);
    now_ns = realtime_ns();
  }

  const fleet::SiteView view = fleet::make_site_view(site.peers(), now_ns);
  if (auto s = fleet::write_site_view(view, site.peers(), out_dir); !s) {
    std::fprintf(stderr, "tarmac-fleet: %s\n", s.error().message.c_str());
    return 73;
  }
  std::size_t known = 0, occupied = 0;
  for (const auto c : view.state) {
    known += c >= 0 ? 1 : 0;
    occupied += c == 100 ? 1 : 0;
  }
  std::printf(
      "tarmac-fleet: %zu summaries from %zu vehicles (%zu refused); site %u x %u cells at "
      "%.2f m, %zu known, %zu occupied; wrote %s\n",
      site.taken(), view.vehicles.size(), site.refused().size(), view.width, view.height,
      view.resolution_m, known, occupied, out_dir.c_str());
  return 0;
}
