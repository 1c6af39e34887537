#pragma once
// A DDS domain that no other test on this machine uses while this one runs.
//
// ctest runs tests in parallel (-j2 in CI), each picking its domain from a hash of its name
// (DomainIdForName): ~200 integration tests in 230 domains share some (a server test and a
// DDS wait-set test hashed to 124), and two such tests running at once would see each other's
// servers and clients. So a test reserves its domain with an advisory lock on a file per
// domain (flock on <tmp>/hapco-test-domains/<id>.lock), starting at its hashed id and taking
// the next free one. The lock is held while this process, or any child it spawned (the file
// descriptor is inherited), still runs; a process that dies releases it. Domains above
// kMaxReservedDomain are left to the ctest tests that name theirs (security 201/202,
// loadtest 217, server CLI 218/219).
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>

#include "service/config.h"

namespace hapco::service {

inline constexpr dds_domainid_t kMaxReservedDomain = 200;

inline dds_domainid_t ReserveTestDomain(std::string_view name) {
  static int held_fd = -1;  // the reservation of the test running now (one at a time per process)
  if (held_fd >= 0) {
    close(held_fd);  // the previous test of this process is over (its children keep theirs)
    held_fd = -1;
  }
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hapco-test-domains";
  std::filesystem::create_directories(dir);
  const dds_domainid_t first = 1 + (DomainIdForName(name) - 1) % kMaxReservedDomain;
  for (dds_domainid_t k = 0; k < kMaxReservedDomain; ++k) {
    const dds_domainid_t domain = 1 + (first - 1 + k) % kMaxReservedDomain;
    const std::string path = (dir / (std::to_string(domain) + ".lock")).string();
    const int fd = open(path.c_str(), O_RDWR | O_CREAT, 0666);
    if (fd < 0) continue;
    if (flock(fd, LOCK_EX | LOCK_NB) == 0) {
      held_fd = fd;
      return domain;
    }
    close(fd);
  }
  throw std::runtime_error("no free DDS domain in 1.." + std::to_string(kMaxReservedDomain) + " (locks in " +
                           dir.string() + ")");
}

}  // namespace hapco::service
