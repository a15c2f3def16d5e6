#include "tarmac/core/mapper.hpp"

#include <limits>

#include <algorithm>

namespace tarmac::core {

namespace {

/// Points per scan the buffers are warmed up for (a 64-beam LiDAR's sweep).
constexpr std::size_t kWarmUpPoints = std::size_t{1} << 17;

/// Sensor-frame points into the world frame, the arithmetic filter_scan uses (float), so a scan
/// re-integrated from retention lands exactly where a fresh ingest would put it.
void transform_points(const Eigen::Isometry3d& T_W_S, std::span<const Eigen::Vector3f> points_S,
                      std::vector<Eigen::Vector3f>& points_W) {
  const Eigen::Matrix3f R_W_S = T_W_S.linear().cast<float>();
  const Eigen::Vector3f t_W_S = T_W_S.translation().cast<float>();
  points_W.resize(points_S.size());
  for (std::size_t i = 0; i < points_S.size(); ++i) points_W[i] = R_W_S * points_S[i] + t_W_S;
}

/// Rotates the directions of beams without return into the world frame (float, like the points).
void rotate_directions(const Eigen::Isometry3d& T_W_S, std::span<const Eigen::Vector3f> dirs_S,
                       std::vector<Eigen::Vector3f>& dirs_W) {
  const Eigen::Matrix3f R_W_S = T_W_S.linear().cast<float>();
  dirs_W.resize(dirs_S.size());
  for (std::size_t i = 0; i < dirs_S.size(); ++i) dirs_W[i] = R_W_S * dirs_S[i];
}

/// The ground's height relative to the sensor (along `up`, so negative), from the scan's own
/// returns: the median height of the returns of descending beams between 2 and 30 m away
/// horizontally, most of which, on an apron or a road, are the ground; obstacles among them
/// only raise it (a conservative error below). Without 32 such returns: the base frame's plane.
/// Deterministic: a function of the scan and its pose.
double ground_below_sensor(const Eigen::Isometry3d& T_W_B, const Eigen::Vector3d& sensor_W,
                           std::span<const Eigen::Vector3f> points_W, std::vector<float>& heights) {
  const Eigen::Vector3d up = T_W_B.linear().col(2);
  heights.clear();
  for (const Eigen::Vector3f& p : points_W) {
    if (!p.allFinite()) continue;
    const Eigen::Vector3d rel = p.cast<double>() - sensor_W;
    const double h = up.dot(rel);
    const double planar_sq = rel.squaredNorm() - h * h;
    if (h < 0.0 && planar_sq >= 4.0 && planar_sq <= 900.0) heights.push_back(static_cast<float>(h));
  }
  if (heights.size() < 32) return up.dot(T_W_B.translation() - sensor_W);
  const auto mid = heights.begin() + static_cast<std::ptrdiff_t>(heights.size() / 2);
  std::nth_element(heights.begin(), mid, heights.end());
  return *mid;
}

/// A beam without a return that descends to the ground within the clearing range would have
/// returned from it: its return was lost, on a dark, wet or specular spot of the ground or of
/// something standing on it (real sensors lose a few per cent so). It shows nothing, not even
/// the air along it: clearing that air would erase what the lost return stood on, an obstacle
/// seen by too few returns yet to read occupied (the low edge of a fuselage at 18 m), and below
/// the horizon every voxel it crosses is one a return would show. Such beams are dropped; one
/// that meets the ground only beyond the clearing range clears its whole range, as one above the
/// horizon does. The ground here is a plane normal to the base frame's z axis ("up" for the
/// costmap too) at `ground_h` along it from the sensor (ground_below_sensor). Returns the
/// number dropped.
std::uint64_t clip_at_ground(const Eigen::Vector3d& up, double ground_h, double clear_range_m,
                             std::vector<Eigen::Vector3f>& dirs_W) {
  if (!(clear_range_m > 0.0)) return 0;
  const double above = -ground_h;  // the sensor's height over the plane
  std::uint64_t dropped = 0;
  std::size_t kept = 0;
  for (const Eigen::Vector3f& d : dirs_W) {
    const double descent = -up.dot(d.cast<double>());  // per metre along the (unit) beam
    if (descent > 0.0 && above < descent * clear_range_m) {
      ++dropped;
      continue;
    }
    dirs_W[kept++] = d;
  }
  dirs_W.resize(kept);
  return dropped;
}

/// Ends each beam without return (unit directions in `dirs_W`, from `origin_W`) before the first
/// voxel `map` holds occupied, as the map stood before this scan: a lost return on a surface
/// sends its beam on through it, and what lies behind a surface the map knows was not seen (the
/// unknown inside a fuselage marked free would leave its belly's voxel with free space above and
/// below, no longer an underside, and the rays passing under it would empty it). Each direction
/// is scaled to the share of `clear_range_m` it clears (OccupancyMap::integrate); one that would
/// clear less than a voxel is dropped. Reads only, each beam on its own: the same for any
/// runner. `scale` and `sky` are scratch. Returns the number shortened or dropped.
std::uint64_t stop_at_occupied(const OccupancyMap& map, const Eigen::Vector3d& origin_W,
                               double clear_range_m, double voxel_m,
                               std::vector<Eigen::Vector3f>& dirs_W, std::vector<float>& scale,
                               SkyHorizon& sky, TaskRunner& runner) {
  if (!(clear_range_m > 0.0) || dirs_W.empty()) return 0;
  const std::size_t n = dirs_W.size();
  scale.assign(n, 1.0f);
  constexpr std::size_t kChunk = 512;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  const VoxelIndex origin_voxel = map.voxel_of(origin_W);
  // Most beams without return point at the sky: those above everything the map holds over
  // their sector need no walk (SkyHorizon; the answer is the walk's).
  map.sky_horizon(origin_W, sky);
  runner.parallel_for(chunks, [&](std::size_t c) {
    for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
      const Eigen::Vector3d dir = dirs_W[i].cast<double>();
      if (sky.clears(dir)) continue;
      const double t = map.first_occupied(origin_W, origin_voxel, dir, clear_range_m);
      if (t < clear_range_m) scale[i] = static_cast<float>(t / clear_range_m);
    }
  });
  std::uint64_t stopped = 0;
  std::size_t kept = 0;
  const double min_share = voxel_m / clear_range_m;
  for (std::size_t i = 0; i < n; ++i) {
    if (scale[i] < 1.0f) ++stopped;
    if (scale[i] < min_share) continue;
    dirs_W[kept++] = dirs_W[i] * scale[i];
  }
  dirs_W.resize(kept);
  return stopped;
}

/// Keeps the usable directions of beams without return, normalised, in `out`; counts both.
void accept_no_returns(std::span<const Eigen::Vector3f> dirs_S, std::vector<Eigen::Vector3f>& out,
                       FilterCounts& counts) {
  out.clear();
  for (const Eigen::Vector3f& d : dirs_S) {
    const float n = d.norm();
    if (!(n >= 0.5f && n <= 2.0f)) {  // NaN fails too
      ++counts.no_returns_refused;
      continue;
    }
    out.push_back(d / n);
  }
  counts.no_returns = out.size();
}

}  // namespace

Status MapperParams::validate() const {
  if (auto s = filters.validate(); !s) return s;
  if (auto s = occupancy.validate(); !s) return s;
  if (auto s = tsdf.validate(); !s) return s;
  if (auto s = corrections.validate(); !s) return s;
  if (auto s = esdf_band.validate(); !s) return s;
  if (auto s = debris.validate(); !s) return s;
  if (esdf_band.enabled) {
    const double top_m = occupancy.window_z_vox * occupancy.voxel_size_m - occupancy.window_below_m;
    if (esdf_band.below_m > occupancy.window_below_m) {
      return Error{"config.range",
                   "esdf_band.below_m: reaches below the window (occupancy.window_below_m)"};
    }
    if (esdf_band.above_m > top_m) {
      return Error{"config.range", "esdf_band.above_m: reaches above the window's top (" +
                                       std::to_string(top_m) + " m above the base)"};
    }
  }
  return costmap.validate();
}

namespace {
/// The occupancy parameters with the low objects' rise threshold taken from the costmap's: one
/// setting says what height above the ground blocks.
OccupancyParams occupancy_params(const MapperParams& params) {
  OccupancyParams p = params.occupancy;
  p.low_objects.min_rise_m =
      std::clamp(params.costmap.min_obstacle_height_m, 0.01, p.low_objects.max_rise_m);
  return p;
}
}  // namespace

Mapper::Mapper(const MapperParams& params)
    : params_(params),
      map_(occupancy_params(params)),
      tsdf_integrator_(params.tsdf),
      tsdf_(tsdf_integrator_.make_layer()) {
  TARMAC_ASSERT(params.validate().ok(), "MapperParams must be validated first");
  if (params.corrections.enabled) {
    retained_.resize(static_cast<std::size_t>(params.corrections.retain_scans));
    spare_ = std::make_unique<OccupancyMap>(occupancy_params(params));
  }
  // Warm-up, so the first cycle costs what the others do: the per-point buffers sized for a
  // 64-beam scan and written once, and one costmap of the empty window (all unknown: it sizes
  // and writes every costmap and 2D ESDF buffer; the first update_costmap() replaces it).
  filter_scratch_.reserve(kWarmUpPoints, params.filters);
  points_W_.assign(kWarmUpPoints, Eigen::Vector3f::Zero());
  points_W_.clear();
  clearing_W_.reserve(kWarmUpPoints / 2);  // an organised 64 x 1024 sweep into the open sky
  no_return_scratch_S_.reserve(kWarmUpPoints / 2);
  no_return_scale_.reserve(kWarmUpPoints / 2);
  ground_heights_.reserve(kWarmUpPoints);
  SerialRunner serial;
  build_costmap(map_, params_.costmap, T_W_B_, {}, 0, layers_, serial);
  const auto objects = static_cast<std::size_t>(params_.occupancy.low_objects.capacity);
  debris_scratch_.reserve(objects, layers_.column_class.cells().size());
  debris_.reserve(objects);
  // The 3D band likewise (about 50 MB of states, scratch and field at the default window).
  if (params_.esdf_band.enabled) {
    build_esdf_band(map_, layers_, params_.costmap, params_.esdf_band, T_W_B_, {}, 0, band_,
                    serial);
  }
}

FilteredScan Mapper::ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                            const Eigen::Isometry3d& T_B_S, const ScanMotion* motion) {
  SerialRunner serial;
  return ingest(cloud, T_W_B, T_B_S, serial, motion);
}

FilteredScan Mapper::ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                            const Eigen::Isometry3d& T_B_S, TaskRunner& runner,
                            const ScanMotion* motion) {
  const Eigen::Isometry3d T_W_S = T_W_B * T_B_S;
  sensor_W_ = T_W_S.translation();
  T_W_B_ = T_W_B;
  // Filters in the sensor frame (none of them depends on the pose), so the survivors can be
  // retained for a rebuild and re-integrated with the same float transform (transform_points).
  // With a motion, the sweep is first deskewed into the sensor frame at the stamp.
  // First the sweep as beams (organise()), on a copy: the caller's cloud stays as it came.
  const PointCloud* source = &cloud;
  SweepLayout layout = SweepLayout::kUnorganised;
  if (!cloud.organised && (cloud.grid_rows > 0 || cloud.has_ring()) && cloud.consistent()) {
    organised_ = cloud;
    layout = organise(organised_, organise_scratch_).layout;
    source = &organised_;
  }
  const PointCloud* input = source;
  if (motion != nullptr && source->has_time() && source->consistent() &&
      motion->t1_s > motion->t0_s) {
    deskewed_.stamp_ns = cloud.stamp_ns;
    deskew_points(*source, *motion, T_W_B, T_B_S, deskewed_.points_S);
    input = &deskewed_;
  }
  // The survivors in the world frame, and, when scans are retained, straight into the slot this
  // scan takes in the sensor frame (nothing reads a slot's points between here and below).
  FilterCounts counts =
      filter_scan(*input, T_W_S, T_B_S, params_.filters, points_W_, filter_scratch_, runner,
                  retained_.empty() ? nullptr : &retained(next_seq_).points_S);
  std::vector<Eigen::Vector3f>& no_return_S =
      retained_.empty() ? no_return_scratch_S_ : retained(next_seq_).no_return_S;
  accept_no_returns(source->no_return_S, no_return_S, counts);
  counts.layout_undecided = layout == SweepLayout::kUndecided ? 1 : 0;
  rotate_directions(T_W_S, no_return_S, clearing_W_);
  counts.no_returns_grounded = clip_at_ground(
      T_W_B.linear().col(2), ground_below_sensor(T_W_B, sensor_W_, points_W_, ground_heights_),
      params_.occupancy.clearing_range_m, clearing_W_);
  counts.no_returns_stopped =
      stop_at_occupied(map_, sensor_W_, params_.occupancy.clearing_range_m,
                       params_.occupancy.voxel_size_m, clearing_W_, no_return_scale_, sky_, runner);
  if (!retained_.empty()) {
    if (rebuilding_ && next_seq_ >= retained_.size() &&
        cursor_seq_ <= next_seq_ - retained_.size()) {
      // The slot about to be overwritten has not been re-integrated yet: it rolls out.
      correction_stats_.scans_rolled_out += next_seq_ - retained_.size() + 1 - cursor_seq_;
      cursor_seq_ = next_seq_ - retained_.size() + 1;
    }
    RetainedScan& slot = retained(next_seq_);
    slot.stamp_ns = cloud.stamp_ns;
    slot.T_W_B = T_W_B;
    slot.T_B_S = T_B_S;
    slot.tsdf_wanted = false;
    slot.tsdf_done = false;
    slot.tsdf_blocks.clear();
    ++next_seq_;
  }
  return FilteredScan{cloud.stamp_ns, T_W_B, sensor_W_, points_W_, clearing_W_, counts};
}

bool Mapper::is_last_ingested(const FilteredScan& scan) const {
  return scan.points_W.data() == points_W_.data() && scan.points_W.size() == points_W_.size() &&
         scan.clearing_W.data() == clearing_W_.data() &&
         scan.clearing_W.size() == clearing_W_.size();
}

void Mapper::reserve_scans(std::size_t points_per_scan) {
  if (params_.tsdf.enabled) {
    tsdf_integrator_.reserve_scan(points_per_scan);
    tsdf_integrator_.reserve_layer(tsdf_);
  }
  for (auto& r : retained_) {
    r.points_S.reserve(points_per_scan);
    r.no_return_S.reserve(points_per_scan);  // an organised sweep: returns + beams without
  }
}

std::size_t Mapper::top_up_tsdf_spares(std::size_t max_blocks) {
  // Nodes first: a missing node costs a new block's scan eight times a missing block.
  const TsdfSpareCount missing = tsdf_spare_shortfall();
  TsdfSpareCount n;
  std::size_t budget = max_blocks;
  n.top_nodes = std::min(missing.top_nodes, budget / TsdfSpareCount::kTopNodeBlocks);
  budget -= TsdfSpareCount::kTopNodeBlocks * n.top_nodes;
  n.nodes = std::min(missing.nodes, budget / TsdfSpareCount::kNodeBlocks);
  budget -= TsdfSpareCount::kNodeBlocks * n.nodes;
  n.blocks = std::min(missing.blocks, budget);
  if (!n.empty()) tsdf_integrator_.add_spares(TsdfSpareBlocks::build(params_.tsdf, n));
  return n.block_equivalents();
}

OccupancyUpdate Mapper::integrate(const FilteredScan& scan, TaskRunner& runner) {
  TARMAC_ASSERT(is_last_ingested(scan), "Mapper::integrate takes the last ingest()'s scan");
  map_.recenter(scan.T_W_B.translation(), runner);
  map_.set_observation_stamp(scan.stamp_ns);
  return map_.integrate(scan.sensor_W, scan.points_W, scan.clearing_W, runner,
                        scan.T_W_B.linear().col(2));
}

const TsdfUpdate& Mapper::integrate_tsdf(const FilteredScan& scan, TaskRunner& runner) {
  if (!params_.tsdf.enabled) return no_tsdf_update_;
  // The retained slot marked below is the last ingested scan's.
  TARMAC_ASSERT(is_last_ingested(scan), "Mapper::integrate_tsdf takes the last ingest()'s scan");
  if (retained_.empty() || next_seq_ == 0) {
    return tsdf_integrator_.integrate(scan.sensor_W, scan.points_W, tsdf_, runner);
  }
  RetainedScan& slot = retained(next_seq_ - 1);
  slot.tsdf_wanted = true;
  // During a rebuild the TSDF is integrated by rebuild_step(), in stamp order.
  if (rebuilding_) return no_tsdf_update_;
  const TsdfUpdate& update =
      tsdf_integrator_.integrate(scan.sensor_W, scan.points_W, tsdf_, runner);
  record_tsdf(slot, update);
  return update;
}

void Mapper::record_tsdf(RetainedScan& scan, const TsdfUpdate& update) {
  scan.tsdf_blocks.assign(update.blocks.begin(), update.blocks.end());
  scan.tsdf_done = true;
}

const CostmapLayers& Mapper::update_costmap(const Eigen::Isometry3d& T_W_B,
                                            std::span<const VirtualZone> zones,
                                            std::int64_t stamp_ns, TaskRunner& runner) {
  build_costmap(map_, params_.costmap, T_W_B, zones, stamp_ns, layers_, runner);
  extract_debris(map_.low_objects(), layers_, params_.debris, debris_scratch_, debris_);
  return layers_;
}

void Mapper::track_fleet_observations() {
  const double v = params_.occupancy.voxel_size_m;
  const double below = params_.occupancy.window_below_m;
  const CostmapParams& c = params_.costmap;
  const int lo = static_cast<int>(std::floor((below - c.ground_tolerance_m) / v));
  const int hi = static_cast<int>(std::floor((below + c.vehicle_height_m + c.clearance_m) / v));
  map_.track_column_observations(lo, hi);
  // The window a pose correction rebuilds replaces this one: it keeps the times too.
  if (spare_) spare_->track_column_observations(lo, hi);
}

const CostmapLayers& Mapper::update_costmap(const Eigen::Isometry3d& T_W_B,
                                            std::span<const VirtualZone> zones,
                                            std::int64_t stamp_ns, TaskRunner& runner,
                                            const BevPeers* peers, BevFusionCounts& counts) {
  map_.export_column_observed(column_observed_);
  CostmapPeers fleet{peers, column_observed_, stamp_ns, {}};
  build_costmap(map_, params_.costmap, T_W_B, zones, stamp_ns, layers_, runner, &fleet);
  extract_debris(map_.low_objects(), layers_, params_.debris, debris_scratch_, debris_);
  counts = std::move(fleet.counts);
  return layers_;
}

BevSnapshot Mapper::fleet_snapshot() {
  const std::vector<std::uint8_t>& own = layers_.own_column_class;
  const GridGeometry2D& g = layers_.costmap.geometry();
  if (own.size() != g.cell_count() || column_observed_.size() != g.cell_count()) {
    // No update_costmap() with peers yet: nothing of one's own to share.
    return BevSnapshot{GridGeometry2D{0.0, 0.0, params_.occupancy.voxel_size_m, 0, 0}, {}, {}};
  }
  own_cells_.resize(own.size());
  for (std::size_t i = 0; i < own.size(); ++i) {
    const auto c = static_cast<ColumnClass>(own[i]);
    own_cells_[i] = c == ColumnClass::kFree       ? BevState::kFree
                    : c == ColumnClass::kObstacle ? BevState::kOccupied
                                                  : BevState::kUnknown;
  }
  return BevSnapshot{g, own_cells_, column_observed_};
}

const EsdfBand& Mapper::update_esdf_band(const Eigen::Isometry3d& T_W_B,
                                         std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                                         TaskRunner& runner) {
  if (params_.esdf_band.enabled) {
    build_esdf_band(map_, layers_, params_.costmap, params_.esdf_band, T_W_B, zones, stamp_ns,
                    band_, runner);
  }
  return band_;
}

std::size_t Mapper::retained_scans() const {
  return static_cast<std::size_t>(std::min<std::uint64_t>(next_seq_, retained_.size()));
}

std::uint64_t Mapper::oldest_seq() const {
  return next_seq_ - retained_scans();
}

void Mapper::retained_poses(std::vector<StampedPose>& out) const {
  out.clear();
  for (std::uint64_t s = oldest_seq(); s < next_seq_; ++s) {
    const RetainedScan& r = retained_[s % retained_.size()];
    out.push_back({r.stamp_ns, r.T_W_B});
  }
}

std::uint64_t Mapper::correct_rigid(const Eigen::Isometry3d& delta, std::int64_t before_stamp_ns) {
  std::uint64_t revised = 0;
  for (std::uint64_t s = oldest_seq(); s < next_seq_; ++s) {
    RetainedScan& r = retained(s);
    if (r.stamp_ns >= before_stamp_ns) continue;
    r.T_W_B = delta * r.T_W_B;
    ++revised;
  }
  if (revised == 0) {
    ++correction_stats_.corrections_empty;
    return 0;
  }
  schedule_rebuild(before_stamp_ns);
  return revised;
}

std::uint64_t Mapper::correct_trajectory(std::span<const StampedPose> trajectory_W_B) {
  std::uint64_t revised = 0;
  for (std::uint64_t s = oldest_seq(); s < next_seq_; ++s) {
    RetainedScan& r = retained(s);
    if (const auto T = interpolate_pose(trajectory_W_B, r.stamp_ns)) {
      r.T_W_B = *T;
      ++revised;
    }
  }
  if (revised == 0) {
    ++correction_stats_.corrections_empty;
    return 0;
  }
  schedule_rebuild(trajectory_W_B.back().stamp_ns + 1);
  return revised;
}

void Mapper::schedule_rebuild(std::int64_t from_stamp_ns) {
  ++correction_stats_.corrections;
  // A correction during a rebuild restarts it: what was re-integrated so far used older poses.
  rebuilding_ = false;
  pending_from_stamp_ns_ =
      pending_ ? std::max(pending_from_stamp_ns_, from_stamp_ns) : from_stamp_ns;
  pending_ = true;
  // The costmap's vehicle pose is the newest scan's: revised with it.
  T_W_B_ = retained(next_seq_ - 1).T_W_B;
}

void Mapper::start_rebuild() {
  if (params_.tsdf.enabled) {
    // Erase what the retained scans put into the TSDF under their old poses; rebuild_step()
    // re-integrates them with the revised ones.
    for (std::uint64_t s = oldest_seq(); s < next_seq_; ++s) {
      RetainedScan& r = retained(s);
      if (!r.tsdf_done) continue;
      correction_stats_.tsdf_blocks_erased += tsdf_.erase_blocks(r.tsdf_blocks);
      r.tsdf_done = false;
      r.tsdf_blocks.clear();
    }
  }
  spare_->reset();
  cursor_seq_ = oldest_seq();
  rebuilding_ = true;
  pending_ = false;
  ++correction_stats_.rebuilds_started;
}

RebuildStep Mapper::rebuild_step(TaskRunner& runner) {
  RebuildStep step;
  // A scheduled rebuild starts once a scan stamped at or after the correction's stamp is in:
  // every scan before it that will ever be integrated is then retained, whatever the order in
  // which the correction and the scans arrived.
  if (pending_ && next_seq_ > 0 && retained(next_seq_ - 1).stamp_ns >= pending_from_stamp_ns_) {
    start_rebuild();
  }
  if (!rebuilding_) return step;
  const std::uint64_t quota = params_.corrections.rebuild_points_per_cycle;
  while (cursor_seq_ < next_seq_) {
    RetainedScan& r = retained(cursor_seq_);
    const std::uint64_t n = r.points_S.size();
    // At least two scans per step: one for the scan just ingested, one to catch up, so a
    // rebuild always completes within retain_scans steps whatever the quota.
    if (quota != 0 && step.scans >= 2 && step.points + n > quota) break;
    const Eigen::Isometry3d T_W_S = r.T_W_B * r.T_B_S;
    transform_points(T_W_S, r.points_S, rebuild_points_W_);
    rotate_directions(T_W_S, r.no_return_S, rebuild_clearing_W_);
    clip_at_ground(
        r.T_W_B.linear().col(2),
        ground_below_sensor(r.T_W_B, T_W_S.translation(), rebuild_points_W_, ground_heights_),
        params_.occupancy.clearing_range_m, rebuild_clearing_W_);
    stop_at_occupied(*spare_, T_W_S.translation(), params_.occupancy.clearing_range_m,
                     params_.occupancy.voxel_size_m, rebuild_clearing_W_, no_return_scale_, sky_,
                     runner);
    spare_->recenter(r.T_W_B.translation());
    spare_->set_observation_stamp(r.stamp_ns);
    spare_->integrate(T_W_S.translation(), rebuild_points_W_, rebuild_clearing_W_, runner,
                      r.T_W_B.linear().col(2));
    if (params_.tsdf.enabled && r.tsdf_wanted) {
      record_tsdf(
          r, tsdf_integrator_.integrate(T_W_S.translation(), rebuild_points_W_, tsdf_, runner));
    }
    step.points += n;
    ++step.scans;
    ++cursor_seq_;
  }
  correction_stats_.scans_reintegrated += step.scans;
  if (cursor_seq_ == next_seq_) {
    std::swap(map_, *spare_);
    rebuilding_ = false;
    step.completed = true;
    ++correction_stats_.rebuilds_completed;
  }
  return step;
}

void Mapper::rebuild_sensors(std::vector<Eigen::Vector3d>& out) const {
  out.clear();
  if (!rebuilding()) return;
  for (std::uint64_t s = rebuilding_ ? cursor_seq_ : oldest_seq(); s < next_seq_; ++s) {
    const RetainedScan& r = retained(s);
    if (r.tsdf_wanted) out.push_back((r.T_W_B * r.T_B_S).translation());
  }
}

}  // namespace tarmac::core
