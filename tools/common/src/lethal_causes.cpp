#include "tarmac/tools/lethal_causes.hpp"

#include <algorithm>
#include <cstdio>
#include <numeric>

#include <nlohmann/json.hpp>

#include "tarmac/core/costmap_builder.hpp"
#include "tarmac/tools/array_io.hpp"

namespace tarmac::tools {

std::string_view lethal_cause_name(LethalCause cause) {
  switch (cause) {
    case LethalCause::kVoxel: return "voxel";
    case LethalCause::kDrop: return "drop";
    case LethalCause::kRise: return "rise";
    case LethalCause::kLowObject: return "low_object";
    case LethalCause::kPeer: return "peer";
    case LethalCause::kZone: return "zone";
    case LethalCause::kOther: break;
  }
  return "other";
}

LethalCause LethalCauseView::of(std::size_t cell) const {
  namespace rule = core::obstacle_rule;
  if (column_class[cell] == static_cast<std::uint8_t>(core::ColumnClass::kVirtual)) {
    return LethalCause::kZone;
  }
  const std::uint8_t bits = obstacle_rule[cell];
  return (bits & rule::kVoxel) != 0       ? LethalCause::kVoxel
         : (bits & rule::kDrop) != 0      ? LethalCause::kDrop
         : (bits & rule::kRise) != 0      ? LethalCause::kRise
         : (bits & rule::kLowObject) != 0 ? LethalCause::kLowObject
         : (bits & rule::kPeer) != 0      ? LethalCause::kPeer
                                          : LethalCause::kOther;
}

LethalCauseCounts& LethalCauseCounts::operator+=(const LethalCauseCounts& other) {
  for (std::size_t k = 0; k < kLethalCauses; ++k) cells[k] += other.cells[k];
  return *this;
}

std::size_t LethalCauseCounts::total() const {
  return std::accumulate(cells.begin(), cells.end(), std::size_t{0});
}

std::string LethalCauseCounts::shares() const {
  const std::size_t n = total();
  if (n == 0) return "none";
  std::string out;
  for (std::size_t k = 0; k < kLethalCauses; ++k) {
    if (cells[k] == 0) continue;
    char part[64];
    std::snprintf(part, sizeof part, "%s%s %.1f %%", out.empty() ? "" : ", ",
                  lethal_cause_name(static_cast<LethalCause>(k)).data(),
                  100.0 * static_cast<double>(cells[k]) / static_cast<double>(n));
    out += part;
  }
  return out;
}

nlohmann::ordered_json LethalCauseCounts::json() const {
  nlohmann::ordered_json j = nlohmann::ordered_json::object();
  for (std::size_t k = 0; k < kLethalCauses; ++k) {
    j[std::string(lethal_cause_name(static_cast<LethalCause>(k)))] = cells[k];
  }
  return j;
}

std::vector<std::uint8_t> render_lethal_causes(const core::Costmap& costmap,
                                               const LethalCauseView& view) {
  const std::uint32_t w = costmap.width(), h = costmap.height();
  std::vector<std::uint8_t> rgb(std::size_t{w} * h * 3);
  constexpr std::uint8_t kOtherCell[3] = {230, 230, 230};
  for (std::uint32_t y = 0; y < h; ++y) {
    for (std::uint32_t x = 0; x < w; ++x) {
      const int c = costmap.at(x, y);
      const std::uint8_t* colour =
          c == core::kCostLethal
              ? kLethalCauseColour[static_cast<std::size_t>(view.of(std::size_t{y} * w + x))]
          : c == core::kCostUnknown ? kUnobservedRgb
                                    : kOtherCell;
      std::copy(colour, colour + 3, &rgb[(std::size_t{h - 1 - y} * w + x) * 3]);  // north up
    }
  }
  return rgb;
}

}  // namespace tarmac::tools
