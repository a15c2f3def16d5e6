#pragma once
/// @file Real-time setup of the calling thread, attempted and reported, never required
/// (DESIGN.md §6): CPU affinity, SCHED_FIFO, mlockall. Threads created afterwards inherit the
/// scheduling policy and priority (glibc's default PTHREAD_INHERIT_SCHED).

#include <string>

namespace tarmac::daemon {

/// Empty on success, else why it failed ("sched_setscheduler: Operation not permitted").
std::string pin_current_thread(int cpu);
std::string set_fifo_priority(int priority);
std::string lock_all_memory();

}  // namespace tarmac::daemon
