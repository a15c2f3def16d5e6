#pragma once
/// @file The open-ground figure for sequences without ground truth (real data): the cells the
/// drive's own returns show as open flat ground, and what the costmap reads there. A cell is open
/// flat ground when it holds at least 3 returns, its highest lies less than 0.25 m above the
/// lowest return within 1 m of it, and nothing within 1 m rises 0.3 m or more above that lowest
/// return (no wall, vehicle or overhang near it). Returns higher than the vehicle's envelope above
/// that lowest return (a hall's ceiling, a canopy) do not count: the vehicle passes under them. A
/// costmap that reads such a cell lethal or inscribed would stop a vehicle on open ground: on
/// slopes, a ground model that does not follow the terrain does exactly that (docs/mapping.md,
/// "Ground").
///
/// A kerb or a low object under 0.25 m passes that test, and the costmap must read it lethal
/// (min_obstacle_height_m, 0.08 m) with its inscribed band round it. So the cycle also counts
/// the open flat ground away from them: within 1 m, no two side-by-side cells whose lowest
/// returns differ by 0.1 m or more (a 50 % grade over one cell: no road's, every kerb's face)
/// and no cell whose own returns spread 0.08 m or more. What reads lethal there has no return
/// to explain it.

#include <cstdint>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/grid2d.hpp"
#include "tarmac/tools/lethal_causes.hpp"

namespace tarmac::tools {

/// What the costmap read on the open flat ground of one cycle.
struct OpenGroundCycle {
  int scan = 0;
  std::size_t cells = 0;      ///< open flat ground cells in the costmap's window
  std::size_t lethal = 0;     ///< of those, reading 100
  std::size_t inscribed = 0;  ///< reading 99
  std::size_t inflated = 0;   ///< reading 1..98
  std::size_t free = 0;       ///< reading 0
  std::size_t unknown = 0;    ///< reading −1
  std::size_t away = 0;  ///< of the open flat ground cells, those away from steps and low returns
  std::size_t away_lethal = 0, away_inscribed = 0;  ///< of those, reading 100 and 99
  /// The lethal cells (all, and those away from steps and low returns) by the rule that made
  /// them lethal, when observe() was given the costmap's rules.
  LethalCauseCounts lethal_by_cause, away_lethal_by_cause;
};

/// Collects the returns of the drive (world frame, cells of the costmap's resolution) and scores
/// costmaps against the open flat ground they show so far.
class OpenGroundTracker {
 public:
  /// `envelope_m`: the vehicle's height and clearance (costmap.vehicle_height_m + clearance_m).
  OpenGroundTracker(double cell_m, double envelope_m) : cell_m_(cell_m), envelope_m_(envelope_m) {}
  /// One scan's returns in the world frame (z up).
  void add(std::span<const Eigen::Vector3f> points_W);
  /// Scores `costmap` (values 0..100, −1; resolution cell_m, origin a lattice point) against the
  /// open flat ground of the returns added so far. `causes`, when known, are the costmap's
  /// rules: its lethal cells are then counted by the rule that made them lethal.
  const OpenGroundCycle& observe(const core::Grid2D<std::int8_t>& costmap, int scan,
                                 const LethalCauseView& causes = {});
  [[nodiscard]] const std::vector<OpenGroundCycle>& cycles() const { return cycles_; }
  /// The last observed window as RGB, rows top (max y) to bottom, 3 bytes per cell: open flat
  /// ground by what the costmap read there (lethal red, inscribed orange, inflated yellow, free
  /// green, unknown blue), other cells with returns grey, cells without any black.
  [[nodiscard]] std::vector<std::uint8_t> render(std::uint32_t& width, std::uint32_t& height) const;

 private:
  struct Cell {
    std::vector<float> z;  ///< the returns' heights, sorted when `sorted`
    bool sorted = true;
  };
  double cell_m_, envelope_m_;
  std::unordered_map<std::int64_t, Cell> cells_;
  std::vector<OpenGroundCycle> cycles_;
  std::vector<const std::vector<float>*> window_;  ///< observe()'s cells, with a margin
  std::vector<std::uint8_t>
      step_;  ///< per window_ cell: a step to a side neighbour, or low returns
  /// The last observed window's cells: kNone, kReturns, or the costmap's read of open ground.
  std::vector<std::uint8_t> last_;
  std::uint32_t last_width_ = 0, last_height_ = 0;
};

/// The one-line summary tarmac-map prints ("open flat ground (...)"), no newline.
std::string open_ground_summary(const OpenGroundTracker& tracker);
/// The cycles as JSON (tarmac-map's timing.json "open_ground").
nlohmann::ordered_json open_ground_json(const OpenGroundTracker& tracker);

}  // namespace tarmac::tools
