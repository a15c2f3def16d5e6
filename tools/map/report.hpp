// tarmac-map's report of a finished run (report.cpp).
#pragma once

#include "outputs.hpp"
#include "run.hpp"
#include "tarmac/core/mapper.hpp"

namespace tarmac::map_tool {

/// Prints the stage table, the run's summaries and the digests; writes timing.json. 0 or
/// kExitIo.
int report(const Options& opt, const Inputs& in, const core::Mapper& mapper, const Run& run,
           const WindowOutputs& window_out, const TsdfOutputs& tsdf_out);

}  // namespace tarmac::map_tool
