#pragma once
// A token bucket: at most `burst` tokens, refilled at a steady rate; each event takes one, and
// an event that finds none is refused. The server's flood limit on a client's poses
// (service/pose_intake.h) and its log's rate limit (service/server_loop.cc) are both one.
#include <algorithm>
#include <cstdint>

namespace hapco {

struct TokenBucket {
  double tokens = -1.0;      // < 0 before the first event: the bucket starts full
  std::int64_t last_ns = 0;  // time of the last event, ns (any monotonic clock)

  // Refills for the time since the last event at rate_per_ms tokens per ms, up to burst, then
  // takes a token if there is one: false when there is none (the event is refused).
  bool Take(std::int64_t now_ns, double burst, double rate_per_ms) {
    const double elapsed_ms = static_cast<double>(now_ns - last_ns) * 1e-6;
    tokens = tokens < 0 ? burst : std::min(burst, tokens + elapsed_ms * rate_per_ms);
    last_ns = now_ns;
    if (tokens < 1.0) return false;
    tokens -= 1.0;
    return true;
  }
};

}  // namespace hapco
