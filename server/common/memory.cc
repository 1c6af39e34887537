#include "common/memory.h"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <initializer_list>
#include <string>

namespace hapco {

std::size_t PeakResidentBytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::size_t>(usage.ru_maxrss) * 1024;  // ru_maxrss is in KiB on Linux.
}

std::size_t CurrentResidentBytes() {
  std::FILE* file = std::fopen("/proc/self/statm", "r");
  if (file == nullptr) return 0;
  unsigned long total_pages = 0, resident_pages = 0;
  const int read = std::fscanf(file, "%lu %lu", &total_pages, &resident_pages);
  std::fclose(file);
  if (read != 2) return 0;
  return static_cast<std::size_t>(resident_pages) * static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
}

namespace {

std::optional<std::size_t> ParseCount(std::string_view text) {
  const auto begin = text.find_first_of("0123456789");
  if (begin == std::string_view::npos) return std::nullopt;
  std::size_t value = 0;
  const auto [end, error] = std::from_chars(text.data() + begin, text.data() + text.size(), value);
  if (error != std::errc()) return std::nullopt;
  return value;
}

std::optional<std::string> ReadFile(const std::string& path) {
  std::ifstream file(path);
  if (!file) return std::nullopt;
  std::ostringstream text;
  text << file.rdbuf();
  return text.str();
}

// "cpu,cpuacct" lists "cpu" but not "cpuacc".
bool ListsController(std::string_view controllers, std::string_view name) {
  while (!controllers.empty()) {
    const auto comma = controllers.find(',');
    if (controllers.substr(0, comma) == name) return true;
    if (comma == std::string_view::npos) break;
    controllers.remove_prefix(comma + 1);
  }
  return false;
}

}  // namespace

std::optional<std::size_t> MemAvailableFromMeminfo(std::string_view meminfo) {
  const auto at = meminfo.find("MemAvailable:");
  if (at == std::string_view::npos) return std::nullopt;
  const auto line_end = meminfo.find('\n', at);
  const auto kib = ParseCount(meminfo.substr(at, line_end == std::string_view::npos ? std::string_view::npos : line_end - at));
  if (!kib) return std::nullopt;
  return *kib * 1024;
}

std::optional<std::size_t> CgroupHeadroom(std::string_view limit, std::string_view usage) {
  if (limit.find("max") != std::string_view::npos) return std::nullopt;  // v2: no limit
  const auto limit_bytes = ParseCount(limit);
  const auto usage_bytes = ParseCount(usage);
  if (!limit_bytes || !usage_bytes) return std::nullopt;
  // v1 reports "no limit" as a huge page-rounded number (9223372036854771712).
  if (*limit_bytes >= (std::size_t{1} << 60)) return std::nullopt;
  return *limit_bytes > *usage_bytes ? *limit_bytes - *usage_bytes : 0;
}

std::optional<std::size_t> AvailableMemoryBytes() {
  std::optional<std::size_t> available;
  const auto lower = [&available](std::optional<std::size_t> bytes) {
    if (bytes) available = available ? std::min(*available, *bytes) : *bytes;
  };
  if (const auto meminfo = ReadFile("/proc/meminfo")) lower(MemAvailableFromMeminfo(*meminfo));
  // The process's cgroup, from /proc/self/cgroup lines "0::/path" (v2) or "N:memory:/path"
  // (v1); inside a container the path is often "/" with the container's own files at the root.
  // The first of `dirs` that has both files.
  const auto lower_by_cgroup = [&lower](std::initializer_list<std::string> dirs, const char* limit_file, const char* usage_file) {
    for (const std::string& dir : dirs) {
      const auto limit = ReadFile(dir + "/" + limit_file), usage = ReadFile(dir + "/" + usage_file);
      if (limit && usage) return lower(CgroupHeadroom(*limit, *usage));
    }
  };
  if (const auto cgroups = ReadFile("/proc/self/cgroup")) {
    std::istringstream lines(*cgroups);
    std::string line;
    while (std::getline(lines, line)) {
      const auto first = line.find(':'), second = line.find(':', first + 1);
      if (first == std::string::npos || second == std::string::npos) continue;
      const std::string_view controllers = std::string_view(line).substr(first + 1, second - first - 1);
      const std::string path = line.substr(second + 1);
      if (controllers.empty()) {
        lower_by_cgroup({"/sys/fs/cgroup" + path, "/sys/fs/cgroup"}, "memory.max", "memory.current");
      } else if (ListsController(controllers, "memory")) {
        lower_by_cgroup({"/sys/fs/cgroup/memory" + path, "/sys/fs/cgroup/memory"}, "memory.limit_in_bytes",
                        "memory.usage_in_bytes");
      }
    }
  }
  return available;
}

}  // namespace hapco
