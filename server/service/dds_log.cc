#include "service/dds_log.h"

#include <dds/dds.h>

#include <atomic>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <utility>

#include "common/realtime.h"
#include "common/token_bucket.h"

namespace hapco::service {
namespace {

constexpr double kBurstLines = 5;
constexpr double kLinesPerMs = 1.0 / 10'000.0;  // one line every 10 s per call site after the burst

struct CallSite {
  TokenBucket bucket;
  std::uint64_t held_back = 0;  // since the last line printed from this site
};

struct Limiter {
  std::mutex mutex;
  std::map<std::pair<std::string, std::uint32_t>, CallSite> sites;  // (file, line)
  std::atomic<std::uint64_t> send_failures{0}, suppressed{0};
};

Limiter& TheLimiter() {
  static Limiter* limiter = new Limiter;  // never destroyed: DDS threads may log during exit
  return *limiter;
}

void LimitedSink(void* user, const dds_log_data_t* data) {
  auto* limiter = static_cast<Limiter*>(user);
  const char* message = data->message != nullptr ? data->message : "";
  if (std::strstr(message, "conn_write") != nullptr && std::strstr(message, "failed") != nullptr) {
    limiter->send_failures.fetch_add(1, std::memory_order_relaxed);
  }
  std::uint64_t held_back = 0;
  {
    std::lock_guard<std::mutex> lock(limiter->mutex);
    CallSite& site = limiter->sites[{data->file != nullptr ? data->file : "", data->line}];
    if (!site.bucket.Take(MonotonicNowNs(), kBurstLines, kLinesPerMs)) {
      ++site.held_back;
      limiter->suppressed.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    held_back = std::exchange(site.held_back, 0);
  }
  std::string line(message, data->size);
  while (!line.empty() && line.back() == '\n') line.pop_back();
  if (held_back > 0) {
    std::fprintf(stderr, "%s (%llu more lines like it held back)\n", line.c_str(),
                 static_cast<unsigned long long>(held_back));
  } else {
    std::fprintf(stderr, "%s\n", line.c_str());
  }
}

}  // namespace

void InstallDdsLogLimiter() {
  static std::once_flag once;
  std::call_once(once, [] { dds_set_log_sink(&LimitedSink, &TheLimiter()); });
}

std::uint64_t DdsSendFailuresLogged() { return TheLimiter().send_failures.load(std::memory_order_relaxed); }

std::uint64_t DdsLogLinesSuppressed() { return TheLimiter().suppressed.load(std::memory_order_relaxed); }

}  // namespace hapco::service
