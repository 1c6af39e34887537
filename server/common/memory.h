#pragma once
#include <cstddef>
#include <optional>
#include <string_view>

namespace hapco {

// Peak resident set size of this process so far, in bytes (Linux getrusage).
std::size_t PeakResidentBytes();
// Current resident set size, in bytes (/proc/self/statm); 0 if unavailable.
std::size_t CurrentResidentBytes();

// Memory this process can still take, in bytes: the kernel's MemAvailable (/proc/meminfo),
// lowered to the headroom of the process's cgroup memory limit where it has one (a container's
// --memory: cgroup v2 memory.max - memory.current, or v1 memory.limit_in_bytes -
// memory.usage_in_bytes). Lets a model refuse what it cannot hold instead of being killed by
// the OOM killer half way through its precomputation. std::nullopt if nothing can be read.
std::optional<std::size_t> AvailableMemoryBytes();

// The parts of AvailableMemoryBytes, on file contents (tests): "MemAvailable: N kB" in a
// /proc/meminfo text; a cgroup limit ("max" or a byte count) less its usage.
std::optional<std::size_t> MemAvailableFromMeminfo(std::string_view meminfo);
std::optional<std::size_t> CgroupHeadroom(std::string_view limit, std::string_view usage);

}  // namespace hapco
