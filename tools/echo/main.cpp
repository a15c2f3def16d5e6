// tarmac-echo: subscribes to one tarmac topic over localhost DDS and prints one line per sample
// (stamp, frame, sizes and the fields that matter). The type follows from the topic name, as the
// config names it (default topics of README "DDS types and topics").

#include <signal.h>
#include <time.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "diagnostic_msgsPubSubTypes.h"
#include "geometry_msgsPubSubTypes.h"
#include "nav_msgsPubSubTypes.h"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac_msgsPubSubTypes.h"

namespace {

using namespace tarmac;
using namespace std::chrono_literals;

std::atomic<bool> g_stop{false};

double seconds(const transport::TimeMsg& t) {
  return static_cast<double>(transport::from_time_msg(t)) / 1e9;
}

double age_ms(const transport::TimeMsg& t) {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  const std::int64_t now = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
  return static_cast<double>(now - transport::from_time_msg(t)) / 1e6;
}

void print(const transport::OccupancyGridMsg& m) {
  std::size_t unknown = 0, lethal = 0;
  for (const auto c : m.data()) {
    unknown += c < 0 ? 1 : 0;
    lethal += c >= 100 ? 1 : 0;
  }
  std::printf("costmap stamp %.3f (age %.1f ms) frame %s %ux%u @ %.2f m, %zu lethal, %zu unknown\n",
              seconds(m.header().stamp()), age_ms(m.header().stamp()),
              m.header().frame_id().c_str(), m.info().width(), m.info().height(),
              m.info().resolution(), lethal, unknown);
}

void print(const transport::DistanceMapSliceMsg& m) {
  float nearest = INFINITY;
  for (const float d : m.distance()) {
    if (!std::isnan(d)) nearest = std::min(nearest, d);
  }
  std::printf("esdf_slice stamp %.3f frame %s %ux%u @ %.2f m, min distance %.2f m\n",
              seconds(m.header().stamp()), m.header().frame_id().c_str(), m.width(), m.height(),
              m.resolution(), nearest);
}

void print(const transport::DistanceMapVolumeMsg& m) {
  float nearest = INFINITY;
  for (const float d : m.distance()) {
    if (!std::isnan(d)) nearest = std::min(nearest, d);
  }
  std::printf(
      "esdf_band stamp %.3f frame %s %ux%ux%u @ %.2f m from z %.2f m, min distance %.2f m\n",
      seconds(m.header().stamp()), m.header().frame_id().c_str(), m.width(), m.height(), m.depth(),
      m.resolution(), m.origin().position().z(), nearest);
}

void print(const transport::CycleReportMsg& m) {
  std::string stages;
  for (const auto& s : m.stages()) {
    char buf[64];
    std::snprintf(buf, sizeof buf, " %s=%.2f%s", s.name().c_str(), s.duration_ms(),
                  s.overrun() ? "!" : "");
    stages += buf;
  }
  std::printf(
      "cycle %llu tick %.3f jitter %.3f ms skipped %u: %.2f/%.0f ms%s, points %llu/%llu, columns "
      "changed %u, debris %u%s\n",
      static_cast<unsigned long long>(m.cycle_index()), seconds(m.tick_time()), m.wake_jitter_ms(),
      m.skipped_ticks(), m.cycle_duration_ms(), m.cycle_budget_ms(), stages.c_str(),
      static_cast<unsigned long long>(m.points_used()),
      static_cast<unsigned long long>(m.points_in()), m.columns_changed(), m.debris(),
      m.overrun() ? " OVERRUN" : "");
}

void print(const transport::DebrisArrayMsg& m) {
  std::printf("debris stamp %.3f frame %s: %zu\n", seconds(m.header().stamp()),
              m.header().frame_id().c_str(), m.objects().size());
  for (const auto& d : m.objects()) {
    std::printf(
        "  id %u at %.2f %.2f (ground z %.2f m) height %.2f m footprint %.2f m, first seen %.3f, "
        "last confirmed %.3f, %u returns\n",
        d.id(), d.position().x(), d.position().y(), d.position().z(), d.height_m(), d.footprint_m(),
        seconds(d.first_seen()), seconds(d.last_confirmed()), d.returns());
  }
}

void print(const transport::DiagnosticArrayMsg& m) {
  for (const auto& s : m.status()) {
    std::string values;
    for (const auto& kv : s.values()) values += " " + kv.key() + "=" + kv.value();
    std::printf("diagnostics %s level %d '%s':%s\n", s.name().c_str(), s.level(),
                s.message().c_str(), values.c_str());
  }
}

void print(const transport::PoseStampedMsg& m) {
  const auto& p = m.pose().pose();
  std::printf("pose stamp %.3f frame %s position %.3f %.3f %.3f orientation %.4f %.4f %.4f %.4f\n",
              seconds(m.header().stamp()), m.header().frame_id().c_str(), p.position().x(),
              p.position().y(), p.position().z(), p.orientation().x(), p.orientation().y(),
              p.orientation().z(), p.orientation().w());
}

void print(const transport::PointCloud2Msg& m) {
  std::string fields;
  for (const auto& f : m.fields()) fields += " " + f.name();
  std::printf("cloud stamp %.3f (age %.1f ms) frame %s %ux%u points, step %u, fields:%s\n",
              seconds(m.header().stamp()), age_ms(m.header().stamp()),
              m.header().frame_id().c_str(), m.width(), m.height(), m.point_step(), fields.c_str());
}

void print(const transport::VirtualObstacleArrayMsg& m) {
  std::printf("virtual_obstacles stamp %.3f: %zu zones\n", seconds(m.header().stamp()),
              m.obstacles().size());
}

template <typename PubSubType>
int echo(const transport::Participant& participant, const std::string& topic,
         const transport::QosSpec& qos, std::size_t count) {
  auto reader = transport::Reader<PubSubType>::create(participant, topic, qos, 64);
  if (!reader) {
    std::fprintf(stderr, "tarmac-echo: %s\n", reader.error().message.c_str());
    return 69;
  }
  std::vector<typename PubSubType::type> batch;
  std::size_t seen = 0;
  while (!g_stop && (count == 0 || seen < count)) {
    reader.value()->wait_for_sample(100ms);
    batch.clear();
    reader.value()->take_all(batch);
    for (const auto& m : batch) {
      print(m);
      std::fflush(stdout);
      if (count != 0 && ++seen >= count) break;
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string topic, config_path, identity_dir;
  std::size_t count = 0;
  cli::App app("tarmac-echo",
               "Subscribes to one tarmac topic over localhost DDS and prints one line per sample "
               "until --count or SIGINT.");
  app.add_option("topic", topic,
                 "any topic of the config (costmap, esdf slice, esdf band, cycle report, "
                 "DiagnosticArray, pose, a sensor's points, virtual obstacles), e.g. "
                 "rt/tarmac/costmap")
      ->type_name("TOPIC")
      ->required();
  app.add_option("--config", config_path, "tarmacd config (default: the built-in defaults)")
      ->type_name("FILE");
  app.add_option("--count", count, "stop after N samples (0: no limit)")
      ->transform(cli::number<std::size_t>());
  app.add_option("--identity", identity_dir,
                 "DDS Security identity DIR/cert.pem, DIR/key.pem instead of the config's "
                 "(dds.security; e.g. make-dds-security.sh's 'monitor')")
      ->check(CLI::ExistingDirectory);
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  config::Config cfg;
  if (const int rc = config::load_tool_config("tarmac-echo", config_path, cfg); rc != 0) return rc;
  cfg.dds.participant.name = "tarmac-echo";
  if (!identity_dir.empty()) cfg.dds.participant.security.use_identity_dir(identity_dir);
  auto participant = transport::Participant::create(cfg.dds.participant);
  if (!participant) {
    std::fprintf(stderr, "tarmac-echo: %s\n", participant.error().message.c_str());
    return 69;
  }
  struct sigaction sa {};
  sa.sa_handler = [](int) { g_stop = true; };
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  const auto& q = cfg.dds.qos;
  const auto& o = cfg.outputs;
  const auto& p = participant.value();
  if (topic == o.costmap_topic) {
    return echo<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>(p, topic, q.costmap, count);
  }
  if (topic == o.esdf_slice_topic) {
    return echo<tarmac_msgs::msg::dds_::DistanceMapSlice_PubSubType>(p, topic, q.esdf_slice, count);
  }
  if (topic == o.esdf_band_topic) {
    return echo<tarmac_msgs::msg::dds_::DistanceMapVolume_PubSubType>(p, topic, q.esdf_band, count);
  }
  if (!o.debris_topic.empty() && topic == o.debris_topic) {
    return echo<tarmac_msgs::msg::dds_::DebrisArray_PubSubType>(p, topic, q.debris, count);
  }
  if (topic == o.cycle_report_topic) {
    return echo<tarmac_msgs::msg::dds_::CycleReport_PubSubType>(p, topic, q.diagnostics, count);
  }
  if (topic == o.diagnostic_array_topic) {
    return echo<diagnostic_msgs::msg::dds_::DiagnosticArray_PubSubType>(p, topic, q.diagnostics,
                                                                        count);
  }
  if (topic == o.virtual_obstacles_topic) {
    return echo<tarmac_msgs::msg::dds_::VirtualObstacleArray_PubSubType>(
        p, topic, q.virtual_obstacles, count);
  }
  if (topic == cfg.pose.topic && cfg.pose.type == config::PoseType::kPoseWithCovarianceStamped) {
    return echo<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>(p, topic, q.pose,
                                                                                count);
  }
  for (const auto& s : cfg.sensors) {
    if (topic == s.topic) {
      return echo<sensor_msgs::msg::dds_::PointCloud2_PubSubType>(p, topic, q.lidar, count);
    }
  }
  return cli::usage_error(app, topic + " is not a topic of this config");
}
