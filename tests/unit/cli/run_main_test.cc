#include "common/cli.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include "common/error.h"

namespace hapco::cli {
namespace {

TEST(CliTest, ParsesNumbersAndNamesTheFlagOnBadInput) {
  EXPECT_DOUBLE_EQ(ParseDouble("--tol", "1e-6"), 1e-6);
  EXPECT_EQ(ParseInteger("--steps", "42", 1, 100), 42);
  for (const char* bad : {"", "abc", "1e-6x", "nan", "inf"}) {
    try {
      ParseDouble("--tol", bad);
      FAIL() << bad;
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find("--tol expects a number"), std::string::npos);
    }
  }
  EXPECT_THROW(ParseInteger("--steps", "0", 1, 100), InputError);
  EXPECT_THROW(ParseInteger("--steps", "101", 1, 100), InputError);
  EXPECT_THROW(ParseInteger("--steps", "3.5", 1, 100), InputError);
}

TEST(CliTest, RunMainMapsErrorsToExitCodes) {
  EXPECT_EQ(RunMain("tool", [] { return 0; }), 0);
  EXPECT_EQ(RunMain("tool", [] { return 2; }), 2);
  testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("tool", []() -> int { throw InputError("bad flag"); }), 1);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "tool: bad flag\n");
  testing::internal::CaptureStderr();
  EXPECT_EQ(RunMain("tool", []() -> int { throw std::runtime_error("boom"); }), 3);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "tool: unexpected error: boom\n");
}

}  // namespace
}  // namespace hapco::cli
