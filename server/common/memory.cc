#include "common/memory.h"

#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>

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

}  // namespace hapco
