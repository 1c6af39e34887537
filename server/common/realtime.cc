#include "common/realtime.h"

#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <cstdio>
#include <cstring>

namespace hapco {

void UseRealtimePriority(int priority, const char* program) {
  if (priority <= 0) return;
  sched_param param{};
  param.sched_priority = priority;
  const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
  if (rc != 0) {
    std::fprintf(stderr, "%s: SCHED_FIFO %d not available (%s); running with the normal policy\n", program,
                 priority, std::strerror(rc));
  }
}

std::int64_t MonotonicNowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

}  // namespace hapco
