#include "site_view.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>

#include <nlohmann/json.hpp>

#include "tarmac/tools/array_io.hpp"

namespace tarmac::fleet {

namespace {

constexpr int kEdge = core::kBevTileEdge;
constexpr char kMagic[4] = {'T', 'F', 'B', 'R'};
constexpr std::uint32_t kVersion = 1;

/// Colours by vehicle index (ColorBrewer-like, distinct on grey).
constexpr std::array<std::array<std::uint8_t, 3>, 8> kPalette{{{31, 119, 180},
                                                               {255, 127, 14},
                                                               {44, 160, 44},
                                                               {214, 39, 40},
                                                               {148, 103, 189},
                                                               {140, 86, 75},
                                                               {227, 119, 194},
                                                               {23, 190, 207}}};

}  // namespace

SiteView make_site_view(const core::BevPeers& peers, std::int64_t now_ns) {
  SiteView v;
  v.resolution_m = peers.resolution_m();
  v.now_ns = now_ns;
  for (const auto& [id, st] : peers.stats()) v.vehicles.push_back(id);
  const auto tiles = peers.tiles();
  if (tiles.empty()) return v;
  std::int32_t x0 = tiles.front().first, x1 = x0, y0 = tiles.front().second, y1 = y0;
  for (const auto& [x, y] : tiles) {
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
  v.i0 = std::int64_t{x0} * kEdge;
  v.j0 = std::int64_t{y0} * kEdge;
  v.width = static_cast<std::uint32_t>((x1 - x0 + 1) * kEdge);
  v.height = static_cast<std::uint32_t>((y1 - y0 + 1) * kEdge);
  const std::size_t n = std::size_t{v.width} * v.height;
  v.state.assign(n, -1);
  v.vehicle.assign(n, -1);
  v.age_s.assign(n, -1.0f);
  const std::int64_t oldest = now_ns - peers.max_age_ns();
  for (const auto& [tx, ty] : tiles) {  // only the tiles held: the box between stays unknown
    for (int cy = 0; cy < kEdge; ++cy) {
      for (int cx = 0; cx < kEdge; ++cx) {
        const std::int64_t i = std::int64_t{tx} * kEdge + cx, j = std::int64_t{ty} * kEdge + cy;
        const core::BevPeerCell c = peers.lookup(i, j);
        if (c.vehicle_id == nullptr || c.cell.observed_ns < oldest) continue;
        const auto k = static_cast<std::size_t>((j - v.j0) * v.width + (i - v.i0));
        v.state[k] = c.cell.state == core::BevState::kOccupied ? std::int8_t{100} : std::int8_t{0};
        const auto who = std::lower_bound(v.vehicles.begin(), v.vehicles.end(), *c.vehicle_id);
        v.vehicle[k] = static_cast<std::int8_t>(
            std::min<std::ptrdiff_t>(std::distance(v.vehicles.begin(), who), 127));
        v.age_s[k] = static_cast<float>(
            static_cast<double>(std::max<std::int64_t>(now_ns - c.cell.observed_ns, 0)) / 1e9);
      }
    }
  }
  return v;
}

core::Status write_site_view(const SiteView& v, const core::BevPeers& peers,
                             const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return core::Error{"io", dir.string() + ": " + ec.message()};
  const std::vector<std::size_t> shape{v.height, v.width};
  if (auto s = tools::write_npy(dir / "site.npy", v.state, shape); !s) return s;
  if (auto s = tools::write_npy(dir / "site_vehicle.npy", v.vehicle, shape); !s) return s;
  if (auto s = tools::write_npy(dir / "site_age_s.npy", v.age_s, shape); !s) return s;

  // North up: image row 0 is the highest y.
  const double max_age_s = static_cast<double>(peers.max_age_ns()) / 1e9;
  std::vector<std::uint8_t> rgb(std::size_t{v.width} * v.height * 3, 60);
  std::map<std::string, std::pair<std::size_t, std::size_t>> cells;  // free, occupied
  for (std::uint32_t y = 0; y < v.height; ++y) {
    for (std::uint32_t x = 0; x < v.width; ++x) {
      const std::size_t k = std::size_t{y} * v.width + x;
      if (v.state[k] < 0) continue;
      const auto& colour = kPalette[static_cast<std::size_t>(v.vehicle[k]) % kPalette.size()];
      auto& counts = cells[v.vehicles[static_cast<std::size_t>(v.vehicle[k])]];
      std::uint8_t* px = &rgb[((std::size_t{v.height} - 1 - y) * v.width + x) * 3];
      const double fresh = std::clamp(1.0 - v.age_s[k] / max_age_s, 0.0, 1.0);
      for (int c = 0; c < 3; ++c) {
        if (v.state[k] == 100) {
          px[c] = static_cast<std::uint8_t>(colour[static_cast<std::size_t>(c)] * 0.35);
        } else {  // free: the vehicle's colour, towards white as it ages
          const double a = 0.35 + 0.65 * fresh;
          px[c] = static_cast<std::uint8_t>(a * colour[static_cast<std::size_t>(c)] +
                                            (1.0 - a) * 235.0);
        }
      }
      (v.state[k] == 100 ? counts.second : counts.first) += 1;
    }
  }
  if (v.width > 0 && v.height > 0) {
    if (auto s = tools::write_png(dir / "site.png", rgb, v.width, v.height); !s) return s;
  }

  nlohmann::ordered_json j;
  j["now_ns"] = v.now_ns;
  j["resolution_m"] = v.resolution_m;
  j["origin_m"] = {static_cast<double>(v.i0) * v.resolution_m,
                   static_cast<double>(v.j0) * v.resolution_m};
  j["width"] = v.width;
  j["height"] = v.height;
  j["max_age_s"] = max_age_s;
  j["vehicles"] = nlohmann::ordered_json::array();
  for (std::size_t i = 0; i < v.vehicles.size(); ++i) {
    const auto& st = peers.stats().at(v.vehicles[i]);
    const auto c = cells.count(v.vehicles[i]) != 0 ? cells.at(v.vehicles[i])
                                                   : std::pair<std::size_t, std::size_t>{0, 0};
    const auto& colour = kPalette[i % kPalette.size()];
    nlohmann::ordered_json e;
    e["id"] = v.vehicles[i];
    e["colour"] = {colour[0], colour[1], colour[2]};
    e["summaries_applied"] = st.messages;
    e["summaries_refused"] = st.rejected;
    e["gaps"] = st.gaps;
    e["newest_stamp_ns"] = st.newest_stamp_ns;
    e["tiles"] = st.tiles;
    e["free_cells"] = c.first;
    e["occupied_cells"] = c.second;
    j["vehicles"].push_back(std::move(e));
  }
  return tools::write_json(dir / "site.json", j);
}

// ---- recordings ----

namespace {

template <typename T>
void put(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

/// Reads from a byte buffer, failing (not throwing) past its end.
struct Cursor {
  const std::string& bytes;
  std::size_t at = 0;
  bool ok = true;
  template <typename T>
  T get() {
    T v{};
    if (at + sizeof(T) > bytes.size()) {
      ok = false;
      return v;
    }
    std::memcpy(&v, bytes.data() + at, sizeof(T));
    at += sizeof(T);
    return v;
  }
  std::string text(std::size_t n) {
    if (!ok || at + n > bytes.size()) {
      ok = false;
      return {};
    }
    std::string s = bytes.substr(at, n);
    at += n;
    return s;
  }
};

}  // namespace

core::Result<Recorder> Recorder::open(const std::filesystem::path& file) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (!out) return core::Error{"io", file.string() + ": cannot create"};
  out.write(kMagic, 4);
  out.write(reinterpret_cast<const char*>(&kVersion), sizeof kVersion);
  if (!out) return core::Error{"io", file.string() + ": cannot write"};
  return Recorder(file, std::move(out));
}

core::Status Recorder::append(const core::BevMessage& m) {
  std::string rec;
  put<std::uint32_t>(rec, static_cast<std::uint32_t>(m.vehicle_id.size()));
  rec += m.vehicle_id;
  put<std::int64_t>(rec, m.stamp_ns);
  put<std::uint32_t>(rec, m.sequence);
  put<std::uint8_t>(rec, m.keyframe ? 1 : 0);
  put<double>(rec, m.resolution_m);
  put<std::uint32_t>(rec, static_cast<std::uint32_t>(m.tiles.size()));
  for (const auto& t : m.tiles) {
    put<std::int32_t>(rec, t.x);
    put<std::int32_t>(rec, t.y);
    put<std::uint32_t>(rec, static_cast<std::uint32_t>(t.runs.size()));
    rec.append(reinterpret_cast<const char*>(t.runs.data()), t.runs.size());
  }
  out_.write(rec.data(), static_cast<std::streamsize>(rec.size()));
  out_.flush();  // a recording cut short by a kill keeps every summary written so far
  if (!out_) return core::Error{"io", file_.string() + ": cannot append"};
  return core::Ok{};
}

core::Result<std::vector<core::BevMessage>> read_recording(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return core::Error{"io", file.string() + ": cannot open"};
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  Cursor c{bytes};
  if (c.text(4) != std::string(kMagic, 4) || c.get<std::uint32_t>() != kVersion) {
    return core::Error{"fleet.recording", file.string() + ": not a tarmac-fleet recording (v1)"};
  }
  std::vector<core::BevMessage> out;
  while (c.ok && c.at < bytes.size()) {
    const std::size_t start = c.at;
    core::BevMessage m;
    const auto id_len = c.get<std::uint32_t>();
    m.vehicle_id = id_len <= 64 ? c.text(id_len) : (c.ok = false, std::string());
    m.stamp_ns = c.get<std::int64_t>();
    m.sequence = c.get<std::uint32_t>();
    m.keyframe = c.get<std::uint8_t>() != 0;
    m.resolution_m = c.get<double>();
    const auto tiles = c.get<std::uint32_t>();
    if (tiles > core::kBevMaxPeerTiles) c.ok = false;
    for (std::uint32_t t = 0; t < tiles && c.ok; ++t) {
      core::BevTile tile;
      tile.x = c.get<std::int32_t>();
      tile.y = c.get<std::int32_t>();
      const std::string runs = c.text(c.get<std::uint32_t>());
      tile.runs.assign(runs.begin(), runs.end());
      m.tiles.push_back(std::move(tile));
    }
    if (!c.ok) {
      return core::Error{"fleet.recording", file.string() +
                                                ": truncated or malformed record at "
                                                "byte " +
                                                std::to_string(start)};
    }
    out.push_back(std::move(m));
  }
  return out;
}

}  // namespace tarmac::fleet
