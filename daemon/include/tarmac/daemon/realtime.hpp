#pragma once
/// @file Real-time setup of the calling thread, attempted and reported, never required
/// (DESIGN.md §6): CPU affinity, SCHED_FIFO, mlockall. Threads created afterwards inherit the
/// scheduling policy and priority (glibc's default PTHREAD_INHERIT_SCHED).

#include <cstddef>
#include <string>
#include <vector>

namespace tarmac::daemon {

/// Empty on success, else why it failed ("sched_setscheduler: Operation not permitted").
std::string pin_current_thread(int cpu);
std::string set_fifo_priority(int priority);
/// The process's threads (Linux thread ids, ascending), from /proc/self/task.
std::vector<int> thread_ids();
/// The threads created since `before` (a thread_ids() result): e.g. a library's.
std::vector<int> threads_since(const std::vector<int>& before);
/// SCHED_FIFO at `priority` for another thread of this process: 0, or the errno of
/// sched_setscheduler (ESRCH: the thread has ended; EPERM: not allowed).
int set_thread_fifo_priority(int tid, int priority);
/// mlockall(MCL_CURRENT | MCL_FUTURE); then malloc keeps what it has faulted in (no trimming,
/// no per-block mmap) and its heap is grown by `heap_bytes`, faulted in, for the first cycles.
std::string lock_all_memory(std::size_t heap_bytes = 0);

}  // namespace tarmac::daemon
