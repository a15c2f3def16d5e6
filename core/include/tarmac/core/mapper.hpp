#pragma once
/// @file The per-scan mapping pipeline as the daemon and the offline tools run it:
/// filter → integrate occupancy → costmap + 2D ESDF. Each stage is a separate call so the caller
/// can time it and give it a budget (the core has no clock).

#include <span>
#include <vector>

#include <Eigen/Geometry>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/deskew.hpp"
#include "tarmac/core/occupancy_map.hpp"
#include "tarmac/core/point_cloud.hpp"
#include "tarmac/core/scan_filter.hpp"
#include "tarmac/core/tsdf_integrator.hpp"

namespace tarmac::core {

struct MapperParams {
  FilterParams filters;
  OccupancyParams occupancy;
  CostmapParams costmap;
  TsdfParams tsdf;

  [[nodiscard]] Status validate() const;
};

class Mapper {
 public:
  /// @pre params.validate().ok()
  explicit Mapper(const MapperParams& params);

  /// Stage 1: filters `cloud` (sensor frame) and keeps the survivors in the world frame.
  /// T_W_B is the vehicle base pose at the scan stamp, T_B_S the sensor's extrinsic. With
  /// `motion` and per-point times in `cloud`, the points are first motion-compensated into the
  /// sensor frame at the stamp (deskew_points); without either, the sweep is taken as rigid.
  FilterCounts ingest(const PointCloud& cloud, const Eigen::Isometry3d& T_W_B,
                      const Eigen::Isometry3d& T_B_S, const ScanMotion* motion = nullptr);
  /// Stage 2: moves the window with the vehicle and integrates the ingested scan.
  OccupancyUpdateStats integrate(TaskRunner& runner);
  /// Stage 3: rebuilds the costmap and the 2D distance map from the window.
  void update_costmap(std::span<const VirtualZone> zones, std::int64_t stamp_ns,
                      TaskRunner& runner);
  /// Stage 2b: integrates the ingested scan into the TSDF (sparse, whole site). Does nothing
  /// (and returns an empty update) when tsdf.enabled is false.
  const TsdfUpdate& integrate_tsdf(TaskRunner& runner);

  /// The last ingested scan's surviving points, world frame, and the sensor origin.
  [[nodiscard]] const std::vector<Eigen::Vector3f>& points_W() const { return points_W_; }
  [[nodiscard]] const Eigen::Vector3d& sensor_W() const { return sensor_W_; }
  [[nodiscard]] const OccupancyMap& occupancy() const { return map_; }
  /// For loading a saved static occupancy layer (OccupancyMap::import_static).
  [[nodiscard]] OccupancyMap& occupancy() { return map_; }
  [[nodiscard]] const CostmapLayers& costmap() const { return layers_; }
  [[nodiscard]] const MapperParams& params() const { return params_; }
  [[nodiscard]] const TsdfLayer& tsdf() const { return tsdf_; }
  /// For loading a saved map into the mapper (the layer must match tsdf params).
  [[nodiscard]] TsdfLayer& tsdf() { return tsdf_; }

 private:
  MapperParams params_;
  OccupancyMap map_;
  CostmapLayers layers_;
  std::vector<Eigen::Vector3f> points_W_;
  FilterScratch filter_scratch_;
  PointCloud deskewed_;  ///< the scan after deskew (points only), reused
  Eigen::Vector3d sensor_W_ = Eigen::Vector3d::Zero();
  Eigen::Isometry3d T_W_B_ = Eigen::Isometry3d::Identity();  ///< of the last ingested scan
  TsdfIntegrator tsdf_integrator_;
  TsdfLayer tsdf_;
  TsdfUpdate no_tsdf_update_;
};

}  // namespace tarmac::core
