#pragma once
// tarmac-fleet's pieces (docs/fleet.md "Site view"): the fused site-wide occupancy of every
// vehicle's summaries, its files, and the recording format.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "tarmac/core/fleet_bev.hpp"
#include "tarmac/core/result.hpp"

namespace tarmac::fleet {

/// The site at one time: every cell any vehicle's summary holds, the freshest observation of
/// each (BevPeers::lookup), on the lattice box that covers all their tiles. Row 0 is the
/// lowest y.
struct SiteView {
  std::int64_t i0 = 0, j0 = 0;  ///< lattice index of cell (0, 0)
  std::uint32_t width = 0, height = 0;
  double resolution_m = 0.2;
  std::int64_t now_ns = 0;
  std::vector<std::string> vehicles;  ///< by index, sorted
  std::vector<std::int8_t> state;     ///< −1 unknown, 0 free, 100 occupied
  std::vector<std::int8_t> vehicle;   ///< index into vehicles, −1 none
  std::vector<float> age_s;           ///< now − observation, −1 unknown
};

/// The view of `peers` at `now_ns` (cells older than the peers' max age read unknown).
SiteView make_site_view(const core::BevPeers& peers, std::int64_t now_ns);

/// site.npy (int8 states), site_vehicle.npy (int8), site_age_s.npy (float32), site.png (free
/// cells in their vehicle's colour, paler with age; occupied dark in it; unknown grey; north up)
/// and site.json (geometry, vehicles with their counts) into `dir`.
core::Status write_site_view(const SiteView& view, const core::BevPeers& peers,
                             const std::filesystem::path& dir);

/// A recording: summaries as received, one after another, in a file of our own ("TFBR" v1,
/// little endian: vehicle id, stamp, sequence, keyframe, resolution, tiles with their runs).
class Recorder {
 public:
  static core::Result<Recorder> open(const std::filesystem::path& file);
  core::Status append(const core::BevMessage& message);

 private:
  Recorder(std::filesystem::path file, std::ofstream out)
      : file_(std::move(file)), out_(std::move(out)) {}
  std::filesystem::path file_;
  std::ofstream out_;  // open for the recording's life: one write per summary
};

/// Every summary of a recording, in file order. A truncated or malformed file is an error that
/// names the offset.
core::Result<std::vector<core::BevMessage>> read_recording(const std::filesystem::path& file);

}  // namespace tarmac::fleet
