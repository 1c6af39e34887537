// Recording files (framed, checksummed records; torn tails, damage, resync).
#include <string_view>

#include "common/error.h"
#include "fuzz_targets.h"
#include "io/recording.h"

namespace hapco::fuzz {

int Recording(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  io::RecordingReadReport report;
  try {
    const auto records = io::ParseRecording(bytes, "fuzz.rec", &report);
    HAPCO_FUZZ_CHECK(report.records == static_cast<std::int64_t>(records.size()), "report miscounts records");
    HAPCO_FUZZ_CHECK(report.skipped_bytes >= 0 && report.torn_tail_bytes >= 0, "negative byte counts");
    HAPCO_FUZZ_CHECK(static_cast<std::size_t>(report.skipped_bytes + report.torn_tail_bytes) <= size,
                     "report skips more bytes than the file has");
    HAPCO_FUZZ_CHECK(report.torn_tail == (report.torn_tail_bytes > 0), "torn tail flag and bytes disagree");
    (void)report.Summary();
  } catch (const InputError&) {
  }
  return 0;
}

}  // namespace hapco::fuzz
