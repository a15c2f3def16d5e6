// The child process of the StopSignals tests (executor_stop_test.cpp). It installs StopSignals,
// writes one byte to READY_FD once set up, then plays one part until SIGTERM ends it:
//   tarmac-stop-signals-child startup READY_FD   still starting up: SIGTERM exits 0 at once
//   tarmac-stop-signals-child running READY_FD   a loop that polls the stop, then "saves" for
//                                                longer than the grace: exits 42 on SIGTERM
//   tarmac-stop-signals-child stuck READY_FD     a stage that never returns: exits 70 after
//                                                StopSignals::kStopGrace
// Exit 99: the part ran to its end, which the test counts as a failure. A process of its own
// (fork and exec), not a forked copy of the test binary: StopSignals starts a thread, and a
// forked copy of a multi-threaded process may not start threads (POSIX; ThreadSanitizer refuses
// it). Every process that loads OpenVDB is multi-threaded from its start (log4cplus's pool).

#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <string>
#include <thread>

#include "tarmac/daemon/stop_signals.hpp"

namespace {

using namespace std::chrono_literals;
using tarmac::daemon::StopSignals;

void report_ready(int fd) {
  (void)!write(fd, "r", 1);
  close(fd);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) return 2;
  const std::string part = argv[1];
  const int ready = std::atoi(argv[2]);
  if (part == "startup") {
    StopSignals::install();
    report_ready(ready);
    std::this_thread::sleep_for(10s);  // "creating the participant", "loading the TSDF"
  } else if (part == "running") {
    StopSignals& stop = StopSignals::install();
    stop.begin_loop();
    report_ready(ready);
    while (!stop.requested()) std::this_thread::sleep_for(1ms);
    stop.loop_ended();
    // The save on exit may take longer than the grace: nothing ends the process meanwhile.
    std::this_thread::sleep_for(StopSignals::kStopGrace + 300ms);
    _exit(stop.signal() == SIGTERM ? 42 : 43);
  } else if (part == "stuck") {
    StopSignals::install().begin_loop();
    report_ready(ready);
    std::this_thread::sleep_for(10s);  // a stage that never returns
  } else {
    return 2;
  }
  _exit(99);
}
