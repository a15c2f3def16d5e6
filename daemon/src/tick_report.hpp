#pragma once
/// @file What each tick reports (DESIGN.md §3): the CycleReport's stages, budgets and inputs and
/// the DiagnosticArray's keys, laid out once from the config so that filling them in the cycle
/// does not allocate, and the DiagnosticArray's verdict on a tick.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "tarmac/config/config.hpp"
#include "tarmac/daemon/reason_counters.hpp"
#include "tarmac/daemon/tsdf_pager.hpp"
#include "tarmac/transport/cycle_report.hpp"

namespace tarmac::daemon {

/// The tick's stages, in the order of CycleReport::stages.
enum Stage : std::size_t {
  kDrain,
  kIngest,
  kIntegrate,
  kTsdf,
  kRebuild,
  kCostmap,
  kEsdfBand,
  kPublish,
  kStageCount
};

/// Fixed window of recent values with percentiles computed on a stack copy (no allocation).
class RecentWindow {
 public:
  void add(double v) {
    values_[next_ % values_.size()] = v;
    ++next_;
  }
  [[nodiscard]] double percentile(double q) const {
    const std::size_t n = std::min<std::size_t>(next_, values_.size());
    if (n == 0) return 0.0;
    std::array<double, 256> copy{};
    std::copy_n(values_.begin(), n, copy.begin());
    const auto k = static_cast<std::size_t>(std::ceil(q * static_cast<double>(n))) - 1;
    const auto at = std::min(k, n - 1);
    std::nth_element(copy.begin(), copy.begin() + static_cast<std::ptrdiff_t>(at),
                     copy.begin() + static_cast<std::ptrdiff_t>(n));
    return copy[at];
  }

 private:
  std::array<double, 256> values_{};
  std::size_t next_ = 0;
};

/// What the DiagnosticArray says besides this tick's CycleReport, gathered by the executor.
struct DiagnosticFacts {
  const double* stage_ms = nullptr;  ///< kStageCount durations
  double jitter_ms = 0.0;
  bool overrun = false;
  bool have_costmap = false;
  std::int64_t newest_stamp_ns = 0;  ///< the newest scan in the costmap (0: none)
  std::uint64_t scans_integrated = 0;
  std::uint64_t drops = 0;
  std::uint64_t rejections = 0;
  std::uint64_t skipped_ticks = 0;
  double stamp_to_publish_p99_ms = 0.0;
  std::size_t pending_scans = 0;
  std::size_t pose_samples = 0;
  std::uint64_t clock_steps = 0;
  /// tsdf.resident_limit_mb > 0: the pager's counts (null: no paging).
  const TsdfPagerStats* paging = nullptr;
};

class TickReport {
 public:
  /// Names the stages with their budgets, the inputs (each sensor, then "pose") and the
  /// DiagnosticArray's keys, and reserves what the tick fills.
  TickReport(const config::Config& config, const std::string& config_hash);

  /// Declares every reason the cycle can count in `drops` and `rejections`, so that each is
  /// reported from the first tick (0 until it happens).
  static void declare_reasons(ReasonCounters& drops, ReasonCounters& rejections);

  [[nodiscard]] transport::CycleReport& report() { return report_; }

  /// Sets the stages' durations, overruns and shed items and the tick's duration; returns
  /// whether the tick or any stage ran over its budget. RT-safe.
  bool set_stages(const double* stage_ms, const std::uint64_t* shed, double cycle_ms);

  /// Fills the DiagnosticArray from this tick's report (set first) and `facts`: ERROR while the
  /// costmap is stale (older than outputs.costmap_max_age_ms, or none yet: the planner is
  /// driving on an old map), WARN while an input is stale or the tick ran over budget, OK
  /// otherwise; the message names what is wrong, with ages. RT-safe.
  const transport::DiagnosticReport& diagnostics(const DiagnosticFacts& facts);

 private:
  static constexpr std::size_t kDiagFixed = 17;
  static constexpr std::size_t kDiagMessageSize = 256;

  /// The fleet's values (fleet.enabled): from report_'s fleet fields.
  void put_fleet();
  /// Index of the first paging pair (after the inputs' pairs), and how many there are.
  [[nodiscard]] std::size_t paging_base() const {
    return kDiagFixed + 2 * report_.input_ages.size();
  }
  std::size_t paging_keys_ = 0;

  transport::CycleReport report_;
  transport::DiagnosticReport diag_;
  double costmap_max_age_ms_;
  bool fleet_;
  std::vector<std::string> diag_peers_;  ///< the peer whose keys hold each fleet pair
};

}  // namespace tarmac::daemon
