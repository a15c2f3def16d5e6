#pragma once
/// @file tarmac-map's run: its options, what it reads before any work is done, and what it
/// measures and counts while it maps.

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tarmac/config/config.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/tools/clearing.hpp"
#include "tarmac/tools/kitti.hpp"
#include "tarmac/tools/open_ground.hpp"
#include "tarmac/tools/safety.hpp"
#include "tarmac/tools/small_objects.hpp"

namespace tarmac::map_tool {

constexpr int kExitData = 65;
constexpr int kExitIo = 74;
constexpr int kExitConfig = 78;

struct Options {
  std::string dataset, out = "out/map", config, poses = "poses.txt", prior, corrections;
  std::size_t threads = 2;
  std::size_t max_scans = 0;  // 0: all
  double sensor_height_m = 1.9;
  double fleet_period_s = 0.0;  ///< > 0: encode a fleet summary this often, report its bytes
  std::string memory_log;       ///< per scan: distance driven, RSS, resident and stored TSDF
  bool open_ground = false;     ///< score the open flat ground of the returns with a truth too
  /// The sensor tilts on its carrier (handheld): the base is level in the world frame, under
  /// the sensor by sensor_height_m, with the sensor's heading (see base_pose()).
  bool level_base = false;
};

struct StageTimes {
  const char* name;
  std::vector<double> ms;
};

/// Everything the run reads, checked before any work is done.
struct Inputs {
  config::Config cfg;
  tools::KittiSequence seq;
  std::optional<core::LoadedTsdf> prior;           ///< --prior
  std::optional<tools::ClearingTracker> clearing;  ///< tarmac-sim's dynamic_boxes.txt
  /// tarmac-sim's obstacle_columns.txt (ground_cells.txt, curb_columns.txt)
  std::optional<tools::SafetyTracker> safety;
  /// tarmac-sim's small_objects.txt: a score per cone, piece of debris, pole
  std::optional<tools::SmallObjectTracker> small_objects;
  /// Without a truth (real data), or --open-ground: the open flat ground of the drive's returns.
  std::optional<tools::OpenGroundTracker> open_ground;
  std::vector<tools::Correction> corrections;  ///< --corrections
};

/// What the run measured and counted.
struct Run {
  std::size_t scans = 0;           ///< scans mapped (--scans, or all)
  std::int64_t last_stamp_ns = 0;  ///< the last scan's stamp
  StageTimes t_read{"read", {}}, t_filter{"filter", {}}, t_occ{"occupancy", {}},
      t_cost{"costmap+esdf2d", {}}, t_tsdf{"tsdf", {}}, t_band{"esdf_band", {}},
      t_total{"pipeline", {}}, t_spares{"tsdf spares", {}};
  std::uint64_t tsdf_samples = 0, tsdf_updates = 0;
  std::uint64_t points_in = 0, points_used = 0, dropped_nonfinite = 0, dropped_close = 0,
                dropped_ego = 0, dropped_isolated = 0, voxel_visits = 0, promotions = 0,
                demotions = 0;
  std::vector<double> rebuild_ms;  ///< per rebuild step that re-integrated scans
  std::uint64_t jump_corrections = 0;
  std::size_t next_correction = 0;  ///< --corrections applied so far
  std::size_t rebuild_steps_after_end = 0;
  double distance_m = 0.0;  ///< driven (sensor path in x, y)
  /// --memory-log: one CSV line per scan.
  std::FILE* memory_log = nullptr;
  /// tsdf.resident_limit_mb > 0: the TSDF's tiles paged to out/tsdf_tiles.
  daemon::TsdfPager* pager = nullptr;
  /// --fleet-period: each summary's wire bytes and whether it was a keyframe.
  std::vector<std::pair<std::size_t, bool>> fleet_messages;
  /// Debris pieces after each scan's costmap (written to debris.json).
  std::vector<std::uint32_t> debris_per_scan;
};

}  // namespace tarmac::map_tool
