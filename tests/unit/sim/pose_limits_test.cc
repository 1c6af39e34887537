// The pose plausibility checks shared by hapco-server's sessions and hapco-sim.
#include "sim/pose_limits.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace hapco::sim {
namespace {

TEST(PoseLimitsTest, ChecksInTheServersOrder) {
  const PoseLimits limits;  // 0.1 m workspace, 2 mm per sequence step
  const AcceptedPose last{10, Eigen::Vector3d(0.01, 0, 0)};
  EXPECT_EQ(CheckPose({0.0115, 0, 0}, 11, last, limits), PoseVerdict::kAccept);
  EXPECT_EQ(CheckPose({std::nan(""), 0, 0}, 11, last, limits), PoseVerdict::kNonFinite);
  EXPECT_EQ(CheckPose({0.2, 0, 0}, 11, last, limits), PoseVerdict::kOutOfWorkspace);
  EXPECT_EQ(CheckPose({0.01, 0, 0}, 10, last, limits), PoseVerdict::kDuplicate);
  EXPECT_EQ(CheckPose({0.01, 0, 0}, 9, last, limits), PoseVerdict::kOutOfOrder);
  EXPECT_EQ(CheckPose({0.015, 0, 0}, 11, last, limits), PoseVerdict::kJump);  // 5 mm in one step
  // A lost pose allows a longer move: 5 mm after a gap of 3 sequence numbers is 1.7 mm/step.
  EXPECT_EQ(CheckPose({0.015, 0, 0}, 13, last, limits), PoseVerdict::kAccept);
  // ... but the gap counts at most 10 times: 25 mm is a jump whatever the gap.
  EXPECT_EQ(CheckPose({0.035, 0, 0}, 1000, last, limits), PoseVerdict::kJump);
  EXPECT_EQ(CheckPose({0.05, 0, 0}, 1, std::nullopt, limits), PoseVerdict::kAccept) << "first pose";
  EXPECT_STREQ(VerdictName(PoseVerdict::kJump), "position jump");
}

}  // namespace
}  // namespace hapco::sim
