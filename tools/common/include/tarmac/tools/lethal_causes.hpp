#pragma once
/// @file Why a costmap's lethal cells are lethal, counted by the costmap rule that made each one
/// (core::obstacle_rule): what tarmac-map's reports say of the lethal cells on the open flat
/// ground of a real drive and of the false lethal cells in tarmac-sim's scenes.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "tarmac/core/grid2d.hpp"

namespace tarmac::tools {

/// What a lethal cell is counted under: the first of these that holds for it.
enum class LethalCause : std::uint8_t {
  kVoxel,      ///< an occupied voxel in the envelope (core::obstacle_rule::kVoxel)
  kDrop,       ///< the ground falls away there (kDrop)
  kRise,       ///< its latest returns rise over their scan's ground next to them (kRise)
  kLowObject,  ///< a confirmed low object, kept across scans (kLowObject)
  kPeer,       ///< a peer's obstacle (kPeer)
  kZone,       ///< a virtual zone (core::ColumnClass::kVirtual)
  kOther,      ///< none of those: an unknown cell under costmap.unknown_cost: lethal
};
inline constexpr std::size_t kLethalCauses = 7;

/// Its name in the reports: "voxel", "drop", "rise", "low_object", "peer", "zone", "other".
std::string_view lethal_cause_name(LethalCause cause);

/// A costmap's column classes and obstacle rules (core::CostmapLayers::column_class,
/// obstacle_rule), row-major on the costmap's cells. Empty: not known (a costmap received over
/// DDS carries neither), and nothing is counted.
struct LethalCauseView {
  std::span<const std::uint8_t> column_class, obstacle_rule;

  [[nodiscard]] bool known() const {
    return !obstacle_rule.empty() && column_class.size() == obstacle_rule.size();
  }
  /// The cause of lethal cell `cell`. @pre known() and cell in range
  [[nodiscard]] LethalCause of(std::size_t cell) const;
};

/// Lethal cells counted by cause.
struct LethalCauseCounts {
  std::array<std::size_t, kLethalCauses> cells{};

  /// Counts cell `cell` of `view` when the view is known.
  void add(const LethalCauseView& view, std::size_t cell) {
    if (view.known()) ++cells[static_cast<std::size_t>(view.of(cell))];
  }
  LethalCauseCounts& operator+=(const LethalCauseCounts& other);
  [[nodiscard]] std::size_t total() const;
  /// "voxel 61.2 %, rise 38.8 %": each cause's share of the total, the causes with no cell left
  /// out; "none" when nothing was counted.
  [[nodiscard]] std::string shares() const;
  /// {"voxel": n, "drop": n, ...}: every cause, in the enum's order.
  [[nodiscard]] nlohmann::ordered_json json() const;
};

/// The costmap as RGB, rows top (max y) to bottom, 3 bytes per cell: each lethal cell in the
/// colour of its cause (kLethalCauseColour), unknown cells slate, the others light grey.
/// tarmac-map's obstacle_rule.png. @pre view.known(), on the costmap's cells
std::vector<std::uint8_t> render_lethal_causes(const core::Costmap& costmap,
                                               const LethalCauseView& view);
/// Per cause, in the enum's order: voxel black, drop purple, rise orange, low object red, peer
/// cyan, zone magenta, other grey.
inline constexpr std::uint8_t kLethalCauseColour[kLethalCauses][3] = {
    {0, 0, 0},     {130, 40, 200}, {240, 140, 0},  {220, 30, 30},
    {0, 170, 200}, {200, 0, 200},  {110, 110, 110}};

}  // namespace tarmac::tools
