#include "tarmac/replay/replayer.hpp"

#include <time.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include "conversions.hpp"
#include "dds_endpoints.hpp"
#include "geometry_msgsPubSubTypes.h"
#include "nav_msgsPubSubTypes.h"
#include "sensor_msgsPubSubTypes.h"
#include "tarmac/daemon/clock.hpp"
#include "tarmac/replay/driver_message.hpp"
#include "tarmac/transport/qos.hpp"

namespace tarmac::tools {

namespace {

std::int64_t realtime_ns() {
  return daemon::clock_now_ns(CLOCK_REALTIME);
}

void sleep_until_realtime(std::int64_t t_ns) {
  daemon::clock_sleep_until_ns(CLOCK_REALTIME, t_ns);
}

enum class EventKind : std::uint8_t { kScan, kPose, kCorrection };

struct Event {
  std::int64_t publish_ns;
  std::size_t index;  ///< scan (kScan, kPose) or correction (kCorrection)
  EventKind kind;
};

/// The replay stamp of a sequence stamp: that of the scan with this time when there is one (bit
/// for bit), else re-based the same way.
std::int64_t replay_stamp(std::int64_t t_ns, const KittiSequence& seq, std::size_t n,
                          const std::vector<std::int64_t>& stamps, std::int64_t start,
                          double rate_scale) {
  for (std::size_t k = 0; k < n; ++k) {
    if (std::llround(seq.times_s[k] * 1e9) == t_ns) return stamps[k];
  }
  return start +
         std::llround((static_cast<double>(t_ns) / 1e9 - seq.times_s[0]) * 1e9 / rate_scale);
}

/// `cloud` (rows × cols, row-major, channels with it) transposed to cols × rows, in place
/// (`scratch` holds the other copy).
void transpose(core::PointCloud& cloud, std::size_t rows, std::size_t cols,
               core::PointCloud& scratch) {
  const auto swap_in = [&](auto& channel, auto& spare) {
    if (channel.empty()) return;
    spare.resize(channel.size());
    for (std::size_t r = 0; r < rows; ++r) {
      for (std::size_t c = 0; c < cols; ++c) spare[c * rows + r] = channel[r * cols + c];
    }
    channel.swap(spare);
  };
  swap_in(cloud.points_S, scratch.points_S);
  swap_in(cloud.intensity, scratch.intensity);
  swap_in(cloud.ring, scratch.ring);
  swap_in(cloud.time_offset_s, scratch.time_offset_s);
}

/// Keeps the returns of `cloud` (finite, not 0,0,0) and their channels, in order: what a
/// driver that publishes unorganised clouds sends (it drops the beams without return).
void drop_no_returns(core::PointCloud& cloud) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& p = cloud.points_S[i];
    if (!p.allFinite() || p.isZero(0.0f)) continue;
    cloud.points_S[kept] = p;
    if (cloud.has_intensity()) cloud.intensity[kept] = cloud.intensity[i];
    if (cloud.has_ring()) cloud.ring[kept] = cloud.ring[i];
    if (cloud.has_time()) cloud.time_offset_s[kept] = cloud.time_offset_s[i];
    ++kept;
  }
  cloud.points_S.resize(kept);
  if (cloud.has_intensity()) cloud.intensity.resize(kept);
  if (cloud.has_ring()) cloud.ring.resize(kept);
  if (cloud.has_time()) cloud.time_offset_s.resize(kept);
}

}  // namespace

Eigen::Isometry3d base_pose(const Eigen::Isometry3d& T_W_S, const Eigen::Isometry3d& T_B_S) {
  return T_W_S * T_B_S.inverse();
}

core::Result<std::function<bool(std::size_t, std::int64_t)>> pace_by_costmap(
    const transport::Participant& participant, const std::string& costmap_topic,
    const transport::QosSpec& costmap_qos, std::size_t ahead, std::chrono::milliseconds patience,
    const std::atomic<bool>* stop) {
  using GridReader = transport::Reader<nav_msgs::msg::dds_::OccupancyGrid_PubSubType>;
  auto created = GridReader::create(participant, costmap_topic, costmap_qos, 8);
  if (!created) return created.error();
  struct State {
    std::unique_ptr<GridReader> reader;
    std::vector<std::int64_t> stamps;  ///< of the scans paced so far, by index
    std::int64_t newest_ns = INT64_MIN;
    std::vector<transport::OccupancyGridMsg> batch;
  };
  auto state = std::make_shared<State>();
  state->reader = std::move(created).value();
  return std::function<bool(std::size_t, std::int64_t)>(
      [state, ahead, patience, stop](std::size_t k, std::int64_t stamp_ns) {
        State& st = *state;
        st.stamps.resize(k + 1);
        st.stamps[k] = stamp_ns;
        if (k < ahead) return true;
        const std::int64_t needed = st.stamps[k - ahead];
        auto deadline = std::chrono::steady_clock::now() + patience;
        while (st.newest_ns < needed) {
          if (std::chrono::steady_clock::now() > deadline) return false;
          if (stop != nullptr && stop->load()) return false;
          st.reader->wait_for_sample(std::chrono::milliseconds(50));
          st.batch.clear();
          st.reader->take_all(st.batch);
          for (const auto& g : st.batch) {
            const std::int64_t stamp = transport::from_time_msg(g.header().stamp());
            if (stamp > st.newest_ns) {
              st.newest_ns = stamp;
              deadline = std::chrono::steady_clock::now() + patience;  // progress
            }
          }
        }
        return true;
      });
}

namespace {

/// The scans' stamps on the sender's clock (CLOCK_REALTIME + clock_offset_ns), the first at
/// `start`: the sequence's spacing over rate_scale, loop after loop.
std::vector<std::int64_t> scan_stamps(const KittiSequence& seq, std::size_t n,
                                      const ReplayOptions& options, std::int64_t& start) {
  const std::size_t total = n * options.loops;
  start = options.start_ns != 0 ? options.start_ns
                                : realtime_ns() + options.clock_offset_ns +
                                      static_cast<std::int64_t>(options.lead_ms * 1e6);
  if (options.start_ns == 0 && options.align_ms > 0.0) {
    const auto grid = static_cast<std::int64_t>(std::llround(options.align_ms * 1e6));
    start = (start / grid + 1) * grid;
  }
  // A loop lasts the sequence plus one scan interval, so stamps keep their spacing across loops.
  const double step_s =
      n > 1 ? (seq.times_s[n - 1] - seq.times_s[0]) / static_cast<double>(n - 1) : 0.1;
  const double loop_s = seq.times_s[n - 1] - seq.times_s[0] + step_s;
  std::vector<std::int64_t> stamps(total);
  for (std::size_t k = 0; k < total; ++k) {
    const double t_s = seq.times_s[k % n] - seq.times_s[0] + static_cast<double>(k / n) * loop_s;
    stamps[k] = start + std::llround(t_s * 1e9 / options.rate_scale);
  }
  return stamps;
}

/// Every message to send, in the order of their send times (CLOCK_REALTIME): each scan's pose
/// and cloud, jittered, and each correction after its scan. Errors: "replay.options".
core::Result<std::vector<Event>> schedule(const std::vector<std::int64_t>& stamps, std::size_t n,
                                          const ReplayOptions& options) {
  const std::size_t total = stamps.size();
  const std::int64_t offset = options.clock_offset_ns;
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> jitter(0.0, std::max(0.0, options.jitter_ms) * 1e6);
  std::vector<Event> events;
  events.reserve(2 * total);
  for (std::size_t k = 0; k < total; ++k) {
    const Event scan{stamps[k] - offset + std::llround(jitter(rng)), k, EventKind::kScan};
    const bool in_gap =
        k >= options.pose_gap_first && k < options.pose_gap_first + options.pose_gap_count;
    if (options.publish_poses && (options.pose_count == 0 || k < options.pose_count) && !in_gap) {
      // Without jitter the pose leaves first (the sort below is stable): a scan that reaches a
      // busy daemon late then finds its pose there, rather than waiting for it.
      events.push_back({stamps[k] - offset + std::llround(jitter(rng)), k, EventKind::kPose});
    }
    events.push_back(scan);
  }
  // After its scan whatever the jitter: a localiser corrects what it has seen.
  const auto jitter_bound = static_cast<std::int64_t>(std::ceil(jitter.max())) + 1;
  for (std::size_t c = 0; c < options.corrections.size(); ++c) {
    const std::size_t after = options.corrections[c].after_scan;
    if (after >= n || options.corrections[c].trajectory_W_S.empty()) {
      return core::Error{"replay.options", "correction " + std::to_string(c) + ": after scan " +
                                               std::to_string(after) + " of " + std::to_string(n) +
                                               ", or empty"};
    }
    events.push_back(
        {stamps[after] - offset + jitter_bound - std::llround(options.correction_lead_s * 1e9), c,
         EventKind::kCorrection});
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const Event& a, const Event& b) { return a.publish_ns < b.publish_ns; });
  return events;
}

/// Scan `index`'s cloud as the configured driver or layout publishes it. Errors:
/// read_kitti_scan's, "dataset.scan".
core::Result<transport::PointCloud2Msg> scan_message(const KittiSequence& seq, std::size_t n,
                                                     std::size_t index, std::int64_t stamp,
                                                     const ReplayOptions& options,
                                                     core::PointCloud& cloud,
                                                     core::PointCloud& transposed) {
  // Organised sweeps (tarmac-sim) go out organised, NaN where a beam returned nothing, as a
  // spinning LiDAR's driver publishes them.
  const bool organised = !seq.organised.empty();
  if (auto read =
          read_kitti_scan(organised ? seq.organised[index % n] : seq.scans[index % n], cloud);
      !read) {
    return read.error();
  }
  if (organised && cloud.size() != seq.rows * seq.cols) {
    return core::Error{"dataset.scan", seq.organised[index % n].string() +
                                           ": not rows x cols of organised/shape.txt"};
  }
  cloud.frame_id = options.frame_id;
  cloud.stamp_ns = stamp;
  std::size_t height = seq.rows, width = seq.cols;
  transport::PointCloud2Msg msg;
  if (organised && options.driver) {
    // The driver's message of the (instantaneous) sweep taken at the scan's stamp.
    msg = driver_sweep_message(cloud, seq.rows, seq.cols, *options.driver, cloud.stamp_ns, 0.0,
                               options.frame_id);
  } else {
    if (organised) {
      if (options.ring_field) {
        cloud.ring.resize(cloud.size());
        for (std::size_t i = 0; i < cloud.size(); ++i) {
          cloud.ring[i] = static_cast<std::uint16_t>(i / seq.cols);
        }
      }
      if (options.layout != ReplayOptions::Layout::kRowsAreBeams) {
        transpose(cloud, seq.rows, seq.cols, transposed);
        std::swap(height, width);
      }
      if (options.layout == ReplayOptions::Layout::kUnorganised) {
        drop_no_returns(cloud);  // in firing order, as Hesai's and Velodyne's lists come
        height = 1;
      }
    }
    msg = transport::to_point_cloud2(cloud);
    if (organised && height > 1) {
      msg.height(static_cast<std::uint32_t>(height));
      msg.width(static_cast<std::uint32_t>(width));
      msg.row_step(msg.point_step() * msg.width());
      msg.is_dense(false);
    }
  }
  return msg;
}

/// Correction `c` as a nav_msgs/Path of base poses, stamped on the replay's clock.
transport::PathMsg correction_message(const Correction& c, const KittiSequence& seq, std::size_t n,
                                      const std::vector<std::int64_t>& stamps, std::int64_t start,
                                      const ReplayOptions& options) {
  transport::PathMsg msg;
  msg.header().stamp(transport::to_time_msg(stamps[c.after_scan]));
  msg.header().frame_id(options.pose_frame_id);
  for (const auto& p : c.trajectory_W_S) {
    geometry_msgs::msg::dds_::PoseStamped_ ps;
    ps.header().stamp(transport::to_time_msg(
        replay_stamp(p.stamp_ns, seq, n, stamps, start, options.rate_scale)));
    ps.header().frame_id(options.pose_frame_id);
    ps.pose(transport::to_pose_msg(base_pose(p.T_W_B, options.T_base_sensor)));
    msg.poses().push_back(std::move(ps));
  }
  return msg;
}

}  // namespace

core::Result<ReplayStats> replay(const transport::Participant& participant,
                                 const KittiSequence& seq, const ReplayOptions& options,
                                 const std::atomic<bool>* stop) {
  using CloudWriter = transport::Writer<sensor_msgs::msg::dds_::PointCloud2_PubSubType>;
  using PoseWriter =
      transport::Writer<geometry_msgs::msg::dds_::PoseWithCovarianceStamped_PubSubType>;
  using PathWriter = transport::Writer<nav_msgs::msg::dds_::Path_PubSubType>;
  if (!(options.rate_scale > 0.0)) return core::Error{"replay.options", "rate_scale must be > 0"};
  auto clouds = CloudWriter::create(participant, options.lidar_topic, options.lidar_qos);
  if (!clouds) return clouds.error();
  // Deep enough that a reliable pose reader never makes the replay block.
  transport::QosSpec pose_qos = transport::qos::kPose;
  pose_qos.history_depth = 100;
  auto poses = PoseWriter::create(participant, options.pose_topic, pose_qos);
  if (!poses) return poses.error();
  std::unique_ptr<PathWriter> paths;
  if (!options.corrections.empty()) {
    auto created = PathWriter::create(participant, options.correction_topic, pose_qos);
    if (!created) return created.error();
    paths = std::move(created).value();
  }
  const auto wait = std::chrono::milliseconds(
      static_cast<std::int64_t>(std::llround(options.wait_for_readers_s * 1000.0)));
  if (!clouds.value()->wait_for_readers(1, wait) ||
      (options.publish_poses &&
       !poses.value()->wait_for_readers(std::max<std::size_t>(1, options.pose_readers), wait)) ||
      (paths && !paths->wait_for_readers(1, wait))) {
    return core::Error{"replay.no_reader",
                       "no reader matched " + options.lidar_topic + ", or fewer than " +
                           std::to_string(std::max<std::size_t>(1, options.pose_readers)) +
                           " matched " + options.pose_topic +
                           " (is tarmacd running on this domain?)"};
  }

  const std::size_t n =
      options.max_scans == 0 ? seq.scans.size() : std::min(options.max_scans, seq.scans.size());
  ReplayStats stats;
  if (n == 0 || options.loops == 0) return stats;
  const std::size_t total = n * options.loops;
  std::int64_t start = 0;
  const std::vector<std::int64_t> stamps = scan_stamps(seq, n, options, start);
  auto scheduled = schedule(stamps, n, options);
  if (!scheduled) return scheduled.error();
  const std::vector<Event>& events = scheduled.value();

  core::PointCloud cloud, transposed;
  std::size_t published_scans = 0;
  std::size_t next_to_pace = 0;  // the first scan whose messages have not been paced yet
  for (const Event& e : events) {
    if (stop != nullptr && stop->load()) break;
    if (options.pace && e.kind != EventKind::kCorrection && e.index >= next_to_pace) {
      for (; next_to_pace <= e.index; ++next_to_pace) {
        if (!options.pace(next_to_pace, stamps[next_to_pace])) {
          if (stop != nullptr && stop->load()) break;  // stopped while waiting: not a failure
          return core::Error{"replay.pace", "the consumer did not take scan " +
                                                std::to_string(next_to_pace) + " in time"};
        }
      }
      if (stop != nullptr && stop->load()) break;
    }
    if (e.kind == EventKind::kPose) {
      transport::PoseStampedMsg msg;
      msg.header().stamp(transport::to_time_msg(stamps[e.index]));
      msg.header().frame_id(options.pose_frame_id);
      msg.pose().pose(
          transport::to_pose_msg(base_pose(seq.T_W_S[e.index % n], options.T_base_sensor)));
      sleep_until_realtime(e.publish_ns);
      poses.value()->write(msg);
    } else if (e.kind == EventKind::kCorrection) {
      const transport::PathMsg msg =
          correction_message(options.corrections[e.index], seq, n, stamps, start, options);
      sleep_until_realtime(e.publish_ns);
      paths->write(msg);
      ++stats.corrections;
    } else {
      auto msg = scan_message(seq, n, e.index, stamps[e.index], options, cloud, transposed);
      if (!msg) return msg.error();
      sleep_until_realtime(e.publish_ns);
      stats.max_late_ms =
          std::max(stats.max_late_ms, static_cast<double>(realtime_ns() - e.publish_ns) / 1e6);
      clouds.value()->write(msg.value());
      ++published_scans;
      if (options.progress) options.progress(published_scans, total);
    }
  }
  poses.value()->wait_for_acknowledgments(std::chrono::milliseconds(2000));
  if (paths) paths->wait_for_acknowledgments(std::chrono::milliseconds(2000));
  stats.scans = published_scans;
  stats.first_stamp_ns = stamps.front();
  stats.last_stamp_ns = stamps[total - 1];
  return stats;
}

}  // namespace tarmac::tools
