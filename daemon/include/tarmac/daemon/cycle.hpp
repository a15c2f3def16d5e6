#pragma once
/// @file One tick's mapping stages, in DESIGN.md §3's order and with the stage quotas: the one
/// sequence tarmacd's executor, tarmac-map and the tests run. DDS-free and clock-free for the
/// caller (the stages are timed here, on the steady clock); the caller brings the scans in stamp
/// order and takes the products:
///
///     begin() → scan() for each scan → update_costmap(pose) → [publish] → update_esdf_band(pose)
///
/// scan() runs ingest (filters, deskew) → integrate (occupancy window) → the TSDF, unless this
/// tick's TSDF points quota is spent (the scan is then shed from the TSDF, and counted) → one
/// step of a running rebuild after a pose correction. The quota is in points, not time, and a
/// rebuild steps once per scan: what a tick does depends on its scans, never on the machine's
/// speed. Pose corrections are the caller's (tarmacd's arrive over DDS): apply them before the
/// scan() of the first scan they must precede.

#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/mapper.hpp"
#include "tarmac/core/task_runner.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"

namespace tarmac::daemon {

class Cycle {
 public:
  struct Quotas {
    /// Points integrated into the TSDF per tick (config quotas.tsdf_points_per_cycle); a scan
    /// that would pass it is shed from the TSDF (the occupancy still takes it).
    std::uint64_t tsdf_points_per_cycle = std::numeric_limits<std::uint64_t>::max();
  };

  /// What one scan() did. `tsdf` points into the mapper (valid until its next TSDF call): null
  /// when the TSDF is off or the scan was shed; empty during a rebuild (the rebuild integrates
  /// the scan in stamp order).
  struct ScanResult {
    core::FilteredScan filtered;  ///< what ingest() left (a view, valid until the next scan())
    core::OccupancyUpdate occupancy;
    const core::TsdfUpdate* tsdf = nullptr;
    bool tsdf_shed = false;
    core::RebuildStep rebuild;  ///< scans == 0: no rebuild step ran
    double ingest_ms = 0.0, integrate_ms = 0.0, tsdf_ms = 0.0, rebuild_ms = 0.0;
  };

  /// The tick so far (since begin()).
  struct Tick {
    std::size_t scans = 0;
    std::size_t tsdf_scans = 0;     ///< integrated into the TSDF
    std::size_t tsdf_shed = 0;      ///< shed from the TSDF by the points quota
    std::uint64_t tsdf_points = 0;  ///< counted against the quota
    std::uint64_t points_in = 0;    ///< returns received
    std::uint64_t points_used = 0;  ///< kept by the filters
    /// Window columns whose voxels the tick's scans changed, each scan's summed (a column two
    /// scans changed counts twice).
    std::uint64_t columns_changed = 0;
    std::uint64_t scans_reintegrated = 0;
    std::uint64_t rebuilds_completed = 0;  ///< rebuilt windows swapped in
    double ingest_ms = 0.0, integrate_ms = 0.0, tsdf_ms = 0.0, rebuild_ms = 0.0;
    double costmap_ms = 0.0, esdf_band_ms = 0.0;
  };

  /// `mapper` and `runner` must outlive the cycle.
  Cycle(core::Mapper& mapper, core::TaskRunner& runner, Quotas quotas);

  /// Starts a tick: the TSDF quota and the tick's counts restart.
  void begin();
  /// One scan through the per-scan stages (see the file comment). `T_W_B`: the vehicle base's
  /// pose at the scan's stamp; `motion`: for deskewing (null: none).
  const ScanResult& scan(const core::PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                         const Eigen::Isometry3d& T_B_S, const core::ScanMotion* motion = nullptr);
  /// Fleet sharing (docs/fleet.md): from now on the window records its columns' observation
  /// times, and update_costmap() fuses `peers`' cells (null: none) and keeps the own classes
  /// for Mapper::fleet_snapshot().
  void share_with_fleet(const core::BevPeers* peers);
  /// Pages the TSDF and the static occupancy through `pager` from now on (null: no paging):
  /// scan() makes one residency step (TsdfPager::step) before each of its stages and one after
  /// the last, so that each stage finds the tiles it can touch and the map stays within the
  /// pager's limit.
  void page_tsdf(TsdfPager* pager) { pager_ = pager; }
  /// What the last update_costmap() took from peers.
  [[nodiscard]] const core::BevFusionCounts& fleet_counts() const { return fleet_counts_; }

  /// The costmap and the 2D ESDF from the window around the vehicle base pose `T_W_B`
  /// (core::Mapper::vehicle_pose(): the newest scan's, revised by corrections), once per tick
  /// (when something changed).
  const core::CostmapLayers& update_costmap(const Eigen::Isometry3d& T_W_B,
                                            std::span<const core::VirtualZone> zones,
                                            std::int64_t stamp_ns);
  /// The 3D ESDF band from the window and this tick's costmap, around the same `T_W_B`; false
  /// (nothing done) when esdf_band.enabled is false.
  bool update_esdf_band(const Eigen::Isometry3d& T_W_B, std::span<const core::VirtualZone> zones,
                        std::int64_t stamp_ns);

  [[nodiscard]] const Tick& tick() const { return tick_; }
  [[nodiscard]] core::Mapper& mapper() { return mapper_; }
  [[nodiscard]] const core::Mapper& mapper() const { return mapper_; }

 private:
  void residency_step(ScanStage next, std::span<const Eigen::Vector3d> at_W,
                      bool rebuild_completed = false);
  void integrate_occupancy(ScanResult& r);
  /// False when the tick's TSDF quota sheds the scan.
  bool integrate_tsdf(ScanResult& r);
  void rebuild_step(ScanResult& r);
  void add_to_tick(const ScanResult& r);

  core::Mapper& mapper_;
  core::TaskRunner& runner_;
  Quotas quotas_;
  Tick tick_;
  ScanResult last_;
  bool fleet_ = false;
  const core::BevPeers* peers_ = nullptr;
  TsdfPager* pager_ = nullptr;
  std::vector<Eigen::Vector3d> rebuild_sensors_;
  core::BevFusionCounts fleet_counts_;
};

}  // namespace tarmac::daemon
