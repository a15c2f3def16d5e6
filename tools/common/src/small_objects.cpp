#include "tarmac/tools/small_objects.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <unordered_map>

#include <nlohmann/json.hpp>

namespace tarmac::tools {

core::Result<std::vector<SmallObject>> read_small_objects(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) return core::Error{"objects.open", path.string() + ": cannot be read"};
  std::vector<SmallObject> objects;
  std::unordered_map<int, std::size_t> by_id;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::string what;
    fields >> what;
    bool ok = false;
    if (what == "object") {
      SmallObject o;
      ok = static_cast<bool>(fields >> o.id >> o.name >> o.kind >> o.min_W.x() >> o.min_W.y() >>
                             o.min_W.z() >> o.max_W.x() >> o.max_W.y() >> o.max_W.z()) &&
           by_id.count(o.id) == 0;
      if (ok) {
        by_id[o.id] = objects.size();
        objects.push_back(std::move(o));
      }
    } else if (what == "returns") {
      int scan = 0, id = 0, count = 0;
      const auto it = (fields >> scan >> id >> count) ? by_id.find(id) : by_id.end();
      ok = it != by_id.end() && scan >= 0 && count > 0;
      if (ok) objects[it->second].returns[scan] += count;
    }
    if (!ok) {
      return core::Error{"objects.parse", path.string() + ":" + std::to_string(n) + ": bad line"};
    }
  }
  for (SmallObject& o : objects) {
    for (const auto& [scan, count] : o.returns) {
      if (count >= 2) {
        o.first_two = scan;
        break;
      }
    }
  }
  return objects;
}

namespace {

/// Whether a cell of `costmap` on or next to the footprint of `o` reads lethal.
bool read_lethal(const core::Grid2D<std::int8_t>& costmap, const SmallObject& o) {
  const core::GridGeometry2D& g = costmap.geometry();
  const double r = g.resolution_m;
  const auto lo_x = static_cast<long>(std::floor((o.min_W.x() - g.origin_x_m) / r)) - 1;
  const auto hi_x = static_cast<long>(std::floor((o.max_W.x() - g.origin_x_m) / r)) + 1;
  const auto lo_y = static_cast<long>(std::floor((o.min_W.y() - g.origin_y_m) / r)) - 1;
  const auto hi_y = static_cast<long>(std::floor((o.max_W.y() - g.origin_y_m) / r)) + 1;
  for (long y = std::max(0L, lo_y); y <= std::min<long>(g.height - 1, hi_y); ++y) {
    for (long x = std::max(0L, lo_x); x <= std::min<long>(g.width - 1, hi_x); ++x) {
      if (costmap.at(static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y)) == 100) {
        return true;
      }
    }
  }
  return false;
}

double share(int part, int whole) {
  return whole == 0 ? 0.0 : 100.0 * part / whole;
}

}  // namespace

void SmallObjectTracker::observe(const core::Grid2D<std::int8_t>& costmap, int scan,
                                 const Eigen::Vector2d& vehicle_xy, double radius_m) {
  for (SmallObject& o : objects_) {
    if (o.first_two < 0 || scan < o.first_two) continue;
    const Eigen::Vector2d centre = 0.5 * (o.min_W + o.max_W).head<2>();
    const double range = (centre - vehicle_xy).norm();
    if (scan == o.first_two) o.first_two_range_m = range;
    const bool lethal = read_lethal(costmap, o);
    if (lethal && o.first_lethal < 0) {
      o.first_lethal = scan;
      o.first_lethal_range_m = range;
    }
    if (range <= radius_m) {
      ++o.cycles_near;
      o.cycles_lethal += lethal ? 1 : 0;
    }
  }
}

std::string small_objects_summary(const SmallObjectTracker& tracker, double min_height_m,
                                  double radius_m) {
  int near = 0, lethal = 0, seen = 0, scored = 0;
  double worst = 100.0;
  std::string worst_name = "-", lines;
  char line[512];
  for (const SmallObject& o : tracker.objects()) {
    if (o.first_two < 0) {
      std::snprintf(line, sizeof line, "  %s (%s, %.2f m high): never two returns in a scan\n",
                    o.name.c_str(), o.kind.c_str(), o.height_m());
      lines += line;
      continue;
    }
    ++seen;
    if (o.height_m() < min_height_m - 1e-9) {
      std::snprintf(line, sizeof line,
                    "  %s (%s, %.2f m high, under %.2f m: not scored): two returns first at scan "
                    "%d (%.1f m), lethal in %d of %d cycles within %.0f m from then\n",
                    o.name.c_str(), o.kind.c_str(), o.height_m(), min_height_m, o.first_two,
                    o.first_two_range_m, o.cycles_lethal, o.cycles_near, radius_m);
      lines += line;
      continue;
    }
    ++scored;
    near += o.cycles_near;
    lethal += o.cycles_lethal;
    const double held = share(o.cycles_lethal, o.cycles_near);
    // The first object scored sets it: with every object at 100 % the worst is one of them.
    if (o.cycles_near > 0 && (worst_name == "-" || held < worst)) {
      worst = held;
      worst_name = o.name;
    }
    std::snprintf(line, sizeof line,
                  "  %s (%s, %.2f m high): two returns first at scan %d (%.1f m), lethal first at "
                  "scan %d (%.1f m), lethal in %d of %d cycles within %.0f m from then (%.1f %%)\n",
                  o.name.c_str(), o.kind.c_str(), o.height_m(), o.first_two, o.first_two_range_m,
                  o.first_lethal, o.first_lethal_range_m, o.cycles_lethal, o.cycles_near, radius_m,
                  held);
    lines += line;
  }
  std::snprintf(line, sizeof line,
                "small objects (%zu, %d with two returns in a scan, %d of them %.2f m high or "
                "more; cycles within %.0f m from then): lethal in %.1f %% of them, worst object "
                "%.1f %% (%s)\n",
                tracker.objects().size(), seen, scored, min_height_m, radius_m, share(lethal, near),
                worst_name == "-" ? 0.0 : worst, worst_name.c_str());
  return line + lines;
}

nlohmann::ordered_json small_objects_json(const SmallObjectTracker& tracker) {
  auto out = nlohmann::ordered_json::array();
  for (const SmallObject& o : tracker.objects()) {
    out.push_back({{"name", o.name},
                   {"kind", o.kind},
                   {"height_m", o.height_m()},
                   {"first_two_returns_scan", o.first_two},
                   {"first_two_returns_range_m", o.first_two_range_m},
                   {"first_lethal_scan", o.first_lethal},
                   {"first_lethal_range_m", o.first_lethal_range_m},
                   {"cycles_near", o.cycles_near},
                   {"cycles_lethal", o.cycles_lethal}});
  }
  return out;
}

}  // namespace tarmac::tools
