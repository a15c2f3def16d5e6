#include "tarmac/core/tsdf_io.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <tuple>

#include <openvdb/io/Stream.h>

#include "tsdf_grids.hpp"

namespace tarmac::core {

namespace {

constexpr char kMagic[8] = {'T', 'A', 'R', 'M', 'A', 'C', 'v', '1'};
constexpr char kEnd[8] = {'T', 'S', 'D', 'F', '-', 'E', 'N', 'D'};
constexpr std::size_t kTrailerBytes = 32;

std::uint64_t fnv1a(const char* data, std::size_t n) {
  std::uint64_t h = 1469598103934665603ull;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= 1099511628211ull;
  }
  return h;
}

void put_u64(char* out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out[i] = static_cast<char>((v >> (8 * i)) & 0xff);
}
std::uint64_t get_u64(const char* in) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v |= static_cast<std::uint64_t>(static_cast<unsigned char>(in[i])) << (8 * i);
  return v;
}

Error write_error(const std::filesystem::path& file, const std::string& why) {
  return Error{"tsdf_io.write", file.string() + ": " + why};
}

/// Flushes a file (or directory) to the storage device.
bool sync_path(const std::filesystem::path& p, bool directory) {
  const int fd = ::open(p.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
}

template <typename MetaT, typename T>
bool read_meta(const openvdb::MetaMap& meta, const std::string& key, T& out) {
  const auto m = meta.getMetadata<MetaT>(key);
  if (!m) return false;
  out = m->value();
  return true;
}

using FloatLeaf = openvdb::FloatTree::LeafNodeType;
using PairLeaf = TsdfTree::LeafNodeType;

/// The in-memory (distance, weight) grid as the two standard float grids of the file.
void split_grids(const TsdfLayer& layer, openvdb::FloatGrid::Ptr& distance,
                 openvdb::FloatGrid::Ptr& weight) {
  const auto& src = *layer.grids().tsdf;
  distance = openvdb::FloatGrid::create(layer.truncation_m());
  distance->setName("tsdf");
  distance->setGridClass(openvdb::GRID_LEVEL_SET);
  distance->setTransform(src.transform().copy());
  weight = openvdb::FloatGrid::create(0.0f);
  weight->setName("weight");
  weight->setTransform(src.transform().copy());
  openvdb::tree::ValueAccessor<openvdb::FloatTree> da(distance->tree()), wa(weight->tree());
  for (auto leaf = src.tree().cbeginLeaf(); leaf; ++leaf) {
    auto dl = std::make_unique<FloatLeaf>(leaf->origin(), layer.truncation_m(), false);
    auto wl = std::make_unique<FloatLeaf>(leaf->origin(), 0.0f, false);
    for (openvdb::Index n = 0; n < PairLeaf::SIZE; ++n) {
      const auto& v = leaf->getValue(n);
      dl->setValueOnly(n, v[0]);
      wl->setValueOnly(n, v[1]);
      if (leaf->isValueOn(n)) {
        dl->setActiveState(n, true);
        wl->setActiveState(n, true);
      }
    }
    da.addLeaf(dl.release());
    wa.addLeaf(wl.release());
  }
}

/// The file's two float grids merged into the in-memory grid; false when a weight leaf is missing.
bool merge_grids(const openvdb::FloatGrid& distance, const openvdb::FloatGrid& weight,
                 TsdfLayer& layer) {
  TsdfTree& tree = layer.grids().tsdf->tree();
  openvdb::tree::ValueAccessor<TsdfTree> acc(tree);
  openvdb::tree::ValueAccessor<const openvdb::FloatTree> wa(weight.tree());
  const TsdfTree::ValueType background(layer.truncation_m(), 0.0f);
  for (auto dl = distance.tree().cbeginLeaf(); dl; ++dl) {
    const FloatLeaf* wl = wa.probeConstLeaf(dl->origin());
    if (wl == nullptr) return false;
    auto leaf = std::make_unique<PairLeaf>(dl->origin(), background, false);
    for (openvdb::Index n = 0; n < FloatLeaf::SIZE; ++n) {
      if (!dl->isValueOn(n)) continue;
      leaf->setValueOn(n, TsdfTree::ValueType(dl->getValue(n), wl->getValue(n)));
    }
    acc.addLeaf(leaf.release());
  }
  return true;
}

}  // namespace

Status save_tsdf(const std::filesystem::path& file, const TsdfLayer& layer, TsdfMapInfo info,
                 const StaticOccupancy* occupancy) {
  openvdb::initialize();
  info.voxel_size_m = layer.voxel_size_m();
  info.truncation_m = layer.truncation_m();
  std::filesystem::path tmp = file;
  tmp += ".tmp";
  try {
    openvdb::MetaMap meta;
    meta.insertMeta("tarmac.format_version", openvdb::Int32Metadata(kTsdfFileVersion));
    meta.insertMeta("tarmac.frame_id", openvdb::StringMetadata(info.frame_id));
    meta.insertMeta("tarmac.voxel_size_m", openvdb::FloatMetadata(info.voxel_size_m));
    meta.insertMeta("tarmac.truncation_m", openvdb::FloatMetadata(info.truncation_m));
    meta.insertMeta("tarmac.config_hash", openvdb::StringMetadata(info.config_hash));
    meta.insertMeta("tarmac.stamp_ns", openvdb::Int64Metadata(info.stamp_ns));
    openvdb::FloatGrid::Ptr distance, weight;
    split_grids(layer, distance, weight);
    openvdb::GridCPtrVec grids{distance, weight};
    if (occupancy != nullptr && occupancy->voxel_size_m > 0.0f) {
      meta.insertMeta("tarmac.static_voxel_size_m",
                      openvdb::FloatMetadata(occupancy->voxel_size_m));
      auto mask = openvdb::BoolGrid::create(false);
      mask->setName("static_occupancy");
      mask->setTransform(tsdf_transform(occupancy->voxel_size_m));
      openvdb::tree::ValueAccessor<openvdb::BoolTree> acc(mask->tree());
      for (const Eigen::Vector3i& v : occupancy->voxels) {
        acc.setValueOn(openvdb::Coord(v.x(), v.y(), v.z()), true);
      }
      grids.push_back(mask);
    }
    openvdb::io::File out(tmp.string());
    // Blosc is ~10x faster than zlib here; integrity comes from the trailer's checksum.
    const std::uint32_t codec = openvdb::io::Archive::hasBloscCompression()
                                    ? openvdb::io::COMPRESS_BLOSC
                                    : openvdb::io::COMPRESS_ZIP;
    out.setCompression(codec | openvdb::io::COMPRESS_ACTIVE_MASK);
    out.write(grids, meta);
    out.close();
  } catch (const std::exception& e) {
    std::error_code ec;
    std::filesystem::remove(tmp, ec);
    return write_error(tmp, std::string("OpenVDB write failed: ") + e.what());
  }
  // Trailer: length and checksum of the .vdb bytes.
  {
    std::ifstream in(tmp, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    const std::string body = bytes.str();
    if (!in.good() && !in.eof()) return write_error(tmp, "cannot be read back");
    char trailer[kTrailerBytes];
    std::memcpy(trailer, kMagic, 8);
    put_u64(trailer + 8, body.size());
    put_u64(trailer + 16, fnv1a(body.data(), body.size()));
    std::memcpy(trailer + 24, kEnd, 8);
    std::ofstream app(tmp, std::ios::binary | std::ios::app);
    app.write(trailer, kTrailerBytes);
    app.close();
    if (!app) return write_error(tmp, "cannot append the trailer");
  }
  if (!sync_path(tmp, false)) return write_error(tmp, "fsync failed");
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) return write_error(file, "rename failed: " + ec.message());
  const auto dir = file.has_parent_path() ? file.parent_path() : std::filesystem::path(".");
  sync_path(dir, true);  // best effort: the rename is atomic either way
  return Ok{};
}

Result<LoadedTsdf> load_tsdf(const std::filesystem::path& file) {
  const std::string name = file.string();
  std::ifstream in(file, std::ios::binary);
  if (!in) return Error{"tsdf_io.open", name + ": cannot be read"};
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return parse_tsdf(std::move(bytes).str(), name);
}

Result<LoadedTsdf> parse_tsdf(std::string data, const std::string& name) {
  if (data.size() < kTrailerBytes || std::memcmp(data.data() + data.size() - 8, kEnd, 8) != 0 ||
      std::memcmp(data.data() + data.size() - kTrailerBytes, kMagic, 8) != 0) {
    return Error{"tsdf_io.truncated",
                 name + ": no tarmac end marker (truncated, or not written by tarmac)"};
  }
  const char* trailer = data.data() + data.size() - kTrailerBytes;
  const std::uint64_t length = get_u64(trailer + 8);
  if (length != data.size() - kTrailerBytes) {
    return Error{"tsdf_io.corrupt", name + ": length field says " + std::to_string(length) +
                                        " bytes, file holds " +
                                        std::to_string(data.size() - kTrailerBytes)};
  }
  if (fnv1a(data.data(), length) != get_u64(trailer + 16)) {
    return Error{"tsdf_io.corrupt", name + ": checksum mismatch (the file was damaged)"};
  }
  data.resize(length);

  openvdb::initialize();
  TsdfMapInfo info;
  StaticOccupancy occupancy;
  openvdb::FloatGrid::Ptr distance, weight;
  openvdb::BoolGrid::Ptr mask;
  bool has_static_meta = false;
  try {
    std::istringstream stream(std::move(data));
    openvdb::io::Stream vdb(stream, /*delayLoad=*/false);
    const openvdb::MetaMap::Ptr meta = vdb.getMetadata();
    int version = -1;
    if (!meta || !read_meta<openvdb::Int32Metadata>(*meta, "tarmac.format_version", version)) {
      return Error{"tsdf_io.format", name + ": no tarmac.format_version: not a tarmac TSDF"};
    }
    if (version != kTsdfFileVersion) {
      return Error{"tsdf_io.format", name + ": format version " + std::to_string(version) +
                                         ", this build reads " + std::to_string(kTsdfFileVersion)};
    }
    if (!read_meta<openvdb::StringMetadata>(*meta, "tarmac.frame_id", info.frame_id) ||
        !read_meta<openvdb::FloatMetadata>(*meta, "tarmac.voxel_size_m", info.voxel_size_m) ||
        !read_meta<openvdb::FloatMetadata>(*meta, "tarmac.truncation_m", info.truncation_m) ||
        !read_meta<openvdb::StringMetadata>(*meta, "tarmac.config_hash", info.config_hash) ||
        !read_meta<openvdb::Int64Metadata>(*meta, "tarmac.stamp_ns", info.stamp_ns)) {
      return Error{"tsdf_io.format", name + ": incomplete tarmac metadata"};
    }
    has_static_meta = read_meta<openvdb::FloatMetadata>(*meta, "tarmac.static_voxel_size_m",
                                                        occupancy.voxel_size_m);
    for (const auto& g : *vdb.getGrids()) {
      if (g->getName() == "tsdf") distance = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
      if (g->getName() == "weight") weight = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
      if (g->getName() == "static_occupancy") mask = openvdb::gridPtrCast<openvdb::BoolGrid>(g);
    }
  } catch (const std::exception& e) {
    return Error{"tsdf_io.corrupt", name + ": OpenVDB cannot parse it: " + e.what()};
  }
  if (!distance || !weight) {
    return Error{"tsdf_io.format", name + ": float grids 'tsdf' and 'weight' required"};
  }
  if (!(info.voxel_size_m >= 0.01f && info.voxel_size_m <= 2.0f) ||
      !(info.truncation_m > 0.0f && info.truncation_m <= 32.0f * info.voxel_size_m)) {
    return Error{"tsdf_io.corrupt", name + ": implausible voxel size or truncation"};
  }
  if (distance->tree().hasActiveTiles() || weight->tree().hasActiveTiles()) {
    return Error{"tsdf_io.corrupt", name + ": active tiles (a TSDF has voxels only)"};
  }
  if (distance->transform() != *tsdf_transform(info.voxel_size_m) ||
      weight->transform() != distance->transform()) {
    return Error{"tsdf_io.corrupt", name + ": grid transform does not match the voxel size"};
  }
  if (!distance->tree().hasSameTopology(weight->tree())) {
    return Error{"tsdf_io.corrupt", name + ": 'tsdf' and 'weight' topologies differ"};
  }
  // Content: finite distances within the band, finite non-negative weights.
  const float limit = info.truncation_m * (1.0f + 1e-6f);
  for (auto it = distance->tree().cbeginValueOn(); it; ++it) {
    const float d = *it;
    if (!std::isfinite(d) || std::abs(d) > limit) {
      return Error{"tsdf_io.corrupt", name + ": distance out of the truncation band"};
    }
  }
  for (auto it = weight->tree().cbeginValueOn(); it; ++it) {
    if (!std::isfinite(*it) || *it <= 0.0f) {
      return Error{"tsdf_io.corrupt", name + ": invalid weight"};
    }
  }
  if (has_static_meta != (mask != nullptr)) {
    return Error{"tsdf_io.corrupt",
                 name +
                     ": bool grid 'static_occupancy' and tarmac.static_voxel_size_m must come "
                     "together"};
  }
  if (mask) {
    if (!(occupancy.voxel_size_m >= 0.02f && occupancy.voxel_size_m <= 2.0f)) {
      return Error{"tsdf_io.corrupt", name + ": implausible static occupancy voxel size"};
    }
    if (mask->tree().hasActiveTiles() ||
        mask->transform() != *tsdf_transform(occupancy.voxel_size_m)) {
      return Error{"tsdf_io.corrupt",
                   name + ": 'static_occupancy' has tiles or a transform unlike its voxel size"};
    }
    occupancy.voxels.reserve(mask->tree().activeVoxelCount());
    for (auto it = mask->tree().cbeginValueOn(); it; ++it) {
      const openvdb::Coord c = it.getCoord();
      occupancy.voxels.emplace_back(c.x(), c.y(), c.z());
    }
    std::sort(occupancy.voxels.begin(), occupancy.voxels.end(),
              [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
                return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
              });
  } else {
    occupancy.voxel_size_m = 0.0f;
  }
  TsdfLayer layer(info.voxel_size_m, info.truncation_m);
  if (!merge_grids(*distance, *weight, layer)) {
    return Error{"tsdf_io.corrupt", name + ": 'weight' lacks a block that 'tsdf' has"};
  }
  return LoadedTsdf{std::move(layer), std::move(info), std::move(occupancy)};
}

Status check_tsdf_matches(const TsdfMapInfo& info, const std::string& frame_id, float voxel_size_m,
                          float truncation_m) {
  if (info.frame_id != frame_id) {
    return Error{"tsdf_io.mismatch",
                 "map frame '" + info.frame_id + "', expected '" + frame_id + "'"};
  }
  if (info.voxel_size_m != voxel_size_m || info.truncation_m != truncation_m) {
    std::ostringstream os;
    os << "map voxel " << info.voxel_size_m << " m / truncation " << info.truncation_m
       << " m, expected " << voxel_size_m << " m / " << truncation_m << " m";
    return Error{"tsdf_io.mismatch", os.str()};
  }
  return Ok{};
}

Status check_static_occupancy_matches(const StaticOccupancy& occupancy, float voxel_size_m) {
  if (occupancy.voxel_size_m != 0.0f && occupancy.voxel_size_m != voxel_size_m) {
    std::ostringstream os;
    os << "static occupancy voxel " << occupancy.voxel_size_m << " m, expected " << voxel_size_m
       << " m";
    return Error{"tsdf_io.mismatch", os.str()};
  }
  return Ok{};
}

}  // namespace tarmac::core
