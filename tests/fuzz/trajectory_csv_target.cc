// Trajectory / pose CSV (hapco-phantom --trajectory, hapco-sim --trajectory, server traces).
// The first byte picks the client_id argument; the rest is the file.
#include <string>

#include "common/error.h"
#include "fuzz_targets.h"
#include "io/trajectory_file.h"

namespace hapco::fuzz {

int TrajectoryCsv(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const char* const kClients[4] = {"", "a", "client-1", "phantom_0"};
  const std::string client = kClients[data[0] & 3u];
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    const auto points = io::ParseTrajectoryCsv(text, "fuzz.csv", client);
    HAPCO_FUZZ_CHECK(points.size() >= 2, "accepted a trajectory without rows");
    HAPCO_FUZZ_CHECK(points.front().isZero(), "point 0 is not the origin");
    for (const auto& p : points) HAPCO_FUZZ_CHECK(p.allFinite(), "accepted a non-finite position");
  } catch (const InputError&) {
  }
  return 0;
}

}  // namespace hapco::fuzz
