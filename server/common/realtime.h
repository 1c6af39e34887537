#pragma once
// Real-time helpers for the 1 kHz processes (server, phantom).
#include <cstdint>

namespace hapco {

// SCHED_FIFO at `priority` (1..99) for the calling thread; call it before creating the DDS
// participant so Cyclone's threads inherit it (platform-notes.md: chrt -f 80 cut the max round
// trip from ~12 ms to ~1.4 ms on the shared machine). 0 = leave the policy alone. Without the
// privilege it prints one warning ("PROGRAM: SCHED_FIFO ... not available") and carries on.
void UseRealtimePriority(int priority, const char* program);

// CLOCK_MONOTONIC now, ns.
std::int64_t MonotonicNowNs();

}  // namespace hapco
