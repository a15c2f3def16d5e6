// libFuzzer target: core::TsdfTile::decode and core::StaticTile::decode, the readers of the tile
// store (state.dir/tsdf_tiles, tsdf.resident_limit_mb) that tarmacd reads back as the vehicle
// returns. The first byte picks how the rest is used (mod 4):
//   0: the rest is a TSDF tile file as found on disk: truncated, bit-flipped, foreign. Refused
//      ("tsdf_tile.*"), never a crash.
//   1: a u32 block count, then the rest is the payload; a valid header with the right
//      checksum is put in front, so the block parser behind the checksum sees fuzzed content.
//   2, 3: the same for a static occupancy tile (a u32 voxel count for 3).
// Properties: a decode either fails with a "tsdf_tile.*" code or yields a tile of at most 4096
// blocks that encodes to bytes which decode to the same blocks, and which a layer takes back;
// a static tile fails with a "static_tile.*" code or yields voxels inside its columns, sorted,
// that encode and decode to the same voxels and that an occupancy map takes back.

#include <cstring>
#include <string>
#include <tuple>

#include "fuzz_bytes.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/task_runner.hpp"
#include "tarmac/core/tsdf_tiles.hpp"

namespace tarmac::fuzz {
namespace {

constexpr float kVoxel = 0.1f, kTrunc = 0.3f;
constexpr std::size_t kHeaderBytes = 48;

std::uint64_t fnv1a(std::span<const std::uint8_t> bytes) {
  std::uint64_t h = 1469598103934665603ull;
  for (const std::uint8_t b : bytes) {
    h ^= b;
    h *= 1099511628211ull;
  }
  return h;
}

/// A header as TsdfTile::encode writes it (tsdf_tiles.hpp) for tile (0, 0, 0), then `payload`.
Bytes sealed(std::uint32_t blocks, std::span<const std::uint8_t> payload) {
  ByteWriter w;
  for (const char c : std::string("TMTSDFT1")) w.put(c);
  w.put<std::uint32_t>(1);
  w.put(kVoxel);
  w.put(kTrunc);
  for (int a = 0; a < 3; ++a) w.put<std::int32_t>(0);
  w.put(blocks);
  w.put<std::uint64_t>(payload.size());
  w.put(fnv1a(payload));
  w.bytes(payload);
  return w.take();
}

/// A header as StaticTile::encode writes it for column tile (0, 0), then `payload`.
Bytes sealed_static(std::uint32_t voxels, std::span<const std::uint8_t> payload) {
  ByteWriter w;
  for (const char c : std::string("TMSTATC1")) w.put(c);
  w.put<std::uint32_t>(1);
  w.put(0.2f);
  w.put<std::int32_t>(0);
  w.put<std::int32_t>(0);
  w.put(voxels);
  w.put(fnv1a(payload));
  w.bytes(payload);
  return w.take();
}

void check_static(std::span<const std::uint8_t> file) {
  const core::StaticTileIndex zero = core::StaticTileIndex::Zero();
  core::Result<core::StaticTile> tile = core::StaticTile::decode(file, 0.2f, zero);
  if (!tile) {
    TARMAC_FUZZ_CHECK(tile.error().code.rfind("static_tile.", 0) == 0);
    return;
  }
  const std::vector<Eigen::Vector3i>& v = tile.value().voxels;
  for (std::size_t i = 0; i < v.size(); ++i) {
    TARMAC_FUZZ_CHECK(v[i].x() >= 0 && v[i].x() < core::kStaticTileEdge);
    TARMAC_FUZZ_CHECK(v[i].y() >= 0 && v[i].y() < core::kStaticTileEdge);
    if (i > 0) {
      TARMAC_FUZZ_CHECK(std::tie(v[i - 1].z(), v[i - 1].y(), v[i - 1].x()) <
                        std::tie(v[i].z(), v[i].y(), v[i].x()));
    }
  }
  core::Result<core::StaticTile> back =
      core::StaticTile::decode(tile.value().encode(0.2f), 0.2f, zero);
  TARMAC_FUZZ_CHECK(back.ok() && back.value().voxels == v);
  core::OccupancyParams p;
  p.window_x_vox = p.window_y_vox = 16;
  p.window_z_vox = 16;
  core::OccupancyMap map(p);
  map.put_static(v);
  std::vector<core::VoxelIndex> out;
  map.export_static(out);
  TARMAC_FUZZ_CHECK(out == v);
}

std::uint64_t digest(const core::TsdfTile& tile) {
  core::TsdfDigest d;
  tile.for_each_block([&d](const core::TsdfBlockView& b) { d.add(b); });
  return d.value();
}

void check(std::span<const std::uint8_t> file) {
  const core::TileIndex zero = core::TileIndex::Zero();
  core::Result<core::TsdfTile> tile = core::TsdfTile::decode(file, kVoxel, kTrunc, zero);
  if (!tile) {
    TARMAC_FUZZ_CHECK(tile.error().code.rfind("tsdf_tile.", 0) == 0);
    return;
  }
  TARMAC_FUZZ_CHECK(tile.value().block_count() <= 4096);
  const std::uint64_t d = digest(tile.value());
  const std::vector<std::uint8_t> again = tile.value().encode(kVoxel, kTrunc);
  core::Result<core::TsdfTile> back = core::TsdfTile::decode(again, kVoxel, kTrunc, zero);
  TARMAC_FUZZ_CHECK(back.ok());
  TARMAC_FUZZ_CHECK(digest(back.value()) == d);
  core::TsdfLayer layer(kVoxel, kTrunc);
  layer.mark_absent(zero);
  layer.attach_tile(std::move(tile).value());
  TARMAC_FUZZ_CHECK(!layer.is_absent(zero));
  TARMAC_FUZZ_CHECK(layer.digest() == d);
}

/// Real tiles: a few scans of walls around the origin, encoded.
const std::vector<Bytes>& seeds() {
  static const std::vector<Bytes> all = [] {
    core::TsdfParams p;
    core::TsdfIntegrator integrator(p);
    core::TsdfLayer layer = integrator.make_layer();
    std::vector<Eigen::Vector3f> pts;
    for (int i = -30; i <= 30; ++i) {
      for (int j = -10; j <= 10; ++j) {
        pts.emplace_back(4.03f, 0.1f * static_cast<float>(i), 0.1f * static_cast<float>(j) + 1.f);
        pts.emplace_back(0.1f * static_cast<float>(i) + 3.f, 6.1f,
                         0.1f * static_cast<float>(j) + 1.f);
      }
    }
    core::SerialRunner runner;
    for (int s = 0; s < 3; ++s) {
      integrator.integrate(Eigen::Vector3d(1.0 + 0.1 * s, 1.0, 1.5), pts, layer, runner);
    }
    std::vector<Bytes> out;
    const std::optional<core::TsdfTile> tile = layer.copy_tile(core::TileIndex::Zero());
    if (!tile) return out;
    const std::vector<std::uint8_t> bytes = tile->encode(kVoxel, kTrunc);
    Bytes whole{0};
    whole.insert(whole.end(), bytes.begin(), bytes.end());
    out.push_back(whole);
    std::uint32_t blocks = 0;
    std::memcpy(&blocks, bytes.data() + 32, 4);
    ByteWriter w;
    w.put<std::uint8_t>(1);
    w.put(blocks);
    w.bytes(std::span<const std::uint8_t>(bytes).subspan(kHeaderBytes));
    out.push_back(w.take());
    // A static tile: a wall along y, three heights.
    core::StaticTile st{core::StaticTileIndex::Zero(), {}};
    for (int z = -1; z < 2; ++z) {
      for (int y = 0; y < core::kStaticTileEdge; y += 3) st.voxels.emplace_back(7, y, z);
    }
    const std::vector<std::uint8_t> sb = st.encode(0.2f);
    Bytes whole_static{2};
    whole_static.insert(whole_static.end(), sb.begin(), sb.end());
    out.push_back(whole_static);
    ByteWriter ws;
    ws.put<std::uint8_t>(3);
    ws.put(static_cast<std::uint32_t>(st.voxels.size()));
    ws.bytes(std::span<const std::uint8_t>(sb).subspan(36));
    out.push_back(ws.take());
    return out;
  }();
  return all;
}

}  // namespace
}  // namespace tarmac::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  tarmac::fuzz::handle_make_seeds(argc, argv, &tarmac::fuzz::seeds, {"TMTSDFT1", "TMSTATC1"});
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tarmac::fuzz;
  ByteReader in(data, size);
  const auto mode = in.get<std::uint8_t>();
  if (mode % 4 == 0) {
    check(in.rest());
  } else if (mode % 4 == 1) {
    const auto blocks = in.get<std::uint32_t>();
    check(sealed(blocks, in.rest()));
  } else if (mode % 4 == 2) {
    check_static(in.rest());
  } else {
    const auto voxels = in.get<std::uint32_t>();
    check_static(sealed_static(voxels, in.rest()));
  }
  return 0;
}
