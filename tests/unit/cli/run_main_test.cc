#include "cli/run_main.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include "common/error.h"

namespace hapco::cli {
namespace {

TEST(RunMainTest, MapsErrorsToExitCodes) {
  EXPECT_EQ(RunMain("tool", [] { return 0; }), 0);
  EXPECT_EQ(RunMain("tool", [] { return 2; }), 2);
  testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("tool", []() -> int { throw InputError("bad flag"); }), 1);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "tool: bad flag\n");
  testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("tool", []() -> int { throw std::runtime_error("boom"); }), 3);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "tool: unexpected error: boom\n");
}

TEST(RunMainTest, VersionLineNamesToolAndVersion) {
  const std::string line = VersionLine("hapco-x");
  EXPECT_EQ(line.rfind("hapco-x HapCo ", 0), 0u) << line;
  EXPECT_NE(line.find("(git "), std::string::npos) << line;
}

}  // namespace
}  // namespace hapco::cli
