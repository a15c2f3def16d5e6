// Tiles of the TSDF (tsdf_tiles.hpp): moving a tile out of and back into a layer's OpenVDB tree,
// and its byte encoding.

#include "tarmac/core/tsdf_tiles.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <tuple>

#include "tarmac/core/assert.hpp"
#include "tsdf_grids.hpp"

namespace tarmac::core {

namespace {

using Value = TsdfTree::ValueType;
using Mask = TsdfLeaf::NodeMaskType;

constexpr char kMagic[8] = {'T', 'M', 'T', 'S', 'D', 'F', 'T', '1'};
constexpr std::uint32_t kVersion = 1;
/// magic, version, voxel size, truncation, tile (3 × int32), blocks, payload bytes, checksum.
constexpr std::size_t kHeaderBytes = 8 + 4 + 4 + 4 + 12 + 4 + 8 + 8;
constexpr std::size_t kMaskWords = Mask::WORD_COUNT;
enum WeightMode : std::uint8_t { kU8 = 0, kU16 = 1, kF32 = 2 };

std::uint64_t fnv1a(std::span<const std::uint8_t> bytes) {
  std::uint64_t h = 1469598103934665603ull;
  for (const std::uint8_t b : bytes) {
    h ^= b;
    h *= 1099511628211ull;
  }
  return h;
}

std::uint32_t bits(float x) {
  std::uint32_t u;
  std::memcpy(&u, &x, 4);
  return u;
}

openvdb::Coord tile_origin(const TileIndex& t) {
  return {t.x() * kTsdfTileEdge, t.y() * kTsdfTileEdge, t.z() * kTsdfTileEdge};
}

class Writer {
 public:
  explicit Writer(std::vector<std::uint8_t>& out) : out_(out) {}
  template <typename T>
  void put(const T& x) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&x);
    out_.insert(out_.end(), p, p + sizeof(T));
  }

 private:
  std::vector<std::uint8_t>& out_;
};

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> in) : in_(in) {}
  template <typename T>
  bool get(T& x) {
    if (in_.size() - pos_ < sizeof(T)) return false;
    std::memcpy(&x, in_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  [[nodiscard]] std::size_t left() const { return in_.size() - pos_; }

 private:
  std::span<const std::uint8_t> in_;
  std::size_t pos_ = 0;
};

/// The narrowest weight encoding that keeps every stored weight of the block exactly.
WeightMode weight_mode(const Value* values, const Mask& stored) {
  WeightMode mode = kU8;
  for (auto it = stored.beginOn(); it; ++it) {
    const float w = values[it.pos()][1];
    if (!(w >= 0.0f && w <= 65535.0f) || w != static_cast<float>(static_cast<int>(w)) ||
        std::signbit(w)) {
      return kF32;
    }
    if (w > 255.0f) mode = kU16;
  }
  return mode;
}

}  // namespace

struct TsdfTile::Impl {
  std::unique_ptr<TsdfNode> node;
};

TsdfTile::TsdfTile() : impl_(std::make_unique<Impl>()) {}
TsdfTile::~TsdfTile() = default;
TsdfTile::TsdfTile(TsdfTile&&) noexcept = default;
TsdfTile& TsdfTile::operator=(TsdfTile&&) noexcept = default;

std::size_t TsdfTile::block_count() const {
  return impl_ && impl_->node ? impl_->node->leafCount() : 0;
}

void TsdfTile::for_each_block(const std::function<void(const TsdfBlockView&)>& fn) const {
  if (!impl_ || !impl_->node) return;
  for (auto it = impl_->node->cbeginChildOn(); it; ++it) {
    const openvdb::Coord o = it->origin();
    fn(TsdfBlockView{BlockIndex(o.x() >> 3, o.y() >> 3, o.z() >> 3),
                     reinterpret_cast<const TsdfVoxel*>(it->buffer().data())});
  }
}

TsdfTile TsdfTile::clone() const {
  TsdfTile copy;
  copy.index_ = index_;
  if (impl_ && impl_->node) copy.impl_->node = std::make_unique<TsdfNode>(*impl_->node);
  return copy;
}

std::vector<std::uint8_t> TsdfTile::encode(float voxel_size_m, float truncation_m) const {
  const Value background(truncation_m, 0.0f);
  std::vector<std::uint8_t> payload;
  Writer w(payload);
  std::uint32_t blocks = 0;
  if (impl_ && impl_->node) {
    payload.reserve(impl_->node->leafCount() * 1024);
    for (auto it = impl_->node->cbeginChildOn(); it; ++it) {
      const Value* values = it->buffer().data();
      Mask stored;  // voxels whose bits differ from the background's
      for (openvdb::Index i = 0; i < TsdfLeaf::SIZE; ++i) {
        if (bits(values[i][0]) != bits(background[0]) ||
            bits(values[i][1]) != bits(background[1])) {
          stored.setOn(i);
        }
      }
      const WeightMode mode = weight_mode(values, stored);
      w.put(static_cast<std::uint16_t>(it.pos()));
      w.put(static_cast<std::uint8_t>(mode));
      for (std::size_t k = 0; k < kMaskWords; ++k)
        w.put(it->getValueMask().getWord<std::uint64_t>(k));
      for (std::size_t k = 0; k < kMaskWords; ++k) w.put(stored.getWord<std::uint64_t>(k));
      for (auto v = stored.beginOn(); v; ++v) {
        const Value& x = values[v.pos()];
        w.put(bits(x[0]));
        if (mode == kU8) w.put(static_cast<std::uint8_t>(x[1]));
        if (mode == kU16) w.put(static_cast<std::uint16_t>(x[1]));
        if (mode == kF32) w.put(bits(x[1]));
      }
      ++blocks;
    }
  }
  std::vector<std::uint8_t> out;
  out.reserve(kHeaderBytes + payload.size());
  Writer h(out);
  for (const char c : kMagic) h.put(c);
  h.put(kVersion);
  h.put(voxel_size_m);
  h.put(truncation_m);
  h.put(static_cast<std::int32_t>(index_.x()));
  h.put(static_cast<std::int32_t>(index_.y()));
  h.put(static_cast<std::int32_t>(index_.z()));
  h.put(blocks);
  h.put(static_cast<std::uint64_t>(payload.size()));
  h.put(fnv1a(payload));
  out.insert(out.end(), payload.begin(), payload.end());
  return out;
}

Result<TsdfTile> TsdfTile::decode(std::span<const std::uint8_t> bytes, float voxel_size_m,
                                  float truncation_m, const TileIndex& expected) {
  const auto corrupt = [](const std::string& why) -> Error {
    return Error{"tsdf_tile.corrupt", why};
  };
  Reader r(bytes);
  char magic[8];
  for (char& c : magic) {
    if (!r.get(c)) return corrupt("shorter than its header");
  }
  if (std::memcmp(magic, kMagic, 8) != 0) return corrupt("not a tarmac TSDF tile");
  std::uint32_t version = 0, blocks = 0;
  float voxel = 0.0f, trunc = 0.0f;
  std::int32_t t[3];
  std::uint64_t payload_bytes = 0, checksum = 0;
  if (!r.get(version) || !r.get(voxel) || !r.get(trunc) || !r.get(t[0]) || !r.get(t[1]) ||
      !r.get(t[2]) || !r.get(blocks) || !r.get(payload_bytes) || !r.get(checksum)) {
    return corrupt("shorter than its header");
  }
  if (version != kVersion) return corrupt("version " + std::to_string(version));
  if (payload_bytes != r.left()) return corrupt("truncated or padded");
  if (fnv1a(bytes.subspan(kHeaderBytes)) != checksum) return corrupt("checksum mismatch");
  if (bits(voxel) != bits(voxel_size_m) || bits(trunc) != bits(truncation_m)) {
    return Error{"tsdf_tile.mismatch", "written for another voxel size or truncation"};
  }
  if (TileIndex(t[0], t[1], t[2]) != expected) {
    return Error{"tsdf_tile.mismatch", "holds another tile"};
  }
  const Value background(truncation_m, 0.0f);
  TsdfTile tile;
  tile.index_ = expected;
  tile.impl_->node = std::make_unique<TsdfNode>(tile_origin(expected), background, false);
  TsdfNode& node = *tile.impl_->node;
  for (std::uint32_t b = 0; b < blocks; ++b) {
    std::uint16_t pos = 0;
    std::uint8_t mode = 0;
    if (!r.get(pos) || !r.get(mode)) return corrupt("block " + std::to_string(b) + " cut short");
    if (pos >= TsdfNode::NUM_VALUES || mode > kF32 || node.isChildMaskOn(pos)) {
      return corrupt("block " + std::to_string(b) + " malformed");
    }
    auto leaf = std::make_unique<TsdfLeaf>(node.offsetToGlobalCoord(pos), background, false);
    Mask stored;
    for (std::size_t k = 0; k < kMaskWords; ++k) {
      if (!r.get(leaf->getValueMask().getWord<std::uint64_t>(k))) return corrupt("cut short");
    }
    for (std::size_t k = 0; k < kMaskWords; ++k) {
      if (!r.get(stored.getWord<std::uint64_t>(k))) return corrupt("cut short");
    }
    Value* values = leaf->buffer().data();
    for (auto v = stored.beginOn(); v; ++v) {
      std::uint32_t d = 0;
      float weight = 0.0f;
      bool got = r.get(d);
      if (mode == kU8) {
        std::uint8_t x = 0;
        got = got && r.get(x);
        weight = x;
      } else if (mode == kU16) {
        std::uint16_t x = 0;
        got = got && r.get(x);
        weight = x;
      } else {
        std::uint32_t x = 0;
        got = got && r.get(x);
        std::memcpy(&weight, &x, 4);
      }
      if (!got) return corrupt("cut short");
      float distance;
      std::memcpy(&distance, &d, 4);
      values[v.pos()] = Value(distance, weight);
    }
    node.addChild(leaf.release());
  }
  if (r.left() != 0) return corrupt("bytes after the last block");
  return tile;
}

void TsdfDigest::add(const TsdfBlockView& b) {
  const auto word = [this](std::uint32_t x) {
    h_ ^= x;
    h_ *= 1099511628211ull;
  };
  for (int a = 0; a < 3; ++a) word(static_cast<std::uint32_t>(b.block[a]));
  for (int n = 0; n < kTsdfBlockVoxels; ++n) {
    word(bits(b.voxels[n].distance_m));
    word(bits(b.voxels[n].weight));
  }
}

// ---------------------------------------------------------------------------------------------
// The layer's side

std::vector<TsdfTileInfo> TsdfLayer::resident_tiles() const {
  std::vector<TsdfTileInfo> out;
  resident_tiles(out);
  return out;
}

void TsdfLayer::resident_tiles(std::vector<TsdfTileInfo>& out) const {
  out.clear();
  const auto& root = grids_->tsdf->tree().root();
  for (auto top = root.cbeginChildOn(); top; ++top) {
    for (auto node = top->cbeginChildOn(); node; ++node) {
      const openvdb::Coord o = node->origin();
      out.push_back(TsdfTileInfo{TileIndex(o.x() >> 7, o.y() >> 7, o.z() >> 7),
                                 static_cast<std::size_t>(node->leafCount())});
    }
  }
}

std::size_t TsdfLayer::resident_bytes() const {
  std::size_t bytes = 0;
  const auto& root = grids_->tsdf->tree().root();
  for (auto top = root.cbeginChildOn(); top; ++top) {
    for (auto node = top->cbeginChildOn(); node; ++node) {
      bytes += kTsdfTileNodeBytes + kTsdfBlockBytes * node->leafCount();
    }
  }
  return bytes;
}

std::optional<TsdfTile> TsdfLayer::detach_tile(const TileIndex& t) {
  auto& tree = grids().tsdf->tree();  // grids() drops the integrator's leaf cache
  const Value background = tree.background();
  const openvdb::Coord origin = tile_origin(t);
  TsdfNode* node = tree.stealNode<TsdfNode>(origin, background, false);
  if (node == nullptr) return std::nullopt;
  grids_->absent.insert(pack_tile(t.x(), t.y(), t.z()));
  // A top node left without tiles goes too (256 KB each: a long drive would keep one per
  // 410 m square it crossed).
  auto& root = tree.root();
  if (const TsdfTopNode* top = root.probeConstNode<TsdfTopNode>(origin);
      top != nullptr && top->getChildMask().isOff() && top->getValueMask().isOff()) {
    bool background_only = true;
    for (auto it = top->cbeginValueAll(); it && background_only; ++it) {
      background_only = *it == background;
    }
    if (background_only) {
      root.addTile(origin, background, false);
      root.eraseBackgroundTiles();
    }
  }
  TsdfTile tile;
  tile.index_ = t;
  tile.impl_->node.reset(node);
  return tile;
}

std::optional<TsdfTile> TsdfLayer::copy_tile(const TileIndex& t) const {
  const TsdfNode* node = grids_->tsdf->tree().root().probeConstNode<TsdfNode>(tile_origin(t));
  if (node == nullptr) return std::nullopt;
  TsdfTile tile;
  tile.index_ = t;
  tile.impl_->node = std::make_unique<TsdfNode>(*node);
  return tile;
}

void TsdfLayer::attach_tile(TsdfTile&& tile) {
  TARMAC_ASSERT(tile.impl_ && tile.impl_->node, "TsdfLayer::attach_tile needs a tile");
  auto& tree = grids().tsdf->tree();
  const Value background = tree.background();
  const openvdb::Coord origin = tile_origin(tile.index_);
  auto& root = tree.root();
  TsdfTopNode* top = root.probeNode<TsdfTopNode>(origin);
  if (top == nullptr) {
    top = new TsdfTopNode(origin & ~(TsdfTopNode::DIM - 1), background, false);
    root.addChild(top);
  }
  TARMAC_ASSERT(!top->isChildMaskOn(TsdfTopNode::coordToOffset(origin)),
                "TsdfLayer::attach_tile: the tile has resident blocks");
  top->addChild(tile.impl_->node.release());
  tree.clearAllAccessors();
  grids_->absent.erase(pack_tile(tile.index_.x(), tile.index_.y(), tile.index_.z()));
}

void TsdfLayer::mark_absent(const TileIndex& t) {
  grids_->absent.insert(pack_tile(t.x(), t.y(), t.z()));
}

void TsdfLayer::forget_absent(const TileIndex& t) {
  grids_->absent.erase(pack_tile(t.x(), t.y(), t.z()));
}

bool TsdfLayer::is_absent(const TileIndex& t) const {
  return grids_->absent.contains(pack_tile(t.x(), t.y(), t.z()));
}

std::size_t TsdfLayer::absent_count() const {
  return grids_->absent.size();
}

void TsdfLayer::track_touched_tiles(bool on) {
  grids_->track_touched = on;
  if (!on) grids_->touched.clear();
}

void TsdfLayer::take_touched_tiles(std::vector<TileIndex>& out) {
  out.clear();
  for (const std::uint64_t k : grids_->touched) {
    constexpr std::uint64_t m = (std::uint64_t{1} << 21) - 1;
    constexpr int kBias = 1 << 20;
    out.emplace_back(static_cast<int>((k >> 42) & m) - kBias,
                     static_cast<int>((k >> 21) & m) - kBias, static_cast<int>(k & m) - kBias);
  }
  grids_->touched.clear();  // keeps its buckets
  std::sort(out.begin(), out.end(),
            [](const TileIndex& a, const TileIndex& b) { return TileKey::of(a) < TileKey::of(b); });
}

namespace {
constexpr char kStaticMagic[8] = {'T', 'M', 'S', 'T', 'A', 'T', 'C', '1'};
/// magic, version, voxel size, tile (2 × int32), voxels, checksum.
constexpr std::size_t kStaticHeaderBytes = 8 + 4 + 4 + 8 + 4 + 8;
}  // namespace

std::uint64_t static_voxels_digest(std::span<const Eigen::Vector3i> voxels) {
  std::uint64_t h = 1469598103934665603ull;
  for (const Eigen::Vector3i& v : voxels) {
    for (int a = 0; a < 3; ++a) {
      h ^= static_cast<std::uint32_t>(v[a]);
      h *= 1099511628211ull;
    }
  }
  return h;
}

std::vector<std::uint8_t> StaticTile::encode(float voxel_size_m) const {
  std::vector<std::uint8_t> payload;
  payload.reserve(voxels.size() * 6);
  Writer w(payload);
  for (const Eigen::Vector3i& v : voxels) {
    w.put(static_cast<std::uint8_t>(v.x() - index.x() * kStaticTileEdge));
    w.put(static_cast<std::uint8_t>(v.y() - index.y() * kStaticTileEdge));
    w.put(static_cast<std::int32_t>(v.z()));
  }
  std::vector<std::uint8_t> out;
  out.reserve(kStaticHeaderBytes + payload.size());
  Writer h(out);
  for (const char c : kStaticMagic) h.put(c);
  h.put(kVersion);
  h.put(voxel_size_m);
  h.put(static_cast<std::int32_t>(index.x()));
  h.put(static_cast<std::int32_t>(index.y()));
  h.put(static_cast<std::uint32_t>(voxels.size()));
  h.put(fnv1a(payload));
  out.insert(out.end(), payload.begin(), payload.end());
  return out;
}

Result<StaticTile> StaticTile::decode(std::span<const std::uint8_t> bytes, float voxel_size_m,
                                      const StaticTileIndex& expected) {
  const auto corrupt = [](const std::string& why) -> Error {
    return Error{"static_tile.corrupt", why};
  };
  Reader r(bytes);
  char magic[8];
  for (char& c : magic) {
    if (!r.get(c)) return corrupt("shorter than its header");
  }
  if (std::memcmp(magic, kStaticMagic, 8) != 0) return corrupt("not a tarmac static tile");
  std::uint32_t version = 0, count = 0;
  float voxel = 0.0f;
  std::int32_t t[2];
  std::uint64_t checksum = 0;
  if (!r.get(version) || !r.get(voxel) || !r.get(t[0]) || !r.get(t[1]) || !r.get(count) ||
      !r.get(checksum)) {
    return corrupt("shorter than its header");
  }
  if (version != kVersion) return corrupt("version " + std::to_string(version));
  if (r.left() != std::size_t{count} * 6) return corrupt("truncated or padded");
  if (fnv1a(bytes.subspan(kStaticHeaderBytes)) != checksum) return corrupt("checksum mismatch");
  if (bits(voxel) != bits(voxel_size_m)) {
    return Error{"static_tile.mismatch", "written for another voxel size"};
  }
  if (StaticTileIndex(t[0], t[1]) != expected) {
    return Error{"static_tile.mismatch", "holds another tile"};
  }
  // The static layer keys voxels by 21-bit coordinates (|v| < 2^20 voxels, 200 km at 0.2 m).
  constexpr int kReach = 1 << 20;
  if (std::abs(expected.x()) >= kReach / kStaticTileEdge ||
      std::abs(expected.y()) >= kReach / kStaticTileEdge) {
    return corrupt("tile out of range");
  }
  StaticTile tile;
  tile.index = expected;
  tile.voxels.reserve(count);
  const auto order = [](const Eigen::Vector3i& a) { return std::tuple(a.z(), a.y(), a.x()); };
  for (std::uint32_t i = 0; i < count; ++i) {
    std::uint8_t dx = 0, dy = 0;
    std::int32_t z = 0;
    r.get(dx);
    r.get(dy);
    r.get(z);
    if (dx >= kStaticTileEdge || dy >= kStaticTileEdge) return corrupt("voxel out of its tile");
    if (z <= -kReach || z >= kReach) return corrupt("voxel out of range");
    const Eigen::Vector3i v(expected.x() * kStaticTileEdge + dx,
                            expected.y() * kStaticTileEdge + dy, z);
    if (!tile.voxels.empty() && !(order(tile.voxels.back()) < order(v))) {
      return corrupt("voxels out of order");
    }
    tile.voxels.push_back(v);
  }
  return tile;
}

}  // namespace tarmac::core
