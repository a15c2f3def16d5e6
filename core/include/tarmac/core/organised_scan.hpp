#pragma once
/// @file Organised scans: a spinning LiDAR's sweep as a grid of rows (beams) by columns (firing
/// azimuths), row-major — a PointCloud2 with height > 1, or the organised files tarmac-sim
/// writes. A cell with a non-finite coordinate, or exactly at the origin (a convention of some
/// drivers), is a beam that returned nothing within the sensor's range.
///
/// Such a beam is evidence too: the air along it is free. The costmap's free-space rule needs it
/// (a column is free only when its whole envelope was observed, and above the sensor only beams
/// into the open sky observe it). The beam's direction is not in the data, so it is rebuilt from
/// the returns of the same scan: a row's elevation is the mean elevation of its returns, a
/// column's azimuth the circular mean of its returns' azimuths. A row or column without returns
/// takes the linear interpolation between the nearest rows (columns, round the circle) that have
/// returns, or the linear extrapolation of the two nearest on one side: beams evenly spaced in
/// elevation beyond the outermost returning ones, as on the sensors tarmac is used with.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "tarmac/core/point_cloud.hpp"

namespace tarmac::core {

/// How an organised cloud's grid lies. Drivers differ: ouster-ros publishes one row per beam
/// (columns in firing order); the Velodyne driver (`organize_cloud: true`) and rslidar_sdk
/// (`ros_send_by_rows: false`) one row per firing, one column per laser.
/// An unorganised cloud that carries a ring (Hesai, Velodyne with `organize_cloud: false`,
/// Autoware's PointXYZIRC) is binned by ring and azimuth instead (bin_by_ring).
enum class SweepLayout : std::uint8_t {
  kRowsAreBeams,
  kRowsAreFirings,
  kUndecided,    ///< neither could be told from the data (or, with rings, no sweep found)
  kRingBinned,   ///< unorganised, organised by ring and azimuth (bin_by_ring)
  kUnorganised,  ///< a list of points without rings: nothing to organise
};

/// What split_organised (organise_sweep) found.
struct OrganisedCounts {
  std::uint64_t returns = 0;     ///< cells with a return (kept as points)
  std::uint64_t no_returns = 0;  ///< cells without a return, direction rebuilt (no_return_S)
  /// Cells without a return whose direction could not be rebuilt (fewer than two rows or no
  /// column with returns in the scan; a beam without any return whose place among the others
  /// is unknown; any cell of an undecided layout): dropped, they clear nothing.
  std::uint64_t underivable = 0;
  SweepLayout layout = SweepLayout::kRowsAreBeams;  ///< organise_sweep: the layout found
  bool beams_reordered = false;  ///< organise_sweep: the beams were not in elevation order
};

/// Buffers for split_organised and organise_sweep, kept by the caller so that steady-state
/// calls do not allocate.
struct OrganisedScratch {
  std::vector<double> row_sum, col_x, col_y, row_angle, col_angle;
  std::vector<std::uint32_t> row_n, col_n;
  std::vector<double> row_sq, col_sum, col_sq;  ///< elevation moments (layout)
  std::vector<std::uint32_t> order;             ///< beams in elevation order
  std::vector<double> key;                      ///< each beam's sort key
  PointCloud moved;                             ///< the grid transposed or its rows permuted
  // bin_by_ring: per ring index, then the returns' azimuths grouped by ring
  std::vector<std::uint32_t> ring_n, ring_start;
  std::vector<std::uint8_t> ring_seen;
  std::vector<double> ring_sum, ring_sq, ring_elevation;
  std::vector<float> azimuth, gaps;
  /// Per azimuth bin: the azimuth of a return there (the lowest ring's), NaN where no ring
  /// returned.
  std::vector<float> covered;
};

/// Decides the layout of the organised `cloud` (rows × cols cells, row-major). With a ring
/// channel: rows are beams when the ring is constant along (nearly) every row and not along the
/// columns, firings in the converse case. Otherwise, or when the ring decides nothing (e.g.
/// always 0): the axis along which the returns' elevation stays put is the beam's — rows are
/// beams when the mean spread of elevation within a row is under a tenth of that within a
/// column, firings in the converse case. kUndecided otherwise, or with fewer than two rows,
/// two columns, or returns in fewer than two rows and two columns.
/// @pre rows * cols == cloud.size() and cloud.consistent()
SweepLayout sweep_layout(const PointCloud& cloud, std::size_t rows, std::size_t cols,
                         OrganisedScratch& scratch);

/// Organises the organised `cloud` (rows × cols cells, row-major, as the driver sent it) as
/// beams × firings and splits it (split_organised):
/// 1. its layout (sweep_layout); rows = firings are transposed;
/// 2. the beams in elevation order (split_organised interpolates between neighbouring beams):
///    by ring when the cloud has one (ring 0 at the top or at the bottom, both monotonic); else
///    kept when the beams' measured elevations are already monotonic, else sorted by them, and
///    the cells of a beam without any return are dropped (its place is unknown);
/// 3. an undecided layout is never guessed: the returns are kept as an unorganised cloud's,
///    the cells without a return dropped (underivable).
/// The channels follow their points. RT-safe once the scratch has grown to the sweep's size.
/// @pre rows * cols == cloud.size() and cloud.consistent()
OrganisedCounts organise_sweep(PointCloud& cloud, std::size_t rows, std::size_t cols,
                               OrganisedScratch& scratch);

/// Organises an unorganised sweep that carries a ring channel: the returns binned by ring and,
/// within a ring, by azimuth, so that a gap in a ring's azimuths becomes beams without return.
/// 1. the horizontal resolution is the median gap between azimuth-neighbouring returns of a
///    ring (dropped returns and dual returns do not move a median);
/// 2. within each ring, a gap of k resolutions between neighbouring returns (round the circle)
///    holds k − 1 beams without return, evenly spaced, at the ring's mean elevation — but only
///    in azimuth bins (of the resolution) where some ring returned, as in both neighbouring
///    bins: the sectors a driver cuts away (a field of view crop, its range filter on every
///    ring at once) are not beams without return, nor is the bin at their edge, where a
///    laser's own azimuth offset could put a beam beyond the others' last return;
/// 3. a ring with no return at all between rings that have some (its cells were all NaN or
///    absent) lies at the elevation interpolated by ring index, when the rings' elevations
///    follow their indices, and has a beam in every azimuth bin where some ring returned, at
///    that return's azimuth;
/// 4. explicit markers (NaN, 0,0,0) leave the points: their cells are gaps like the others.
/// Not a sweep — fewer than two rings with returns, rings whose elevations spread as much
/// within as across them (a cloud merged from several sensors, a ring field that is not the
/// beam), no resolution to be found — leaves the returns unorganised, the markers dropped
/// (underivable), layout kUndecided. The channels follow their points; the directions the
/// sensor took are what the data shows (a driver's per-beam azimuth offsets included).
/// @pre cloud.consistent()
OrganisedCounts bin_by_ring(PointCloud& cloud, OrganisedScratch& scratch);

/// What Mapper::ingest runs on every cloud: an organised sweep (`grid_rows` > 0) by
/// organise_sweep, an unorganised one with a ring by bin_by_ring, any other left as it is; then
/// `organised` is set and `grid_rows` 0. Once `organised`, it does nothing.
/// @pre cloud.consistent()
OrganisedCounts organise(PointCloud& cloud, OrganisedScratch& scratch);

/// Splits the organised `cloud` (rows × cols cells, row-major; its channels as long as its
/// points) in place: the returns stay in `points_S` (and the channels) in their order, the
/// cells without a return leave them and their rebuilt directions (sensor frame, unit, row-major
/// order) replace `no_return_S`.
/// @pre rows * cols == cloud.size() and cloud.consistent()
OrganisedCounts split_organised(PointCloud& cloud, std::size_t rows, std::size_t cols,
                                OrganisedScratch& scratch);

}  // namespace tarmac::core
