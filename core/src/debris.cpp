#include "tarmac/core/debris.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>
#include <string>

namespace tarmac::core {

Status DebrisParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) {
    return Error{"config.range", "costmap." + key + ": " + why};
  };
  if (!(max_height_m > 0.0 && max_height_m <= 2.55)) {
    return bad("debris_max_height_m", "must be in (0, 2.55]");
  }
  if (!(max_footprint_m > 0.0 && max_footprint_m <= 10.0)) {
    return bad("debris_max_footprint_m", "must be in (0, 10]");
  }
  if (!(clearance_m >= 0.0 && clearance_m <= 10.0)) {
    return bad("debris_clearance_m", "must be in [0, 10]");
  }
  if (min_scans < 1 || min_scans > 1000) return bad("debris_min_scans", "must be in [1, 1000]");
  return Ok{};
}

void DebrisScratch::reserve(std::size_t objects, std::size_t cells) {
  order.reserve(objects);
  parent.reserve(objects);
  members.reserve(objects);
  piece.reserve(objects);
  standing.reserve(objects);
  in_blob.assign(cells, 0);
  // A piece's blob stops growing past the footprint limit; a few hundred cells cover any
  // limit a config allows at the usual resolutions, and more only grows once.
  blob.reserve(1024);
}

namespace {

std::uint32_t find(std::vector<std::uint32_t>& parent, std::uint32_t k) {
  while (parent[k] != k) {
    parent[k] = parent[parent[k]];
    k = parent[k];
  }
  return k;
}

/// Chains the confirmed objects whose centres lie within kDebrisLinkM into pieces: fills
/// scratch.order (by x, then index) and scratch.parent (roots are the lowest slot).
void link_objects(const LowObjects& objects, DebrisScratch& s) {
  const auto all = objects.all();
  s.order.clear();
  for (std::uint32_t k = 0; k < all.size(); ++k) {
    if (objects.confirmed(all[k])) s.order.push_back(k);
  }
  std::sort(s.order.begin(), s.order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return all[a].xy_W.x() < all[b].xy_W.x() || (all[a].xy_W.x() == all[b].xy_W.x() && a < b);
  });
  const auto n = static_cast<std::uint32_t>(s.order.size());
  s.parent.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) s.parent[i] = i;
  const auto link = static_cast<float>(kDebrisLinkM);
  for (std::uint32_t i = 0; i < n; ++i) {
    const LowObject& a = all[s.order[i]];
    for (std::uint32_t j = i + 1; j < n; ++j) {
      const LowObject& b = all[s.order[j]];
      if (b.xy_W.x() - a.xy_W.x() > link) break;  // sorted by x: none further can link
      if ((b.xy_W - a.xy_W).squaredNorm() > link * link) continue;
      const std::uint32_t ra = find(s.parent, i), rb = find(s.parent, j);
      if (ra != rb) s.parent[std::max(ra, rb)] = std::min(ra, rb);
    }
  }
}

/// Grows the piece's blob (scratch.blob, marked in scratch.in_blob) from its objects' cells
/// through 8-connected obstacle columns. False when it spans more than `max_cells` cells along
/// x or y (growth stops there). `box` gets its bounding box in cells: min x, min y, max x, max y.
bool grow_blob(const CostmapLayers& layers, int max_cells, DebrisScratch& s,
               std::array<int, 4>& box) {
  const GridGeometry2D& g = layers.column_class.geometry();
  const auto& classes = layers.column_class.cells();
  const auto w = static_cast<int>(g.width), h = static_cast<int>(g.height);
  box = {std::numeric_limits<int>::max(), std::numeric_limits<int>::max(),
         std::numeric_limits<int>::min(), std::numeric_limits<int>::min()};
  const auto take = [&](std::uint32_t c) {
    const int x = static_cast<int>(c % g.width), y = static_cast<int>(c / g.width);
    box = {std::min(box[0], x), std::min(box[1], y), std::max(box[2], x), std::max(box[3], y)};
    return box[2] - box[0] < max_cells && box[3] - box[1] < max_cells;
  };
  for (const std::uint32_t c : s.blob) {
    if (!take(c)) return false;
  }
  for (std::size_t next = 0; next < s.blob.size(); ++next) {
    const int cx = static_cast<int>(s.blob[next] % g.width);
    const int cy = static_cast<int>(s.blob[next] / g.width);
    for (int y = std::max(0, cy - 1); y <= std::min(h - 1, cy + 1); ++y) {
      for (int x = std::max(0, cx - 1); x <= std::min(w - 1, cx + 1); ++x) {
        const auto c = static_cast<std::uint32_t>(y * w + x);
        if (s.in_blob[c] != 0 || classes[c] != static_cast<std::uint8_t>(ColumnClass::kObstacle)) {
          continue;
        }
        s.in_blob[c] = 1;
        s.blob.push_back(c);
        if (!take(c)) return false;
      }
    }
  }
  return true;
}

/// Whether an obstacle column outside the blob lies within `clearance_m` of one of its cells
/// (centre to centre).
bool crowded(const CostmapLayers& layers, const std::array<int, 4>& box, double clearance_m,
             const DebrisScratch& s) {
  const GridGeometry2D& g = layers.column_class.geometry();
  const auto& classes = layers.column_class.cells();
  const double r = g.resolution_m;
  const int reach = static_cast<int>(std::floor(clearance_m / r + 1e-9));
  const auto w = static_cast<int>(g.width), h = static_cast<int>(g.height);
  const double limit2 = (clearance_m + 1e-9) * (clearance_m + 1e-9);
  for (int y = std::max(0, box[1] - reach); y <= std::min(h - 1, box[3] + reach); ++y) {
    for (int x = std::max(0, box[0] - reach); x <= std::min(w - 1, box[2] + reach); ++x) {
      const auto c = static_cast<std::uint32_t>(y * w + x);
      if (s.in_blob[c] != 0 || classes[c] != static_cast<std::uint8_t>(ColumnClass::kObstacle)) {
        continue;
      }
      for (const std::uint32_t b : s.blob) {
        const double dx = (x - static_cast<int>(b % g.width)) * r;
        const double dy = (y - static_cast<int>(b / g.width)) * r;
        if (dx * dx + dy * dy <= limit2) return true;
      }
    }
  }
  return false;
}

/// The obstacle-cell checks of one piece (its objects' cells: scratch.standing, from sum_piece):
/// its blob small and apart. Sets its footprint. Leaves scratch.in_blob clear.
bool small_and_apart(const CostmapLayers& layers, const DebrisParams& params, DebrisScratch& s,
                     Debris& d) {
  const GridGeometry2D& g = layers.column_class.geometry();
  s.blob.clear();
  for (const std::uint32_t c : s.standing) {
    if (s.in_blob[c] == 0) {
      s.in_blob[c] = 1;
      s.blob.push_back(c);
    }
  }
  const int max_cells =
      static_cast<int>(std::floor(params.max_footprint_m / g.resolution_m + 1e-9));
  std::array<int, 4> box{};
  bool ok = max_cells >= 1 && grow_blob(layers, max_cells, s, box);
  if (ok) {
    d.footprint_m = (std::max(box[2] - box[0], box[3] - box[1]) + 1) * g.resolution_m;
    ok = !crowded(layers, box, params.clearance_m, s);
  }
  for (const std::uint32_t c : s.blob) s.in_blob[c] = 0;
  return ok;
}

/// Sums one piece's objects into a Debris, and puts the cells they stand on in `cells`; false
/// when one of them is not on its ground.
bool sum_piece(const LowObjects& objects, const CostmapLayers& layers,
               std::span<const std::uint32_t> members, std::vector<std::uint32_t>& cells,
               Debris& d) {
  const auto all = objects.all();
  cells.clear();
  d = Debris{};
  d.id = std::numeric_limits<std::uint32_t>::max();
  d.first_seen_ns = std::numeric_limits<std::int64_t>::max();
  d.last_confirmed_ns = std::numeric_limits<std::int64_t>::min();
  double wx = 0.0, wy = 0.0, weight = 0.0;
  for (const std::uint32_t k : members) {
    const LowObject& o = all[k];
    const std::int64_t cell = standing_cell(o, layers.ground_z_m);
    if (cell < 0) return false;
    cells.push_back(static_cast<std::uint32_t>(cell));
    d.id = std::min(d.id, o.id);
    wx += static_cast<double>(o.returns) * o.xy_W.x();
    wy += static_cast<double>(o.returns) * o.xy_W.y();
    weight += o.returns;
    if (d.objects == 0 || o.rise_m > d.height_m) {
      d.height_m = o.rise_m;
      d.ground_z_m = static_cast<double>(o.top_z_W) - static_cast<double>(o.rise_m);
    }
    d.first_seen_ns = std::min(d.first_seen_ns, o.first_ns);
    d.last_confirmed_ns = std::max(d.last_confirmed_ns, o.last_ns);
    d.returns += o.returns;
    d.scans = std::max(d.scans, o.scans);
    ++d.objects;
  }
  d.xy_W = Eigen::Vector2d(wx / weight, wy / weight);  // confirmed: returns >= 1 each
  return true;
}

}  // namespace

void extract_debris(const LowObjects& objects, const CostmapLayers& layers,
                    const DebrisParams& params, DebrisScratch& s, std::vector<Debris>& out) {
  out.clear();
  const GridGeometry2D& g = layers.column_class.geometry();
  if (layers.ground_z_m.geometry().cell_count() != g.cell_count() || g.cell_count() == 0) return;
  if (s.in_blob.size() != g.cell_count()) s.in_blob.assign(g.cell_count(), 0);
  link_objects(objects, s);
  // Members grouped by piece: (root slot, object index), sorted, so each piece is one run.
  const auto n = static_cast<std::uint32_t>(s.order.size());
  s.members.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    s.members[i] = (std::uint64_t{find(s.parent, i)} << 32) | s.order[i];
  }
  std::sort(s.members.begin(), s.members.end());
  for (std::uint32_t i = 0; i < n;) {
    const std::uint64_t root = s.members[i] >> 32;
    s.piece.clear();
    for (; i < n && (s.members[i] >> 32) == root; ++i) {
      s.piece.push_back(static_cast<std::uint32_t>(s.members[i] & 0xffffffffu));
    }
    Debris d;
    if (!sum_piece(objects, layers, s.piece, s.standing, d)) continue;
    if (!(d.height_m <= params.max_height_m + 1e-6)) continue;
    if (d.scans < static_cast<std::uint32_t>(params.min_scans)) continue;
    if (!small_and_apart(layers, params, s, d)) continue;
    out.push_back(d);
  }
  std::sort(out.begin(), out.end(), [](const Debris& a, const Debris& b) { return a.id < b.id; });
}

}  // namespace tarmac::core
