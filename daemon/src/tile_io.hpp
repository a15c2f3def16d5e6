#pragma once
// The tile store's disk work (docs/mapping.md, "Site-scale maps") on a thread of its own,
// SCHED_OTHER and unpinned: encode and write tiles, read and decode them, in the order
// submitted. The scan side submits work and takes back what is done; it waits on the disk only
// when it asks to (wait_done).

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

#include "tarmac/core/result.hpp"
#include "tarmac/core/tsdf_tiles.hpp"
#include "tile_files.hpp"

namespace tarmac::daemon {

/// One piece of disk work, handed back with its outcome.
struct TileWork {
  enum class Kind { kWriteTsdf, kReadTsdf, kWriteStatic, kReadStatic, kDropStatics };
  Kind kind = Kind::kReadTsdf;
  bool copy = false;  ///< a write of a copy: the tile stayed resident
  core::TileIndex tile = core::TileIndex::Zero();
  std::uint64_t version = 0;  ///< the TSDF tile's changes when its write was asked
  /// A TSDF write: the tile (back after a failed write, gone after a good one); a read: the tile.
  std::optional<core::TsdfTile> data;
  /// A static write: the voxels (kept: their digest is what the store then holds); a read:
  /// the index, then the voxels.
  core::StaticTile static_data;
  std::uint64_t generation = 0;  ///< the static layer's (core::StaticResidency::generation)
  // The outcome.
  std::optional<core::Error> error;
  std::uint64_t bytes = 0;  ///< written
};

class TileIo {
 public:
  /// Starts the thread. `files.dir` must exist.
  explicit TileIo(TileFiles files);
  /// Queued work finishes first.
  ~TileIo();
  TileIo(const TileIo&) = delete;
  TileIo& operator=(const TileIo&) = delete;

  void submit(TileWork work);
  /// Moves the work done so far into `out` (emptied first); never waits.
  void take_done(std::deque<TileWork>& out);
  /// Waits until some work is done, then takes it as take_done; false (nothing taken) when
  /// nothing is queued or running any more.
  bool wait_done(std::deque<TileWork>& out);
  /// Work submitted and not done yet.
  [[nodiscard]] std::size_t queued() const;
  [[nodiscard]] const TileFiles& files() const { return files_; }

 private:
  void run();
  void work(TileWork& w) const;
  void write_tsdf(TileWork& w) const;
  void read_tsdf(TileWork& w) const;
  void write_static(TileWork& w) const;
  void read_static(TileWork& w) const;
  void drop_statics() const;

  const TileFiles files_;
  mutable std::mutex mutex_;
  std::condition_variable wake_worker_, wake_waiter_;
  std::deque<TileWork> jobs_, done_;
  std::size_t busy_ = 0;  // taken, not in done_ yet
  bool stopping_ = false;
  std::thread worker_;
};

}  // namespace tarmac::daemon
