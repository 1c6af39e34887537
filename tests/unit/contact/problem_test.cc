// ValidateProblem: every documented inconsistency is reported with a message naming it.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "common/error.h"
#include "contact/problem.h"
#include "test_problems.h"

namespace hapco::contact {
namespace {

std::string ErrorOf(const ContactProblem& p) {
  try {
    ValidateProblem(p);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(ValidateProblemTest, AcceptsConsistentProblem) {
  EXPECT_NO_THROW(ValidateProblem(testing::RandomSpdProblem(4, 1u)));
}

TEST(ValidateProblemTest, RejectsEachInconsistency) {
  const ContactProblem good = testing::RandomSpdProblem(4, 1u);
  ContactProblem p = good;
  p.flexibility_m_per_n.conservativeResize(11, 11);
  EXPECT_NE(ErrorOf(p).find("3m x 3m"), std::string::npos);

  p = good;
  p.free_displacement_m.conservativeResize(7);
  EXPECT_NE(ErrorOf(p).find("free displacement"), std::string::npos);

  p = good;
  p.friction_coefficient(2) = -0.1;
  EXPECT_NE(ErrorOf(p).find("friction coefficient of contact 2"), std::string::npos);

  p = good;
  p.free_displacement_m(5) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(ErrorOf(p).find("not finite"), std::string::npos);

  p = good;
  p.flexibility_m_per_n(3, 1) = std::numeric_limits<double>::infinity();
  EXPECT_NE(ErrorOf(p).find("W(3,1)"), std::string::npos);

  p = good;
  p.flexibility_m_per_n(6, 6) = -1e-3;
  EXPECT_NE(ErrorOf(p).find("W(6,6)"), std::string::npos);

  p = good;
  p.flexibility_m_per_n(2, 7) += 1e-6;  // relative 1e-3 of the entries: asymmetric
  EXPECT_NE(ErrorOf(p).find("not symmetric"), std::string::npos);

  p = good;
  p.flexibility_m_per_n(2, 7) *= 1.0 + 1e-13;  // round-off level: accepted
  EXPECT_EQ(ErrorOf(p), "");
}

}  // namespace
}  // namespace hapco::contact
