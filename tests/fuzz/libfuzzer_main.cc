// libFuzzer entry point of one harness; HAPCO_FUZZ_TARGET names its function (CMake).
#include "fuzz_targets.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return hapco::fuzz::HAPCO_FUZZ_TARGET(data, size);
}
