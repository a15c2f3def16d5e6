#include "tarmac/tools/safety.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

namespace tarmac::tools {

namespace {

/// Reads a truth file of tarmac-sim: '#' lines, among them "# <kind> ...: cell_m V ..." (the
/// lattice's cell, read into cell_m) and "# T_world_scene" (which must be the identity: the
/// cells are in the scene frame); every other line goes to `row` (false: a bad line).
template <typename Row>
core::Status read_truth_file(const std::filesystem::path& file, std::string_view kind,
                             double& cell_m, Row&& row) {
  std::ifstream in(file);
  if (!in) return core::Error{"truth.open", file.string() + ": cannot be read"};
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty()) continue;
    std::istringstream s(line);
    if (line[0] == '#') {
      std::string word;
      s >> word >> word;
      if (word == kind) {  // "# obstacle columns: cell_m V ...", "# ground cells: cell_m V ..."
        s >> word >> word >> cell_m;
      } else if (word == "T_world_scene") {
        double m[12];
        for (double& v : m) s >> v;
        const double identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
        for (int i = 0; i < 12; ++i) {
          if (!s || std::abs(m[i] - identity[i]) > 1e-9) {
            return core::Error{"truth.frame", file.string() + ":" + std::to_string(n) +
                                                  ": only untilted sequences can be scored"};
          }
        }
      }
      continue;
    }
    if (!row(s)) {
      return core::Error{"truth.parse", file.string() + ":" + std::to_string(n) + ": bad line"};
    }
  }
  if (!(cell_m > 0.0)) return core::Error{"truth.parse", file.string() + ": no cell_m"};
  return core::Ok{};
}

/// A file of columns ("# <kind> columns: cell_m V ...", then `ix iy first_seen_scan`).
core::Result<ObstacleTruth> read_columns(const std::filesystem::path& file, std::string_view kind) {
  ObstacleTruth truth;
  auto read = read_truth_file(file, kind, truth.cell_m, [&](std::istringstream& s) {
    std::int64_t ix = 0, iy = 0;
    int first = 0;
    if (!(s >> ix >> iy >> first)) return false;
    truth.first_seen[ObstacleTruth::key(ix, iy)] = first;
    return true;
  });
  if (!read) return read.error();
  return truth;
}

}  // namespace

core::Result<ObstacleTruth> read_obstacle_truth(const std::filesystem::path& file) {
  return read_columns(file, "obstacle");
}

core::Result<GroundTruth> read_ground_truth(const std::filesystem::path& file) {
  GroundTruth truth;
  auto read = read_truth_file(file, "ground", truth.cell_m, [&](std::istringstream& s) {
    std::int64_t ix = 0, iy = 0;
    float z_m = 0.0f;
    if (!(s >> ix >> iy >> z_m)) return false;
    truth.z_m[ObstacleTruth::key(ix, iy)] = z_m;
    return true;
  });
  if (!read) return read.error();
  return truth;
}

core::Result<ObstacleTruth> read_dataset_truth(const std::filesystem::path& dir) {
  auto truth = read_obstacle_truth(dir / "obstacle_columns.txt");
  if (!truth) return truth.error();
  if (const auto file = dir / "ground_cells.txt"; std::filesystem::exists(file)) {
    auto ground = read_ground_truth(file);
    if (!ground) return ground.error();
    if (std::abs(ground.value().cell_m - truth.value().cell_m) > 1e-9) {
      return core::Error{"truth.cells", file.string() + ": cells of " +
                                            std::to_string(ground.value().cell_m) +
                                            " m, the obstacle columns' " +
                                            std::to_string(truth.value().cell_m) + " m"};
    }
    truth.value().ground = std::move(ground).value();
    GroundTruth& g = *truth.value().ground;
    if (!g.z_m.empty()) {
      std::int64_t x1 = std::numeric_limits<std::int64_t>::min(), y1 = x1;
      g.x0 = g.y0 = std::numeric_limits<std::int64_t>::max();
      for (const auto& [k, z] : g.z_m) {
        const std::int64_t ix = k >> 32, iy = static_cast<std::int32_t>(k & 0xffffffff);
        g.x0 = std::min(g.x0, ix);
        g.y0 = std::min(g.y0, iy);
        x1 = std::max(x1, ix);
        y1 = std::max(y1, iy);
      }
      g.w = x1 - g.x0 + 1;
      g.h = y1 - g.y0 + 1;
      g.drivable_z.assign(static_cast<std::size_t>(g.w * g.h),
                          std::numeric_limits<float>::quiet_NaN());
      for (const auto& [k, z] : g.z_m) {
        const std::int64_t ix = k >> 32, iy = static_cast<std::int32_t>(k & 0xffffffff);
        if (!truth.value().is_column(ix, iy)) {
          g.drivable_z[static_cast<std::size_t>((iy - g.y0) * g.w + ix - g.x0)] = z;
        }
      }
    }
  }
  if (const auto file = dir / "curb_columns.txt"; std::filesystem::exists(file)) {
    auto curbs = read_columns(file, "curb");
    if (!curbs) return curbs.error();
    if (std::abs(curbs.value().cell_m - truth.value().cell_m) > 1e-9) {
      return core::Error{"truth.cells", file.string() + ": cells of " +
                                            std::to_string(curbs.value().cell_m) +
                                            " m, the obstacle columns' " +
                                            std::to_string(truth.value().cell_m) + " m"};
    }
    truth.value().curb_first_seen = std::move(curbs).value().first_seen;
  }
  return truth;
}

namespace {

/// Per cell of a w × h window whose cell (0, 0) is lattice cell (ox, oy): 1 where the ground
/// joins the ground under the vehicle (see SafetyCycle::reach_cells), breadth first from the
/// ground cell nearest to `vehicle_xy` (within 1 m). All zero without ground truth or without
/// ground under the vehicle.
std::vector<std::uint8_t> reachable_ground(const ObstacleTruth& truth, std::int64_t ox,
                                           std::int64_t oy, std::int64_t w, std::int64_t h,
                                           const Eigen::Vector2d& vehicle_xy) {
  const auto n = static_cast<std::size_t>(w * h);
  std::vector<std::uint8_t> reached(n, 0);
  if (!truth.ground) return reached;
  constexpr float kNone = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> z(n, kNone);  // ground height, NaN: no ground or an obstacle column
  const GroundTruth& g = *truth.ground;
  for (std::int64_t y = 0; y < h; ++y) {
    for (std::int64_t x = 0; x < w; ++x) {
      float& to = z[static_cast<std::size_t>(y * w + x)];
      const std::int64_t gx = ox + x - g.x0, gy = oy + y - g.y0;
      if (!g.drivable_z.empty()) {
        if (gx >= 0 && gy >= 0 && gx < g.w && gy < g.h) {
          to = g.drivable_z[static_cast<std::size_t>(gy * g.w + gx)];
        }
        continue;
      }
      const auto it = g.z_m.find(ObstacleTruth::key(ox + x, oy + y));
      if (it != g.z_m.end() && !truth.is_column(ox + x, oy + y)) to = it->second;
    }
  }
  const auto vx = static_cast<std::int64_t>(std::floor(vehicle_xy.x() / truth.cell_m)) - ox;
  const auto vy = static_cast<std::int64_t>(std::floor(vehicle_xy.y() / truth.cell_m)) - oy;
  const auto r = static_cast<std::int64_t>(std::ceil(1.0 / truth.cell_m));
  std::int64_t start = -1, best = std::numeric_limits<std::int64_t>::max();
  for (std::int64_t y = std::max<std::int64_t>(0, vy - r); y <= std::min(h - 1, vy + r); ++y) {
    for (std::int64_t x = std::max<std::int64_t>(0, vx - r); x <= std::min(w - 1, vx + r); ++x) {
      const std::int64_t d2 = (x - vx) * (x - vx) + (y - vy) * (y - vy);
      if (!std::isnan(z[static_cast<std::size_t>(y * w + x)]) && d2 < best) {
        best = d2;
        start = y * w + x;
      }
    }
  }
  if (start < 0) return reached;
  std::vector<std::int64_t> queue{start};
  reached[static_cast<std::size_t>(start)] = 1;
  for (std::size_t head = 0; head < queue.size(); ++head) {
    const std::int64_t i = queue[head], cx = i % w, cy = i / w;
    const float zi = z[static_cast<std::size_t>(i)];
    for (std::int64_t dy = -1; dy <= 1; ++dy) {
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        const std::int64_t ux = cx + dx, uy = cy + dy;
        if (ux < 0 || uy < 0 || ux >= w || uy >= h) continue;
        const auto u = static_cast<std::size_t>(uy * w + ux);
        if (reached[u] != 0 || !(std::abs(z[u] - zi) <= kReachStepM)) continue;  // NaN: no
        reached[u] = 1;
        queue.push_back(uy * w + ux);
      }
    }
  }
  return reached;
}

}  // namespace

SafetyCycle score_costmap(const core::Costmap& costmap, const ObstacleTruth& truth, int scan,
                          const Eigen::Vector2d& vehicle_xy, double radius_m,
                          std::span<const DynamicBox> moving, const LethalCauseView& causes) {
  SafetyCycle c;
  c.scan = scan;
  const auto& g = costmap.geometry();
  const auto ox = static_cast<std::int64_t>(std::llround(g.origin_x_m / truth.cell_m));
  const auto oy = static_cast<std::int64_t>(std::llround(g.origin_y_m / truth.cell_m));
  const auto w = static_cast<std::int64_t>(g.width), h = static_cast<std::int64_t>(g.height);
  const auto value = [&](std::int64_t cx, std::int64_t cy) -> int {
    if (cx < 0 || cy < 0 || cx >= w || cy >= h) return core::kCostUnknown;
    return costmap.at(static_cast<std::uint32_t>(cx), static_cast<std::uint32_t>(cy));
  };
  const auto near = [&](std::int64_t cx, std::int64_t cy, auto&& pred) {
    for (std::int64_t dy = -1; dy <= 1; ++dy) {
      for (std::int64_t dx = -1; dx <= 1; ++dx) {
        if (pred(cx + dx, cy + dy)) return true;
      }
    }
    return false;
  };
  const double r2 = radius_m * radius_m;
  const double outer = std::max(radius_m, kGroundRadiusM);
  // Which cells within reach are obstacle columns, the map's cells plus a border of one: each
  // cell's "column within one cell" then reads nine flags, not nine lookups in the truth.
  const double reach = outer + 2.0 * truth.cell_m;
  std::vector<std::uint8_t> column(static_cast<std::size_t>((w + 2) * (h + 2)), 0);
  for (std::int64_t cy = -1; cy <= h; ++cy) {
    for (std::int64_t cx = -1; cx <= w; ++cx) {
      const Eigen::Vector2d centre((static_cast<double>(ox + cx) + 0.5) * truth.cell_m,
                                   (static_cast<double>(oy + cy) + 0.5) * truth.cell_m);
      if ((centre - vehicle_xy).squaredNorm() > reach * reach) continue;
      column[static_cast<std::size_t>((cy + 1) * (w + 2) + cx + 1)] =
          truth.is_column(ox + cx, oy + cy) ? 1 : 0;
    }
  }
  const auto is_column = [&](std::int64_t x, std::int64_t y) {
    return column[static_cast<std::size_t>((y + 1) * (w + 2) + x + 1)] != 0;
  };
  const std::vector<std::uint8_t> reachable = reachable_ground(truth, ox, oy, w, h, vehicle_xy);
  for (std::int64_t cy = 0; cy < h; ++cy) {
    for (std::int64_t cx = 0; cx < w; ++cx) {
      const Eigen::Vector2d centre((static_cast<double>(ox + cx) + 0.5) * truth.cell_m,
                                   (static_cast<double>(oy + cy) + 0.5) * truth.cell_m);
      const double d2 = (centre - vehicle_xy).squaredNorm();
      if (d2 > outer * outer) continue;
      const int v = value(cx, cy);
      const double margin = truth.cell_m;  // within one cell of a moving object
      const auto under_moving = [&] {
        return std::any_of(moving.begin(), moving.end(), [&](const auto& b) {
          return centre.x() >= b.min_W.x() - margin && centre.x() <= b.max_W.x() + margin &&
                 centre.y() >= b.min_W.y() - margin && centre.y() <= b.max_W.y() + margin;
        });
      };
      if (d2 <= kGroundRadiusM * kGroundRadiusM && truth.is_ground(ox + cx, oy + cy) &&
          !near(cx, cy, is_column) && !under_moving()) {
        ++c.ground_cells;
        if (v == core::kCostLethal) {
          ++c.ground_lethal;
          c.ground_lethal_by_cause.add(causes, static_cast<std::size_t>(cy * w + cx));
        }
        if (reachable[static_cast<std::size_t>(cy * w + cx)] != 0) {
          ++c.reach_cells;
          if (v == core::kCostLethal) ++c.reach_lethal;
        }
      }
      if (d2 > r2) continue;
      if (v == core::kCostLethal) {
        ++c.lethal_cells;
        // Within one cell of a moving object: not false (a ghost further off is).
        if (!under_moving() && !near(cx, cy, is_column)) {
          ++c.false_lethal;
          c.false_lethal_by_cause.add(causes, static_cast<std::size_t>(cy * w + cx));
        }
      }
      if (d2 <= kOpenRadiusM * kOpenRadiusM && truth.is_ground(ox + cx, oy + cy) &&
          !near(cx, cy, is_column)) {
        ++c.open_cells;
        if (v == core::kCostUnknown) ++c.open_unknown;
      }
      const auto it = truth.first_seen.find(ObstacleTruth::key(ox + cx, oy + cy));
      if (it == truth.first_seen.end() || it->second < 0 || it->second > scan) continue;
      ++c.visible;
      const bool lethal_near = near(
          cx, cy, [&](std::int64_t x, std::int64_t y) { return value(x, y) == core::kCostLethal; });
      if (lethal_near) {
        ++c.lethal_near;
      } else if (v == core::kCostFree) {
        ++c.read_free;
      } else if (v == core::kCostUnknown) {
        ++c.read_unknown;
      } else {
        ++c.read_inflated;
      }
      const auto curb = truth.curb_first_seen.find(ObstacleTruth::key(ox + cx, oy + cy));
      if (curb != truth.curb_first_seen.end() && curb->second >= 0 && curb->second <= scan) {
        ++c.curb_visible;
        if (lethal_near) ++c.curb_lethal_near;
      }
    }
  }
  return c;
}

const SafetyCycle& SafetyTracker::observe(const core::Costmap& costmap, int scan,
                                          const Eigen::Vector2d& vehicle_xy, double radius_m,
                                          std::span<const DynamicBox> moving,
                                          const LethalCauseView& causes) {
  cycles_.push_back(score_costmap(costmap, truth_, scan, vehicle_xy, radius_m, moving, causes));
  return cycles_.back();
}

namespace {

/// A ground figure over the cycles: cells and lethal cells summed, the worst cycle's share and
/// scan (−1: none read any lethal), the mean share over the cycles with cells.
struct LethalShares {
  std::size_t cells = 0, lethal = 0, counted = 0;
  double sum = 0.0, worst = 0.0;
  int worst_scan = -1;
  void add(std::size_t cycle_cells, std::size_t cycle_lethal, double share, int scan) {
    cells += cycle_cells;
    lethal += cycle_lethal;
    if (cycle_cells == 0) return;
    ++counted;
    sum += share;
    if (share > worst) {
      worst = share;
      worst_scan = scan;
    }
  }
  [[nodiscard]] double mean() const {
    return counted == 0 ? 0.0 : sum / static_cast<double>(counted);
  }
};

}  // namespace

SafetyReport SafetyTracker::report() const {
  SafetyReport r;
  r.cycles = cycles_.size();
  double sum = 0.0, open_sum = 0.0, curb_sum = 0.0;
  std::size_t counted = 0, curb_counted = 0;
  LethalShares ground, reach;
  r.curbs = !truth_.curb_first_seen.empty();
  for (const SafetyCycle& c : cycles_) {
    if (c.curb_visible > 0) {
      ++curb_counted;
      curb_sum += c.share_curb_lethal();
      if (c.share_curb_lethal() < r.worst_curb_share) {
        r.worst_curb_share = c.share_curb_lethal();
        r.worst_curb_scan = c.scan;
      }
    }
    ground.add(c.ground_cells, c.ground_lethal, c.share_ground_lethal(), c.scan);
    reach.add(c.reach_cells, c.reach_lethal, c.share_reach_lethal(), c.scan);
    r.read_free += c.read_free;
    r.read_inflated += c.read_inflated;
    r.read_unknown += c.read_unknown;
    r.lethal_cells += c.lethal_cells;
    r.false_lethal += c.false_lethal;
    r.false_lethal_by_cause += c.false_lethal_by_cause;
    r.ground_lethal_by_cause += c.ground_lethal_by_cause;
    if (c.lethal_cells > 0) {
      r.worst_false_share = std::max(r.worst_false_share, static_cast<double>(c.false_lethal) /
                                                              static_cast<double>(c.lethal_cells));
    }
    open_sum += c.share_open_known();
    r.worst_open_known = std::min(r.worst_open_known, c.share_open_known());
    if (c.visible == 0) continue;
    ++counted;
    sum += c.share_lethal();
    if (c.share_lethal() < r.worst_share) {
      r.worst_share = c.share_lethal();
      r.worst_scan = c.scan;
    }
  }
  if (counted > 0) r.mean_share = sum / static_cast<double>(counted);
  if (!cycles_.empty()) r.mean_open_known = open_sum / static_cast<double>(cycles_.size());
  r.ground_cells = ground.cells;
  r.ground_lethal = ground.lethal;
  r.worst_ground_lethal = ground.worst;
  r.worst_ground_scan = ground.worst_scan;
  r.mean_ground_lethal = ground.mean();
  r.reach_cells = reach.cells;
  r.reach_lethal = reach.lethal;
  r.worst_reach_lethal = reach.worst;
  r.worst_reach_scan = reach.worst_scan;
  r.mean_reach_lethal = reach.mean();
  if (curb_counted > 0) r.mean_curb_share = curb_sum / static_cast<double>(curb_counted);
  return r;
}

std::string safety_summary(const SafetyReport& r) {
  char line[896];
  std::snprintf(
      line, sizeof line,
      "safety (obstacle columns within 20 m seen by then, %zu cycles): lethal within one cell "
      "worst %.1f %% (scan %d), mean %.1f %%; read free %zu, inflated only %zu, unknown %zu "
      "(column-cycles); false lethal %zu of %zu lethal cells (worst cycle %.2f %%); open ground "
      "within %.0f m known (not unknown) worst %.1f %%, mean %.1f %%; ground within %.0f m read "
      "lethal worst %.2f %% (scan %d), mean %.2f %% (%zu of %zu ground cell-cycles)",
      r.cycles, 100.0 * r.worst_share, r.worst_scan, 100.0 * r.mean_share, r.read_free,
      r.read_inflated, r.read_unknown, r.false_lethal, r.lethal_cells, 100.0 * r.worst_false_share,
      kOpenRadiusM, 100.0 * r.worst_open_known, 100.0 * r.mean_open_known, kGroundRadiusM,
      100.0 * r.worst_ground_lethal, r.worst_ground_scan, 100.0 * r.mean_ground_lethal,
      r.ground_lethal, r.ground_cells);
  std::string summary = line;
  if (r.reach_cells > 0) {
    std::snprintf(line, sizeof line,
                  "; of it reachable inside the window read lethal worst %.2f %% (scan %d), mean "
                  "%.2f %% (%zu of %zu)",
                  100.0 * r.worst_reach_lethal, r.worst_reach_scan, 100.0 * r.mean_reach_lethal,
                  r.reach_lethal, r.reach_cells);
    summary += line;
  }
  if (r.curbs) {
    std::snprintf(line, sizeof line,
                  "; curb columns lethal within one cell worst %.1f %% (scan %d), mean %.1f %%",
                  100.0 * r.worst_curb_share, r.worst_curb_scan, 100.0 * r.mean_curb_share);
    summary += line;
  }
  if (r.false_lethal_by_cause.total() + r.ground_lethal_by_cause.total() > 0) {
    summary += "; by rule, false lethal: " + r.false_lethal_by_cause.shares() +
               ", ground read lethal: " + r.ground_lethal_by_cause.shares();
  }
  return summary;
}

nlohmann::ordered_json safety_json(const SafetyTracker& tracker) {
  const SafetyReport r = tracker.report();
  nlohmann::ordered_json j = {{"cycles", r.cycles},
                              {"worst_share", r.worst_share},
                              {"worst_scan", r.worst_scan},
                              {"mean_share", r.mean_share},
                              {"read_free", r.read_free},
                              {"read_inflated", r.read_inflated},
                              {"read_unknown", r.read_unknown},
                              {"lethal_cells", r.lethal_cells},
                              {"false_lethal", r.false_lethal},
                              {"worst_false_share", r.worst_false_share},
                              {"worst_open_known", r.worst_open_known},
                              {"mean_open_known", r.mean_open_known},
                              {"ground_radius_m", kGroundRadiusM},
                              {"ground_cells", r.ground_cells},
                              {"ground_lethal", r.ground_lethal},
                              {"worst_ground_lethal", r.worst_ground_lethal},
                              {"worst_ground_scan", r.worst_ground_scan},
                              {"mean_ground_lethal", r.mean_ground_lethal},
                              {"reach_cells", r.reach_cells},
                              {"reach_lethal", r.reach_lethal},
                              {"worst_reach_lethal", r.worst_reach_lethal},
                              {"worst_reach_scan", r.worst_reach_scan},
                              {"mean_reach_lethal", r.mean_reach_lethal},
                              {"curbs", r.curbs},
                              {"worst_curb_share", r.worst_curb_share},
                              {"worst_curb_scan", r.worst_curb_scan},
                              {"mean_curb_share", r.mean_curb_share},
                              {"false_lethal_by_rule", r.false_lethal_by_cause.json()},
                              {"ground_lethal_by_rule", r.ground_lethal_by_cause.json()}};
  j["cycle_fields"] = {"scan",          "visible",       "lethal_near",  "read_free",
                       "read_inflated", "read_unknown",  "lethal_cells", "false_lethal",
                       "ground_cells",  "ground_lethal", "curb_visible", "curb_lethal_near",
                       "reach_cells",   "reach_lethal"};
  nlohmann::ordered_json per_cycle = nlohmann::ordered_json::array();
  for (const SafetyCycle& c : tracker.cycles()) {
    per_cycle.push_back({c.scan, c.visible, c.lethal_near, c.read_free, c.read_inflated,
                         c.read_unknown, c.lethal_cells, c.false_lethal, c.ground_cells,
                         c.ground_lethal, c.curb_visible, c.curb_lethal_near, c.reach_cells,
                         c.reach_lethal});
  }
  j["per_cycle"] = std::move(per_cycle);
  return j;
}

}  // namespace tarmac::tools
