#pragma once
/// @file The hot local occupancy map: a dense rolling (ring-buffer) voxel window that follows the
/// vehicle without copying, holding clamped log-odds per voxel (OctoMap's sensor model:
/// Hornung et al., "OctoMap", Autonomous Robots 2013), in two layers:
///  - dynamic: the log-odds themselves, with a low upper clamp so that a voxel the object left
///    reads free after a few misses (clamp_max 0.85 with prob_miss 0.4: 5 scans, 0.5 s at 10 Hz);
///  - static: a voxel observed occupied in static_promote_scans consecutive hits (never reading
///    free in between) joins it, and so does a voxel that leaves the window reading occupied
///    after returns in two scans or more (what the vehicle saw and drove away from is
///    remembered, not forgotten: a surface passed at speed is hit in short runs of scans); while
///    static, misses do not lower it below one hit's log-odds, and it leaves only after
///    static_demote_scans consecutive observations as free space with no return in it. The
///    static layer is site-wide and sparse (it survives the window scrolling away and back, and
///    is what the daemon persists).
///  Undersides (an occupied voxel with observed free space below it and none above: an
///  aircraft's belly, an engine) are missed only by rays that pass through them at or above
///  their lowest return: rays grazing under a belly cross the empty bottom of the voxel that
///  holds the belly surface, and have not shown it gone (integrate()).
/// The window's log-odds are the combined result (static voxels read occupied), so the costmap
/// and the ESDF read one array. Unknown stays unknown: only rays change a voxel.

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/low_objects.hpp"
#include "tarmac/core/result.hpp"
#include "tarmac/core/scan_rays.hpp"
#include "tarmac/core/task_runner.hpp"

namespace tarmac::core {

/// Sensor model and window. Defaults: OctoMap's 0.7 / 0.4 / 0.12 / 0.97, 80 m × 80 m × 8 m at 0.2
/// m.
struct OccupancyParams {
  double voxel_size_m = 0.2;
  int window_x_vox = 400;
  int window_y_vox = 400;
  int window_z_vox = 40;
  /// The window spans [vehicle z − window_below_m, … + window_z_vox·voxel) vertically.
  double window_below_m = 3.0;
  float prob_hit = 0.7f;
  float prob_miss = 0.4f;
  float clamp_min = 0.12f;
  /// Upper clamp of the dynamic layer: ceil(logit(clamp_max) / −logit(prob_miss)) misses clear a
  /// voxel (0.85 / 0.4: 5, i.e. 0.5 s at 10 Hz; OctoMap's 0.97 needs 9).
  float clamp_max = 0.85f;
  /// Returns farther than this do not mark; their ray clears free space up to clearing_range_m.
  double max_range_m = 50.0;
  /// How far a beam with no return (or beyond max range) clears free space.
  double clearing_range_m = 30.0;
  /// Heights of returns above the ground are taken against the second-lowest return of the same
  /// scan within this horizontal radius (one stray return below the ground does not count).
  /// Where that scan returned little round the spot (at range, a beam that grazes a 10 cm object
  /// lands 0.1·d/h further on, and the ring below lands well short), the ground a scan of the
  /// last second returned densely there is taken instead, when lower. Larger radii met road
  /// camber and noise on real data (tests/data).
  double ground_radius_m = 0.4;
  /// Static layer: consecutive scans hitting a voxel (it reading occupied throughout) that make it
  /// static, 0 disables the layer, 0..127. Must exceed the scans a moving object covers one voxel
  /// for (the simulator's tug: 3 m long at 2 m/s, 16 scans at 10 Hz): default 20 (2 s at 10 Hz).
  int static_promote_scans = 20;
  /// Consecutive scans observing a static voxel as free (a ray through it, no return in it) that
  /// remove it, 1..127: default 10 (1 s at 10 Hz), so sporadic misses (grazing rays, dropped
  /// returns) never clear a building or a parked aircraft.
  int static_demote_scans = 10;
  /// Low objects kept across scans (low_objects.hpp); min_rise_m is the costmap's
  /// min_obstacle_height_m (the Mapper sets it).
  LowObjectParams low_objects;

  [[nodiscard]] Status validate() const;
};

/// Integer voxel coordinates on the world lattice: voxel i covers [i·v, (i+1)·v).
using VoxelIndex = Eigen::Vector3i;

/// The window columns one integrate() changed: those where a voxel's log-odds or sub-voxel rise
/// (OccupancyMap::ring_layer_rise_cm) now differs from before the scan. A view of the map's
/// storage, valid until its next integrate() or reset() (a recenter() in between does not move
/// it: it keeps the window of its scan); empty before the first.
class ChangedColumns {
 public:
  ChangedColumns() = default;
  /// `bits`: one per window column in ring order (ring_y · width + ring_x); `ring_x0`, `ring_y0`:
  /// the ring column of window column (0, 0).
  ChangedColumns(std::span<const std::uint64_t> bits, int width, int height, int ring_x0,
                 int ring_y0)
      : bits_(bits), width_(width), height_(height), ring_x0_(ring_x0), ring_y0_(ring_y0) {}
  /// Whether window column (x, y), counted from the window's lowest corner like the costmap's
  /// cells, changed; false outside the window.
  [[nodiscard]] bool contains(int x, int y) const;
  /// How many columns changed.
  [[nodiscard]] std::size_t count() const;

 private:
  std::span<const std::uint64_t> bits_;
  int width_ = 0, height_ = 0, ring_x0_ = 0, ring_y0_ = 0;
};

/// What one scan changed, for later stages and reports: the columns, and counts.
struct OccupancyUpdate {
  ChangedColumns changed;            ///< the window columns whose voxels this scan changed
  std::uint64_t rays = 0;            ///< rays cast (returns + clearing beams)
  std::uint64_t hit_updates = 0;     ///< voxels updated as occupied
  std::uint64_t miss_updates = 0;    ///< voxels updated as free
  std::uint64_t voxel_visits = 0;    ///< voxels stepped through, including repeats
  std::uint64_t outside_window = 0;  ///< returns whose voxel lies outside the window
  std::uint64_t promotions = 0;      ///< voxels that joined the static layer
  std::uint64_t demotions = 0;       ///< voxels that left it
};

struct StaticStore;

/// The sky round one origin, as the window's bricks flagged occupied draw it: per azimuth sector
/// the steepest rise over horizontal run at which a beam from the origin can still touch such a
/// brick above the origin (OccupancyMap::sky_horizon). A beam that does not descend and rises
/// more steeply than its sector's horizon touches none of them, so first_occupied() would walk
/// it to its end and find nothing: the beams without return of a scan are mostly such beams.
/// Only a shortcut: clears() is false wherever it cannot be sure.
class SkyHorizon {
 public:
  /// True when OccupancyMap::first_occupied(origin, `dir_W`, any max_t) is infinity for
  /// certain: `dir_W` does not descend and passes above every flagged brick of its sector.
  [[nodiscard]] bool clears(const Eigen::Vector3d& dir_W) const;

 private:
  friend class OccupancyMap;
  static constexpr int kSectors = 1024;
  /// A horizontal direction (x, y) ≠ 0 as a pseudo-angle in [0, 4] that grows with the angle.
  [[nodiscard]] static double turn(double x, double y);
  /// The sector of a turn.
  [[nodiscard]] static int sector(double turn);
  /// Per sector; -1: nothing above the origin. A fixed array: drawn each scan on the executor's
  /// threads, which allocate nothing in steady state.
  std::array<double, kSectors> slope_{};
  /// A flagged brick reaching above the origin is over its column; true until first drawn, so
  /// that a SkyHorizon never drawn clears nothing.
  bool overhead_ = true;
};

/// The rolling window. Move-only (tens of MB). Not thread-safe: one writer.
class OccupancyMap {
 public:
  /// Log-odds value that marks a voxel never observed.
  static constexpr float kUnknown = -1.0e9f;

  explicit OccupancyMap(const OccupancyParams& params);
  OccupancyMap(OccupancyMap&&) noexcept;
  OccupancyMap& operator=(OccupancyMap&&) noexcept;
  ~OccupancyMap();
  OccupancyMap(const OccupancyMap&) = delete;
  OccupancyMap& operator=(const OccupancyMap&) = delete;

  /// The most rays the walks may take at a time: 8 (the default) runs them in AVX-512 lanes where
  /// the processor has them, else in AVX2 lanes, four at a time; 4 stops at AVX2; 1 walks them
  /// one at a time. The marks, and so the map, are the same bits on every path; the limit is for
  /// measuring the difference and for testing one path against another.
  void set_walk_lanes(int max_lanes) { walk_lanes_ = max_lanes; }
  /// How many rays integrate() walks at a time: 8 (AVX-512), 4 (AVX2) or 1, the most that
  /// set_walk_lanes() allows and this processor supports.
  [[nodiscard]] int walk_lanes() const;

  /// Moves the window so that it is centred on `position_W` in x/y and spans
  /// [z − window_below_m, …) in z. Voxels that leave are forgotten (unknown when they re-enter);
  /// voxels that stay keep their content, without copying. RT-safe. The voxels that leave are
  /// cleared in fixed ranges of slots on `runner` (same result for any runner).
  void recenter(const Eigen::Vector3d& position_W, TaskRunner& runner);
  /// The same on the calling thread.
  void recenter(const Eigen::Vector3d& position_W);

  /// Integrates one scan: `points_W` are returns in the world frame taken from `origin_W`.
  /// Each voxel is updated at most once per scan, occupied winning over free; free space is
  /// every voxel a ray passes through before its return voxel — except undersides: a voxel
  /// reading occupied with observed free space below it and none above is missed only by a
  /// ray that passes through it at or above its lowest return and goes on more than a voxel
  /// (rays grazing under an aircraft's belly cross the empty bottom of the voxel that holds
  /// the belly surface; they have not shown the surface gone). Non-finite points are skipped
  /// (filters count them). Returns beyond max_range_m clear up to clearing_range_m.
  /// `clearing_dirs_W` are directions of beams with no return: they clear up to
  /// clearing_range_m times their length when it is below 1 (a beam the mapper clipped at the
  /// ground plane), up to clearing_range_m otherwise. Deterministic for any runner.
  /// `up_W` is the vehicle's up axis (its base frame's z in the world frame): heights of returns
  /// above the scan's ground (ring_layer_rise_cm) are measured along it, so a world frame that
  /// is not gravity-aligned does not tilt them. A zero or non-finite `up_W` is taken as +z.
  /// Returns the columns it changed (later stages need look at no other) and counts.
  OccupancyUpdate integrate(const Eigen::Vector3d& origin_W,
                            std::span<const Eigen::Vector3f> points_W,
                            std::span<const Eigen::Vector3f> clearing_dirs_W, TaskRunner& runner,
                            const Eigen::Vector3d& up_W = Eigen::Vector3d::UnitZ());

  /// Per window column, the time of its last observation (fleet sharing, docs/fleet.md): a
  /// return, or a ray passing, in one of the window-relative layers [band_lo, band_hi] (the
  /// vehicle's envelope; a ray passing high above a column does not show what is on its
  /// ground). Off until called (no memory, no cost); changes no map value. integrate() records
  /// the stamp of set_observation_stamp().
  void track_column_observations(int band_lo, int band_hi);
  /// The stamp integrate() records for the columns it observes (the scan's time, ns).
  void set_observation_stamp(std::int64_t stamp_ns) { observation_stamp_ns_ = stamp_ns; }
  /// Each window column's last observation time, ns (0: never, or tracking off), row-major from
  /// the window's lowest corner like the costmap: out[y · window x + x]. Resized to fit.
  void export_column_observed(std::vector<std::int64_t>& out) const;

  /// Forgets everything: every voxel unknown, the static layer empty (site-wide), the window
  /// unplaced (the next recenter() or integrate() places it), as if just constructed. Keeps the
  /// window storage; a rebuild after a pose correction starts from it.
  void reset();

  /// Log-odds at a voxel, kUnknown when unobserved or outside the window.
  [[nodiscard]] float log_odds(const VoxelIndex& v) const;
  [[nodiscard]] bool in_window(const VoxelIndex& v) const;
  /// How far along the unit `dir_W` from `origin_W` the ray enters the first voxel past the
  /// origin's that reads occupied, when that is within `max_t` and the window; infinity
  /// otherwise. The walk of OccupancyMap::integrate's rays (Amanatides & Woo), reading only; it
  /// crosses bricks of 8³ voxels that hold nothing occupied in one step (first_occupied.cpp).
  [[nodiscard]] double first_occupied(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                                      double max_t) const;
  /// The same, with `origin_voxel` = voxel_of(origin_W) computed once for many rays.
  [[nodiscard]] double first_occupied(const Eigen::Vector3d& origin_W,
                                      const VoxelIndex& origin_voxel, const Eigen::Vector3d& dir_W,
                                      double max_t) const;
  [[nodiscard]] VoxelIndex voxel_of(const Eigen::Vector3d& p_W) const;
  /// Draws the sky round `origin_W` into `out` (SkyHorizon), from the brick flags
  /// first_occupied() reads.
  void sky_horizon(const Eigen::Vector3d& origin_W, SkyHorizon& out) const;

  /// Lowest-corner voxel of the window (inclusive) and its size in voxels.
  [[nodiscard]] const VoxelIndex& window_min() const { return min_; }
  [[nodiscard]] Eigen::Vector3i window_size() const { return dims_; }
  [[nodiscard]] const OccupancyParams& params() const { return params_; }
  [[nodiscard]] float hit_log_odds() const { return l_hit_; }
  [[nodiscard]] float miss_log_odds() const { return l_miss_; }
  [[nodiscard]] float min_log_odds() const { return l_min_; }
  [[nodiscard]] float max_log_odds() const { return l_max_; }
  [[nodiscard]] std::size_t memory_bytes() const;

  /// Direct read access for whole-window passes, cache-friendly: the storage of window layer
  /// `wz` is a plane of window_x·window_y floats in ring order; window cell (wx, wy) of it is at
  /// ring_y(wy)·window_x + ring_x(wx).
  [[nodiscard]] const float* ring_layer(int wz) const;
  /// Height of the latest returns above the local ground of their own scan, per voxel, in the
  /// same ring order as ring_layer(): the highest return of the latest scan that hit the voxel,
  /// in cm above the second-lowest return of that scan within ground_radius_m of it (the lowest
  /// where it is alone there; or the ground remembered there, see ground_radius_m; 0..255; 0
  /// also where
  /// nothing was returned). Heights within one sweep share one pose, so pose error between
  /// scans cannot look like an object, and they stay after grazing rays clear the voxel (rays
  /// through the empty upper part of a 20 cm voxel over 10 cm debris do not contradict it). The
  /// costmap uses them for objects lower than a voxel.
  [[nodiscard]] const std::uint8_t* ring_layer_rise_cm(int wz) const;
  /// The low objects kept across scans (debris), with their evidence: integrate() updates
  /// them from its returns' rises; the costmap reads the confirmed ones as obstacles.
  [[nodiscard]] const LowObjects& low_objects() const { return low_objects_; }
  [[nodiscard]] int ring_x(int wx) const;
  [[nodiscard]] int ring_y(int wy) const;
  /// The ground the latest scan that returned densely round the column at ring slot `ring_slot`
  /// (ring_y(wy)·window_x + ring_x(wx)) returned there (hit_rises()), as a map-frame z, however
  /// long ago, while the column stays in the window; NaN where none did.
  [[nodiscard]] float remembered_ground_z(std::size_t ring_slot) const {
    return ground_memory_scan_[ring_slot] != 0 ? ground_memory_z_[ring_slot]
                                               : std::numeric_limits<float>::quiet_NaN();
  }

  /// Copies the window into `out` in window order (z slowest, x fastest) starting at window_min().
  void export_log_odds(std::vector<float>& out) const;

  /// True when the voxel belongs to the static layer (inside or outside the window).
  [[nodiscard]] bool is_static(const VoxelIndex& v) const;
  /// Voxels of the static layer, site-wide.
  [[nodiscard]] std::size_t static_count() const;
  /// The static layer's voxels, sorted by (z, y, x), into `out` (for persistence and tests).
  void export_static(std::vector<VoxelIndex>& out) const;
  /// Site paging (daemon/tsdf_pager.hpp): takes the static voxels of the columns x in
  /// [lo_x, hi_x], y in [lo_y, hi_y] (world voxel indices, inclusive, whole 8-voxel blocks) out
  /// of the layer, appending them to `out` sorted by (z, y, x). Refused (false, nothing taken)
  /// when the columns meet the window: its voxels hold the static state too. No allocation once
  /// its scratch has grown.
  bool take_static_columns(int lo_x, int lo_y, int hi_x, int hi_y, std::vector<VoxelIndex>& out);
  /// The same voxels copied, the layer unchanged (a save).
  void copy_static_columns(int lo_x, int lo_y, int hi_x, int hi_y, std::vector<VoxelIndex>& out);
  /// The (x, y) squares of `edge` voxels (a multiple of 8) that hold static blocks: square t
  /// covers [edge·t, edge·t + edge); sorted by (y, x), each once.
  void static_tiles(int edge, std::vector<Eigen::Vector2i>& out) const;
  /// Puts static voxels back (a tile read from the store); those inside the window read static
  /// at once, as if it had been there when the window reached them.
  void put_static(std::span<const VoxelIndex> voxels);
  /// Bytes the static layer's table holds (it never shrinks: its size is its peak).
  [[nodiscard]] std::size_t static_bytes() const;
  /// The window's lowest corner were it centred on `position_W` (where recenter() puts it).
  [[nodiscard]] VoxelIndex window_min_at(const Eigen::Vector3d& position_W) const;

  /// Replaces the static layer by `voxels` (a loaded map): those inside the window read occupied
  /// at once, the others when the window reaches them. Forgets the dynamic content of voxels that
  /// left the static layer by this call.
  void import_static(std::span<const VoxelIndex> voxels);

 private:
  [[nodiscard]] std::size_t slot(const VoxelIndex& v) const;
  /// Forgets the voxels of `count` consecutive slabs along `axis`, from world index `first`
  /// (count < the window's size along the axis).
  void clear_slabs(int axis, int first, int count, TaskRunner& runner);
  /// Appends to `kept` the slots of [first, first + count) that leave the window to join the
  /// static layer: reading occupied, not static, with returns in kKeepHits scans or more and
  /// never read free since. What the vehicle saw and drove away from is remembered, not
  /// forgotten: a surface passed at speed is hit in short runs of scans, never the
  /// static_promote_scans in a row that promote inside the window.
  void keep_leaving(std::size_t first, std::size_t count, std::vector<std::uint32_t>& kept) const;
  /// Makes the voxels of the static layer inside [lo, hi] (world indices, inclusive, within the
  /// window) read static.
  void restore_static(const VoxelIndex& lo, const VoxelIndex& hi);
  [[nodiscard]] VoxelIndex voxel_of_slot(std::size_t slot) const;
  bool static_columns(int lo_x, int lo_y, int hi_x, int hi_y, std::vector<VoxelIndex>& out,
                      bool take);
  /// Ring index of the window's first voxel, per axis.
  [[nodiscard]] std::array<int, 3> ring_origin() const;
  /// World index along axis `a` of the voxels at ring index `r` (`seam`: ring_origin()[a]).
  [[nodiscard]] int world_of_ring(int a, int r, int seam) const;
  /// integrate()'s hit pass: each return's slot, column, height and rise above the scan's ground,
  /// then one hit per voxel in point order (the static layer's promotions too).
  void integrate_hits(const Eigen::Vector3d& origin_W, std::span<const Eigen::Vector3f> points_W,
                      const Eigen::Vector3d& up_W, OccupancyUpdate& stats);
  /// integrate_hits' steps. Each return's slot and window column (hit_slot_, kNoSlot for none:
  /// not finite, beyond max range or outside the window); returns those outside the window.
  std::uint64_t hit_voxels(const Eigen::Vector3d& origin_W,
                           std::span<const Eigen::Vector3f> points_W);
  /// Each return's height along `up` and the scan's two lowest returns per window column.
  void hit_heights(std::span<const Eigen::Vector3f> points_W, const Eigen::Vector3f& up);
  /// Each return's rise (cm) above the scan's second-lowest return within ground_radius_m.
  void hit_rises(std::size_t n_points);
  /// The lower of `z` and the ground remembered in the 3×3 columns round window column
  /// (cx, cy) by scans at most `max_age` scans old, as a height along up_ (hit_rises()).
  [[nodiscard]] float lowest_remembered(int cx, int cy, std::uint32_t max_age, float z) const;
  /// The ground the low objects' clearing reads: this scan's under a column that holds a
  /// return, or the ground remembered round it from any earlier scan where lower (a scan that
  /// sees a kerb's top from behind, without its road, is no evidence that the road rose).
  class ClearingGround final : public LowObjects::GroundMemory {
   public:
    explicit ClearingGround(const OccupancyMap& map) : map_(map) {}
    [[nodiscard]] float ground_z(std::uint32_t column) const override;

   private:
    const OccupancyMap& map_;
  };
  /// One hit per voxel in point order, its static-layer state and its sub-voxel heights.
  void apply_hits(std::span<const Eigen::Vector3f> points_W, OccupancyUpdate& stats);
  /// integrate()'s last step: the misses of the occupied voxels a ray crossed (candidates_),
  /// decided against the map as the free-space misses left it, then applied.
  void miss_occupied(TaskRunner& runner, OccupancyUpdate& stats);
  /// Clears the floor bits of slots [first, first + count) (their log-odds are being rewritten).
  void clear_floor_bits(std::size_t first, std::size_t count);
  /// The brick of a voxel given by its ring coordinates: bricks are 8³ voxels of ring space
  /// (a brick never straddles the ring's wrap; the last along an axis may be thinner).
  [[nodiscard]] std::size_t brick_of_ring(int rx, int ry, int rz) const {
    return (static_cast<std::size_t>(rz >> kBrickShift) * bricks_.y() +
            static_cast<std::size_t>(ry >> kBrickShift)) *
               bricks_.x() +
           static_cast<std::size_t>(rx >> kBrickShift);
  }
  /// Flags the brick of `slot` as holding an occupied voxel (first_occupied() reads it);
  /// update_brick_skips() must run before the next walk.
  void flag_brick(std::size_t slot);
  /// Whether brick `b` (brick_of_ring()) is flagged.
  [[nodiscard]] bool brick_flagged(std::size_t b) const {
    return ((brick_bits_[b >> 6] >> (b & 63)) & 1U) != 0;
  }
  /// Recomputes the flags of the next `rows` rows of bricks (round robin) from the log-odds, so
  /// that bricks whose occupied voxels were cleared stop costing the walk time.
  void refresh_bricks(int rows);
  /// brick_skip_ from the flags.
  void update_brick_skips();

  OccupancyParams params_;
  int walk_lanes_ = 8;
  Eigen::Vector3i dims_;
  VoxelIndex min_;
  float l_hit_, l_miss_, l_min_, l_max_;
  std::vector<float> log_odds_;
  std::vector<std::uint8_t> rise_cm_;  ///< see ring_layer_rise_cm()
  /// Per voxel, slot order: the height of its lowest return since it last read free or
  /// unknown, in 32nds of the voxel above its bottom (0..31; 0xff: none). Decides the misses of
  /// undersides (miss_occupied()).
  std::vector<std::uint8_t> hit_floor_;
  ScanRays scan_rays_;           ///< the rays of the scan being integrated, by direction
  bool has_no_returns_ = false;  ///< the scan being integrated has beams without a return
  /// Static layer state per voxel, slot order: bit 7 static; bits 0..6 the consecutive hits
  /// (not static) or consecutive free observations (static). Non-zero only where the log-odds
  /// read occupied, so the apply pass reads it only for occupied voxels.
  std::vector<std::uint8_t> state_;
  std::unique_ptr<StaticStore> static_;  ///< the site-wide static layer (sparse bit blocks)
  /// Per apply task: the voxels reading occupied that a ray crossed this scan (slots), and per
  /// such voxel (the tasks' lists in order) whether it gets its miss.
  std::vector<std::vector<std::uint32_t>> candidates_;
  std::vector<std::uint8_t> miss_decision_;
  std::vector<std::vector<std::uint32_t>> kept_;  ///< per slab task, leaving slots kept as static
  std::vector<std::uint64_t> taken_keys_;         ///< take_static_columns' scratch
  /// Per scan: the lowest and second-lowest return heights per window column (m along the up
  /// axis, +inf where none) and the columns that hold one (reset next scan).
  std::vector<float> scan_ground_z_, scan_ground2_z_;
  /// Per scan, for the columns that hold a return: the ground under a return's rise, the
  /// second-lowest return within ground_radius_m (see hit_rises()).
  std::vector<float> scan_ground_near_z_;
  std::vector<std::uint32_t> scan_ground_cols_;  ///< the first n_ground_cols_ (no per-scan fill)
  /// Per window column, ring order: the ground of the latest scan that returned densely round
  /// it (kDenseColumns of the columns within ground_radius_m), as a map-frame z, and that
  /// scan's number (hit_rises()). Rises read it for kGroundMemoryScans scans, the costmap's
  /// ground (remembered_ground_z()) for as long as it lasts; forgotten when the column leaves
  /// the window.
  std::vector<float> ground_memory_z_;
  std::vector<std::uint32_t> ground_memory_scan_;
  static constexpr int kDenseColumns = 4;
  static constexpr std::uint32_t kGroundMemoryScans = 10;
  static constexpr float kGroundAgreeM = 0.03f;
  std::uint32_t scans_integrated_ = 0;  ///< integrate() calls (the memory's clock)
  LowObjects low_objects_;
  Eigen::Vector3f up_ = Eigen::Vector3f::UnitZ();  ///< the scan being integrated's up axis
  std::size_t n_ground_cols_ = 0;
  /// Per-scan marks, one bit per window voxel in slot order: the voxels this scan's returns hit,
  /// and, per ray task, the voxels its rays passed through. A bit set costs far less memory
  /// traffic than a list of visits (a 400×400×40 window is 0.8 MB of bits, cache-resident), and
  /// membership is all that decides an update, so the result is independent of ray order.
  std::vector<std::uint64_t> hit_bits_;
  /// One bit per window voxel, slot order: set only where the voxel reads free at the lower
  /// clamp (log-odds == min_log_odds(), not static), where a miss changes nothing. Most of the
  /// free space a scan passes through has been observed free scan after scan; the apply pass
  /// skips it without reading its log-odds. Every other write of a voxel's log-odds clears
  /// its bit (a clear bit says nothing).
  std::vector<std::uint64_t> floor_bits_;
  /// One bit per window column, ring order: the columns the scan being integrated changed
  /// (integrate()'s ChangedColumns; cleared as the next scan starts).
  std::vector<std::uint64_t> changed_columns_;
  /// Per voxel the hit pass updates (hit_slots_' order): its log-odds and rise before the scan,
  /// to tell whether the hits changed it.
  std::vector<float> hit_before_;
  std::vector<std::uint8_t> hit_rise_before_;
  std::vector<std::vector<std::uint64_t>> free_bits_;
  /// Large windows only: per ray task, one bit per mark word its rays marked (a word of these
  /// covers 4096 voxels), so the apply pass reads only those words.
  std::vector<std::vector<std::uint64_t>> dirty_words_;
  /// track_column_observations(): per column in ring order, the last observation's stamp;
  /// in_band_[ring layer] when the layer is in the band. Empty when off.
  std::vector<std::int64_t> column_observed_ns_;
  std::vector<std::uint8_t> in_band_;
  int band_lo_ = 0, band_hi_ = -1;
  std::int64_t observation_stamp_ns_ = 0;
  /// Recomputes in_band_ for the window's current ring origin (after it moves in z).
  void update_band();
  std::vector<std::uint32_t> hit_slots_;  ///< the first n_hit_slots_: to clear hit_bits_ after
  std::size_t n_hit_slots_ = 0;           ///< the scan
  /// Per scan: the rays in the order they are walked (by direction), their direction buckets
  /// and the buckets' counts (scratch of the counting sort).
  std::vector<std::uint32_t> ray_order_;
  std::vector<std::uint16_t> ray_bucket_;
  std::vector<std::uint32_t> ray_bucket_count_;
  /// Per return of the scan being integrated: its slot (or none), window column, height along
  /// the up axis and rise above the scan's local ground.
  std::vector<std::uint32_t> hit_slot_;
  std::vector<std::uint32_t> hit_column_;
  std::vector<float> hit_height_;
  std::vector<std::uint8_t> hit_rise_;
  bool placed_ = false;
  /// One bit per brick of 8³ voxels (brick_of_ring()): set wherever a voxel of the brick reads
  /// occupied (and possibly where none does any more). Set as a voxel turns occupied (a hit,
  /// the static layer restored), recomputed a few rows of bricks per scan (refresh_bricks()).
  static constexpr int kBrickShift = 3;
  Eigen::Vector3i bricks_;
  std::vector<std::uint64_t> brick_bits_;
  int brick_refresh_row_ = 0;  ///< the next row of bricks refresh_bricks() recomputes
  /// Per brick: 0 where flagged, else how many bricks in x and y (Chebyshev, round the ring,
  /// within its layer of bricks, at most kMaxBrickSkip) to the nearest flagged one.
  /// first_occupied() crosses the empty bricks round it in one step: most of what a beam
  /// without return passes through is empty, and these 12 KB (default window) stay in cache
  /// where the log-odds (25 MB) do not. They decide how fast the walk goes, never its result.
  std::vector<std::uint8_t> brick_skip_;
  /// Per brick with a skip: how many layers of bricks above it (up) and below it (down), in a
  /// row round the ring, have a skip at least its own at the same x and y: the box of its skip
  /// holds nothing occupied through them too, and the walk crosses them in the same step.
  std::vector<std::uint8_t> brick_run_up_, brick_run_down_;
  bool bricks_dirty_ = false;                    ///< a flag changed since update_brick_skips()
  std::vector<std::uint8_t> brick_row_scratch_;  ///< update_brick_skips()' distances along x
};

/// ln(p / (1 − p)).
float log_odds_of(float probability);
/// 1 / (1 + exp(−l)).
float probability_of(float log_odds);

}  // namespace tarmac::core
