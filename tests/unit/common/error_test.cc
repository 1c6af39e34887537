#include "common/error.h"

#include <gtest/gtest.h>

namespace hapco {
namespace {

TEST(InputErrorTest, CarriesTheMessage) {
  try {
    throw InputError("scene: obstacle.material.youngs_modulus_pa must be > 0");
  } catch (const std::exception& error) {
    EXPECT_STREQ(error.what(), "scene: obstacle.material.youngs_modulus_pa must be > 0");
  }
}

TEST(AssertDeathTest, FailingAssertionAbortsWithItsMessage) {
  EXPECT_DEATH(HAPCO_ASSERT(1 + 1 == 3, "arithmetic broke"), "arithmetic broke");
}

}  // namespace
}  // namespace hapco
