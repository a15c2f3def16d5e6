// Compiled into every executable of the ThreadSanitizer build (tools/sanitize.sh thread; see the
// top-level CMakeLists.txt): OpenVDB's parallel algorithms run on the thread that calls them.
// Debian's libtbb is not instrumented, so TSan cannot see how it hands tasks to its workers and
// reports every parallel OpenVDB call as a race inside TBB's headers. Run serially, OpenVDB's
// code stays on tarmac's threads and TSan still checks it against them; a suppression of TBB's
// frames would also hide a real race of tarmac's on a grid that OpenVDB reads in a task.
#include <oneapi/tbb/global_control.h>

namespace {

const oneapi::tbb::global_control serial_tbb(oneapi::tbb::global_control::max_allowed_parallelism,
                                             1);

}  // namespace
