#pragma once
/// @file Low objects kept across scans (issue 39): debris, a chock, a wheel, a kerb's edge —
/// objects lower than the voxels that separate them from the ground (10 cm debris shares a
/// 20 cm voxel with the ground under it), seen by a few returns a scan that rise above that
/// scan's ground. The voxels cannot hold them: a scan whose returns on the spot all lie low on
/// the object's face (most do: at 15 m a beam lands on a 10 cm face at any height) rewrites the
/// voxel's heights, and rays crossing the empty top of the voxel read it free. Here each object
/// is kept as a point with its evidence:
///  - returns rising at least min_rise_m above their scan's ground, up to max_rise_m (taller
///    objects fill voxels above the ground's, which the costmap reads directly), within
///    match_radius_m of the object's centre are its evidence; lethal_returns of them make it
///    an obstacle in the costmap, confirm_returns of them (in one scan or over several) confirm
///    it;
///  - it is removed only when clear_scans scans in a row, with no rising return on it, each
///    showed its spot empty: a ray that passed its centre (within clear_radius_m, horizontally)
///    lower than its top and went on past it (the rays that would have hit it went past), or a
///    return within 8 cm of its centre lying on the ground, as this scan and the ground
///    remembered round it have it, no more than 4 cm under its top (the ground rose to its
///    top: what rose was ground seen against a wrong reference, e.g. a glossy floor's mirror
///    returns under it). A return on its spot at ground height under its top does not clear it
///    (a beam under its front edge lands there), nor does a beam without a return (a black
///    object returns nothing), nor any time elapsed;
///  - a candidate (fewer returns than confirm) lapses after candidate_scans scans without
///    another: a lone stray return is no object;
///  - objects are kept while their centre is inside the occupancy window.
/// Pure and deterministic, and independent of the order of the scan's returns (a driver's
/// layout): the rising returns are taken in an order of their own.

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/result.hpp"

namespace tarmac::core {

struct LowObjectParams {
  double min_rise_m = 0.08;      ///< costmap.min_obstacle_height_m (the Mapper sets it)
  double max_rise_m = 0.5;       ///< rising returns above this are not low objects'
  double match_radius_m = 0.15;  ///< rising returns this close to a centre are its evidence
  double clear_radius_m = 0.03;  ///< a ray this close to a centre, under its top, saw through
  int lethal_returns = 1;        ///< rising returns that make it lethal (≤ confirm_returns)
  int confirm_returns = 2;       ///< rising returns that make a candidate an object
  int clear_scans = 2;           ///< scans in a row seeing through an object that remove it
  int candidate_scans = 10;      ///< scans a candidate waits for its next rising return
  int capacity = 4096;           ///< objects and candidates kept at most (fixed memory)

  [[nodiscard]] Status validate() const;
};

struct LowObject {
  std::uint32_t id = 0;                            ///< stable while the object is kept
  Eigen::Vector2f xy_W = Eigen::Vector2f::Zero();  ///< centre: mean of its rising returns
  float top_z_W = 0.0f;                            ///< map-frame z of its highest rising return
  float rise_m = 0.0f;                             ///< that return's height above its scan's ground
  std::uint32_t returns = 0;                       ///< rising returns on it, all scans
  std::uint32_t scans = 0;                         ///< scans with a rising return on it
  std::uint32_t first_scan = 0;                    ///< scan numbers (LowObjects::Scan::number)
  std::uint32_t last_scan = 0;                     ///< the latest scan with a rising return on it
  std::int64_t first_ns = 0;                       ///< stamps of those scans
  std::int64_t last_ns = 0;
  std::uint8_t seen_through = 0;  ///< scans in a row that saw through it
};

/// Whether `o` stands on a column whose ground (CostmapLayers::ground_z_m) is `ground_z_m`: its
/// base (top less rise) within one voxel of it. An object's rise is taken above its scan's
/// lowest returns round it, which where the ground went unreturned are a wing's or a roof's.
/// The costmap marks only such objects lethal, and only they can be debris.
inline bool stands_on_ground(const LowObject& o, double ground_z_m, double voxel_m) {
  const double base_z = static_cast<double>(o.top_z_W) - static_cast<double>(o.rise_m);
  return !(std::abs(base_z - ground_z_m) > voxel_m);
}

class LowObjects {
 public:
  /// The ground under a window column that holds a return of the scan being integrated, as a
  /// height along its up axis: the lower of the scan's ground there and the ground remembered
  /// round it from earlier scans (OccupancyMap's). Asked only for the few returns that may show
  /// an object's spot empty.
  class GroundMemory {
   public:
    [[nodiscard]] virtual float ground_z(std::uint32_t column) const = 0;

   protected:
    GroundMemory() = default;
    GroundMemory(const GroundMemory&) = default;
    GroundMemory& operator=(const GroundMemory&) = default;
    ~GroundMemory() = default;
  };

  /// One scan, as OccupancyMap::integrate has it.
  struct Scan {
    static constexpr std::uint32_t kNoColumn = ~std::uint32_t{0};
    Eigen::Vector3f origin_W = Eigen::Vector3f::Zero();
    Eigen::Vector3f up_W = Eigen::Vector3f::UnitZ();  ///< unit
    std::span<const Eigen::Vector3f> points_W;
    /// Per return: its voxel's slot, kNoColumn for none (not finite, beyond range, outside
    /// the window), and where it has one, its window column (y · nx + x).
    std::span<const std::uint32_t> voxel;
    std::span<const std::uint32_t> column;
    std::span<const std::uint8_t> rise_cm;  ///< per return, above its scan's ground
    /// The ground the clearing reads (nullptr: the scan's own, as rise_cm has it).
    const GroundMemory* ground = nullptr;
    std::uint32_t number = 0;  ///< increasing per scan
    std::int64_t stamp_ns = 0;
  };

  /// A window of nx × ny columns of voxel_m; `params` validated.
  LowObjects(const LowObjectParams& params, int nx, int ny, double voxel_m);

  /// The window's lowest column (world voxel indices) for the next update() and for objects().
  /// Objects whose centre leaves the window are dropped.
  void place(int min_x, int min_y);
  void update(const Scan& scan);
  void clear();

  /// Objects and candidates, in the order they were first seen.
  [[nodiscard]] std::span<const LowObject> all() const { return objects_; }
  [[nodiscard]] bool confirmed(const LowObject& o) const {
    return o.returns >= static_cast<std::uint32_t>(params_.confirm_returns);
  }
  /// Whether the costmap reads it as an obstacle (where it stands on the ground): a candidate
  /// too, from lethal_returns, until it lapses.
  [[nodiscard]] bool lethal(const LowObject& o) const {
    return o.returns >= static_cast<std::uint32_t>(params_.lethal_returns);
  }
  /// Rising returns that found no room (capacity reached), since construction.
  [[nodiscard]] std::uint64_t refused() const { return refused_; }
  [[nodiscard]] const LowObjectParams& params() const { return params_; }
  [[nodiscard]] std::size_t memory_bytes() const;

 private:
  /// Window column of a map-frame (x, y), or -1 outside.
  [[nodiscard]] std::int64_t column_of(const Eigen::Vector2f& xy) const;
  /// Links every object into its column's list and flags the columns within kReach of it.
  void index();
  void unindex();
  void add_to_index(std::uint32_t k);
  /// Sets near_ over the columns within kReach of window column c.
  void flag_reach(std::size_t c, std::uint8_t value);
  /// The object within match radius nearest to xy (kNone if none), searching the 3×3 columns.
  [[nodiscard]] std::uint32_t nearest(const Eigen::Vector2f& xy, std::int64_t column) const;
  void evidence(std::uint32_t k, const Eigen::Vector3f& p, float rise_m, const Scan& scan);
  /// Whether the ray origin → q passed object k under its top and went on past it.
  [[nodiscard]] bool sees_through(const LowObject& o, const Eigen::Vector3f& origin,
                                  const Eigen::Vector3f& q, const Eigen::Vector3f& up) const;
  /// Whether return i of `scan` lies on the ground known round it at o's top.
  [[nodiscard]] bool ground_at_top(const LowObject& o, const Scan& scan, std::size_t i) const;
  void expire(const Scan& scan);

  static constexpr std::uint32_t kNone = ~std::uint32_t{0};
  /// Columns round an object whose returns are tested against it (a ray passing a 10 cm top at
  /// 15 m lands up to 0.6 m beyond).
  static constexpr int kReach = 3;

  LowObjectParams params_;
  int nx_, ny_;
  float v_;
  int min_x_ = 0, min_y_ = 0;
  std::vector<LowObject> objects_;
  std::vector<std::uint32_t> head_;            ///< per window column: first object in it, kNone
  std::vector<std::uint32_t> next_;            ///< per object: next in its column
  std::vector<std::uint32_t> indexed_column_;  ///< per object: the column it is listed in
  std::vector<std::uint8_t> near_;  ///< per window column: an object within kReach columns
  std::vector<std::uint8_t> touched_, saw_through_;  ///< per object, this scan
  std::vector<std::uint32_t> rising_;  ///< this scan's rising returns (indices), sorted
  std::uint32_t next_id_ = 1;
  std::uint64_t refused_ = 0;
};

}  // namespace tarmac::core
