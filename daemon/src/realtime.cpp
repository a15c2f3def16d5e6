#include "tarmac/daemon/realtime.hpp"

#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>

#include <dirent.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <iterator>

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

std::vector<int> thread_ids() {
  std::vector<int> ids;
  DIR* dir = opendir("/proc/self/task");
  if (dir == nullptr) return ids;
  while (const dirent* e = readdir(dir)) {
    char* end = nullptr;
    const long id = std::strtol(e->d_name, &end, 10);
    if (end != e->d_name && *end == '\0' && id > 0) ids.push_back(static_cast<int>(id));
  }
  closedir(dir);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::vector<int> threads_since(const std::vector<int>& before) {
  std::vector<int> now = thread_ids(), created;
  std::set_difference(now.begin(), now.end(), before.begin(), before.end(),
                      std::back_inserter(created));
  return created;
}

int set_thread_fifo_priority(int tid, int priority) {
  sched_param param{};
  param.sched_priority = priority;
  return sched_setscheduler(tid, SCHED_FIFO, &param) == 0 ? 0 : errno;
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
