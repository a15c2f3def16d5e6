// tarmac-map: the offline mapping tool. Runs the same core pipeline as the daemon, scan by scan,
// on a KITTI-layout sequence, and writes the maps, images, timings and a digest.

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "outputs.hpp"
#include "run.hpp"
#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tarmac/daemon/cycle.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/tools/array_io.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/tools/mesh_io.hpp"
#include "tarmac/tools/open_ground.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/stats.hpp"

namespace {

using namespace tarmac;

using namespace map_tool;  // NOLINT(google-build-using-namespace): this tool's own run
using tools::mean;
using tools::percentile;

using tools::timed_ms;

/// Reads and checks everything the run needs before any work is done: the config, the sequence,
/// the prior TSDF, the ground truths of tarmac-sim's sequences, the corrections. 0, or the exit
/// code after saying why on stderr.
int load_inputs(const Options& opt, Inputs& in) {
  config::Config& cfg = in.cfg;
  if (!opt.config.empty()) {
    auto loaded = config::load_config_file(opt.config);
    if (!loaded) {
      std::fprintf(stderr, "tarmac-map: invalid config: %s\n", loaded.error().message.c_str());
      return kExitConfig;
    }
    cfg = std::move(loaded).value();
  }
  const core::MapperParams& params = cfg.mapping;
  if (auto valid = params.validate(); !valid) {
    std::fprintf(stderr, "tarmac-map: invalid config: %s\n", valid.error().message.c_str());
    return kExitConfig;
  }
  auto seq = tools::open_kitti(opt.dataset, opt.poses);
  if (!seq) {
    std::fprintf(stderr, "tarmac-map: %s\n", seq.error().message.c_str());
    return kExitData;
  }
  in.seq = std::move(seq).value();
  if (!in.seq.organised.empty()) {
    std::fprintf(
        stderr, "tarmac-map: organised sweeps (%zu x %zu): beams without return clear free space\n",
        in.seq.rows, in.seq.cols);
  } else if (params.costmap.free_rule == core::FreeRule::kWholeEnvelope) {
    std::fprintf(stderr,
                 "tarmac-map: note: unorganised scans carry no beams without return; with "
                 "costmap.free_rule whole_envelope the envelope above the sensor stays unknown "
                 "where nothing above returns (docs/mapping.md, \"Safety argument\")\n");
  }
  std::error_code ec;
  std::filesystem::create_directories(opt.out, ec);
  if (ec) {
    std::fprintf(stderr, "tarmac-map: %s: %s\n", opt.out.c_str(), ec.message().c_str());
    return kExitIo;
  }

  // With a limit the prior is a tile store, compared tile by tile; without, a .vdb held whole.
  const bool prior_is_store = !opt.prior.empty() && std::filesystem::is_directory(opt.prior, ec);
  if (!opt.prior.empty() && (params.tsdf.resident_limit_mb > 0) != prior_is_store) {
    std::fprintf(stderr,
                 params.tsdf.resident_limit_mb > 0
                     ? "tarmac-map: with tsdf.resident_limit_mb, --prior is an earlier run's tile "
                       "store (its out/tsdf_tiles directory), not a .vdb held whole\n"
                     : "tarmac-map: --prior %s is a tile store: set tsdf.resident_limit_mb to "
                       "compare tile by tile, or give a tsdf.vdb\n",
                 opt.prior.c_str());
    return kExitConfig;
  }
  // The prior map for change detection, checked before any work is done.
  if (!opt.prior.empty() && !prior_is_store) {
    auto loaded = core::load_tsdf(opt.prior);
    if (loaded.ok()) {
      if (auto m = core::check_tsdf_matches(loaded.value().info, map_tool::kTsdfFrame,
                                            params.tsdf.voxel_size_m, params.tsdf.truncation_m);
          !m) {
        loaded = core::Error{m.error().code, opt.prior + ": " + m.error().message};
      }
    }
    if (!loaded) {
      std::fprintf(stderr, "tarmac-map: prior refused: %s [%s]\n", loaded.error().message.c_str(),
                   loaded.error().code.c_str());
      return kExitData;
    }
    in.prior.emplace(std::move(loaded).value());
  }

  // Moving objects' ground truth (tarmac-sim's dynamic_boxes.txt): dynamic-clearing figures.
  if (const auto truth_file = std::filesystem::path(opt.dataset) / "dynamic_boxes.txt";
      std::filesystem::exists(truth_file)) {
    auto truth = tools::read_dynamic_truth(truth_file);
    if (!truth) {
      std::fprintf(stderr, "tarmac-map: %s\n", truth.error().message.c_str());
      return kExitData;
    }
    in.clearing.emplace(std::move(truth).value());
  }

  // The costmap's ground truth (tarmac-sim's obstacle_columns.txt; on terrain ground_cells.txt
  // and curb_columns.txt): safety figures per cycle.
  if (std::filesystem::exists(std::filesystem::path(opt.dataset) / "obstacle_columns.txt")) {
    auto truth = tools::read_dataset_truth(opt.dataset);
    if (!truth) {
      std::fprintf(stderr, "tarmac-map: %s\n", truth.error().message.c_str());
      return kExitData;
    }
    if (std::abs(truth.value().cell_m - params.occupancy.voxel_size_m) > 1e-9) {
      std::fprintf(stderr,
                   "tarmac-map: safety figures skipped: the truth's cells are %g m, the "
                   "costmap's %g m\n",
                   truth.value().cell_m, params.occupancy.voxel_size_m);
    } else {
      in.safety.emplace(std::move(truth).value());
    }
  }

  if (!in.safety || opt.open_ground) {
    in.open_ground.emplace(params.occupancy.voxel_size_m,
                           params.costmap.vehicle_height_m + params.costmap.clearance_m);
  }

  if (!opt.corrections.empty()) {
    auto read = tools::read_corrections(opt.corrections);
    if (!read) {
      std::fprintf(stderr, "tarmac-map: %s [%s]\n", read.error().message.c_str(),
                   read.error().code.c_str());
      return kExitData;
    }
    in.corrections = std::move(read).value();
    if (!params.corrections.enabled) {
      std::fprintf(stderr, "tarmac-map: --corrections needs corrections.enabled: true\n");
      return kExitConfig;
    }
  }

  return 0;
}

/// Resident set of this process, bytes (/proc/self/statm).
std::size_t rss_bytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return 0;
  unsigned long size = 0, resident = 0;
  const int got = std::fscanf(f, "%lu %lu", &size, &resident);
  std::fclose(f);
  return got == 2 ? resident * static_cast<std::size_t>(sysconf(_SC_PAGESIZE)) : 0;
}

/// --memory-log: scan, distance driven (m), RSS, the TSDF's resident tiles as counted against
/// the limit, and the tile store (MiB).
void log_memory(const Run& run, const core::Mapper& mapper, std::size_t k) {
  constexpr double kMiB = 1024.0 * 1024.0;
  const daemon::TsdfPagerStats st = run.pager ? run.pager->stats() : daemon::TsdfPagerStats{};
  std::fprintf(run.memory_log, "%zu,%.1f,%.1f,%.1f,%.1f\n", k, run.distance_m,
               static_cast<double>(rss_bytes()) / kMiB,
               static_cast<double>(mapper.tsdf().resident_bytes()) / kMiB,
               static_cast<double>(st.stored_bytes) / kMiB);
}

/// Scores scan k's costmap against what the dataset holds to score it by: tarmac-sim's truths
/// (dynamic clearing, safety), or the open flat ground of the drive's returns.
void score_scan(Inputs& in, const core::Mapper& mapper, std::size_t k, std::size_t n,
                const Eigen::Isometry3d& T_W_B, const Eigen::Isometry3d& T_B_S,
                std::span<const Eigen::Vector3f> points_W) {
  const tools::KittiSequence& s = in.seq;
  if (in.clearing) {
    // The base sits on the ground (--sensor-height): its z is the ground's near the vehicle.
    const Eigen::Vector3d sensor_W = T_W_B * T_B_S.translation();
    in.clearing->observe(
        static_cast<int>(k), s.times_s[k], mapper.costmap().column_class, sensor_W.head<2>(),
        tools::blind_radius_from_ground(sensor_W, points_W, T_W_B.translation().z()));
  }
  if (in.safety) {
    std::vector<tools::DynamicBox> moving_now;  // the moving objects' boxes at this scan
    if (in.clearing) {
      for (const auto& b : in.clearing->truth().boxes) {
        if (b.scan == static_cast<int>(k)) moving_now.push_back(b);
      }
    }
    // The vehicle's position: the base under the sensor (as tarmac-audit takes it), which on a
    // slope is not where the pitched base frame puts its origin.
    in.safety->observe(mapper.costmap().costmap, static_cast<int>(k),
                       s.T_W_S[k].translation().head<2>(), 20.0, moving_now);
  }
  if (in.open_ground) {
    in.open_ground->add(points_W);
    // Every 10th scan and the last: a full-window pass each.
    if (k % 10 == 9 || k + 1 == n) {
      in.open_ground->observe(mapper.costmap().costmap, static_cast<int>(k));
    }
  }
}

/// The vehicle base under a sensor at T_W_S. A vehicle's sensor is fixed to it: the base is the
/// sensor's frame moved down sensor_height_m along the sensor's own z. A handheld or
/// cart-carried sensor (--level-base) tilts on its carrier: the base keeps only the sensor's
/// heading and stands level in the world frame, which must then be gravity-aligned (e.g.
/// balm_hall's poses_leveled.txt); else the map's "up" would tilt with the hand and a flat
/// floor would read as a slope rising into obstacles.
Eigen::Isometry3d base_pose(const Options& opt, const Eigen::Isometry3d& T_W_S) {
  if (!opt.level_base) return T_W_S * Eigen::Translation3d(0.0, 0.0, -opt.sensor_height_m);
  Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
  const Eigen::Matrix3d& R = T_W_S.linear();
  T_W_B.linear() =
      Eigen::AngleAxisd(std::atan2(R(1, 0), R(0, 0)), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T_W_B.translation() = T_W_S.translation() - opt.sensor_height_m * Eigen::Vector3d::UnitZ();
  return T_W_B;
}

/// Maps the sequence scan by scan through the daemon's stages (daemon::Cycle), applying the
/// corrections and feeding the ground-truth trackers; a rebuild still running after the last
/// scan is finished. Exits with kExitData on a scan it cannot read.
void run_sequence(const Options& opt, Inputs& in, core::Mapper& mapper, daemon::ThreadPool& pool,
                  Run& run) {
  const core::MapperParams& params = in.cfg.mapping;
  const config::Config& cfg = in.cfg;
  daemon::Cycle cycle(mapper, pool, daemon::Cycle::Quotas{cfg.quotas.tsdf_points_per_cycle});
  cycle.page_tsdf(run.pager);
  core::PoseJumpDetector jumps(params.corrections);
  std::optional<Eigen::Vector3d> last_sensor_W;
  // --fleet-period: this vehicle's summaries as tarmacd would send them (a keyframe every
  // kKeyframeEvery messages), to measure their bytes; no peers.
  constexpr std::size_t kKeyframeEvery = 10;
  std::optional<core::BevEncoder> fleet;
  std::int64_t next_summary_ns = std::numeric_limits<std::int64_t>::min();
  if (opt.fleet_period_s > 0.0) {
    cycle.share_with_fleet(nullptr);
    fleet.emplace("vehicle", params.occupancy.voxel_size_m);
  }
  const auto send_summary = [&](core::BevEncoder& enc, std::int64_t stamp_ns) {
    if (stamp_ns < next_summary_ns) return;
    next_summary_ns = stamp_ns + static_cast<std::int64_t>(opt.fleet_period_s * 1e9);
    const bool keyframe = enc.next_sequence() % kKeyframeEvery == 0;
    const core::BevMessage m = enc.encode(mapper.fleet_snapshot(), stamp_ns, keyframe,
                                          static_cast<std::int64_t>(cfg.fleet.max_age_s * 1e9));
    run.fleet_messages.emplace_back(core::bev_wire_bytes(m, cfg.outputs.frame_id.size()), keyframe);
  };
  // The corrected trajectories published after the scans before scan `k`.
  const auto apply_corrections_before = [&](std::size_t k) {
    while (run.next_correction < in.corrections.size() &&
           in.corrections[run.next_correction].after_scan < k) {
      std::vector<core::StampedPose> traj = in.corrections[run.next_correction].trajectory_W_S;
      for (auto& p : traj) p.T_W_B = base_pose(opt, p.T_W_B);
      mapper.correct_trajectory(traj);
      jumps.reset(traj);  // the next live poses are predicted from the corrected ones
      ++run.next_correction;
    }
  };
  const std::size_t n =
      opt.max_scans == 0 ? in.seq.scans.size() : std::min(opt.max_scans, in.seq.scans.size());
  run.scans = n;
  const bool tty = isatty(STDERR_FILENO) != 0;
  core::PointCloud cloud;
  core::OrganisedScratch organised_scratch;
  for (std::size_t k = 0; k < n; ++k) {
    const auto& s = in.seq;
    run.t_read.ms.push_back(timed_ms([&] {
      // Organised sweeps when the sequence has them (tarmac-sim): their beams without return
      // clear free space, as tarmacd derives them from an organised PointCloud2.
      if (auto r = tools::read_sequence_scan(s, k, cloud, organised_scratch); !r) {
        std::fprintf(stderr, "tarmac-map: %s\n", r.error().message.c_str());
        std::exit(kExitData);
      }
    }));
    cloud.stamp_ns = static_cast<std::int64_t>(std::llround(s.times_s[k] * 1e9));
    const Eigen::Isometry3d T_W_B = base_pose(opt, s.T_W_S[k]);
    const Eigen::Isometry3d T_B_S = T_W_B.inverse() * s.T_W_S[k];
    // One scan a tick, through the daemon's stages (daemon::Cycle); corrections first, as
    // tarmacd applies a correction before the first scan stamped after it.
    cycle.begin();
    // (a) a corrected trajectory published after the previous scan.
    apply_corrections_before(k);
    // (b) a jump in the pose stream: a rigid correction of every retained scan before this one.
    if (params.corrections.enabled) {
      if (const auto jump = jumps.feed({cloud.stamp_ns, T_W_B})) {
        if (mapper.correct_rigid(*jump, cloud.stamp_ns) > 0) ++run.jump_corrections;
      }
    }
    const daemon::Cycle::ScanResult& r = cycle.scan(cloud, T_W_B, T_B_S);
    const core::FilteredScan& scan = r.filtered;
    const core::FilterCounts& counts = scan.counts;
    const core::OccupancyUpdateStats& occ = r.occupancy;
    if (r.tsdf != nullptr) {
      run.tsdf_samples += r.tsdf->samples;
      run.tsdf_updates += r.tsdf->voxel_updates;
    }
    if (r.rebuild.scans > 0)
      run.rebuild_ms.push_back(r.rebuild_ms);  // not the steps waiting to start
    cycle.update_costmap({}, cloud.stamp_ns);
    if (fleet) send_summary(*fleet, cloud.stamp_ns);
    // The 3D band (esdf_band.enabled), every scan as the daemon does every cycle.
    cycle.update_esdf_band({}, cloud.stamp_ns);
    const double f_ms = r.ingest_ms, o_ms = r.integrate_ms, tsdf_ms = r.tsdf_ms;
    const double c_ms = cycle.tick().costmap_ms, b_ms = cycle.tick().esdf_band_ms;
    score_scan(in, mapper, k, n, T_W_B, T_B_S, scan.points_W);
    run.promotions += occ.promotions;
    run.demotions += occ.demotions;
    run.t_filter.ms.push_back(f_ms);
    run.t_occ.ms.push_back(o_ms);
    run.t_cost.ms.push_back(c_ms);
    if (params.tsdf.enabled) {
      run.t_tsdf.ms.push_back(tsdf_ms);
      // The spare blocks this scan took, rebuilt between scans as tarmacd rebuilds them between
      // ticks (all of them here, at most a 16th of reserve_blocks a tick there): timed on its own.
      run.t_spares.ms.push_back(
          timed_ms([&] { mapper.top_up_tsdf_spares(std::numeric_limits<std::size_t>::max()); }));
    }
    if (params.esdf_band.enabled) run.t_band.ms.push_back(b_ms);
    run.t_total.ms.push_back(f_ms + o_ms + tsdf_ms + c_ms + b_ms);
    run.points_in += counts.input;
    run.points_used += counts.kept;
    run.dropped_nonfinite += counts.non_finite;
    run.dropped_close += counts.too_close;
    run.dropped_ego += counts.ego_vehicle;
    run.dropped_isolated += counts.isolated;
    run.voxel_visits += occ.voxel_visits;
    if (last_sensor_W) run.distance_m += (scan.sensor_W - *last_sensor_W).head<2>().norm();
    last_sensor_W = scan.sensor_W;
    if (run.memory_log != nullptr) log_memory(run, mapper, k);
    if (tty) std::fprintf(stderr, "\rtarmac-map: scan %zu/%zu", k + 1, n);
  }
  if (tty) std::fprintf(stderr, "\n");
  // Offline there is no next scan to wait for: corrections after the last scan are applied and
  // a rebuild still running at the end is finished (steps of the same quota), so the written
  // maps are the corrected ones.
  apply_corrections_before(n);
  while (mapper.rebuilding()) {
    core::RebuildStep step;
    const double ms = timed_ms([&] { step = mapper.rebuild_step(pool); });
    if (step.scans == 0) break;  // scheduled after the last scan's stamp: never starts
    run.rebuild_ms.push_back(ms);
    ++run.rebuild_steps_after_end;
  }
  if (run.rebuild_steps_after_end > 0) {
    mapper.update_costmap({}, cloud.stamp_ns, pool);
    mapper.update_esdf_band({}, cloud.stamp_ns, pool);
  }
  run.last_stamp_ns = cloud.stamp_ns;
}

/// Where the TSDF's bytes go, over the whole site (paged tiles read back one at a time): blocks,
/// observed voxels, the ground they cover (x, y columns of blocks) and the bytes per 1,000 m² and
/// per km driven, in memory (as TsdfLayer::resident_bytes counts them) and in the tile store.
void print_tsdf_footprint(const core::Mapper& mapper, const Run& run) {
  std::unordered_set<std::uint64_t> columns, tiles;
  std::uint64_t blocks = 0, observed = 0;
  const auto visit = [&](const core::TsdfBlockView& b) {
    ++blocks;
    for (int i = 0; i < core::kTsdfBlockVoxels; ++i) observed += b.voxels[i].weight > 0.0f;
    const auto key = [](int x, int y, int z) {
      return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(x)) << 32) ^
             (static_cast<std::uint64_t>(static_cast<std::uint32_t>(y)) << 11) ^
             static_cast<std::uint64_t>(static_cast<std::uint32_t>(z));
    };
    columns.insert(key(b.block.x(), b.block.y(), 0));
    const core::TileIndex t = core::tile_of_block(b.block);
    tiles.insert(key(t.x(), t.y(), t.z()));
  };
  if (run.pager != nullptr) {
    run.pager->site(mapper.tsdf()).for_each_block(visit);
  } else {
    mapper.tsdf().for_each_block(visit);
  }
  const double edge = core::kTsdfBlockEdge * static_cast<double>(mapper.tsdf().voxel_size_m());
  const double area_m2 = static_cast<double>(columns.size()) * edge * edge;
  const double mib = static_cast<double>(blocks * core::kTsdfBlockBytes +
                                         tiles.size() * core::kTsdfTileNodeBytes) /
                     (1024.0 * 1024.0);
  const double km = run.distance_m / 1000.0;
  std::printf(
      "tsdf site: %llu blocks, %.1f %% of their voxels observed, ground covered %.0f m^2; in "
      "memory %.1f MiB = %.2f MiB per 1,000 m^2, %.0f MiB per km driven",
      static_cast<unsigned long long>(blocks),
      blocks > 0 ? 100.0 * static_cast<double>(observed) /
                       static_cast<double>(blocks * core::kTsdfBlockVoxels)
                 : 0.0,
      area_m2, mib, area_m2 > 0 ? mib / area_m2 * 1000.0 : 0.0, km > 0 ? mib / km : 0.0);
  if (run.pager != nullptr) {
    const double store = static_cast<double>(run.pager->stats().stored_bytes) / (1024.0 * 1024.0);
    std::printf("; tile store %.1f MiB = %.2f MiB per 1,000 m^2, %.0f MiB per km", store,
                area_m2 > 0 ? store / area_m2 * 1000.0 : 0.0, km > 0 ? store / km : 0.0);
  }
  std::printf("\n");
}

/// The open flat ground figure: its line, timing.json's "open_ground", open_ground.png.
void report_open_ground(const Options& opt, const tools::OpenGroundTracker& open_ground,
                        nlohmann::ordered_json& timing) {
  std::printf("%s\n", tools::open_ground_summary(open_ground).c_str());
  timing["open_ground"] = tools::open_ground_json(open_ground);
  std::uint32_t w = 0, h = 0;
  const std::vector<std::uint8_t> rgb = open_ground.render(w, h);
  const auto file = std::filesystem::path(opt.out) / "open_ground.png";
  if (auto written = tools::write_png(file, rgb, w, h); !written) {
    std::fprintf(stderr, "tarmac-map: %s\n", written.error().message.c_str());
  }
}

/// The stage table: per stage, ms per scan (mean, p50, p99, max and the max's scan); returns it
/// for timing.json.
nlohmann::ordered_json print_stage_table(const core::MapperParams& params, const Run& run) {
  std::printf("%-16s %9s %9s %9s %9s %7s   (ms per scan; worst: the max's scan index)\n", "stage",
              "mean", "p50", "p99", "max", "worst");
  nlohmann::ordered_json stages_ms = nlohmann::ordered_json::object();
  std::vector<const StageTimes*> stages = {&run.t_read, &run.t_filter, &run.t_occ, &run.t_cost,
                                           &run.t_total};
  if (params.esdf_band.enabled) stages.insert(stages.end() - 1, &run.t_band);
  if (params.tsdf.enabled) {
    stages.insert(stages.begin() + 3, &run.t_tsdf);
    stages.push_back(&run.t_spares);  // off the cycle: after the pipeline's row
  }
  for (const StageTimes* stage : stages) {
    const auto& s = *stage;
    const std::size_t worst = tools::index_of_max(s.ms);
    const double mx = s.ms.empty() ? 0.0 : s.ms[worst];
    std::printf("%-16s %9.2f %9.2f %9.2f %9.2f %7zu\n", s.name, mean(s.ms), percentile(s.ms, 0.5),
                percentile(s.ms, 0.99), mx, worst);
    stages_ms[s.name] = {{"mean", mean(s.ms)},
                         {"p50", percentile(s.ms, 0.5)},
                         {"p99", percentile(s.ms, 0.99)},
                         {"max", mx},
                         {"max_scan", worst}};
  }
  return stages_ms;
}

/// With tsdf.enabled: the mesh's time, the paging's or the whole TSDF's figures, the change
/// layer's counts and the footprint.
void print_tsdf_summary(const Options& opt, const core::MapperParams& params,
                        const core::Mapper& mapper, const Run& run,
                        const map_tool::TsdfOutputs& tsdf_out) {
  if (run.pager != nullptr) {
    std::printf("%-16s %9.2f   (once, at the end, tile by tile: %zu vertices, %zu triangles)\n",
                "tsdf mesh", tsdf_out.mesh_ms, tsdf_out.vertices, tsdf_out.triangles);
    constexpr double kMiB = 1024.0 * 1024.0;
    const daemon::TsdfPagerStats st = run.pager->stats();
    std::printf(
        "tsdf paging (limit %u MiB): peak resident %.1f MiB, now %.1f MiB in %zu tiles; tile "
        "store %zu tiles, %.1f MiB (%s/tsdf_tiles); %llu evicted, %llu written, %llu loaded, "
        "%llu scans over the limit, %llu write / %llu load errors; driven %.0f m\n",
        params.tsdf.resident_limit_mb, static_cast<double>(st.peak_resident_bytes) / kMiB,
        static_cast<double>(st.resident_bytes) / kMiB, st.resident_tiles, st.stored_tiles,
        static_cast<double>(st.stored_bytes) / kMiB, opt.out.c_str(),
        static_cast<unsigned long long>(st.evicted), static_cast<unsigned long long>(st.written),
        static_cast<unsigned long long>(st.loaded), static_cast<unsigned long long>(st.over_limit),
        static_cast<unsigned long long>(st.write_errors),
        static_cast<unsigned long long>(st.load_errors), run.distance_m);
    std::printf(
        "static paging: %zu voxels in memory (table %.1f MiB); %zu tiles stored, %.2f MiB; %llu "
        "evicted, %llu written, %llu loaded\n",
        st.static_resident_voxels, static_cast<double>(st.static_resident_bytes) / kMiB,
        st.static_tiles_stored, static_cast<double>(st.static_stored_bytes) / kMiB,
        static_cast<unsigned long long>(st.static_evicted),
        static_cast<unsigned long long>(st.static_written),
        static_cast<unsigned long long>(st.static_loaded));
  } else {
    std::printf("%-16s %9.2f   (once, at the end: %zu vertices, %zu triangles); save %.2f ms\n",
                "tsdf mesh", tsdf_out.mesh_ms, tsdf_out.vertices, tsdf_out.triangles,
                tsdf_out.save_ms);
    std::printf(
        "tsdf: %zu blocks, %zu voxels, %.1f MiB, %.1f voxel samples/point, %.1f voxel "
        "updates/point\n",
        mapper.tsdf().block_count(), mapper.tsdf().voxel_count(),
        static_cast<double>(mapper.tsdf().memory_bytes()) / (1024.0 * 1024.0),
        run.points_used > 0
            ? static_cast<double>(run.tsdf_samples) / static_cast<double>(run.points_used)
            : 0.0,
        run.points_used > 0
            ? static_cast<double>(run.tsdf_updates) / static_cast<double>(run.points_used)
            : 0.0);
  }
  if (!opt.prior.empty()) {
    std::printf("changes vs %s: %llu voxels compared, %llu new, %llu removed (%.1f ms%s)\n",
                opt.prior.c_str(),
                static_cast<unsigned long long>(tsdf_out.changes.compared_voxels),
                static_cast<unsigned long long>(tsdf_out.changes.new_voxels),
                static_cast<unsigned long long>(tsdf_out.changes.removed_voxels),
                tsdf_out.changes_ms, tsdf_out.paged ? ", tile by tile" : "");
  }

  print_tsdf_footprint(mapper, run);
}

/// With corrections.enabled: corrections applied and ignored, rebuilds and their cost.
void print_corrections(const core::Mapper& mapper, const Run& run) {
  const core::CorrectionStats& cs = mapper.correction_stats();
  double rebuild_total = 0.0;
  for (const double ms : run.rebuild_ms) rebuild_total += ms;
  std::printf(
      "corrections: %llu applied (%llu from pose jumps, %llu from --corrections), %llu "
      "ignored; %llu rebuilds completed, %llu scans re-integrated in %zu steps, %.1f ms in "
      "total (max step %.1f ms; %zu steps after the last scan), %llu scans rolled out, %llu "
      "TSDF blocks erased\n",
      static_cast<unsigned long long>(cs.corrections),
      static_cast<unsigned long long>(run.jump_corrections),
      static_cast<unsigned long long>(run.next_correction),
      static_cast<unsigned long long>(cs.corrections_empty),
      static_cast<unsigned long long>(cs.rebuilds_completed),
      static_cast<unsigned long long>(cs.scans_reintegrated), run.rebuild_ms.size(), rebuild_total,
      run.rebuild_ms.empty() ? 0.0
                             : *std::max_element(run.rebuild_ms.begin(), run.rebuild_ms.end()),
      run.rebuild_steps_after_end, static_cast<unsigned long long>(cs.scans_rolled_out),
      static_cast<unsigned long long>(cs.tsdf_blocks_erased));
}

/// Prints the stage table, the run's summaries and the digests; writes timing.json. 0 or
/// kExitIo.
int report(const Options& opt, const Inputs& in, const core::Mapper& mapper, const Run& run,
           const map_tool::WindowOutputs& window_out, const map_tool::TsdfOutputs& tsdf_out) {
  const core::MapperParams& params = in.cfg.mapping;
  // ---- timing table ----
  double total_s = 0.0;
  for (const double ms : run.t_total.ms) total_s += ms / 1000.0;
  std::printf(
      "tarmac-map: %zu scans, %llu points in, %llu used (dropped: %llu non-finite, %llu too close, "
      "%llu ego vehicle, %llu isolated), %zu threads\n",
      run.scans, static_cast<unsigned long long>(run.points_in),
      static_cast<unsigned long long>(run.points_used),
      static_cast<unsigned long long>(run.dropped_nonfinite),
      static_cast<unsigned long long>(run.dropped_close),
      static_cast<unsigned long long>(run.dropped_ego),
      static_cast<unsigned long long>(run.dropped_isolated), opt.threads);
  nlohmann::ordered_json timing = {{"scans", run.scans}, {"threads", opt.threads}};
  timing["stages_ms"] = print_stage_table(params, run);
  const double pts_per_s = total_s > 0 ? static_cast<double>(run.points_used) / total_s : 0.0;
  std::printf("%-16s %9.2f   (once, at the end, %d x %d x %d voxels)\n", "esdf3d",
              window_out.esdf3d_ms, window_out.esdf3d.dims.x(), window_out.esdf3d.dims.y(),
              window_out.esdf3d.dims.z());
  std::printf(
      "pipeline throughput: %.2f M points/s (filter+occupancy+tsdf+costmap), %.1f voxel "
      "visits/point\n",
      pts_per_s / 1e6,
      run.points_used > 0 ? static_cast<double>(run.voxel_visits) / run.points_used : 0.0);
  timing["esdf3d_ms"] = window_out.esdf3d_ms;
  timing["points_per_s"] = pts_per_s;
  if (params.tsdf.enabled) {
    timing["tsdf_mesh_ms"] = tsdf_out.mesh_ms;
    timing["tsdf_save_ms"] = tsdf_out.save_ms;
    if (!opt.prior.empty()) timing["tsdf_changes_ms"] = tsdf_out.changes_ms;
  }
  // The site's static layer: with paging, the map's part and the stored tiles'.
  std::vector<Eigen::Vector3i> static_site;
  if (run.pager != nullptr) {
    run.pager->site(mapper.tsdf()).static_voxels(static_site);
  } else {
    mapper.occupancy().export_static(static_site);
  }
  std::printf(
      "static layer: %zu voxels at the end (%llu promotions, %llu demotions); in memory %zu "
      "voxels, table %.1f MiB\n",
      static_site.size(), static_cast<unsigned long long>(run.promotions),
      static_cast<unsigned long long>(run.demotions), mapper.occupancy().static_count(),
      static_cast<double>(mapper.occupancy().static_bytes()) / (1024.0 * 1024.0));
  timing["static_voxels"] = static_site.size();
  timing["static_promotions"] = run.promotions;
  timing["static_demotions"] = run.demotions;
  if (in.clearing) {
    const tools::ClearingReport r = in.clearing->report();
    std::printf(
        "dynamic clearing: %zu path cells, %zu measured, %zu cleared, %zu not cleared; "
        "time-to-clear p50 %.2f s, p90 %.2f s, max %.2f s; ghost cells at the end %zu\n"
        "  of those, %zu left inside the blind zone (nearer than the scan's nearest ground "
        "return); "
        "the others: p50 %.2f s, p90 %.2f s, max %.2f s\n",
        r.path_cells, r.measured, r.cleared, r.not_cleared, r.p50_s, r.p90_s, r.max_s,
        r.ghost_cells, r.blind_at_leave, r.in_view_p50_s, r.in_view_p90_s, r.in_view_max_s);
    timing["dynamic_clearing"] = {{"path_cells", r.path_cells},
                                  {"measured", r.measured},
                                  {"cleared", r.cleared},
                                  {"not_cleared", r.not_cleared},
                                  {"time_to_clear_p50_s", r.p50_s},
                                  {"time_to_clear_p90_s", r.p90_s},
                                  {"time_to_clear_max_s", r.max_s},
                                  {"ghost_cells", r.ghost_cells},
                                  {"blind_at_leave", r.blind_at_leave},
                                  {"in_view_p50_s", r.in_view_p50_s},
                                  {"in_view_p90_s", r.in_view_p90_s},
                                  {"in_view_max_s", r.in_view_max_s}};
  }
  if (in.safety) {
    std::printf("%s\n", tools::safety_summary(in.safety->report()).c_str());
    timing["safety"] = tools::safety_json(*in.safety);
  }
  if (in.open_ground) report_open_ground(opt, *in.open_ground, timing);
  if (!run.fleet_messages.empty()) {
    // Each message stands for one period: bytes per second over the messages' periods.
    std::size_t total = 0, keyframes = 0, key_bytes = 0, key_max = 0, change_bytes = 0,
                change_max = 0;
    for (const auto& [bytes, keyframe] : run.fleet_messages) {
      total += bytes;
      if (keyframe) {
        ++keyframes;
        key_bytes += bytes;
        key_max = std::max(key_max, bytes);
      } else {
        change_bytes += bytes;
        change_max = std::max(change_max, bytes);
      }
    }
    const std::size_t n = run.fleet_messages.size(), changes = n - keyframes;
    const double per_s =
        static_cast<double>(total) / (static_cast<double>(n) * opt.fleet_period_s) / 1024.0;
    std::printf(
        "fleet summary every %.2f s: %zu messages (%zu keyframes, mean %.1f KiB, max %.1f KiB; "
        "%zu change messages, mean %.1f KiB, max %.1f KiB) -> %.1f KiB/s per vehicle\n",
        opt.fleet_period_s, n, keyframes,
        keyframes > 0 ? static_cast<double>(key_bytes) / keyframes / 1024.0 : 0.0,
        static_cast<double>(key_max) / 1024.0, changes,
        changes > 0 ? static_cast<double>(change_bytes) / changes / 1024.0 : 0.0,
        static_cast<double>(change_max) / 1024.0, per_s);
    timing["fleet"] = {{"period_s", opt.fleet_period_s},
                       {"messages", n},
                       {"keyframes", keyframes},
                       {"bytes", total},
                       {"kib_per_s", per_s}};
  }
  if (auto w = tools::write_json(std::filesystem::path(opt.out) / "timing.json", timing); !w) {
    std::fprintf(stderr, "tarmac-map: %s\n", w.error().message.c_str());
    return kExitIo;
  }
  if (params.tsdf.enabled) print_tsdf_summary(opt, params, mapper, run, tsdf_out);

  if (params.corrections.enabled) print_corrections(mapper, run);

  const auto bytes = [](const auto& vec) {
    return std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(vec.data()),
                                         vec.size() * sizeof(vec[0]));
  };
  std::printf(
      "digest: occupancy %s costmap %s esdf_slice %s esdf %s tsdf %016llx\n",
      tools::digest(bytes(window_out.log_odds)).c_str(),
      tools::digest(bytes(mapper.costmap().costmap.cells())).c_str(),
      tools::digest(bytes(mapper.costmap().obstacle_distance.distance_m)).c_str(),
      tools::digest(bytes(window_out.esdf3d.distance_m)).c_str(),
      static_cast<unsigned long long>(run.pager != nullptr ? run.pager->site(mapper.tsdf()).digest()
                                                           : mapper.tsdf().digest()));
  std::printf("digest: static %016llx\n",
              static_cast<unsigned long long>(core::static_voxels_digest(static_site)));
  if (window_out.have_band) {
    std::printf("digest: esdf_band %s\n",
                tools::digest(bytes(mapper.esdf_band().field.distance_m)).c_str());
  }
  std::printf(
      "wrote "
      "%s/"
      "{map.json,occupancy.npy,esdf.npy,esdf_slice.npy,esdf_slice.png,costmap.npy,costmap.png,"
      "timing.json%s%s}\n",
      opt.out.c_str(), window_out.have_band ? ",esdf_band.npy" : "",
      tsdf_out.paged        ? (opt.prior.empty()
                                   ? ",tsdf_tiles/,tsdf_vdb/,tsdf.json,mesh.ply"
                                   : ",tsdf_tiles/,tsdf_vdb/,tsdf.json,mesh.ply,changes.npy,changes.png")
      : params.tsdf.enabled ? (in.prior ? ",tsdf.vdb,tsdf.json,mesh.ply,changes.npy,changes.png"
                                        : ",tsdf.vdb,tsdf.json,mesh.ply")
                            : "");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  cli::App app("tarmac-map",
               "Runs tarmacd's core pipeline scan by scan on a sequence in KITTI layout and writes "
               "the maps, images, timings and a digest.");
  app.add_option("--dataset", opt.dataset,
                 "the sequence: scans/NNNNNN.bin, poses.txt (T_world_sensor), times.txt")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--out", opt.out, "output directory (created)")->type_name("DIR");
  app.add_option("--config", opt.config, "tarmacd config (default: the built-in defaults)")
      ->type_name("FILE");
  app.add_option("--threads", opt.threads, "worker threads")
      ->transform(cli::positive<std::size_t>());
  app.add_option("--poses", opt.poses, "pose file inside DIR")->type_name("FILE");
  app.add_option("--scans", opt.max_scans, "first N scans only (0: all)")
      ->transform(cli::number<std::size_t>());
  app.add_option("--sensor-height", opt.sensor_height_m, "sensor above the vehicle base, m")
      ->transform(cli::number<double>());
  app.add_option("--prior", opt.prior,
                 "an earlier run's map: writes changes.npy/.png; its tsdf.vdb, or with "
                 "tsdf.resident_limit_mb its tsdf_tiles directory (compared tile by tile)")
      ->check(CLI::ExistingPath);
  app.add_option("--fleet-period", opt.fleet_period_s,
                 "encode this vehicle's fleet summary every S seconds of scan time (a keyframe "
                 "every 10th) and report its bytes per second (docs/fleet.md); 0: off")
      ->type_name("S")
      ->transform(cli::non_negative<double>());
  app.add_option("--corrections", opt.corrections,
                 "corrected trajectories: lines 'K stamp_s' + 12 numbers of T_world_sensor (as "
                 "poses.txt); the lines of one K form one correction, applied after scan K "
                 "(tarmac-sim --correct-at)")
      ->check(CLI::ExistingFile);
  app.add_option("--memory-log", opt.memory_log,
                 "CSV, one line per scan: scan, distance driven m, RSS MiB, TSDF resident MiB "
                 "(as counted against tsdf.resident_limit_mb), tile store MiB")
      ->type_name("FILE");
  app.add_flag("--level-base", opt.level_base,
               "the sensor tilts on its carrier (handheld): the base stands level in the "
               "(gravity-aligned) world frame under it, with its heading");
  app.add_flag("--open-ground", opt.open_ground,
               "also with a ground truth: score the open flat ground that the drive's own returns "
               "show (always on without one; docs/tools.md)");
  if (auto exit = cli::parse(app, argc, argv)) return *exit;

  Inputs in;
  if (const int exit = load_inputs(opt, in); exit != 0) return exit;
  daemon::ThreadPool pool(opt.threads);
  core::Mapper mapper(in.cfg.mapping);
  mapper.reserve_scans(in.cfg.quotas.reserve_points_per_scan);  // as tarmacd before READY=1
  Run run;
  const core::TsdfParams& tsdf = in.cfg.mapping.tsdf;
  std::unique_ptr<daemon::TsdfPager> pager;
  if (tsdf.enabled && tsdf.resident_limit_mb > 0) {
    // Offline, each scan waits for the tiles it can touch: the map is the unlimited one, bit
    // for bit (tarmacd never waits).
    daemon::TsdfPagerParams pp = daemon::TsdfPagerParams::for_mapper(
        in.cfg.mapping, std::filesystem::path(opt.out) / "tsdf_tiles");
    pp.wait_for_loads = true;
    pp.resume = false;
    auto opened = daemon::TsdfPager::open(pp, mapper.tsdf(), &mapper.occupancy());
    if (!opened) {
      std::fprintf(stderr, "tarmac-map: %s\n", opened.error().message.c_str());
      return kExitIo;
    }
    pager = std::move(opened).value();
    run.pager = pager.get();
  }
  if (!opt.memory_log.empty()) {
    run.memory_log = std::fopen(opt.memory_log.c_str(), "w");
    if (run.memory_log == nullptr) {
      std::fprintf(stderr, "tarmac-map: %s: cannot write\n", opt.memory_log.c_str());
      return kExitIo;
    }
    std::fprintf(run.memory_log, "scan,distance_m,rss_mib,tsdf_resident_mib,tile_store_mib\n");
  }
  run_sequence(opt, in, mapper, pool, run);
  if (run.memory_log != nullptr) std::fclose(run.memory_log);
  if (pager) {
    pager->flush(mapper.tsdf());
    if (auto stored = pager->store_all(mapper.tsdf()); !stored) {
      std::fprintf(stderr, "tarmac-map: %s\n", stored.error().message.c_str());
      return kExitIo;
    }
  }

  // ---- outputs ----
  const std::filesystem::path out = opt.out;
  map_tool::WindowOutputs window_out;
  if (auto w = map_tool::write_window_outputs(out, mapper, run.scans, pool, window_out); !w) {
    std::fprintf(stderr, "tarmac-map: %s\n", w.error().message.c_str());
    return kExitIo;
  }
  map_tool::TsdfOutputs tsdf_out;
  if (pager) {
    // The site is the tile store: its products are made tile by tile.
    const std::filesystem::path prior_dir = opt.prior;
    if (auto w = map_tool::write_tsdf_site_outputs(
            out, pager->site(mapper.tsdf()), mapper.tsdf(), config::config_hash(in.cfg),
            run.last_stamp_ns, opt.prior.empty() ? nullptr : &prior_dir, tsdf_out);
        !w) {
      std::fprintf(stderr, "tarmac-map: %s\n", w.error().message.c_str());
      return kExitIo;
    }
  } else if (in.cfg.mapping.tsdf.enabled) {
    if (auto w = map_tool::write_tsdf_outputs(out, mapper.tsdf(), config::config_hash(in.cfg),
                                              run.last_stamp_ns,
                                              in.prior ? &in.prior->layer : nullptr, tsdf_out);
        !w) {
      std::fprintf(stderr, "tarmac-map: %s\n", w.error().message.c_str());
      return kExitIo;
    }
  }
  return report(opt, in, mapper, run, window_out, tsdf_out);
}
