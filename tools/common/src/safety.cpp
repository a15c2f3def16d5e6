#include "tarmac/tools/safety.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include <nlohmann/json.hpp>

namespace tarmac::tools {

core::Result<ObstacleTruth> read_obstacle_truth(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return core::Error{"truth.open", file.string() + ": cannot be read"};
  ObstacleTruth truth;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty()) continue;
    std::istringstream s(line);
    if (line[0] == '#') {
      std::string word;
      s >> word >> word;
      if (word == "obstacle") {  // "# obstacle columns: cell_m V envelope_z_m LO HI"
        s >> word >> word >> truth.cell_m;
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
    std::int64_t ix = 0, iy = 0;
    int first = 0;
    if (!(s >> ix >> iy >> first)) {
      return core::Error{"truth.parse", file.string() + ":" + std::to_string(n) + ": bad line"};
    }
    truth.first_seen[ObstacleTruth::key(ix, iy)] = first;
  }
  if (!(truth.cell_m > 0.0)) return core::Error{"truth.parse", file.string() + ": no cell_m"};
  return truth;
}

SafetyCycle score_costmap(const core::Costmap& costmap, const ObstacleTruth& truth, int scan,
                          const Eigen::Vector2d& vehicle_xy, double radius_m,
                          std::span<const DynamicBox> moving) {
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
  for (std::int64_t cy = 0; cy < h; ++cy) {
    for (std::int64_t cx = 0; cx < w; ++cx) {
      const Eigen::Vector2d centre((static_cast<double>(ox + cx) + 0.5) * truth.cell_m,
                                   (static_cast<double>(oy + cy) + 0.5) * truth.cell_m);
      if ((centre - vehicle_xy).squaredNorm() > r2) continue;
      const int v = value(cx, cy);
      if (v == core::kCostLethal) {
        ++c.lethal_cells;
        const double margin = truth.cell_m;  // within one cell of a moving object: not false
        const bool under_moving = std::any_of(moving.begin(), moving.end(), [&](const auto& b) {
          return centre.x() >= b.min_W.x() - margin && centre.x() <= b.max_W.x() + margin &&
                 centre.y() >= b.min_W.y() - margin && centre.y() <= b.max_W.y() + margin;
        });
        if (!under_moving && !near(cx, cy, [&](std::int64_t x, std::int64_t y) {
              return truth.is_column(ox + x, oy + y);
            })) {
          ++c.false_lethal;
        }
      }
      if ((centre - vehicle_xy).squaredNorm() <= kOpenRadiusM * kOpenRadiusM &&
          !near(cx, cy,
                [&](std::int64_t x, std::int64_t y) { return truth.is_column(ox + x, oy + y); })) {
        ++c.open_cells;
        if (v == core::kCostUnknown) ++c.open_unknown;
      }
      const auto it = truth.first_seen.find(ObstacleTruth::key(ox + cx, oy + cy));
      if (it == truth.first_seen.end() || it->second < 0 || it->second > scan) continue;
      ++c.visible;
      if (near(cx, cy,
               [&](std::int64_t x, std::int64_t y) { return value(x, y) == core::kCostLethal; })) {
        ++c.lethal_near;
      } else if (v == core::kCostFree) {
        ++c.read_free;
      } else if (v == core::kCostUnknown) {
        ++c.read_unknown;
      } else {
        ++c.read_inflated;
      }
    }
  }
  return c;
}

const SafetyCycle& SafetyTracker::observe(const core::Costmap& costmap, int scan,
                                          const Eigen::Vector2d& vehicle_xy, double radius_m,
                                          std::span<const DynamicBox> moving) {
  cycles_.push_back(score_costmap(costmap, truth_, scan, vehicle_xy, radius_m, moving));
  return cycles_.back();
}

SafetyReport SafetyTracker::report() const {
  SafetyReport r;
  r.cycles = cycles_.size();
  double sum = 0.0, open_sum = 0.0;
  std::size_t counted = 0;
  for (const SafetyCycle& c : cycles_) {
    r.read_free += c.read_free;
    r.read_inflated += c.read_inflated;
    r.read_unknown += c.read_unknown;
    r.lethal_cells += c.lethal_cells;
    r.false_lethal += c.false_lethal;
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
  return r;
}

std::string safety_summary(const SafetyReport& r) {
  char line[640];
  std::snprintf(
      line, sizeof line,
      "safety (obstacle columns within 20 m seen by then, %zu cycles): lethal within one cell "
      "worst %.1f %% (scan %d), mean %.1f %%; read free %zu, inflated only %zu, unknown %zu "
      "(column-cycles); false lethal %zu of %zu lethal cells (worst cycle %.2f %%); open ground "
      "within %.0f m known (not unknown) worst %.1f %%, mean %.1f %%",
      r.cycles, 100.0 * r.worst_share, r.worst_scan, 100.0 * r.mean_share, r.read_free,
      r.read_inflated, r.read_unknown, r.false_lethal, r.lethal_cells, 100.0 * r.worst_false_share,
      kOpenRadiusM, 100.0 * r.worst_open_known, 100.0 * r.mean_open_known);
  return line;
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
                              {"mean_open_known", r.mean_open_known}};
  j["cycle_fields"] = {"scan",          "visible",      "lethal_near",  "read_free",
                       "read_inflated", "read_unknown", "lethal_cells", "false_lethal"};
  nlohmann::ordered_json per_cycle = nlohmann::ordered_json::array();
  for (const SafetyCycle& c : tracker.cycles()) {
    per_cycle.push_back({c.scan, c.visible, c.lethal_near, c.read_free, c.read_inflated,
                         c.read_unknown, c.lethal_cells, c.false_lethal});
  }
  j["per_cycle"] = std::move(per_cycle);
  return j;
}

}  // namespace tarmac::tools
