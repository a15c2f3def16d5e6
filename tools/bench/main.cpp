// tarmac-bench: tarmac's occupancy integration against OctoMap (Debian liboctomap-dev,
// insertPointCloud, same resolution, max range and sensor model) on the same scans in one run;
// map agreement; tarmac's full pipeline per stage; tarmac's exact ESDF against OctoMap's
// dynamicEDT3D on the same occupancy.

#include <dynamicEDT3D/dynamicEDT3D.h>
#include <octomap/OcTree.h>

#include <sys/resource.h>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "tarmac/config/cli.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/daemon/thread_pool.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/tools/phase_runner.hpp"
#include "tarmac/tools/stats.hpp"
#include "vdbfusion_reference.hpp"
#include "walk_compare.hpp"

namespace {

using namespace tarmac;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string dataset;
  std::string poses = "poses.txt";
  double resolution_m = 0.2;
  double max_range_m = 50.0;
  std::size_t threads = 2;
  int walk_lanes = 8;   ///< most rays walked at a time (8: AVX-512, 4: AVX2, 1), as supported
  bool phases = false;  ///< time each stage's parallel_for calls and serial stretches
  /// Leave the workers asleep before each scan's stages (by default they are woken
  /// ThreadPool::kWakeLead before, as tarmacd does before each tick).
  bool asleep_workers = false;
  std::size_t max_scans = 0;
  double sensor_height_m = 1.9;
  bool esdf = true;
  float tsdf_voxel_m = 0.1f;
  float tsdf_truncation_m = 0.3f;
  /// As tarmacd warms up with the shipped config (tsdf.reserve_blocks,
  /// quotas.reserve_points_per_scan): new blocks and the first scans' scratch cost no page faults.
  std::uint32_t tsdf_reserve_blocks = 8192;
  std::size_t reserve_points = 65536;
  bool tsdf_only = false;
  bool walk_compare = false;  ///< also time the TSDF band walk against OpenVDB's DDA
  /// Occupancy window in voxels (x, y, z); 0: derived from the max range (x, y) and 8 m (z).
  std::array<int, 3> window{0, 0, 0};
};

using tools::timed_ms;
/// CPU time of the whole process (all threads), ms: robust to other load on the machine.
double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

/// Minor page faults of the whole process so far.
double process_minor_faults() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_minflt);
}

/// Finishes the allocator work that OctoMap's frees leave behind, so that the stage measured next
/// does not pay for it. glibc defers it: freed small nodes (OctoMap's key sets, ~10^5 per
/// insertion) sit in fast bins and in the unsorted list, and the next allocations on this thread
/// consolidate and sort them, at most 10,000 chunks per malloc call. Measured on MulRan (0.2 m):
/// 11-16 ms per scan, which the TSDF row (the next stage that allocates on this thread: new
/// leaves, OpenVDB internal nodes, the retained block list) was charged before. Allocating a
/// request no free chunk fits until a call is fast again drains that list.
void settle_allocator() {
  for (int i = 0; i < 10000; ++i) {
    const auto t0 = Clock::now();
    void* volatile p = std::malloc(std::size_t{64} << 10);
    std::free(p);
    if (Clock::now() - t0 < std::chrono::microseconds(20)) break;
  }
}

struct Summary {
  double mean, p50, p99, max;
};
Summary summarize(const std::vector<double>& v) {
  return {tools::mean(v), tools::percentile(v, 0.5), tools::percentile(v, 0.99),
          tools::percentile(v, 1.0)};
}

/// The header of print_row's rows.
void print_header() {
  std::printf("  %-26s %9s %9s %9s %9s %7s   (ms per scan; worst: the max's scan index)\n", "",
              "mean", "p50", "p99", "max", "worst");
}

/// A row of per-scan values: mean, p50, p99, max, and the scan index of the max.
void print_row(const char* name, const std::vector<double>& ms) {
  const auto s = summarize(ms);
  std::printf("  %-26s %9.2f %9.2f %9.2f %9.2f %7zu\n", name, s.mean, s.p50, s.p99, s.max,
              tools::index_of_max(ms));
}

/// The command line into `opt`; cli::parse's exit code when it is not a run (help, version, an
/// error).
std::optional<int> parse_options(cli::App& app, Options& opt, int argc, char** argv) {
  app.add_option("--dataset", opt.dataset, "the sequence, KITTI layout")
      ->required()
      ->check(CLI::ExistingDirectory);
  app.add_option("--poses", opt.poses, "pose file inside DIR")->type_name("FILE");
  app.add_option("--resolution", opt.resolution_m, "occupancy voxel size, m")
      ->transform(cli::positive<double>());
  app.add_option("--max-range", opt.max_range_m, "max range, m")
      ->transform(cli::positive<double>());
  app.add_option("--threads", opt.threads, "worker threads")
      ->transform(cli::positive<std::size_t>());
  app.add_option("--scans", opt.max_scans, "first N scans only (0: all)")
      ->transform(cli::number<std::size_t>());
  app.add_option("--sensor-height", opt.sensor_height_m, "sensor above the vehicle base, m")
      ->transform(cli::number<double>());
  app.add_flag_callback(
      "--no-esdf", [&opt] { opt.esdf = false; }, "no 3D ESDF comparison and no 3D band stage");
  app.add_option("--tsdf-voxel", opt.tsdf_voxel_m, "TSDF voxel size, m")
      ->transform(cli::positive<float>());
  app.add_option("--tsdf-truncation", opt.tsdf_truncation_m, "TSDF truncation distance, m")
      ->transform(cli::positive<float>());
  app.add_option("--tsdf-reserve-blocks", opt.tsdf_reserve_blocks,
                 "TSDF blocks reserved up front (tsdf.reserve_blocks; 0: none)")
      ->transform(cli::number<std::uint32_t>());
  app.add_option("--reserve-points", opt.reserve_points,
                 "per-scan buffers sized and touched up front for scans of N points "
                 "(quotas.reserve_points_per_scan; 0: none, they grow in the first scans)")
      ->transform(cli::number<std::size_t>());
  app.add_flag("--tsdf-only", opt.tsdf_only,
               "the TSDF only: no occupancy, costmap, OctoMap or ESDF stages");
  app.add_option("--window", opt.window,
                 "occupancy window in voxels, e.g. 400,400,40 (default: 2*ceil(range/res)+2 x "
                 "same x 8 m)")
      ->delimiter(',')
      ->type_name("X,Y,Z")
      ->default_str("")
      ->multi_option_policy(CLI::MultiOptionPolicy::Throw)  // 1,2,3,4: an error, not 2,3,4
      ->transform(cli::positive<int>());
  auto* lanes =
      app.add_option("--walk-lanes", opt.walk_lanes,
                     "most rays walked at a time: 8 (AVX-512), 4 (AVX2), 1; as the CPU supports")
          ->check(CLI::IsMember({8, 4, 1}));
  app.add_flag_callback(
         "--narrow-walk", [&opt] { opt.walk_lanes = 1; },
         "rays walked one at a time (--walk-lanes 1)")
      ->excludes(lanes);
  app.add_flag("--phases", opt.phases,
               "per stage: each parallel_for call and the serial stretches between");
  app.add_flag("--asleep-workers", opt.asleep_workers,
               "do not wake the workers before each scan, as tarmacd does before each tick");
  app.add_flag("--walk-compare", opt.walk_compare,
               "also time the TSDF's band walk against OpenVDB's DDA on the same rays");
  if (auto exit = cli::parse(app, argc, argv)) return *exit;
  return cli::parse(app, argc, argv);
}

/// tarmac's stages and the baselines, run on the same scans, and their per-scan figures.
class Bench {
 public:
  Bench(const Options& opt, const core::MapperParams& params)
      : opt_(opt),
        params_(params),
        pool_(opt.threads),
        phased_(pool_),
        mapper_(params),
        octree_(opt.resolution_m),
        vdbfusion_(opt.tsdf_voxel_m, opt.tsdf_truncation_m) {
    mapper_.reserve_scans(opt.reserve_points);
    mapper_.occupancy().set_walk_lanes(opt.walk_lanes);
    octree_.setProbHit(params.occupancy.prob_hit);
    octree_.setProbMiss(params.occupancy.prob_miss);
    octree_.setClampingThresMin(params.occupancy.clamp_min);
    octree_.setClampingThresMax(params.occupancy.clamp_max);
  }

  /// One scan through tarmac's stages, then through the baselines on the points tarmac kept.
  void run_scan(std::size_t k, const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                const Eigen::Isometry3d& T_B_S) {
    const core::FilteredScan scan = run_tarmac(k, cloud, T_W_B, T_B_S);
    const double cpu1 = process_cpu_ms();
    vdbfusion_ms_.push_back(
        timed_ms([&] { vdbfusion_.integrate(scan.sensor_W, scan.points_W, opt_.max_range_m); }));
    vdbfusion_cpu_.push_back(process_cpu_ms() - cpu1);
    if (opt_.walk_compare) {
      walks_.add_scan(scan.sensor_W, scan.points_W, opt_.tsdf_voxel_m, opt_.tsdf_truncation_m,
                      opt_.max_range_m);
    }
    time_esdf2d(k);
    points_ += scan.counts.kept;
    if (!opt_.tsdf_only) run_octomap(scan);
  }

  void report_tsdf(std::size_t n) const;
  /// Occupancy against OctoMap (time, agreement in the window) and tarmac's stages.
  void report_occupancy(std::size_t n) const;
  /// The 3D ESDF over the window against dynamicEDT3D on the final occupancy.
  void compare_esdf();
  void report_targets() const;
  void report_walks() const {
    if (opt_.walk_compare) walks_.print();
  }

 private:
  const Options& opt_;
  core::MapperParams params_;
  daemon::ThreadPool pool_;
  /// --phases: the filter, occupancy, costmap and band stages run on a PhaseRunner over the same
  /// pool (the same tasks on the same threads; a clock read around each task is added).
  tools::PhaseRunner phased_;
  core::Mapper mapper_;
  octomap::OcTree octree_;
  /// VDBFusion's algorithm on the same points, single-threaded (as VDBFusion is): the TSDF
  /// baseline.
  bench::VdbFusionReference vdbfusion_;
  bench::WalkCompare walks_;
  core::DistanceField field2d_;
  core::DistanceFieldScratch scratch2d_;

  // Per scan, ms unless named otherwise.
  std::vector<double> filter_, occ_, cost_, pipeline_, mapping_, octomap_, occ_only_, tsdf_,
      tsdf_cpu_, tsdf_faults_, esdf2d_, band_, vdbfusion_ms_, vdbfusion_cpu_, spares_, spares_cpu_;
  std::vector<tools::StagePhases> ph_filter_, ph_occ_, ph_cost_, ph_band_;
  std::uint64_t points_ = 0, tsdf_samples_ = 0, tsdf_updates_ = 0, first_scan_blocks_ = 0;

  core::TaskRunner& runner() {
    return opt_.phases ? static_cast<core::TaskRunner&>(phased_) : pool_;
  }
  template <typename Fn>
  double staged(std::vector<tools::StagePhases>& out, Fn&& fn) {
    if (opt_.phases) phased_.begin_stage();
    const double ms = timed_ms(fn);
    if (opt_.phases) out.push_back(phased_.end_stage());
    return ms;
  }

  core::FilteredScan run_tarmac(std::size_t k, const core::PointCloud& cloud,
                                const Eigen::Isometry3d& T_W_B, const Eigen::Isometry3d& T_B_S);
  void time_esdf2d(std::size_t k);
  void run_octomap(const core::FilteredScan& scan);
};

core::FilteredScan Bench::run_tarmac(std::size_t k, const core::PointCloud& cloud,
                                     const Eigen::Isometry3d& T_W_B,
                                     const Eigen::Isometry3d& T_B_S) {
  // The workers slept through the last scan's OctoMap insertion, as tarmacd's sleep between
  // ticks: they are woken kWakeLead before the stages, as tarmacd wakes them before each tick
  // (waking one takes tens of µs, which the first parallel_for would otherwise spend on one
  // thread).
  if (!opt_.asleep_workers) {
    pool_.wake();
    const auto until = Clock::now() + daemon::ThreadPool::kWakeLead;
    while (Clock::now() < until) {
    }
  }
  core::FilteredScan scan;
  const double f =
      staged(ph_filter_, [&] { scan = mapper_.ingest(cloud, T_W_B, T_B_S, runner()); });
  const double o =
      opt_.tsdf_only ? 0.0 : staged(ph_occ_, [&] { mapper_.integrate(scan, runner()); });
  const double faults0 = process_minor_faults();
  const double cpu0 = process_cpu_ms();
  const double ts = timed_ms([&] {
    const core::TsdfUpdate& up = mapper_.integrate_tsdf(scan, pool_);
    if (k == 0) first_scan_blocks_ = up.blocks_created;
    tsdf_samples_ += up.samples;
    tsdf_updates_ += up.voxel_updates;
  });
  tsdf_cpu_.push_back(process_cpu_ms() - cpu0);
  tsdf_faults_.push_back(process_minor_faults() - faults0);
  tsdf_.push_back(ts);
  // The spare blocks this scan took, rebuilt between scans as tarmacd rebuilds them between
  // ticks (all of them here, at most a 16th of reserve_blocks a tick there): timed on its own.
  const double cpu_spares = process_cpu_ms();
  spares_.push_back(
      timed_ms([&] { mapper_.top_up_tsdf_spares(std::numeric_limits<std::size_t>::max()); }));
  spares_cpu_.push_back(process_cpu_ms() - cpu_spares);
  const double c = opt_.tsdf_only ? 0.0 : staged(ph_cost_, [&] {
    mapper_.update_costmap(mapper_.vehicle_pose(), {}, 0, runner());
  });
  // The band stage: its states from the window and this costmap's ground, then the transform.
  if (params_.esdf_band.enabled) {
    band_.push_back(staged(
        ph_band_, [&] { mapper_.update_esdf_band(mapper_.vehicle_pose(), {}, 0, runner()); }));
  }
  filter_.push_back(f);
  occ_.push_back(o);
  cost_.push_back(c);
  pipeline_.push_back(f + o + ts + c);
  mapping_.push_back(f + o + c);
  occ_only_.push_back(f + o);
  return scan;
}

void Bench::time_esdf2d(std::size_t k) {
  // The 2D ESDF alone, on the costmap's own input (the costmap stage computes it inside).
  const auto& layers = mapper_.costmap();
  const Eigen::Vector3i dims2d(static_cast<int>(layers.costmap.width()),
                               static_cast<int>(layers.costmap.height()), 1);
  const auto esdf2d = [&] {
    core::compute_distance_field(layers.esdf_input, dims2d, opt_.resolution_m,
                                 core::UnknownPolicy::kReportUnknown, field2d_, scratch2d_, pool_);
  };
  // Warm-up, untimed: the first call sizes (and page-faults in) the 2.6 MB field and its
  // scratch, which the daemon does once in its first cycle and then reuses; timed, that
  // one-off cost was this row's p99 (p99 of 21 scans is their maximum).
  if (k == 0) esdf2d();
  esdf2d_.push_back(timed_ms(esdf2d));
}

void Bench::run_octomap(const core::FilteredScan& scan) {
  // OctoMap on exactly the points tarmac kept, in the world frame, from the same origin.
  octomap::Pointcloud cloud;
  cloud.reserve(scan.points_W.size());
  for (const auto& p : scan.points_W) cloud.push_back(p.x(), p.y(), p.z());
  const Eigen::Vector3d& o_W = scan.sensor_W;
  octomap_.push_back(timed_ms([&] {
    octree_.insertPointCloud(
        cloud,
        octomap::point3d(static_cast<float>(o_W.x()), static_cast<float>(o_W.y()),
                         static_cast<float>(o_W.z())),
        opt_.max_range_m, false, false);
    // OctoMap's own deferred allocator work, charged to it rather than to the next stage.
    settle_allocator();
  }));
}

/// TSDF: integration time per scan against VDBFusion's algorithm, and memory per mapped area
/// (area = voxel columns holding at least one observed voxel).
void Bench::report_tsdf(std::size_t n) const {
  const core::TsdfLayer& tsdf = mapper_.tsdf();
  std::vector<std::uint64_t> columns;
  tsdf.for_each_block([&](const core::TsdfBlockView& b) {
    for (int i = 0; i < core::kTsdfBlockEdge; ++i) {
      for (int j = 0; j < core::kTsdfBlockEdge; ++j) {
        bool seen = false;
        for (int k = 0; k < core::kTsdfBlockEdge && !seen; ++k) {
          seen = b.voxels[core::tsdf_voxel_offset(i, j, k)].weight > 0.0f;
        }
        if (!seen) continue;
        const auto x = static_cast<std::uint32_t>(b.block.x() * core::kTsdfBlockEdge + i);
        const auto y = static_cast<std::uint32_t>(b.block.y() * core::kTsdfBlockEdge + j);
        columns.push_back((static_cast<std::uint64_t>(x) << 32) | y);
      }
    }
  });
  std::sort(columns.begin(), columns.end());
  columns.erase(std::unique(columns.begin(), columns.end()), columns.end());
  const double vox = tsdf.voxel_size_m();
  const double area_m2 = static_cast<double>(columns.size()) * vox * vox;
  const double mib = static_cast<double>(tsdf.memory_bytes()) / (1024.0 * 1024.0);
  std::printf(
      "\ntarmac-bench: TSDF %.2f m voxels, truncation %.2f m, max range %.0f m, %zu threads, %zu "
      "scans, %.0f points/scan\n",
      vox, static_cast<double>(tsdf.truncation_m()), opt_.max_range_m, opt_.threads, n,
      static_cast<double>(points_) / static_cast<double>(n));
  print_header();
  print_row("tsdf integrate (wall)", tsdf_);
  print_row("tsdf integrate (CPU, sum)", tsdf_cpu_);
  print_row("tsdf minor faults (count)", tsdf_faults_);
  print_row("spare blocks top-up (wall)", spares_);
  print_row("VDBFusion algo (wall)", vdbfusion_ms_);
  print_row("VDBFusion algo (CPU)", vdbfusion_cpu_);
  const auto ts = summarize(tsdf_), tv = summarize(vdbfusion_ms_);
  const auto tsc = summarize(tsdf_cpu_), tvc = summarize(vdbfusion_cpu_);
  std::printf(
      "  speed ratio VDBFusion / tarmac: wall mean %.2fx, p50 %.2fx; CPU mean %.2fx, p50 %.2fx\n",
      tv.mean / ts.mean, tv.p50 / ts.p50, tvc.mean / tsc.mean, tvc.p50 / tsc.p50);
  // The first scan into the empty map (every block and node new) against the scans after it.
  if (tsdf_.size() > 1) {
    const auto later = summarize(std::vector<double>(tsdf_.begin() + 1, tsdf_.end()));
    std::printf(
        "  first scan into the empty map: %.2f ms, %.0f faults, %llu new blocks (reserved: %u) "
        "(later scans: p50 %.2f, p99 %.2f, max %.2f ms) -> %.2fx the later p50\n",
        tsdf_[0], tsdf_faults_[0], static_cast<unsigned long long>(first_scan_blocks_),
        opt_.tsdf_reserve_blocks, later.p50, later.p99, later.max, tsdf_[0] / later.p50);
  }
  // The same with the top-up's work added to each scan (all the work, off the cycle or not).
  std::vector<double> with_spares(tsdf_.size()), with_spares_cpu(tsdf_.size());
  for (std::size_t k = 0; k < tsdf_.size(); ++k) {
    with_spares[k] = tsdf_[k] + spares_[k];
    with_spares_cpu[k] = tsdf_cpu_[k] + spares_cpu_[k];
  }
  const auto tw = summarize(with_spares), twc = summarize(with_spares_cpu);
  std::printf(
      "  the same, top-up counted in each scan: wall mean %.2fx, p50 %.2fx; CPU mean %.2fx, "
      "p50 %.2fx\n",
      tv.mean / tw.mean, tv.p50 / tw.p50, tvc.mean / twc.mean, tvc.p50 / twc.p50);
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) > 0) {
    std::printf("  (CPU = process CPU time over all threads; machine load average %.2f)\n",
                load[0]);
  }
  std::printf("  %.1f band samples/point, %.1f voxel updates/point\n",
              static_cast<double>(tsdf_samples_) / static_cast<double>(points_),
              static_cast<double>(tsdf_updates_) / static_cast<double>(points_));
  std::printf(
      "  map: %zu blocks, %zu voxels, %.1f MiB over %.0f m^2 mapped -> %.2f MiB per 1000 m^2\n",
      tsdf.block_count(), tsdf.voxel_count(), mib, area_m2,
      area_m2 > 0 ? mib / area_m2 * 1000.0 : 0.0);
  std::printf("  digest %016llx; VDBFusion algorithm: %zu voxels\n",
              static_cast<unsigned long long>(tsdf.digest()), vdbfusion_.voxel_count());
}

void Bench::report_occupancy(std::size_t n) const {
  // Agreement inside tarmac's window, voxel by voxel on the shared lattice [i·v, (i+1)·v).
  const auto& map = mapper_.occupancy();
  const Eigen::Vector3i dims = map.window_size();
  std::uint64_t both_occ = 0, either_occ = 0, either_known = 0, same_state = 0;
  std::uint64_t tarmac_only_known = 0, octomap_only_known = 0;
  for (int z = 0; z < dims.z(); ++z) {
    for (int y = 0; y < dims.y(); ++y) {
      for (int x = 0; x < dims.x(); ++x) {
        const core::VoxelIndex g = map.window_min() + core::VoxelIndex(x, y, z);
        const float l = map.log_odds(g);
        const int t_state = l == core::OccupancyMap::kUnknown ? 0 : (l > 0.0f ? 2 : 1);
        const octomap::point3d c(static_cast<float>((g.x() + 0.5) * opt_.resolution_m),
                                 static_cast<float>((g.y() + 0.5) * opt_.resolution_m),
                                 static_cast<float>((g.z() + 0.5) * opt_.resolution_m));
        const octomap::OcTreeNode* node = octree_.search(c);
        const int o_state = node == nullptr ? 0 : (octree_.isNodeOccupied(node) ? 2 : 1);
        both_occ += (t_state == 2 && o_state == 2);
        either_occ += (t_state == 2 || o_state == 2);
        if (t_state != 0 || o_state != 0) {
          ++either_known;
          same_state += t_state == o_state;
          tarmac_only_known += (o_state == 0);
          octomap_only_known += (t_state == 0);
        }
      }
    }
  }

  const auto occ = summarize(occ_only_);
  const auto oct = summarize(octomap_);
  std::printf(
      "\ntarmac-bench: %s, %zu scans, %.0f points/scan used, resolution %.2f m, max range %.0f m, "
      "%zu threads, rays walked %s\n",
      opt_.dataset.c_str(), n, static_cast<double>(points_) / static_cast<double>(n),
      opt_.resolution_m, opt_.max_range_m, opt_.threads,
      mapper_.occupancy().walk_lanes() == 8   ? "8 at a time (AVX-512)"
      : mapper_.occupancy().walk_lanes() == 4 ? "4 at a time (AVX2)"
                                              : "one at a time");
  print_header();
  print_row("OctoMap insertPointCloud", octomap_);
  print_row("tarmac filter+occupancy", occ_only_);
  std::printf("  speed ratio (OctoMap / tarmac): mean %.1fx, p50 %.1fx\n", oct.mean / occ.mean,
              oct.p50 / occ.p50);
  // OctoMap gets the points_ tarmac's filter kept, already in the world frame: the ratio above
  // charges tarmac its filter too (the target is read on it); this one is the
  // occupancy update alone, on the same input.
  const auto occ_stage = summarize(occ_);
  std::printf("  speed ratio, occupancy stage only: mean %.1fx, p50 %.1fx\n",
              oct.mean / occ_stage.mean, oct.p50 / occ_stage.p50);
  std::printf(
      "  agreement in the window: occupied IoU %.3f, same state %.3f of %llu voxels known to "
      "either "
      "(known to tarmac only %llu, to OctoMap only %llu)\n",
      either_occ > 0 ? static_cast<double>(both_occ) / static_cast<double>(either_occ) : 1.0,
      either_known > 0 ? static_cast<double>(same_state) / static_cast<double>(either_known) : 1.0,
      static_cast<unsigned long long>(either_known),
      static_cast<unsigned long long>(tarmac_only_known),
      static_cast<unsigned long long>(octomap_only_known));
  std::printf("  tarmac full pipeline per stage:\n");
  print_row("filter", filter_);
  print_row("occupancy", occ_);
  print_row("tsdf", tsdf_);
  print_row("costmap + 2D ESDF", cost_);
  print_row("  of which 2D ESDF", esdf2d_);
  if (!band_.empty()) print_row("3D ESDF band stage", band_);
  print_row("pipeline", pipeline_);
  print_row("filter+occupancy+costmap", mapping_);
  if (opt_.phases) {
    std::printf(
        "  phases of each stage (--phases; which call is which: see the stage's source):\n");
    std::fputs(tools::summarize_phases("filter", ph_filter_).c_str(), stdout);
    std::fputs(tools::summarize_phases("occupancy", ph_occ_).c_str(), stdout);
    std::fputs(tools::summarize_phases("costmap + 2D ESDF", ph_cost_).c_str(), stdout);
    if (!ph_band_.empty())
      std::fputs(tools::summarize_phases("3D ESDF band", ph_band_).c_str(), stdout);
  }
}

void Bench::compare_esdf() {
  const auto& map = mapper_.occupancy();
  const Eigen::Vector3i dims = map.window_size();
  // 3D ESDF over the whole window on the final occupancy: tarmac's exact transform against
  // dynamicEDT3D's full update on the same binary map.
  std::vector<core::CellState> states(static_cast<std::size_t>(dims.prod()));
  bool*** grid = new bool**[dims.x()];
  std::vector<float> lo;
  map.export_log_odds(lo);
  for (int x = 0; x < dims.x(); ++x) {
    grid[x] = new bool*[dims.y()];
    for (int y = 0; y < dims.y(); ++y) grid[x][y] = new bool[dims.z()];
  }
  for (std::size_t i = 0; i < lo.size(); ++i) {
    const bool occ_i = lo[i] != core::OccupancyMap::kUnknown && lo[i] > 0.0f;
    states[i] = occ_i ? core::CellState::kOccupied : core::CellState::kFree;
    const int x = static_cast<int>(i % dims.x()), y = static_cast<int>((i / dims.x()) % dims.y()),
              z = static_cast<int>(i / (static_cast<std::size_t>(dims.x()) * dims.y()));
    grid[x][y][z] = occ_i;
  }
  core::DistanceField field;
  core::DistanceFieldScratch scratch;
  std::vector<double> t_tarmac_edt;
  for (int r = 0; r < 3; ++r) {
    t_tarmac_edt.push_back(timed_ms([&] {
      core::compute_distance_field(states, dims, opt_.resolution_m,
                                   core::UnknownPolicy::kReportUnknown, field, scratch, pool_);
    }));
  }
  const int maxdist = dims.x() * dims.x() + dims.y() * dims.y() + dims.z() * dims.z();
  DynamicEDT3D edt(maxdist);
  double t_dyn = 0.0;
  edt.initializeMap(dims.x(), dims.y(), dims.z(), grid);
  t_dyn = timed_ms([&] { edt.update(true); });
  std::uint64_t differ = 0;
  double max_diff_m = 0.0;
  for (std::size_t i = 0; i < lo.size(); ++i) {
    const int x = static_cast<int>(i % dims.x()), y = static_cast<int>((i / dims.x()) % dims.y()),
              z = static_cast<int>(i / (static_cast<std::size_t>(dims.x()) * dims.y()));
    const double d_dyn =
        std::sqrt(static_cast<double>(edt.getSQCellDistance(x, y, z))) * opt_.resolution_m;
    const double d_t = field.distance_m[i];
    if (std::isinf(d_t)) continue;
    const double diff = std::abs(d_dyn - d_t);
    if (diff > 1e-4) ++differ;
    max_diff_m = std::max(max_diff_m, diff);
  }
  // Where the two disagree, who is right: brute force over every occupied voxel.
  std::vector<Eigen::Vector3i> occupied;
  for (std::size_t i = 0; i < lo.size(); ++i) {
    if (states[i] == core::CellState::kOccupied) {
      occupied.emplace_back(static_cast<int>(i % dims.x()),
                            static_cast<int>((i / dims.x()) % dims.y()),
                            static_cast<int>(i / (static_cast<std::size_t>(dims.x()) * dims.y())));
    }
  }
  std::uint64_t checked = 0, tarmac_exact = 0, dyn_exact = 0;
  for (std::size_t i = 0; i < lo.size() && checked < 200; ++i) {
    const int x = static_cast<int>(i % dims.x()), y = static_cast<int>((i / dims.x()) % dims.y()),
              z = static_cast<int>(i / (static_cast<std::size_t>(dims.x()) * dims.y()));
    const double d_dyn =
        std::sqrt(static_cast<double>(edt.getSQCellDistance(x, y, z))) * opt_.resolution_m;
    const double d_t = field.distance_m[i];
    if (std::isinf(d_t) || std::abs(d_dyn - d_t) <= 1e-4) continue;
    long best = std::numeric_limits<long>::max();
    for (const auto& o : occupied) {
      const long dx = o.x() - x, dy = o.y() - y, dz = o.z() - z;
      best = std::min(best, dx * dx + dy * dy + dz * dz);
    }
    const double d_ref = std::sqrt(static_cast<double>(best)) * opt_.resolution_m;
    ++checked;
    tarmac_exact += std::abs(d_t - d_ref) <= 1e-4;
    dyn_exact += std::abs(d_dyn - d_ref) <= 1e-4;
  }
  // DynamicEDT3D took ownership of `grid` and frees it in its destructor.
  const auto te = summarize(t_tarmac_edt);
  std::printf("  3D ESDF over the window (%d x %d x %d voxels), same occupancy:\n", dims.x(),
              dims.y(), dims.z());
  std::printf(
      "    tarmac exact EDT: p50 %.1f ms (of 3 runs); dynamicEDT3D full update: %.1f ms; ratio "
      "%.1fx\n",
      te.p50, t_dyn, t_dyn / te.p50);
  std::printf("    distances differing by > 0.1 mm: %llu of %zu voxels, max difference %.4f m\n",
              static_cast<unsigned long long>(differ), lo.size(), max_diff_m);
  std::printf(
      "    brute force on %llu of those: tarmac exact in %llu, dynamicEDT3D exact in %llu\n",
      static_cast<unsigned long long>(checked), static_cast<unsigned long long>(tarmac_exact),
      static_cast<unsigned long long>(dyn_exact));
}

/// Issue 3's speed targets on this run's window (the shipped config's is 400 x 400 x 40).
void Bench::report_targets() const {
  const Eigen::Vector3i dims = mapper_.occupancy().window_size();
  const auto esdf2d = summarize(esdf2d_), mapping = summarize(mapping_);
  const auto yes = [](bool met) { return met ? "met" : "NOT met"; };
  std::printf("  issue 3 targets, window %d x %d x %d, %zu threads:\n", dims.x(), dims.y(),
              dims.z(), opt_.threads);
  std::printf("    2D ESDF <= 2 ms: p50 %.2f ms, p99 %.2f ms (%s at p50)\n", esdf2d.p50, esdf2d.p99,
              yes(esdf2d.p50 <= 2.0));
  if (!band_.empty()) {
    const auto band = summarize(band_);
    const Eigen::Vector3i bd = mapper_.esdf_band().field.dims;
    std::printf(
        "    3D band (%d x %d x %d voxels, states + transform) <= 20 ms: p50 %.1f ms, p99 %.1f ms "
        "(%s at p50)\n",
        bd.x(), bd.y(), bd.z(), band.p50, band.p99, yes(band.p50 <= 20.0));
  }
  std::printf("    filter+occupancy+costmap p99 <= 30 ms: p99 %.1f ms, p50 %.1f ms (%s)\n",
              mapping.p99, mapping.p50, yes(mapping.p99 <= 30.0));
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) > 0) std::printf("    (machine load average %.2f)\n", load[0]);
}

/// The run's settings, the same for tarmac and the baselines where both have them.
core::MapperParams make_params(const Options& opt) {
  // Same settings for both: resolution, max range, OctoMap's sensor model. tarmac's window covers
  // the max range around the vehicle horizontally and 8 m vertically (3 m below the base), unless
  // --window sets it (e.g. the shipped config's 400 x 400 x 40): rays leaving it are clipped by
  // design, so agreement is measured inside the window only.
  core::MapperParams params;
  params.occupancy.voxel_size_m = opt.resolution_m;
  const int half = static_cast<int>(std::ceil(opt.max_range_m / opt.resolution_m));
  params.occupancy.window_x_vox = opt.window[0] > 0 ? opt.window[0] : 2 * half + 2;
  params.occupancy.window_y_vox = opt.window[1] > 0 ? opt.window[1] : 2 * half + 2;
  params.occupancy.window_z_vox =
      opt.window[2] > 0 ? opt.window[2] : static_cast<int>(std::ceil(8.0 / opt.resolution_m));
  params.occupancy.max_range_m = opt.max_range_m;
  // OctoMap's insertPointCloud: a return beyond max range clears free space up to max range.
  params.occupancy.clearing_range_m = opt.max_range_m;
  // TSDF at its own resolution (default 0.1 m / 0.3 m, VDBFusion's KITTI setting), same max range.
  params.tsdf.voxel_size_m = opt.tsdf_voxel_m;
  params.tsdf.truncation_m = opt.tsdf_truncation_m;
  params.tsdf.reserve_blocks = opt.tsdf_reserve_blocks;
  params.tsdf.max_range_m = static_cast<float>(opt.max_range_m);
  // The 3D ESDF band stage as tarmacd runs it (esdf_band defaults: −0.2 … +3.0 m around the
  // base), unless the window is too low for it.
  params.esdf_band.enabled = opt.esdf && !opt.tsdf_only;
  if (params.esdf_band.enabled && !params.validate()) params.esdf_band.enabled = false;
  return params;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  cli::App app("tarmac-bench",
               "tarmac's occupancy integration against OctoMap (insertPointCloud, same resolution, "
               "max range and sensor model) on the same scans in one run; map agreement; "
               "tarmac's full pipeline per stage; tarmac's exact ESDF against dynamicEDT3D; its "
               "TSDF against VDBFusion's algorithm.");
  if (auto exit = parse_options(app, opt, argc, argv)) return *exit;
  auto seq = tools::open_kitti(opt.dataset, opt.poses);
  if (!seq) {
    std::fprintf(stderr, "tarmac-bench: %s\n", seq.error().message.c_str());
    return 65;
  }
  const std::size_t n = opt.max_scans == 0 ? seq.value().scans.size()
                                           : std::min(opt.max_scans, seq.value().scans.size());
  const core::MapperParams params = make_params(opt);
  if (auto valid = params.validate(); !valid) return cli::usage_error(app, valid.error().message);
  std::vector<core::PointCloud> clouds(n);
  for (std::size_t k = 0; k < n; ++k) {
    if (auto r = tools::read_kitti_scan(seq.value().scans[k], clouds[k]); !r) {
      std::fprintf(stderr, "tarmac-bench: %s\n", r.error().message.c_str());
      return 65;
    }
  }

  Bench bench(opt, params);
  Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
  T_B_S.translation().z() = opt.sensor_height_m;
  for (std::size_t k = 0; k < n; ++k) {
    bench.run_scan(k, clouds[k], seq.value().T_W_S[k] * T_B_S.inverse(), T_B_S);
    std::fprintf(stderr, "\rtarmac-bench: scan %zu/%zu", k + 1, n);
  }
  std::fprintf(stderr, "\n");
  bench.report_tsdf(n);
  bench.report_walks();
  if (opt.tsdf_only) return 0;
  bench.report_occupancy(n);
  if (opt.esdf) bench.compare_esdf();
  bench.report_targets();
  return 0;
}
