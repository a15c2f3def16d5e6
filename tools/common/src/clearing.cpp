#include "tarmac/tools/clearing.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "tarmac/core/costmap_builder.hpp"

namespace tarmac::tools {

core::Result<DynamicTruth> read_dynamic_truth(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return core::Error{"truth.open", file.string() + ": cannot be read"};
  DynamicTruth truth;
  bool have_pose = false;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const auto bad = [&](const std::string& why) {
      return core::Error{"truth.parse", file.string() + ":" + std::to_string(n) + ": " + why};
    };
    if (line.empty()) continue;
    std::istringstream is(line);
    if (line.starts_with("# T_world_scene")) {
      is.ignore(15);
      Eigen::Matrix<double, 3, 4> m;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) is >> m(r, c);
      }
      if (!is || !m.allFinite()) return bad("T_world_scene needs 12 numbers");
      truth.T_world_scene.matrix().topRows<3>() = m;
      have_pose = true;
      continue;
    }
    if (line.starts_with('#')) continue;
    DynamicBox b;
    is >> b.scan >> b.id;
    for (int a = 0; a < 3; ++a) is >> b.min_W[a];
    for (int a = 0; a < 3; ++a) is >> b.max_W[a];
    std::string rest;
    if (!is || (is >> rest) || !b.min_W.allFinite() || !b.max_W.allFinite() ||
        (b.min_W.array() > b.max_W.array()).any() || b.scan < 0) {
      return bad("expected 'scan id min_x min_y min_z max_x max_y max_z' with min <= max");
    }
    if (!truth.boxes.empty() && b.scan < truth.boxes.back().scan) {
      return bad("scans must be in ascending order");
    }
    truth.boxes.push_back(b);
  }
  if (!have_pose) return core::Error{"truth.parse", file.string() + ": no '# T_world_scene' line"};
  return truth;
}

void ClearingTracker::observe(int scan, double stamp_s,
                              const core::Grid2D<std::uint8_t>& column_class,
                              const Eigen::Vector2d& sensor_xy, double blind_radius_m) {
  const core::GridGeometry2D& g = column_class.geometry();
  const double res = g.resolution_m;
  resolution_m_ = res;
  // The cells under an object at this scan.
  while (next_box_ < truth_.boxes.size() && truth_.boxes[next_box_].scan < scan) ++next_box_;
  for (std::size_t i = next_box_; i < truth_.boxes.size() && truth_.boxes[i].scan == scan; ++i) {
    const DynamicBox& b = truth_.boxes[i];
    Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
    for (int c = 0; c < 8; ++c) {
      const Eigen::Vector3d corner((c & 1) ? b.max_W.x() : b.min_W.x(),
                                   (c & 2) ? b.max_W.y() : b.min_W.y(),
                                   (c & 4) ? b.max_W.z() : b.min_W.z());
      const Eigen::Vector3d p = truth_.T_world_scene * corner;
      lo = lo.cwiseMin(p.head<2>());
      hi = hi.cwiseMax(p.head<2>());
    }
    // Global cell index on the map frame's lattice of the costmap (origin multiple of res).
    const auto first = [&](double v) { return static_cast<int>(std::ceil(v / res - 1e-9)) - 1; };
    const auto last = [&](double v) { return static_cast<int>(std::floor(v / res + 1e-9)); };
    for (int y = first(lo.y()); y <= last(hi.y()); ++y) {
      for (int x = first(lo.x()); x <= last(hi.x()); ++x) {
        // Squares [x·res, (x+1)·res] meeting [lo, hi] (closed).
        if ((x + 1) * res < lo.x() - 1e-9 || x * res > hi.x() + 1e-9) continue;
        if ((y + 1) * res < lo.y() - 1e-9 || y * res > hi.y() + 1e-9) continue;
        Cell& cell = cells_[{x, y}];
        cell.last_under_scan = scan;
        cell.last_under_s = stamp_s;
      }
    }
  }
  const auto cls = [&](int x, int y) {
    const auto c = g.cell_of((x + 0.5) * res, (y + 0.5) * res);
    return c ? static_cast<core::ColumnClass>(column_class.at(c->x(), c->y()))
             : core::ColumnClass::kUnknown;
  };
  for (auto& [key, cell] : cells_) {
    const core::ColumnClass c = cls(key.first, key.second);
    const bool under = cell.last_under_scan == scan;
    cell.ghost = !under && c == core::ColumnClass::kObstacle;
    if (under) {
      cell.pending = false;
      cell.blocked_under = cell.blocked_under || c == core::ColumnClass::kObstacle;
      continue;
    }
    const Eigen::Vector2d centre((key.first + 0.5) * res, (key.second + 0.5) * res);
    const bool in_view = (centre - sensor_xy).norm() > blind_radius_m;
    if (cell.blocked_under) {  // just left
      cell.blocked_under = false;
      cell.pending = true;
      cell.blind_at_leave = !in_view;
    }
    if (cell.pending && c == core::ColumnClass::kFree) {
      cell.pending = false;
      ttc_s_.push_back(stamp_s - cell.last_under_s);
      if (cell.blind_at_leave) {
        ++blind_at_leave_;
      } else {
        in_view_s_.push_back(stamp_s - cell.last_under_s);
      }
    }
  }
}

double blind_radius_from_ground(const Eigen::Vector3d& sensor_W,
                                std::span<const Eigen::Vector3f> points_W, double ground_z_m,
                                double tolerance_m) {
  double nearest_sq = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3f& p : points_W) {
    if (std::abs(static_cast<double>(p.z()) - ground_z_m) > tolerance_m) continue;
    nearest_sq =
        std::min(nearest_sq, (p.head<2>().cast<double>() - sensor_W.head<2>()).squaredNorm());
  }
  return std::sqrt(nearest_sq);
}

ClearingReport ClearingTracker::report() const {
  ClearingReport r;
  r.path_cells = cells_.size();
  r.cleared = ttc_s_.size();
  for (const auto& [key, cell] : cells_) {
    r.not_cleared += cell.pending ? 1 : 0;
    r.ghost_cells += cell.ghost ? 1 : 0;
  }
  r.measured = r.cleared + r.not_cleared;
  r.blind_at_leave = blind_at_leave_;
  const auto quantiles = [](std::vector<double> t, double& p50, double& p90, double& max) {
    if (t.empty()) return;
    std::sort(t.begin(), t.end());
    const auto at = [&](double q) {
      return t[std::min(t.size() - 1, static_cast<std::size_t>(q * static_cast<double>(t.size())))];
    };
    p50 = at(0.5);
    p90 = at(0.9);
    max = t.back();
  };
  quantiles(ttc_s_, r.p50_s, r.p90_s, r.max_s);
  quantiles(in_view_s_, r.in_view_p50_s, r.in_view_p90_s, r.in_view_max_s);
  return r;
}

}  // namespace tarmac::tools
