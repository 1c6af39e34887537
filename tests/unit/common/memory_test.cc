// The memory a process can still take: parsed from /proc/meminfo and cgroup files (texts as
// the kernel writes them), and read on this machine.
#include "common/memory.h"

#include <gtest/gtest.h>

namespace hapco {
namespace {

TEST(MemoryTest, MemAvailableIsReadInKibibytes) {
  const char* meminfo =
      "MemTotal:       24683856 kB\n"
      "MemFree:        22944820 kB\n"
      "MemAvailable:   24188104 kB\n"
      "Buffers:          123456 kB\n";
  EXPECT_EQ(MemAvailableFromMeminfo(meminfo), std::size_t{24188104} * 1024);
  EXPECT_EQ(MemAvailableFromMeminfo("MemTotal: 1 kB\n"), std::nullopt) << "kernels before 3.14 lack the line";
}

TEST(MemoryTest, CgroupHeadroomIsTheLimitLessTheUsage) {
  EXPECT_EQ(CgroupHeadroom("2147483648\n", "536870912\n"), std::size_t{1610612736});  // v2, 2 GiB limit
  EXPECT_EQ(CgroupHeadroom("max\n", "536870912\n"), std::nullopt) << "v2 without a limit";
  EXPECT_EQ(CgroupHeadroom("9223372036854771712\n", "536870912\n"), std::nullopt) << "v1 without a limit";
  EXPECT_EQ(CgroupHeadroom("1000\n", "4096\n"), std::size_t{0}) << "over the limit already";
  EXPECT_EQ(CgroupHeadroom("", "4096\n"), std::nullopt);
}

TEST(MemoryTest, ThisMachineHasSomeMemoryLeftAndNotMoreThanItsResidentSetCouldGrowTo) {
  const std::optional<std::size_t> available = AvailableMemoryBytes();
  ASSERT_TRUE(available.has_value()) << "/proc/meminfo is readable on Linux";
  EXPECT_GT(*available, std::size_t{1} << 20);
  EXPECT_LT(*available, std::size_t{1} << 50);
}

}  // namespace
}  // namespace hapco
