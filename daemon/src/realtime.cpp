#include "tarmac/daemon/realtime.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>

namespace tarmac::daemon {

namespace {
std::string failure(const char* call, int err) {
  return std::string(call) + ": " + std::strerror(err);
}
}  // namespace

std::string pin_current_thread(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  const int rc = pthread_setaffinity_np(pthread_self(), sizeof set, &set);
  return rc == 0 ? std::string() : failure("pthread_setaffinity_np", rc);
}

std::string set_fifo_priority(int priority) {
  sched_param param{};
  param.sched_priority = priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  return rc == 0 ? std::string() : failure("pthread_setschedparam(SCHED_FIFO)", rc);
}

std::string lock_all_memory() {
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) return {};
  return failure("mlockall", errno);
}

}  // namespace tarmac::daemon
