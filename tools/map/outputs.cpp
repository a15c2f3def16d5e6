// tarmac-map's outputs (outputs.hpp): arrays, images and their JSON descriptions.

#include "outputs.hpp"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>

#include <nlohmann/json.hpp>

#include "tarmac/core/esdf_band.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/core/tsdf_mesh.hpp"
#include "tarmac/tools/array_io.hpp"
#include "tarmac/tools/lethal_causes.hpp"
#include "tarmac/tools/mesh_io.hpp"
#include "tarmac/tools/stats.hpp"

namespace tarmac::map_tool {

namespace {

using tools::timed_ms;

std::vector<std::uint8_t> render_costmap(const core::CostmapLayers& layers) {
  const auto& cm = layers.costmap;
  const std::uint32_t w = cm.width(), h = cm.height();
  std::vector<std::uint8_t> rgb(std::size_t{w} * h * 3);
  for (std::uint32_t y = 0; y < h; ++y) {
    for (std::uint32_t x = 0; x < w; ++x) {
      std::uint8_t* px = &rgb[(std::size_t{h - 1 - y} * w + x) * 3];  // north up
      const auto cls = static_cast<core::ColumnClass>(layers.column_class.at(x, y));
      const int c = cm.at(x, y);
      if (cls == core::ColumnClass::kVirtual) {
        px[0] = 200, px[1] = 0, px[2] = 200;  // virtual zone: magenta
      } else if (c == core::kCostUnknown) {
        std::copy_n(tools::kUnobservedRgb, 3, px);  // unknown
      } else if (c == core::kCostLethal) {
        px[0] = 0, px[1] = 0, px[2] = 0;  // lethal: black
      } else if (c == core::kCostInscribed) {
        px[0] = 180, px[1] = 0, px[2] = 0;  // inscribed: dark red
      } else if (c > 0) {
        px[0] = 255, px[1] = static_cast<std::uint8_t>(230 - 2 * c), px[2] = 60;  // inflated
      } else {
        px[0] = px[1] = px[2] = 245;  // free: white
      }
    }
  }
  return rgb;
}

std::vector<std::uint8_t> render_distance(const core::DistanceField& field, double max_m) {
  const int w = field.dims.x(), h = field.dims.y();
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      std::uint8_t* px = &rgb[(static_cast<std::size_t>(h - 1 - y) * w + x) * 3];
      const float d = field.distance_m[static_cast<std::size_t>(y) * w + x];
      if (std::isnan(d)) {
        std::copy_n(tools::kUnobservedRgb, 3, px);
        continue;
      }
      const double t = std::min(1.0, static_cast<double>(d) / max_m);
      px[0] = static_cast<std::uint8_t>(255 * (1.0 - t));
      px[1] = static_cast<std::uint8_t>(255 * t * (1.0 - t) * 4 * 0.8);
      px[2] = static_cast<std::uint8_t>(255 * t);
    }
  }
  return rgb;
}

/// A float for JSON: the double of its shortest decimal (0.1f is written 0.1, not
/// 0.10000000149011612).
double decimal(float value) {
  char text[32];
  const auto written = std::to_chars(text, text + sizeof text, value);
  double d = 0.0;
  std::from_chars(text, written.ptr, d);
  return d;
}

/// One row of the change layer's image (`cells`: the layer's row) into `rgb`, 3 bytes per cell.
void render_change_row(std::span<const float> cells, std::uint8_t* rgb) {
  for (std::size_t x = 0; x < cells.size(); ++x) {
    std::uint8_t* px = rgb + x * 3;
    const float c = cells[x];
    const auto fade = [&](int full) {  // from white at confidence 0 to `full` at 1
      return static_cast<std::uint8_t>(245 - (245 - full) * std::min(1.0f, std::abs(c)));
    };
    if (std::isnan(c)) {
      std::copy_n(tools::kUnobservedRgb, 3, px);  // not observed in both
    } else if (c > 0) {
      px[0] = 230, px[1] = fade(0), px[2] = fade(0);  // new: red
    } else if (c < 0) {
      px[0] = fade(0), px[1] = fade(90), px[2] = 230;  // removed: blue
    } else {
      px[0] = px[1] = px[2] = 245;  // unchanged: white
    }
  }
}

std::vector<std::uint8_t> render_changes(const core::ChangeMap& m) {
  const std::uint32_t w = m.geometry.width, h = m.geometry.height;
  std::vector<std::uint8_t> rgb(std::size_t{w} * h * 3);
  for (std::uint32_t y = 0; y < h; ++y) {  // north up
    render_change_row(std::span<const float>(m.change).subspan(std::size_t{y} * w, w),
                      &rgb[std::size_t{h - 1 - y} * w * 3]);
  }
  return rgb;
}

/// tsdf.json's part on the change layer.
void describe_changes(const core::ChangeMap& m, nlohmann::ordered_json& j,
                      nlohmann::ordered_json& files) {
  const auto& g = m.geometry;
  j["changes"] = {{"origin_m", {g.origin_x_m, g.origin_y_m}},
                  {"resolution_m", g.resolution_m},
                  {"shape", {g.height, g.width}},
                  {"compared_voxels", m.compared_voxels},
                  {"new_voxels", m.new_voxels},
                  {"removed_voxels", m.removed_voxels}};
  files["changes.npy"] =
      "float32 (ny, nx) per voxel column: +c new surface, -c removed, confidence c in (0, 1]; "
      "0 unchanged; NaN not observed in both maps";
  files["changes.png"] =
      "red new, blue removed (fainter = less confident), white unchanged, slate unknown; north "
      "up";
}

}  // namespace

core::Status write_window_outputs(const std::filesystem::path& out, const core::Mapper& mapper,
                                  std::size_t scans, core::TaskRunner& runner,
                                  WindowOutputs& result) {
  const auto& occ_map = mapper.occupancy();
  const auto& layers = mapper.costmap();
  const Eigen::Vector3i dims = occ_map.window_size();
  const double v = occ_map.params().voxel_size_m;
  std::vector<float>& log_odds = result.log_odds;
  occ_map.export_log_odds(log_odds);
  std::vector<float> probability(log_odds.size());
  std::vector<core::CellState> states3d(log_odds.size());
  const auto& ground = layers.ground_z_m;
  for (std::size_t i = 0; i < log_odds.size(); ++i) {
    const float l = log_odds[i];
    probability[i] = l == core::OccupancyMap::kUnknown ? std::nanf("") : core::probability_of(l);
    const int x = static_cast<int>(i % dims.x());
    const int y = static_cast<int>((i / dims.x()) % dims.y());
    const int z = static_cast<int>(i / (static_cast<std::size_t>(dims.x()) * dims.y()));
    const double bottom_m = (occ_map.window_min().z() + z) * v;
    // Ground excluded: the voxel layer holding the local ground is not an obstacle.
    const bool is_ground = bottom_m < ground.at(x, y) + v * 0.5;
    states3d[i] = l == core::OccupancyMap::kUnknown ? core::CellState::kUnknown
                  : (l > 0.0f && !is_ground)        ? core::CellState::kOccupied
                                                    : core::CellState::kFree;
  }
  core::DistanceFieldScratch scratch3d;
  result.esdf3d_ms = timed_ms([&] {
    core::compute_distance_field(states3d, dims, v, core::UnknownPolicy::kReportUnknown,
                                 result.esdf3d, scratch3d, runner);
  });
  const std::vector<std::size_t> shape3{static_cast<std::size_t>(dims.z()),
                                        static_cast<std::size_t>(dims.y()),
                                        static_cast<std::size_t>(dims.x())};
  const std::vector<std::size_t> shape2{static_cast<std::size_t>(dims.y()),
                                        static_cast<std::size_t>(dims.x())};
  const auto& slice = layers.obstacle_distance;
  std::vector<core::Status> writes;
  writes.push_back(tools::write_npy(out / "occupancy.npy", probability, shape3));
  writes.push_back(tools::write_npy(out / "esdf.npy", result.esdf3d.distance_m, shape3));
  writes.push_back(tools::write_npy(out / "esdf_slice.npy", slice.distance_m, shape2));
  const core::EsdfBand& band = mapper.esdf_band();
  const bool have_band = mapper.params().esdf_band.enabled && band.field.dims.z() > 0;
  result.have_band = have_band;
  if (have_band) {
    const std::vector<std::size_t> shape_band{static_cast<std::size_t>(band.field.dims.z()),
                                              static_cast<std::size_t>(dims.y()),
                                              static_cast<std::size_t>(dims.x())};
    writes.push_back(tools::write_npy(out / "esdf_band.npy", band.field.distance_m, shape_band));
  }
  writes.push_back(tools::write_npy(out / "costmap.npy", layers.costmap.cells(), shape2));
  writes.push_back(tools::write_npy(out / "obstacle_rule.npy", layers.obstacle_rule, shape2));
  writes.push_back(
      tools::write_png(out / "obstacle_rule.png",
                       tools::render_lethal_causes(
                           layers.costmap, {layers.column_class.cells(), layers.obstacle_rule}),
                       dims.x(), dims.y()));
  writes.push_back(
      tools::write_png(out / "costmap.png", render_costmap(layers), dims.x(), dims.y()));
  writes.push_back(
      tools::write_png(out / "esdf_slice.png", render_distance(slice, 5.0), dims.x(), dims.y()));
  for (const auto& w : writes) {
    if (!w) return w;
  }
  const double ox = occ_map.window_min().x() * v, oy = occ_map.window_min().y() * v,
               oz = occ_map.window_min().z() * v;
  nlohmann::ordered_json map_json = {
      {"frame", "world (the dataset's pose frame)"},
      {"voxel_size_m", v},
      {"origin_m", {ox, oy, oz}},
      {"lattice", "voxel i along an axis covers [origin + i*v, origin + (i+1)*v)"},
      {"axis_order", "arrays are C order, shape (nz, ny, nx) or (ny, nx): x varies fastest"},
      {"shape_3d", {dims.z(), dims.y(), dims.x()}},
      {"shape_2d", {dims.y(), dims.x()}},
      {"scans", scans}};
  if (have_band) {
    map_json["esdf_band"] = {{"origin_m", {band.min.x() * v, band.min.y() * v, band.min.z() * v}},
                             {"shape", {band.field.dims.z(), dims.y(), dims.x()}},
                             {"obstacles", core::esdf_band_obstacles(band)}};
  }
  nlohmann::ordered_json files = {
      {"occupancy.npy", "float32 occupancy probability, NaN = unknown (3D window at the end)"},
      {"esdf.npy",
       "float32 m to the nearest occupied voxel, ground layer excluded, NaN = unknown, inf = none "
       "in window"},
      {"esdf_slice.npy",
       "float32 m to the nearest costmap obstacle cell (vehicle height band), NaN = unknown"}};
  if (have_band) {
    files["esdf_band.npy"] =
        "float32 m to the nearest obstacle voxel of the 3D band around the vehicle (esdf_band: "
        "costmap rules per voxel, overhangs included), NaN = unknown; origin and shape under "
        "esdf_band";
  }
  files["costmap.npy"] =
      "int8 nav_msgs/OccupancyGrid values: 0 free .. 99 inscribed, 100 lethal, -1 unknown";
  files["obstacle_rule.npy"] =
      "uint8 per costmap cell, why it is an obstacle (0: it is not): 1 occupied voxel, 2 drop, 4 "
      "rise, 8 kept low object, 16 peer's cell (bits; docs/tools.md)";
  files["obstacle_rule.png"] =
      "lethal cells by the rule that made them: occupied voxel black, drop purple, rise orange, "
      "kept low object red, peer cyan, zone magenta, other grey; unknown slate, the rest light "
      "grey; north up";
  files["costmap.png"] =
      "white free, yellow-orange inflated, dark red inscribed, black lethal, slate unknown, "
      "magenta virtual zone; north up";
  files["esdf_slice.png"] = "red near an obstacle to blue at >= 5 m, slate unknown; north up";
  map_json["files"] = std::move(files);
  return tools::write_json(out / "map.json", map_json);
}

core::Status write_tsdf_outputs(const std::filesystem::path& out, const core::TsdfLayer& tsdf,
                                const std::string& config_hash, std::int64_t stamp_ns,
                                const core::TsdfLayer* prior, TsdfOutputs& result) {
  core::TsdfMapInfo info;
  info.frame_id = kTsdfFrame;
  info.config_hash = config_hash;
  info.stamp_ns = stamp_ns;
  core::Status saved = core::Ok{};
  result.save_ms = timed_ms([&] { saved = core::save_tsdf(out / "tsdf.vdb", tsdf, info); });
  if (!saved) return saved;
  core::TriangleMesh mesh;
  core::Status meshed = core::Ok{};
  result.mesh_ms = timed_ms([&] { meshed = core::extract_mesh(tsdf, 1.0f, mesh); });
  if (!meshed) return meshed;
  result.vertices = mesh.vertices_W.size();
  result.triangles = mesh.triangles.size();
  if (auto w = tools::write_ply(out / "mesh.ply", mesh); !w) return w;
  nlohmann::ordered_json j = {{"frame", kTsdfFrame},
                              {"voxel_size_m", decimal(tsdf.voxel_size_m())},
                              {"truncation_m", decimal(tsdf.truncation_m())},
                              {"blocks", tsdf.block_count()},
                              {"voxels", tsdf.voxel_count()},
                              {"memory_bytes", tsdf.memory_bytes()},
                              {"config_hash", config_hash},
                              {"stamp_ns", stamp_ns}};
  nlohmann::ordered_json files = {
      {"tsdf.vdb",
       "OpenVDB float grids 'tsdf' (signed distance, m, + in front) and 'weight' (scans, "
       "capped), + tarmac trailer; index i = voxel centre (i + 0.5) * v"},
      {"mesh.ply", "binary PLY of the zero level set, world frame, m"}};
  if (prior != nullptr) {
    core::Status detected = core::Ok{};
    result.changes_ms = timed_ms([&] {
      detected = core::detect_changes(*prior, tsdf, core::ChangeParams{}, result.changes);
    });
    if (!detected) return detected;
    const auto& g = result.changes.geometry;
    const std::vector<std::size_t> shape{g.height, g.width};
    if (auto w = tools::write_npy(out / "changes.npy", result.changes.change, shape); !w) return w;
    if (auto w = tools::write_png(out / "changes.png", render_changes(result.changes), g.width,
                                  g.height);
        !w) {
      return w;
    }
    describe_changes(result.changes, j, files);
  }
  j["files"] = std::move(files);
  return tools::write_json(out / "tsdf.json", j);
}

core::Status write_tsdf_site_outputs(const std::filesystem::path& out,
                                     const daemon::SiteStore& site, const core::TsdfLayer& layer,
                                     const std::string& config_hash, std::int64_t stamp_ns,
                                     const std::filesystem::path* prior_dir, TsdfOutputs& result) {
  result.paged = true;
  // The mesh tile by tile (at most 27 tiles in memory besides the resident ones).
  tools::PlyPieces ply(out / "mesh.ply");
  core::Status meshed = core::Ok{};
  result.mesh_ms = timed_ms([&] {
    meshed = site.mesh(1.0f, [&ply](const core::TriangleMesh& piece) { return ply.add(piece); });
    if (meshed) meshed = ply.finish();
  });
  if (!meshed) return meshed;
  result.vertices = ply.vertices();
  result.triangles = ply.triangles();
  // The .vdb export in parts of kVdbRegionTiles² tile columns, one part in memory at a time.
  core::TsdfMapInfo info;
  info.frame_id = kTsdfFrame;
  info.config_hash = config_hash;
  info.stamp_ns = stamp_ns;
  const std::filesystem::path vdb_dir = out / "tsdf_vdb";
  std::error_code ec;
  std::filesystem::remove_all(vdb_dir, ec);
  std::filesystem::create_directories(vdb_dir, ec);
  if (ec) return core::Error{"io.write", vdb_dir.string() + ": " + ec.message()};
  std::size_t parts = 0;
  core::Status exported = core::Ok{};
  result.save_ms = timed_ms([&] {
    exported = site.export_parts(
        kVdbRegionTiles, [&](const Eigen::Vector2i& r, const core::TsdfLayer& part) {
          ++parts;
          const std::string name =
              "tsdf_" + std::to_string(r.x()) + "_" + std::to_string(r.y()) + ".vdb";
          return core::save_tsdf(vdb_dir / name, part, info);
        });
  });
  if (!exported) return exported;
  const double region_m = kVdbRegionTiles * core::kTsdfTileEdge * decimal(layer.voxel_size_m());
  nlohmann::ordered_json j = {{"frame", kTsdfFrame},
                              {"voxel_size_m", decimal(layer.voxel_size_m())},
                              {"truncation_m", decimal(layer.truncation_m())},
                              {"config_hash", config_hash},
                              {"stamp_ns", stamp_ns},
                              {"vdb_parts", parts},
                              {"vdb_region_m", region_m}};
  nlohmann::ordered_json files = {
      {"tsdf_tiles/",
       "the site TSDF as tiles (tile_X_Y_Z.tsdft) and the static occupancy "
       "(static_X_Y.occs); docs/mapping.md \"Site-scale maps\""},
      {"tsdf_vdb/",
       "the site TSDF in parts, tsdf_RX_RY.vdb: the tiles whose x, y lie in the square "
       "[RX, RX + 1) x [RY, RY + 1) * vdb_region_m; each as tsdf.vdb"},
      {"mesh.ply", "binary PLY of the zero level set, world frame, m (built tile by tile)"}};
  if (prior_dir != nullptr) {
    // The change layer strip by strip: neither map nor the raster is whole in memory.
    tools::NpyBands npy;
    tools::PngRows png;
    std::vector<std::uint8_t> rgb;
    core::ChangeCounts counts;
    core::Status detected = core::Ok{};
    result.changes_ms = timed_ms([&] {
      detected = site.changes(
          *prior_dir, core::ChangeParams{}, counts,
          [&](const core::GridGeometry2D& g) {
            result.changes.geometry = g;
            if (auto s = npy.open(out / "changes.npy", g.height, g.width); !s) return s;
            return png.open(out / "changes.png", g.width, g.height);
          },
          [&](int y0, int rows, std::span<const float> cells) {
            const std::size_t w = result.changes.geometry.width;
            if (auto s = npy.band(static_cast<std::size_t>(y0), cells); !s) return s;
            rgb.resize(w * 3);
            for (int r = rows - 1; r >= 0; --r) {  // north up
              render_change_row(cells.subspan(static_cast<std::size_t>(r) * w, w), rgb.data());
              if (auto s = png.row(rgb); !s) return s;
            }
            return core::Status(core::Ok{});
          });
      if (detected) detected = npy.finish();
      if (detected) detected = png.finish();
    });
    if (!detected) return detected;
    result.changes.compared_voxels = counts.compared_voxels;
    result.changes.new_voxels = counts.new_voxels;
    result.changes.removed_voxels = counts.removed_voxels;
    describe_changes(result.changes, j, files);
  }
  j["files"] = std::move(files);
  return tools::write_json(out / "tsdf.json", j);
}

}  // namespace tarmac::map_tool
