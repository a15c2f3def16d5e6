#pragma once
/// @file Debris for the ground crew (issue 39): the low objects kept across scans that are small,
/// low, on the ground and apart from other obstacles — what a walk of the apron would pick up,
/// as opposed to a kerb, a wall's foot or a wheel beside a vehicle.
///
/// From the occupancy map's confirmed low objects (low_objects.hpp) and the costmap of the same
/// cycle (its column classes and ground):
///  1. objects whose centres lie within kLinkM of each other chain into one piece (a bag seen
///     from two sides is two objects, one piece);
///  2. a piece is debris when every object of it stands on its column's ground (the costmap's
///     rule for marking it lethal), its highest rise above the ground is at most max_height_m,
///     its own obstacle cells — the obstacle columns 8-connected to its objects' cells — span
///     at most max_footprint_m along x and along y, and no other obstacle column lies within
///     clearance_m of them. A kerb's row and a wall are too long, a wheel joins the vehicle
///     over it, debris beside a cone is not "apart". Two debris pieces closer than clearance_m
///     withhold each other: the costmap still shows both lethal;
///  3. it is listed once some object of it had rising returns in min_scans scans (a spot one
///     scan saw rising is lethal at once; the crew is sent out when a second scan agrees).
/// The id of a piece is the smallest id of its objects: it lasts while that object is kept (a
/// piece that gains an older object takes that object's id).
/// Pure and deterministic; extract_debris allocates only when there are more objects or cells
/// than ever before (DebrisScratch::reserve sizes it at start).

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/core/low_objects.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::core {

struct DebrisParams {
  double max_height_m = 0.3;     ///< highest rise above the ground of a piece that is debris
  double max_footprint_m = 0.5;  ///< its obstacle cells' extent along x and along y, at most
  double clearance_m = 0.5;      ///< no other obstacle column this close to its cells
  /// Listed only once some object of it had rising returns in this many scans: one scan's pair
  /// of returns is enough to make a spot lethal, not to send the crew out to it.
  int min_scans = 2;

  [[nodiscard]] Status validate() const;
};

/// Objects whose centres lie this close (horizontally) are one piece.
inline constexpr double kDebrisLinkM = 0.3;

struct Debris {
  std::uint32_t id = 0;                            ///< the smallest LowObject::id in the piece
  Eigen::Vector2d xy_W = Eigen::Vector2d::Zero();  ///< centre: its objects' returns-weighted mean
  double ground_z_m = 0.0;             ///< map-frame z of the ground under its highest object
  double height_m = 0.0;               ///< highest rise above the ground (m)
  double footprint_m = 0.0;            ///< larger side of its obstacle cells' bounding box (m)
  std::int64_t first_seen_ns = 0;      ///< earliest first_ns of its objects
  std::int64_t last_confirmed_ns = 0;  ///< latest last_ns (a rising return on it)
  std::uint32_t returns = 0;           ///< rising returns on it, all scans
  std::uint32_t scans = 0;             ///< most scans with a rising return on one of its objects
  std::uint32_t objects = 0;           ///< low objects in the piece
};

/// Working memory of extract_debris, kept between calls.
struct DebrisScratch {
  std::vector<std::uint32_t> order;     ///< confirmed objects (indices into all()), by x
  std::vector<std::uint32_t> parent;    ///< union-find over `order`'s slots
  std::vector<std::uint64_t> members;   ///< (piece's root slot << 32) | object index, sorted
  std::vector<std::uint32_t> piece;     ///< one piece's object indices
  std::vector<std::uint32_t> standing;  ///< the costmap cell each of them stands on, as `piece`
  std::vector<std::uint8_t> in_blob;    ///< per costmap cell: part of the piece being tested
  std::vector<std::uint32_t> blob;      ///< that piece's cells
  /// Sizes everything for `objects` low objects and `cells` costmap cells.
  void reserve(std::size_t objects, std::size_t cells);
};

/// Writes the debris of `objects` into `out` (cleared first, capacity kept), in id order.
/// `layers` is the costmap built from the map that holds `objects` (build_costmap).
/// RT-safe once `scratch` and `out` are reserved for the objects' capacity and the cell count.
void extract_debris(const LowObjects& objects, const CostmapLayers& layers,
                    const DebrisParams& params, DebrisScratch& scratch, std::vector<Debris>& out);

}  // namespace tarmac::core
