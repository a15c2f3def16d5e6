// TsdfParams and TsdfLayer: the OpenVDB grid the integrator writes (tsdf_integrator.cpp) and
// what readers see of it.

#include "tarmac/core/tsdf_integrator.hpp"

#include <cstring>
#include <string>

#include "tarmac/core/assert.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tsdf_grids.hpp"

namespace tarmac::core {

namespace {
using Tree = TsdfTree;
using Leaf = Tree::LeafNodeType;
using Value = Tree::ValueType;  // (distance, weight)
}  // namespace

Status TsdfParams::validate() const {
  const auto bad = [](const std::string& key, const std::string& why) -> Status {
    return Error{"config.range", "tsdf." + key + ": " + why};  // as every *Params::validate
  };
  if (!(voxel_size_m >= 0.01f && voxel_size_m <= 2.0f)) {
    return bad("voxel_size_m", "must be in [0.01, 2] m");
  }
  if (!(truncation_m >= voxel_size_m && truncation_m <= 32.0f * voxel_size_m)) {
    return bad("truncation_m", "must be in [voxel_size_m, 32 * voxel_size_m]");
  }
  if (!(max_weight >= 1.0f && max_weight <= 1e6f)) return bad("max_weight", "must be in [1, 1e6]");
  if (!(max_range_m > 0.0f && max_range_m <= 1000.0f)) {
    return bad("max_range_m", "must be in (0, 1000] m");
  }
  if (reserve_blocks > 10'000'000) return bad("reserve_blocks", "must be in [0, 1e7]");
  if (resident_limit_mb > 1'000'000) return bad("resident_limit_mb", "must be in [0, 1e6]");
  return Ok{};
}

openvdb::math::Transform::Ptr tsdf_transform(float voxel_size_m) {
  auto xform = openvdb::math::Transform::createLinearTransform(static_cast<double>(voxel_size_m));
  xform->postTranslate(openvdb::Vec3d(0.5 * static_cast<double>(voxel_size_m)));
  return xform;
}

void make_tsdf_grids(float voxel_size_m, float truncation_m, TsdfLayer::Grids& grids) {
  grids.tsdf = TsdfGrid::create(Value(truncation_m, 0.0f));
  grids.tsdf->setName("tsdf_weight");
  grids.tsdf->setTransform(tsdf_transform(voxel_size_m));
}

TsdfLayer::TsdfLayer(float voxel_size_m, float truncation_m)
    : voxel_size_m_(voxel_size_m), truncation_m_(truncation_m), grids_(std::make_unique<Grids>()) {
  TARMAC_ASSERT(voxel_size_m > 0.0f && truncation_m > 0.0f, "TsdfLayer needs positive sizes");
  make_tsdf_grids(voxel_size_m, truncation_m, *grids_);
}
TsdfLayer::~TsdfLayer() = default;
TsdfLayer::TsdfLayer(TsdfLayer&&) noexcept = default;
TsdfLayer& TsdfLayer::operator=(TsdfLayer&&) noexcept = default;

std::optional<TsdfVoxel> TsdfLayer::voxel(const TsdfVoxelIndex& v) const {
  const Value x = grids_->tsdf->tree().getValue(openvdb::Coord(v.x(), v.y(), v.z()));
  if (!(x[1] > 0.0f)) return std::nullopt;
  return TsdfVoxel{x[0], x[1]};
}

TsdfVoxelIndex TsdfLayer::voxel_of(const Eigen::Vector3d& p_W) const {
  return (p_W / static_cast<double>(voxel_size_m_)).array().floor().cast<int>();
}

Eigen::Vector3d TsdfLayer::center_of(const TsdfVoxelIndex& v) const {
  return (v.cast<double>().array() + 0.5) * static_cast<double>(voxel_size_m_);
}

std::size_t TsdfLayer::block_count() const {
  return grids_->tsdf->tree().leafCount();
}

std::size_t TsdfLayer::voxel_count() const {
  return grids_->tsdf->tree().activeLeafVoxelCount();
}

std::size_t TsdfLayer::memory_bytes() const {
  return grids_->tsdf->memUsage();
}

void TsdfLayer::for_each_block(const std::function<void(const TsdfBlockView&)>& fn) const {
  for (auto it = grids_->tsdf->tree().cbeginLeaf(); it; ++it) {
    const openvdb::Coord o = it->origin();
    fn(TsdfBlockView{BlockIndex(o.x() >> 3, o.y() >> 3, o.z() >> 3),
                     reinterpret_cast<const TsdfVoxel*>(it->buffer().data())});
  }
}

std::optional<TsdfBlockView> TsdfLayer::find_block(const BlockIndex& b) const {
  const openvdb::Coord o(b.x() * kTsdfBlockEdge, b.y() * kTsdfBlockEdge, b.z() * kTsdfBlockEdge);
  const Leaf* leaf = grids_->tsdf->tree().probeConstLeaf(o);
  if (leaf == nullptr) return std::nullopt;
  return TsdfBlockView{b, reinterpret_cast<const TsdfVoxel*>(leaf->buffer().data())};
}

std::uint64_t TsdfLayer::digest() const {
  // FNV-1a 64 over 32-bit words (coordinates, then distance and weight of every voxel).
  TsdfDigest digest;
  for_each_block([&digest](const TsdfBlockView& b) { digest.add(b); });
  return digest.value();
}

void TsdfLayer::clear() {
  make_tsdf_grids(voxel_size_m_, truncation_m_, *grids_);
  grids_->absent.clear();
  for (auto& cache : grids_->leaf_cache) cache.drop();
}

std::size_t TsdfLayer::erase_blocks(std::span<const BlockIndex> blocks) {
  auto& tree = grids().tsdf->tree();  // grids() drops the integrator's leaf cache
  const auto background = tree.background();
  std::size_t erased = 0;
  for (const BlockIndex& b : blocks) {
    const openvdb::Coord o(b.x() * kTsdfBlockEdge, b.y() * kTsdfBlockEdge, b.z() * kTsdfBlockEdge);
    // The leaf is replaced by an inactive background tile: the block reads as never observed.
    Leaf* leaf = tree.stealNode<Leaf>(o, background, false);
    if (leaf == nullptr) continue;
    grids_->touch(b.x(), b.y(), b.z());
    delete leaf;
    ++erased;
  }
  return erased;
}

TsdfLayer TsdfLayer::clone() const {
  TsdfLayer copy(voxel_size_m_, truncation_m_);
  copy.grids_->tsdf = grids_->tsdf->deepCopy();
  copy.grids_->absent = grids_->absent;
  return copy;
}

TsdfLayer::Grids& TsdfLayer::grids() {
  for (auto& cache : grids_->leaf_cache) cache.drop();
  return *grids_;
}

}  // namespace tarmac::core
