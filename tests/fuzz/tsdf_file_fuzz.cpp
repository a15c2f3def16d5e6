// libFuzzer target: core::parse_tsdf, the .vdb TSDF loader behind load_tsdf (tarmacd's saved map
// with its static occupancy layer). The first byte picks how the rest is used:
//   even: the rest is the whole file as found on disk: truncated, bit-flipped, foreign. The
//         contract: refused ("tsdf_io.*"), never a crash.
//   odd:  the rest describes a file's content (metadata keys, types and values, which grids,
//         their types, transforms, tiles, voxels, the static layer); OpenVDB writes it and the
//         correct tarmac trailer is appended, so tarmac's checks after the checksum (format
//         version, metadata, plausibility, tiles, transforms, topologies, band, weights, the
//         static layer) all see fuzzed content.
// Bytes that pass the checksum go to OpenVDB's own parser, which does not defend against
// malformed streams (a malformed blosc chunk overflows a heap buffer in OpenVDB 10); the
// checksum is what keeps damaged files from it, so mode "odd" only feeds it streams OpenVDB wrote.
// Properties: a load either fails with a "tsdf_io.*" code or yields a map within the contract
// (plausible voxel size and truncation, sorted static voxels), and an accepted map saves and
// loads back bit-identical.

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <tuple>

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include "fuzz_bytes.hpp"
#include "tarmac/core/task_runner.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tsdf_grids.hpp"  // core/src: the lattice transform the loader expects

namespace tarmac::fuzz {
namespace {

namespace fs = std::filesystem;

constexpr std::size_t kTrailerBytes = 32;

std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 1469598103934665603ull;
  for (const char c : s) {
    h ^= static_cast<unsigned char>(c);
    h *= 1099511628211ull;
  }
  return h;
}

/// The trailer save_tsdf appends (tsdf_io.hpp documents the layout).
std::string sealed(std::string body) {
  const std::uint64_t length = body.size();
  const std::uint64_t sum = fnv1a(body);
  body += "TARMACv1";
  for (int i = 0; i < 8; ++i) body += static_cast<char>((length >> (8 * i)) & 0xff);
  for (int i = 0; i < 8; ++i) body += static_cast<char>((sum >> (8 * i)) & 0xff);
  body += "TSDF-END";
  return body;
}

/// A scratch folder of this process for the save/load round trip, removed at exit.
class Scratch {
 public:
  Scratch() {
    const fs::path base = fs::exists("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    dir_ = base / ("tarmac-fuzz-tsdf-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
  [[nodiscard]] const fs::path& dir() const { return dir_; }

 private:
  fs::path dir_;
};

const fs::path& scratch() {
  static const Scratch s;
  return s.dir();
}

std::string read_all(const fs::path& f) {
  std::ifstream in(f, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A small map (rays onto a wall) saved by save_tsdf, with or without a static layer.
std::string saved_map(bool with_static, int rays) {
  core::TsdfParams params;
  core::TsdfIntegrator integrator(params);
  core::TsdfLayer layer = integrator.make_layer();
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i < rays; ++i) pts.emplace_back(3.03f, 0.05f * (i % 8), 0.05f * (i / 8));
  core::SerialRunner runner;
  integrator.integrate(Eigen::Vector3d(0.01, 0.02, 0.03), pts, layer, runner);
  core::TsdfMapInfo info;
  info.frame_id = "map";
  info.config_hash = "0123456789abcdef";
  info.stamp_ns = 1767225600123456789;
  core::StaticOccupancy occupancy;
  if (with_static) {
    occupancy.voxel_size_m = 0.2f;
    occupancy.voxels = {{1, 2, 0}, {-3, 4, 1}, {15, 0, 2}};
  }
  const fs::path file = scratch() / "seed.vdb";
  if (!core::save_tsdf(file, layer, info, &occupancy)) {
    std::fprintf(stderr, "cannot write the seed map\n");
    std::exit(1);
  }
  return read_all(file);
}

enum MetaFlags : std::uint8_t {
  kVersion = 1,
  kFrame = 2,
  kVoxel = 4,
  kTruncation = 8,
  kHash = 16,
  kStamp = 32,
  kStaticVoxel = 64,
  kVersionAsFloat = 128,
};
enum GridFlags : std::uint8_t {
  kTsdfGrid = 1,
  kWeightGrid = 2,
  kStaticGrid = 4,
  kTsdfAsBool = 8,
  kTsdfTile = 16,
  kWeightTile = 32,
  kWeightOtherTransform = 64,
  kStaticOtherTransform = 128,
};
enum VoxelFlags : std::uint8_t { kNoWeight = 1, kInactive = 2 };
constexpr std::size_t kMaxVoxels = 64, kMaxStatic = 32;
// Voxel coordinates are int8: within a few of OpenVDB's top-level nodes (4096 voxels wide), whose
// 32^3-entry tables make each far-flung voxel cost milliseconds to write and read here.

/// A transform for `voxel_size_m`, or for 1 m when OpenVDB would refuse the value (it wants a
/// scale whose cube is clearly non-zero). The loader never builds one for a size below 0.01 m.
openvdb::math::Transform::Ptr transform(float voxel_size_m) {
  if (!(voxel_size_m >= 0.01f && voxel_size_m <= 1000.0f)) voxel_size_m = 1.0f;
  return core::tsdf_transform(voxel_size_m);
}

openvdb::Coord coord(ByteReader& in) {
  const auto x = in.get<std::int8_t>();
  const auto y = in.get<std::int8_t>();
  const auto z = in.get<std::int8_t>();
  return {x, y, z};
}

/// Mode odd: the file content the bytes describe, written by OpenVDB and sealed.
std::string described_file(ByteReader& in) {
  const auto meta_flags = in.get<std::uint8_t>();
  const auto version = in.get<std::int32_t>();
  const std::string frame = in.string();
  const auto voxel = in.get<float>();
  const auto truncation = in.get<float>();
  const auto static_voxel = in.get<float>();
  const auto grid_flags = in.get<std::uint8_t>();
  openvdb::MetaMap meta;
  if ((meta_flags & kVersion) != 0) {
    if ((meta_flags & kVersionAsFloat) != 0) {
      meta.insertMeta("tarmac.format_version", openvdb::FloatMetadata(static_cast<float>(version)));
    } else {
      meta.insertMeta("tarmac.format_version", openvdb::Int32Metadata(version));
    }
  }
  if ((meta_flags & kFrame) != 0)
    meta.insertMeta("tarmac.frame_id", openvdb::StringMetadata(frame));
  if ((meta_flags & kVoxel) != 0)
    meta.insertMeta("tarmac.voxel_size_m", openvdb::FloatMetadata(voxel));
  if ((meta_flags & kTruncation) != 0) {
    meta.insertMeta("tarmac.truncation_m", openvdb::FloatMetadata(truncation));
  }
  if ((meta_flags & kHash) != 0)
    meta.insertMeta("tarmac.config_hash", openvdb::StringMetadata("0"));
  if ((meta_flags & kStamp) != 0) meta.insertMeta("tarmac.stamp_ns", openvdb::Int64Metadata(1));
  if ((meta_flags & kStaticVoxel) != 0) {
    meta.insertMeta("tarmac.static_voxel_size_m", openvdb::FloatMetadata(static_voxel));
  }
  auto distance = openvdb::FloatGrid::create(truncation);
  distance->setName("tsdf");
  distance->setTransform(transform(voxel));
  auto weight = openvdb::FloatGrid::create(0.0f);
  weight->setName("weight");
  weight->setTransform(transform((grid_flags & kWeightOtherTransform) != 0 ? voxel * 2 : voxel));
  const std::size_t voxels = in.get<std::uint8_t>() % (kMaxVoxels + 1);
  for (std::size_t i = 0; i < voxels; ++i) {
    const openvdb::Coord c = coord(in);
    const auto d = in.get<float>();
    const auto w = in.get<float>();
    const auto flags = in.get<std::uint8_t>();
    const bool on = (flags & kInactive) == 0;
    distance->tree().setValueOnly(c, d);
    distance->tree().setActiveState(c, on);
    if ((flags & kNoWeight) == 0) {
      weight->tree().setValueOnly(c, w);
      weight->tree().setActiveState(c, on);
    }
  }
  if ((grid_flags & kTsdfTile) != 0) distance->tree().addTile(1, openvdb::Coord(4096), 0.0f, true);
  if ((grid_flags & kWeightTile) != 0) weight->tree().addTile(1, openvdb::Coord(4096), 1.0f, true);
  auto mask = openvdb::BoolGrid::create(false);
  mask->setName("static_occupancy");
  mask->setTransform(transform((grid_flags & kStaticOtherTransform) != 0 ? voxel : static_voxel));
  const std::size_t statics = in.get<std::uint8_t>() % (kMaxStatic + 1);
  for (std::size_t i = 0; i < statics; ++i) {
    mask->tree().setValueOn(coord(in), true);
  }
  openvdb::GridCPtrVec grids;
  if ((grid_flags & kTsdfGrid) != 0) {
    if ((grid_flags & kTsdfAsBool) != 0) {
      auto wrong = openvdb::BoolGrid::create(false);
      wrong->setName("tsdf");
      grids.push_back(wrong);
    } else {
      grids.push_back(distance);
    }
  }
  if ((grid_flags & kWeightGrid) != 0) grids.push_back(weight);
  if ((grid_flags & kStaticGrid) != 0) grids.push_back(mask);
  std::ostringstream out;
  openvdb::io::Stream(out).write(grids, meta);
  return sealed(out.str());
}

/// Mode odd bytes for a well-formed map: every key, both grids, `voxels` voxels in the band.
Bytes described_seed(float voxel, float truncation, int voxels, bool with_static) {
  ByteWriter out;
  out.put<std::uint8_t>(1);
  out.put<std::uint8_t>(kVersion | kFrame | kVoxel | kTruncation | kHash | kStamp |
                        (with_static ? kStaticVoxel : 0));
  out.put<std::int32_t>(core::kTsdfFileVersion);
  out.string("map");
  out.put(voxel);
  out.put(truncation);
  out.put(0.2f);
  out.put<std::uint8_t>(kTsdfGrid | kWeightGrid | (with_static ? kStaticGrid : 0));
  out.put(static_cast<std::uint8_t>(voxels));
  for (int i = 0; i < voxels; ++i) {
    out.put(static_cast<std::int8_t>(i));
    out.put(static_cast<std::int8_t>(-i));
    out.put(static_cast<std::int8_t>(i % 3));
    out.put(truncation * (static_cast<float>(i % 7) - 3.0f) / 3.0f);
    out.put(1.0f + static_cast<float>(i));
    out.put<std::uint8_t>(0);
  }
  out.put<std::uint8_t>(with_static ? 3 : 0);
  for (int i = 0; i < (with_static ? 3 : 0); ++i) {
    out.put(static_cast<std::int8_t>(i * 5));
    out.put(static_cast<std::int8_t>(-i));
    out.put(static_cast<std::int8_t>(1));
  }
  return out.take();
}

Bytes input(std::uint8_t mode, const std::string& bytes) {
  Bytes b{mode};
  b.insert(b.end(), bytes.begin(), bytes.end());
  return b;
}

const std::vector<Bytes>& seeds() {
  static const std::vector<Bytes> all = [] {
    std::vector<Bytes> s;
    for (const bool with_static : {false, true}) {
      const std::string file = saved_map(with_static, with_static ? 16 : 48);
      const std::string body = file.substr(0, file.size() - kTrailerBytes);
      s.push_back(input(0, file));
      s.push_back(input(0, file.substr(0, file.size() / 2)));  // truncated
      std::string flipped = file;
      flipped[flipped.size() / 3] = static_cast<char>(flipped[flipped.size() / 3] ^ 0x10);
      s.push_back(input(0, flipped));
    }
    s.push_back(described_seed(0.1f, 0.3f, 40, false));
    s.push_back(described_seed(0.1f, 0.3f, 12, true));
    s.push_back(described_seed(0.05f, 0.2f, 64, true));
    return s;
  }();
  return all;
}

void check_accepted(const core::LoadedTsdf& map) {
  TARMAC_FUZZ_CHECK(map.info.voxel_size_m >= 0.01f && map.info.voxel_size_m <= 2.0f);
  TARMAC_FUZZ_CHECK(map.info.truncation_m > 0.0f &&
                    map.info.truncation_m <= 32.0f * map.info.voxel_size_m);
  TARMAC_FUZZ_CHECK(map.layer.voxel_size_m() == map.info.voxel_size_m);
  const auto& v = map.occupancy.voxels;
  TARMAC_FUZZ_CHECK(std::is_sorted(v.begin(), v.end(), [](const auto& a, const auto& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  }));
  TARMAC_FUZZ_CHECK(map.occupancy.voxel_size_m != 0.0f || v.empty());
  // What was accepted saves and loads back bit-identical.
  const fs::path file = scratch() / "again.vdb";
  TARMAC_FUZZ_CHECK(core::save_tsdf(file, map.layer, map.info, &map.occupancy).ok());
  const auto again = core::load_tsdf(file);
  TARMAC_FUZZ_CHECK(again.ok());
  TARMAC_FUZZ_CHECK(again.value().layer.digest() == map.layer.digest());
  TARMAC_FUZZ_CHECK(again.value().occupancy.voxels == v);
}

}  // namespace
}  // namespace tarmac::fuzz

extern "C" int LLVMFuzzerInitialize(int* argc, char*** argv) {
  openvdb::initialize();
  tarmac::fuzz::handle_make_seeds(argc, argv, &tarmac::fuzz::seeds,
                                  {"TARMACv1", "TSDF-END", "tarmac.format_version", "tsdf",
                                   "weight", "static_occupancy", "tarmac.static_voxel_size_m"});
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tarmac;
  if (size == 0) return 0;
  std::string bytes;
  if ((data[0] & 1) != 0) {
    fuzz::ByteReader in(data + 1, size - 1);
    bytes = fuzz::described_file(in);
  } else {
    bytes.assign(reinterpret_cast<const char*>(data) + 1, size - 1);
  }
  const auto loaded = core::parse_tsdf(std::move(bytes), "fuzz.vdb");
  if (!loaded) {
    TARMAC_FUZZ_CHECK(loaded.error().code.rfind("tsdf_io.", 0) == 0);
    return 0;
  }
  fuzz::check_accepted(loaded.value());
  return 0;
}
