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
#include <utility>
#include <vector>

#include "outputs.hpp"
#include "report.hpp"
#include "run.hpp"
#include "tarmac/config/cli.hpp"
#include "tarmac/config/config.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tarmac/daemon/cycle.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/tools/open_ground.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/stats.hpp"

namespace {

using namespace tarmac;

using namespace map_tool;  // NOLINT(google-build-using-namespace): this tool's own run

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

  if (const auto file = std::filesystem::path(opt.dataset) / "small_objects.txt";
      in.safety && std::filesystem::exists(file)) {
    auto objects = tools::read_small_objects(file);
    if (!objects) {
      std::fprintf(stderr, "tarmac-map: %s\n", objects.error().message.c_str());
      return kExitData;
    }
    in.small_objects.emplace(std::move(objects).value());
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
  const core::CostmapLayers& layers = mapper.costmap();
  const tools::LethalCauseView causes{layers.column_class.cells(), layers.obstacle_rule};
  if (in.clearing) {
    // The base sits on the ground (--sensor-height): its z is the ground's near the vehicle.
    const Eigen::Vector3d sensor_W = T_W_B * T_B_S.translation();
    in.clearing->observe(
        static_cast<int>(k), s.times_s[k], layers.column_class, sensor_W.head<2>(),
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
    in.safety->observe(layers.costmap, static_cast<int>(k), s.T_W_S[k].translation().head<2>(),
                       20.0, moving_now, causes);
    if (in.small_objects) {
      in.small_objects->observe(layers.costmap, static_cast<int>(k),
                                s.T_W_S[k].translation().head<2>());
    }
  }
  if (in.open_ground) {
    in.open_ground->add(points_W);
    // Every 10th scan and the last: a full-window pass each.
    if (k % 10 == 9 || k + 1 == n) {
      in.open_ground->observe(layers.costmap, static_cast<int>(k), causes);
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
    const core::OccupancyUpdate& occ = r.occupancy;
    if (r.tsdf != nullptr) {
      run.tsdf_samples += r.tsdf->samples;
      run.tsdf_updates += r.tsdf->voxel_updates;
    }
    if (r.rebuild.scans > 0)
      run.rebuild_ms.push_back(r.rebuild_ms);  // not the steps waiting to start
    cycle.update_costmap(mapper.vehicle_pose(), {}, cloud.stamp_ns);
    run.debris_per_scan.push_back(static_cast<std::uint32_t>(mapper.debris().size()));
    if (fleet) send_summary(*fleet, cloud.stamp_ns);
    // The 3D band (esdf_band.enabled), every scan as the daemon does every cycle.
    cycle.update_esdf_band(mapper.vehicle_pose(), {}, cloud.stamp_ns);
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
    mapper.update_costmap(mapper.vehicle_pose(), {}, cloud.stamp_ns, pool);
    mapper.update_esdf_band(mapper.vehicle_pose(), {}, cloud.stamp_ns, pool);
  }
  run.last_stamp_ns = cloud.stamp_ns;
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
