#pragma once
// FNV-1a, 64 bit: a fixed hash of bytes, the same in every build (std::hash need not be).
// For cache keys, change detection and rendezvous weights, not for security. Hash several
// pieces by chaining: Fnv1a64(second, Fnv1a64(first)).
#include <cstdint>
#include <string_view>

namespace hapco {

inline constexpr std::uint64_t kFnv1a64Offset = 1469598103934665603ULL;

inline std::uint64_t Fnv1a64(std::string_view bytes, std::uint64_t hash = kFnv1a64Offset) {
  for (const char c : bytes) {
    hash ^= static_cast<unsigned char>(c);
    hash *= 1099511628211ULL;
  }
  return hash;
}

}  // namespace hapco
