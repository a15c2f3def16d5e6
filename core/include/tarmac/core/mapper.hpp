#pragma once
/// @file The per-scan mapping pipeline as the daemon and the offline tools run it:
/// ingest (filters) → integrate (occupancy) → integrate_tsdf → rebuild_step → update_costmap
/// (costmap + 2D ESDF) → update_esdf_band. Each stage is a separate call so the caller can time
/// it and give it a budget (the core has no clock). ingest() returns the filtered scan; the
/// stages after it take that scan and return what they changed.

#include <memory>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/debris.hpp"
#include "tarmac/core/deskew.hpp"
#include "tarmac/core/esdf_band.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/organised_scan.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/pose_correction.hpp"
#include "tarmac/core/scan_filter.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

struct MapperParams {
  FilterParams filters;
  OccupancyParams occupancy;
  CostmapParams costmap;
  TsdfParams tsdf;
  CorrectionParams corrections;
  EsdfBandParams esdf_band;
  DebrisParams debris;  ///< YAML costmap.debris_*

  [[nodiscard]] Status validate() const;
};

/// Pose-correction counters since construction.
struct CorrectionStats {
  std::uint64_t corrections = 0;        ///< corrections that changed a retained pose
  std::uint64_t corrections_empty = 0;  ///< corrections that changed no retained pose (ignored)
  std::uint64_t rebuilds_started = 0;   ///< a correction during a rebuild restarts it
  std::uint64_t rebuilds_completed = 0;
  std::uint64_t scans_reintegrated = 0;
  /// Retained scans that left the ring (a newer scan took their slot) before the rebuild
  /// reached them: the rebuilt window holds the scans retained while it ran.
  std::uint64_t scans_rolled_out = 0;
  std::uint64_t tsdf_blocks_erased = 0;  ///< TSDF blocks cleared for re-integration
};

/// A scan as ingest() leaves it for the stages that follow: where it was taken, its surviving
/// returns and its beams without return in the world frame, and what the filters did. A view
/// into the mapper's buffers, valid until the next ingest().
struct FilteredScan {
  std::int64_t stamp_ns = 0;
  Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();  ///< vehicle base pose at the stamp
  Eigen::Vector3d sensor_W = Eigen::Vector3d::Zero();       ///< the sensor's origin
  std::span<const Eigen::Vector3f> points_W;                ///< filtered returns
  /// Beams without return, directions scaled to the fraction of the clearing range they
  /// clear (unit: all of it; shorter: clipped above the vehicle's ground plane).
  std::span<const Eigen::Vector3f> clearing_W;
  FilterCounts counts;
};

/// What one rebuild_step() did.
struct RebuildStep {
  std::uint64_t scans = 0;   ///< retained scans re-integrated
  std::uint64_t points = 0;  ///< their points
  bool completed = false;    ///< the rebuilt window replaced the live one in this step
};

class Mapper {
 public:
  /// @pre params.validate().ok()
  explicit Mapper(const MapperParams& params);

  /// Stage 1: organises `cloud` (organise(): an organised sweep's cells without a return, an
  /// unorganised sweep's gaps in its rings become beams without return; a layout the data
  /// cannot tell is counted in FilterCounts::layout_undecided), filters it (sensor frame) and
  /// keeps the survivors in the world frame.
  /// T_W_B is the vehicle base pose at the scan stamp, T_B_S the sensor's extrinsic. With
  /// `motion` and per-point times in `cloud`, the points are first motion-compensated into the
  /// sensor frame at the stamp (deskew_points); without either, the sweep is taken as rigid.
  /// The filters run on `runner` (same result for any runner). The cloud's beams without return
  /// (no_return_S) clear free space in integrate(): finite directions of length 0.5..2 are
  /// normalised and kept, others refused (FilterCounts::no_returns_refused).
  FilteredScan ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                      const Eigen::Isometry3d& T_B_S, TaskRunner& runner,
                      const ScanMotion* motion = nullptr);
  /// The same on the calling thread.
  FilteredScan ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                      const Eigen::Isometry3d& T_B_S, const ScanMotion* motion = nullptr);
  /// Sizes, for scans of up to `points_per_scan` points, what would otherwise grow in the first
  /// cycles: every retained-scan slot (corrections.enabled), so the retention ring does not grow
  /// while it first fills, and the TSDF integrator's per-scan scratch (touched, so its page
  /// faults are taken here). The daemon passes quotas.reserve_points_per_scan; a larger scan
  /// grows what it needs once. Not RT-safe (allocates): for start-up.
  void reserve_scans(std::size_t points_per_scan);
  /// TSDF blocks and nodes missing from the spares for tsdf.reserve_blocks (none when the TSDF
  /// is off): new blocks and nodes take spares, and a top-up between scans (top_up_tsdf_spares)
  /// keeps the allocation of what a growing map needs out of integrate_tsdf.
  [[nodiscard]] TsdfSpareCount tsdf_spare_shortfall() const {
    return params_.tsdf.enabled ? tsdf_integrator_.spare_shortfall() : TsdfSpareCount{};
  }
  /// Rebuilds spares missing, up to `max_blocks` block equivalents (TsdfSpareCount), nodes
  /// first (TsdfSpareBlocks::build, then pointer moves); returns the block equivalents built.
  /// Allocates: between ticks or scans, never inside a stage.
  std::size_t top_up_tsdf_spares(std::size_t max_blocks);
  /// Stage 2: moves the window with the vehicle and integrates `scan`; returns the voxels it
  /// updated (counts). @pre `scan` is what the last ingest() returned.
  OccupancyUpdate integrate(const FilteredScan& scan, TaskRunner& runner);
  /// Stage 2b: integrates `scan` into the TSDF (sparse, whole site); returns the blocks it
  /// updated. Empty when tsdf.enabled is false, or during a rebuild (rebuild_step() then
  /// integrates the scan in stamp order). @pre `scan` is what the last ingest() returned.
  const TsdfUpdate& integrate_tsdf(const FilteredScan& scan, TaskRunner& runner);
  /// Stage 3: rebuilds the costmap and the 2D distance map from the window, around the vehicle
  /// base pose `T_W_B` (its ground plane, the seeds of the ground, the ego box: vehicle_pose(),
  /// the newest scan's, for the vehicle's own costmap); returns them.
  const CostmapLayers& update_costmap(const Eigen::Isometry3d& T_W_B,
                                      std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                                      TaskRunner& runner);
  /// Fleet sharing (docs/fleet.md): from now on the window records each column's last
  /// observation in the vehicle's envelope (from ground_tolerance_m below the base to
  /// vehicle_height_m + clearance_m above it), stamped with the scans' stamps.
  void track_fleet_observations();
  /// Stage 3 with peers' cells fused into the classes before inflation (BevPeers::fuse rules);
  /// `peers` may hold none yet. @pre track_fleet_observations() was called.
  const CostmapLayers& update_costmap(const Eigen::Isometry3d& T_W_B,
                                      std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                                      TaskRunner& runner, const BevPeers* peers,
                                      BevFusionCounts& counts);
  /// This vehicle's own cells of the last update_costmap() with peers, for its fleet summary:
  /// the classes before peers and zones, each with its last observation time. Views into the
  /// mapper, valid until its next stage call.
  BevSnapshot fleet_snapshot();

  /// Stage 3b: the 3D ESDF band (esdf_band.hpp) from the window and the costmap of the last
  /// update_costmap() call, around the vehicle base pose `T_W_B` (that call's); returns it
  /// (unchanged when esdf_band.enabled is false).
  const EsdfBand& update_esdf_band(const Eigen::Isometry3d& T_W_B,
                                   std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                                   TaskRunner& runner);

  /// Pose corrections (pose_correction.hpp). With corrections.enabled the mapper retains the
  /// last corrections.retain_scans filtered scans (sensor-frame points, stamp, T_W_B, T_B_S)
  /// in a ring sized at construction. A correction revises the retained poses and schedules a
  /// rebuild, which starts in the first rebuild_step() after a scan stamped at or after the
  /// correction (a jump's stamp; just after a trajectory's end) has been ingested — so the
  /// retained set does not depend on whether the correction arrived before or after the scans
  /// preceding it. The window is then re-integrated from the retained scans, in stamp order,
  /// with their revised poses into a second (spare) window, corrections.rebuild_points_per_cycle
  /// points per rebuild_step() (callers step once per ingested scan); scans ingested meanwhile
  /// join the retention and are integrated into both windows; when the rebuild has caught up,
  /// the rebuilt window replaces the live one. The result equals a fresh mapper fed the
  /// retained scans with the revised poses (the window then holds only what the retained scans
  /// saw: older content is forgotten, unknown).
  /// TSDF (whole site): the blocks the retained scans had updated are erased when the rebuild
  /// starts and the retained scans are re-integrated, in order, by rebuild_step(); TSDF
  /// integration of scans ingested during a rebuild is deferred to it. Content of older scans
  /// in those blocks is lost; the TSDF elsewhere is not moved (counted: tsdf_blocks_erased).
  ///
  /// (b) A rigid correction: T_W_B ← delta · T_W_B for every retained scan stamped before
  /// `before_stamp_ns`. Returns the number of retained scans revised (0: ignored, counted).
  std::uint64_t correct_rigid(const Eigen::Isometry3d& delta, std::int64_t before_stamp_ns);
  /// (a) A corrected trajectory (sorted by stamp): each retained scan within its span gets the
  /// interpolated revised pose; scans outside the span keep theirs. Returns the number revised.
  std::uint64_t correct_trajectory(std::span<const StampedPose> trajectory_W_B);
  /// Starts a scheduled rebuild when its stamp is reached, then advances a running rebuild by
  /// the points quota (at least two scans: it always catches up). Does nothing otherwise.
  /// Deterministic: the quota counts points, never time. Call it after each ingested scan (its
  /// stages done).
  RebuildStep rebuild_step(TaskRunner& runner);
  /// The sensor positions (revised poses) of the retained scans a running or scheduled rebuild
  /// re-integrates into the TSDF, into `out` (cleared): the ground it will write to.
  void rebuild_sensors(std::vector<Eigen::Vector3d>& out) const;
  /// A rebuild is scheduled or running.
  [[nodiscard]] bool rebuilding() const { return rebuilding_ || pending_; }
  /// Retained scans the running rebuild has still to re-integrate (0 when none runs).
  [[nodiscard]] std::uint64_t rebuild_remaining() const {
    return rebuilding_ ? next_seq_ - cursor_seq_ : (pending_ ? retained_scans() : 0);
  }
  [[nodiscard]] const CorrectionStats& correction_stats() const { return correction_stats_; }
  /// Retained scans (0 when corrections are disabled).
  [[nodiscard]] std::size_t retained_scans() const;
  /// The poses of the retained scans, oldest first (for tests and tools).
  void retained_poses(std::vector<StampedPose>& out) const;

  /// The vehicle base pose of the last ingested scan (revised by a correction): the pose the
  /// vehicle's own costmap is built around.
  [[nodiscard]] const Eigen::Isometry3d& vehicle_pose() const { return T_W_B_; }
  [[nodiscard]] const OccupancyMap& occupancy() const { return map_; }
  /// For loading a saved static occupancy layer (OccupancyMap::import_static).
  [[nodiscard]] OccupancyMap& occupancy() { return map_; }
  [[nodiscard]] const CostmapLayers& costmap() const { return layers_; }
  /// The debris of the last update_costmap() (debris.hpp), in id order.
  [[nodiscard]] const std::vector<Debris>& debris() const { return debris_; }
  [[nodiscard]] const EsdfBand& esdf_band() const { return band_; }
  [[nodiscard]] const MapperParams& params() const { return params_; }
  [[nodiscard]] const TsdfLayer& tsdf() const { return tsdf_; }
  /// For loading a saved map into the mapper (the layer must match tsdf params).
  [[nodiscard]] TsdfLayer& tsdf() { return tsdf_; }

 private:
  struct RetainedScan {
    std::int64_t stamp_ns = 0;
    Eigen::Isometry3d T_W_B = Eigen::Isometry3d::Identity();
    Eigen::Isometry3d T_B_S = Eigen::Isometry3d::Identity();
    std::vector<Eigen::Vector3f> points_S;     ///< filtered, sensor frame
    std::vector<Eigen::Vector3f> no_return_S;  ///< accepted beams without return, sensor frame
    bool tsdf_wanted = false;                  ///< the scan was (or is to be) TSDF-integrated
    bool tsdf_done = false;                    ///< its TSDF contribution is in the layer
    std::vector<BlockIndex> tsdf_blocks;       ///< blocks of that contribution
  };
  RetainedScan& retained(std::uint64_t seq) { return retained_[seq % retained_.size()]; }
  const RetainedScan& retained(std::uint64_t seq) const {
    return retained_[seq % retained_.size()];
  }
  [[nodiscard]] std::uint64_t oldest_seq() const;
  void schedule_rebuild(std::int64_t from_stamp_ns);
  void start_rebuild();
  void record_tsdf(RetainedScan& scan, const TsdfUpdate& update);
  /// `scan` views this mapper's buffers as the last ingest() left them.
  [[nodiscard]] bool is_last_ingested(const FilteredScan& scan) const;

  MapperParams params_;
  OccupancyMap map_;
  std::vector<RetainedScan> retained_;   ///< ring, corrections.retain_scans slots
  std::uint64_t next_seq_ = 0;           ///< scans retained so far; seq k is in slot k % size
  std::unique_ptr<OccupancyMap> spare_;  ///< the window being rebuilt
  bool rebuilding_ = false;
  bool pending_ = false;  ///< a rebuild is scheduled, from pending_from_stamp_ns_
  std::int64_t pending_from_stamp_ns_ = 0;
  std::uint64_t cursor_seq_ = 0;  ///< next retained scan the rebuild integrates
  std::vector<Eigen::Vector3f> rebuild_points_W_;
  CorrectionStats correction_stats_;
  CostmapLayers layers_;
  std::vector<Debris> debris_;
  DebrisScratch debris_scratch_;
  std::vector<std::int64_t> column_observed_;  ///< fleet: own observation times, costmap order
  std::vector<BevState> own_cells_;            ///< fleet: the snapshot's states
  EsdfBand band_;
  std::vector<Eigen::Vector3f> points_W_;
  std::vector<Eigen::Vector3f> clearing_W_;  ///< the last scan's beams without return, world
  std::vector<Eigen::Vector3f> rebuild_clearing_W_;
  std::vector<Eigen::Vector3f> no_return_scratch_S_;  ///< accepted directions when not retained
  std::vector<float> no_return_scale_;  ///< stop_at_occupied's share of each beam cleared
  SkyHorizon sky_;                      ///< stop_at_occupied's sky round the sensor
  std::vector<float> ground_heights_;   ///< returns' heights for the ground under the sensor
  FilterScratch filter_scratch_;
  PointCloud deskewed_;   ///< the scan after deskew (points only), reused
  PointCloud organised_;  ///< the scan organised (organise()), when it needed it; reused
  OrganisedScratch organise_scratch_;
  Eigen::Vector3d sensor_W_ = Eigen::Vector3d::Zero();
  Eigen::Isometry3d T_W_B_ = Eigen::Isometry3d::Identity();  ///< of the last ingested scan
  TsdfIntegrator tsdf_integrator_;
  TsdfLayer tsdf_;
  TsdfUpdate no_tsdf_update_;
};

}  // namespace tarmac::core
