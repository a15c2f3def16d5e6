// tarmac-map's report: the stage table, the run's summaries, the digests and timing.json.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "outputs.hpp"
#include "report.hpp"
#include "run.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/tools/array_io.hpp"
#include "tarmac/tools/mesh_io.hpp"
#include "tarmac/tools/open_ground.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/stats.hpp"

namespace tarmac::map_tool {
namespace {

using tools::mean;
using tools::percentile;

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

/// Against a tarmac-sim truth: dynamic clearing, the costmap's safety, the small objects.
void report_truth(const Inputs& in, nlohmann::ordered_json& timing) {
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
  if (in.small_objects) {
    std::printf("%s", tools::small_objects_summary(*in.small_objects,
                                                   in.cfg.mapping.costmap.min_obstacle_height_m)
                          .c_str());
    timing["small_objects"] = tools::small_objects_json(*in.small_objects);
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

/// debris.json: the debris of the last costmap (the ground crew's list, docs/mapping.md "Debris
/// report") and the count after each scan.
core::Status write_debris(const Options& opt, const core::Mapper& mapper, const Run& run) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const core::Debris& d : mapper.debris()) {
    list.push_back({{"id", d.id},
                    {"x_m", d.xy_W.x()},
                    {"y_m", d.xy_W.y()},
                    {"ground_z_m", d.ground_z_m},
                    {"height_m", d.height_m},
                    {"footprint_m", d.footprint_m},
                    {"first_seen_ns", d.first_seen_ns},
                    {"last_confirmed_ns", d.last_confirmed_ns},
                    {"returns", d.returns},
                    {"scans", d.scans},
                    {"objects", d.objects}});
  }
  const std::uint32_t most =
      run.debris_per_scan.empty()
          ? 0
          : *std::max_element(run.debris_per_scan.begin(), run.debris_per_scan.end());
  std::printf("debris: %zu at the end (at most %u after one scan)\n", mapper.debris().size(), most);
  const nlohmann::ordered_json out = {{"frame_id", map_tool::kTsdfFrame},
                                      {"stamp_ns", run.last_stamp_ns},
                                      {"debris", list},
                                      {"per_scan", run.debris_per_scan}};
  return tools::write_json(std::filesystem::path(opt.out) / "debris.json", out);
}

}  // namespace

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
  report_truth(in, timing);
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
  if (auto w = write_debris(opt, mapper, run); !w) {
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
      "obstacle_rule.npy,obstacle_rule.png,"
      "timing.json,debris.json%s%s}\n",
      opt.out.c_str(), window_out.have_band ? ",esdf_band.npy" : "",
      tsdf_out.paged        ? (opt.prior.empty()
                                   ? ",tsdf_tiles/,tsdf_vdb/,tsdf.json,mesh.ply"
                                   : ",tsdf_tiles/,tsdf_vdb/,tsdf.json,mesh.ply,changes.npy,changes.png")
      : params.tsdf.enabled ? (in.prior ? ",tsdf.vdb,tsdf.json,mesh.ply,changes.npy,changes.png"
                                        : ",tsdf.vdb,tsdf.json,mesh.ply")
                            : "");
  return 0;
}

}  // namespace tarmac::map_tool
