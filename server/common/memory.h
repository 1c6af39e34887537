#pragma once
#include <cstddef>

namespace hapco {

// Peak resident set size of this process so far, in bytes (Linux getrusage).
std::size_t PeakResidentBytes();
// Current resident set size, in bytes (/proc/self/statm); 0 if unavailable.
std::size_t CurrentResidentBytes();

}  // namespace hapco
