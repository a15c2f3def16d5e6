#include "tarmac/daemon/realtime.hpp"

#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstdlib>
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

std::string lock_all_memory(std::size_t heap_bytes) {
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) return failure("mlockall", errno);
  // Memory once faulted in stays with malloc: freed blocks are never trimmed or unmapped, and
  // large blocks come from the heap rather than from an mmap of their own, so a buffer freed and
  // allocated again in a later cycle (a deserialised scan, an outgoing message) costs neither a
  // system call nor page faults. Then the heap is grown by `heap_bytes` now (locked, so faulted
  // in) and handed back to malloc, for the first cycles' allocations.
  mallopt(M_TRIM_THRESHOLD, -1);
  mallopt(M_MMAP_MAX, 0);
  if (heap_bytes > 0) {
    void* block = std::malloc(heap_bytes);
    if (block != nullptr) std::memset(block, 0, heap_bytes);
    std::free(block);
  }
  return {};
}

}  // namespace tarmac::daemon
