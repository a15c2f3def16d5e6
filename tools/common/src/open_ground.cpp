#include "tarmac/tools/open_ground.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <nlohmann/json.hpp>

namespace tarmac::tools {
namespace {

constexpr double kRadiusM = 1.0;    ///< the neighbourhood of a cell
constexpr double kMaxRiseM = 0.25;  ///< its highest return above the neighbourhood's lowest
constexpr double kMaxTallM = 0.3;   ///< anything in the neighbourhood above its lowest
constexpr std::uint32_t kMinReturns = 3;
constexpr float kStepM = 0.1f;  ///< side-by-side cells' lowest returns this far apart: a step
constexpr float kLowM = 0.08f;  ///< a cell's returns spread this far: a low object (the default
                                ///< costmap.min_obstacle_height_m)

/// What render() draws per cell.
enum Look : std::uint8_t { kNone, kReturns, kLethal, kInscribed, kInflated, kFree, kUnknown };

std::int64_t key(std::int64_t ix, std::int64_t iy) {
  return (ix << 32) ^ (iy & 0xffffffff);
}

double share(std::size_t part, std::size_t whole) {
  return whole == 0 ? 0.0 : 100.0 * static_cast<double>(part) / static_cast<double>(whole);
}

}  // namespace

void OpenGroundTracker::add(std::span<const Eigen::Vector3f> points_W) {
  for (const Eigen::Vector3f& p : points_W) {
    if (!p.allFinite()) continue;
    const auto ix = static_cast<std::int64_t>(std::floor(p.x() / cell_m_));
    const auto iy = static_cast<std::int64_t>(std::floor(p.y() / cell_m_));
    Cell& c = cells_[key(ix, iy)];
    c.z.push_back(p.z());
    c.sorted = c.z.size() < 2;
  }
}

const OpenGroundCycle& OpenGroundTracker::observe(const core::Grid2D<std::int8_t>& costmap,
                                                  int scan, const LethalCauseView& causes) {
  const core::GridGeometry2D& g = costmap.geometry();
  const int m = static_cast<int>(std::ceil(kRadiusM / cell_m_ - 1e-9));
  const int nx = static_cast<int>(g.width), ny = static_cast<int>(g.height);
  const int px = nx + 2 * m, py = ny + 2 * m;  // the window with a margin of the radius
  const auto ix0 = static_cast<std::int64_t>(std::llround(g.origin_x_m / cell_m_)) - m;
  const auto iy0 = static_cast<std::int64_t>(std::llround(g.origin_y_m / cell_m_)) - m;
  static const std::vector<float> kEmpty;
  window_.assign(static_cast<std::size_t>(px) * static_cast<std::size_t>(py), &kEmpty);
  for (int y = 0; y < py; ++y) {
    for (int x = 0; x < px; ++x) {
      const auto it = cells_.find(key(ix0 + x, iy0 + y));
      if (it == cells_.end()) continue;
      Cell& c = it->second;
      if (!c.sorted) {
        std::sort(c.z.begin(), c.z.end());
        c.sorted = true;
      }
      window_[static_cast<std::size_t>(y) * px + x] = &c.z;
    }
  }
  // Steps: a cell with returns whose lowest lies kStepM or more from its +x or +y neighbour's
  // (both cells marked); low objects: a cell whose own returns below the envelope spread kLowM
  // or more. Cells with fewer than kMinReturns returns are left out, as above.
  step_.assign(window_.size(), 0);
  const auto top = static_cast<float>(envelope_m_);
  const auto lowest_of = [&](std::size_t i) {
    const std::vector<float>& z = *window_[i];
    return z.size() < kMinReturns ? std::numeric_limits<float>::quiet_NaN() : z.front();
  };
  for (int y = 0; y < py; ++y) {
    for (int x = 0; x < px; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * px + x;
      const float z = lowest_of(i);
      if (std::isnan(z)) continue;
      const std::vector<float>& own = *window_[i];
      const auto below_top = std::lower_bound(own.begin(), own.end(), z + top);
      if (*(below_top - 1) - z >= kLowM) step_[i] = 1;
      for (const std::size_t j : {x + 1 < px ? i + 1 : i, y + 1 < py ? i + px : i}) {
        if (j != i && std::abs(lowest_of(j) - z) >= kStepM) step_[i] = step_[j] = 1;
      }
    }
  }
  // The disc of cells whose centres lie within the radius.
  std::vector<std::ptrdiff_t> disc;
  for (int dy = -m; dy <= m; ++dy) {
    for (int dx = -m; dx <= m; ++dx) {
      if ((dx * dx + dy * dy) * cell_m_ * cell_m_ <= kRadiusM * kRadiusM + 1e-9) {
        disc.push_back(static_cast<std::ptrdiff_t>(dy) * px + dx);
      }
    }
  }
  // Any return of `z` (sorted) in [lo, hi).
  const auto any_in = [](const std::vector<float>& z, float lo, float hi) {
    const auto it = std::lower_bound(z.begin(), z.end(), lo);
    return it != z.end() && *it < hi;
  };
  OpenGroundCycle c;
  c.scan = scan;
  last_.assign(static_cast<std::size_t>(nx) * static_cast<std::size_t>(ny), kNone);
  last_width_ = g.width;
  last_height_ = g.height;
  for (int y = 0; y < ny; ++y) {
    for (int x = 0; x < nx; ++x) {
      const auto i = static_cast<std::ptrdiff_t>(y + m) * px + (x + m);
      const std::vector<float>& own = *window_[static_cast<std::size_t>(i)];
      std::uint8_t& look = last_[static_cast<std::size_t>(y) * nx + x];
      if (!own.empty()) look = kReturns;
      if (own.size() < kMinReturns) continue;
      float lowest = std::numeric_limits<float>::infinity();
      for (const std::ptrdiff_t d : disc) {
        const std::vector<float>& z = *window_[static_cast<std::size_t>(i + d)];
        if (!z.empty()) lowest = std::min(lowest, z.front());
      }
      const auto rise = static_cast<float>(kMaxRiseM), tall = static_cast<float>(kMaxTallM);
      if (any_in(own, lowest + rise, lowest + top)) continue;
      bool clear = true;
      for (const std::ptrdiff_t d : disc) {
        if (any_in(*window_[static_cast<std::size_t>(i + d)], lowest + tall, lowest + top)) {
          clear = false;
          break;
        }
      }
      if (!clear) continue;
      ++c.cells;
      const int v = costmap.at(static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y));
      const std::size_t cell = static_cast<std::size_t>(y) * nx + x;
      const bool by_step = std::any_of(disc.begin(), disc.end(), [&](std::ptrdiff_t d) {
        return step_[static_cast<std::size_t>(i + d)] != 0;
      });
      if (!by_step) {
        ++c.away;
        c.away_lethal += v == 100 ? 1 : 0;
        c.away_inscribed += v == 99 ? 1 : 0;
        if (v == 100) c.away_lethal_by_cause.add(causes, cell);
      }
      if (v == 100) {
        ++c.lethal;
        c.lethal_by_cause.add(causes, cell);
        look = kLethal;
      } else if (v == 99) {
        ++c.inscribed;
        look = kInscribed;
      } else if (v > 0) {
        ++c.inflated;
        look = kInflated;
      } else if (v == 0) {
        ++c.free;
        look = kFree;
      } else {
        ++c.unknown;
        look = kUnknown;
      }
    }
  }
  cycles_.push_back(c);
  return cycles_.back();
}

std::vector<std::uint8_t> OpenGroundTracker::render(std::uint32_t& width,
                                                    std::uint32_t& height) const {
  static constexpr std::uint8_t kColour[7][3] = {{0, 0, 0},     {90, 90, 90},   {220, 30, 30},
                                                 {240, 140, 0}, {240, 220, 60}, {40, 170, 60},
                                                 {60, 90, 200}};
  width = last_width_;
  height = last_height_;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(width) * height * 3);
  for (std::uint32_t y = 0; y < height; ++y) {
    for (std::uint32_t x = 0; x < width; ++x) {
      const std::uint8_t* c = kColour[last_[static_cast<std::size_t>(y) * width + x]];
      std::copy(c, c + 3, &rgb[(static_cast<std::size_t>(height - 1 - y) * width + x) * 3]);
    }
  }
  return rgb;
}

namespace {

/// Every cycle's counts added up (`scan` left 0).
OpenGroundCycle total(const OpenGroundTracker& tracker) {
  OpenGroundCycle sum;
  for (const OpenGroundCycle& c : tracker.cycles()) {
    sum.cells += c.cells;
    sum.lethal += c.lethal;
    sum.inscribed += c.inscribed;
    sum.inflated += c.inflated;
    sum.free += c.free;
    sum.unknown += c.unknown;
    sum.away += c.away;
    sum.away_lethal += c.away_lethal;
    sum.away_inscribed += c.away_inscribed;
    sum.lethal_by_cause += c.lethal_by_cause;
    sum.away_lethal_by_cause += c.away_lethal_by_cause;
  }
  return sum;
}

}  // namespace

std::string open_ground_summary(const OpenGroundTracker& tracker) {
  const OpenGroundCycle sum = total(tracker);
  double worst = 0.0;
  int worst_scan = -1;
  for (const OpenGroundCycle& c : tracker.cycles()) {
    if (share(c.lethal, c.cells) > worst || worst_scan < 0) {
      worst = share(c.lethal, c.cells);
      worst_scan = c.scan;
    }
  }
  const std::size_t n = tracker.cycles().size();
  char line[768];
  std::snprintf(line, sizeof line,
                "open flat ground by the drive's own returns (%zu cycles scored, %.0f cells each "
                "on average): lethal %.2f %% (worst cycle %.2f %%, scan %d), inscribed %.2f %%, "
                "inflated %.2f %%, free %.2f %%, unknown %.2f %%; away from steps of %.2f m "
                "and low returns of %.2f m (%.1f %% of it): lethal %.2f %%, inscribed %.2f %%",
                n, n == 0 ? 0.0 : static_cast<double>(sum.cells) / static_cast<double>(n),
                share(sum.lethal, sum.cells), worst, worst_scan, share(sum.inscribed, sum.cells),
                share(sum.inflated, sum.cells), share(sum.free, sum.cells),
                share(sum.unknown, sum.cells), static_cast<double>(kStepM),
                static_cast<double>(kLowM), share(sum.away, sum.cells),
                share(sum.away_lethal, sum.away), share(sum.away_inscribed, sum.away));
  std::string summary = line;
  if (sum.lethal_by_cause.total() > 0) {
    summary += "; its lethal cells by rule: " + sum.lethal_by_cause.shares() +
               " (away from steps and low returns: " + sum.away_lethal_by_cause.shares() + ")";
  }
  return summary;
}

nlohmann::ordered_json open_ground_json(const OpenGroundTracker& tracker) {
  nlohmann::ordered_json out;
  out["cycle_fields"] = {"scan", "cells",   "lethal", "inscribed",   "inflated",
                         "free", "unknown", "away",   "away_lethal", "away_inscribed"};
  auto& rows = out["per_cycle"] = nlohmann::ordered_json::array();
  for (const OpenGroundCycle& c : tracker.cycles()) {
    rows.push_back({c.scan, c.cells, c.lethal, c.inscribed, c.inflated, c.free, c.unknown, c.away,
                    c.away_lethal, c.away_inscribed});
  }
  const OpenGroundCycle sum = total(tracker);
  out["lethal_by_rule"] = sum.lethal_by_cause.json();
  out["away_lethal_by_rule"] = sum.away_lethal_by_cause.json();
  return out;
}

}  // namespace tarmac::tools
