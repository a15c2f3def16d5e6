#pragma once
/// @file The state directory (YAML `state`, docs/operations.md "Static map persistence"): the
/// occupancy window written on exit, and the static map (the TSDF and the occupancy's static
/// layer) loaded at start, saved on exit and saved periodically from a thread of its own. Every
/// file tarmacd keeps is written and read here.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "tarmac/config/config.hpp"
#include "tarmac/core/mapper.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_io.hpp"
#include "tarmac/daemon/executor.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"

namespace tarmac::daemon {

class MapStore {
 public:
  /// Periodic saves since start (the one on exit is not counted).
  struct SaveCounts {
    std::uint64_t saves = 0;
    std::uint64_t failures = 0;
    std::uint64_t skipped = 0;  ///< the previous save was still being written
  };

  /// `hash`: the config hash written into the static map and compared on load.
  MapStore(const config::Config& config, std::string hash);
  /// Stops the saver if it still runs (an in-flight save completes first).
  ~MapStore();
  MapStore(const MapStore&) = delete;
  MapStore& operator=(const MapStore&) = delete;

  /// Writes the window to state.dir/state.map_file: a one-line text header, then float32
  /// log-odds in window order (x fastest); written to <file>.tmp, flushed to the device and
  /// renamed over the file.
  /// `stamp_ns`: the newest scan in it. Not for the cycle.
  core::Status save_window(const core::OccupancyMap& window, std::int64_t stamp_ns) const;

  /// Writes the mapper's TSDF and static occupancy to state.dir/state.tsdf_file with tsdf_io
  /// (atomic: .tmp, fsync, rename). `newest_stamp_ns`: the newest scan integrated since start
  /// (0: none, the file carries the loaded map's stamp). Not for the cycle.
  /// With paging (tsdf.resident_limit_mb > 0) the TSDF is the tile store: every changed tile is
  /// written to it first, and the file holds the static occupancy and an empty TSDF.
  core::Status save_tsdf(core::Mapper& mapper, std::int64_t newest_stamp_ns);

  /// tsdf.resident_limit_mb > 0: opens the tile store state.dir/tsdf_tiles (after load_tsdf):
  /// its tiles are the map when state.load_on_start and the loaded file held no TSDF blocks;
  /// otherwise it is emptied. Call before the real-time setup: the pager's thread stays
  /// SCHED_OTHER and unpinned. Without paging: nothing.
  core::Status open_pager(core::Mapper& mapper);
  /// The pager, or null (no paging, or it could not open).
  [[nodiscard]] TsdfPager* pager() const { return pager_.get(); }

  /// Executor::load_tsdf(): loads the static map into `mapper`, or refuses the file (renamed to
  /// <file>.refused); removes a save cut short (<file>.tmp). Logs one line either way.
  TsdfLoadResult load_tsdf(core::Mapper& mapper);

  /// Whether the TSDF is saved periodically (tsdf.enabled, state.save_period_s > 0).
  [[nodiscard]] bool periodic() const;
  /// The periodic save's interval in ticks at `rate_hz` (at least 1).
  [[nodiscard]] std::uint64_t period_ticks(double rate_hz) const;
  /// Starts the saver thread on the calling thread's scheduling policy: call it before the
  /// real-time setup, so that it stays SCHED_OTHER and unpinned (it lowers itself to nice 10).
  void start_saver();
  /// Ends the saver thread once an in-flight save has completed.
  void stop_saver();
  /// Periodic save, between ticks on the executor thread: copies the TSDF and the static layer
  /// and hands the copy to the saver thread (skipped, counted, when the previous copy is still
  /// being written).
  /// With paging, the changed tiles' copies go to the pager's thread and the file gets the
  /// static occupancy only.
  void snapshot(core::Mapper& mapper, std::int64_t newest_stamp_ns);

  /// Thread-safe.
  [[nodiscard]] SaveCounts counts() const;

 private:
  [[nodiscard]] std::filesystem::path tsdf_path() const;
  [[nodiscard]] core::TsdfMapInfo tsdf_info(std::int64_t newest_stamp_ns) const;
  /// The occupancy window's static layer, saved in the same .vdb as the TSDF.
  [[nodiscard]] core::StaticOccupancy static_occupancy(const core::Mapper& mapper) const;
  void saver_loop();

  config::StateConfig state_;
  std::unique_ptr<TsdfPager> pager_;
  core::TsdfParams tsdf_;
  float static_voxel_size_m_;
  std::string frame_id_;  // the lattice lives in the pose / map frame
  std::string hash_;
  std::int64_t loaded_stamp_ns_ = 0;  // stamp of the TSDF loaded at start (0: none)

  // The executor only swaps a pointer under saver_mutex_ (never while the saver writes: the
  // saver takes the snapshot out first and writes it without the lock).
  std::thread saver_;
  std::mutex saver_mutex_;
  std::condition_variable saver_wake_;
  std::unique_ptr<core::TsdfLayer> saver_snapshot_;  // guarded by saver_mutex_
  core::StaticOccupancy saver_static_;               // guarded by saver_mutex_
  core::TsdfMapInfo saver_info_;                     // guarded by saver_mutex_
  bool saver_stop_ = false;                          // guarded by saver_mutex_
  std::atomic<bool> saver_busy_{false};
  std::atomic<std::uint64_t> saves_{0}, failures_{0}, skipped_{0};
};

}  // namespace tarmac::daemon
