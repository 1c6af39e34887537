// The surface ahead of a separated tool (sim/surface_ahead.h) against full steps: from the
// probed pose, moving the device by gap − ε along −normal gives no contact force and by gap + ε
// a force along the normal (the step's own detection and solve, an independent path), for the
// tool above the bar's top face, beside its side face and beyond its clamped end face.
#include "sim/surface_ahead.h"

#include <gtest/gtest.h>

#include <vector>

#include "sim/local_model.h"
#include "sim/step_pipeline.h"
#include "coarse_test_scene.h"

namespace hapco::sim {
namespace {

constexpr double kEpsilonM = 2e-5;  // well above round-off, below any mesh feature

// Force after one step from a fresh session at d (the tool translated, nothing loaded before).
Eigen::Vector3d ForceAt(const TwoBodyModel& model, const Eigen::Vector3d& d) {
  TwoBodySession session(model);
  const StepOutput& out = session.Step(d);
  EXPECT_EQ(out.status, contact::SolverStatus::kConverged);
  return out.device_force_n;
}

struct Case {
  const char* name;
  Eigen::Vector3d start_m;          // a separated pose
  Eigen::Vector3d expected_normal;  // the face the tool must meet first
  double expected_gap_m;            // from the geometry of the boxes
};

TEST(SurfaceAhead, GapAndNormalMatchTheFirstContactOfFullSteps) {
  // Coarse scene, zero initial gap: tool 20 x 20 x 10 mm at x in [40, 60] mm on the
  // 100 x 20 x 20 mm bar.
  const TwoBodyModel model(testing::CoarseTestScene(0.3));
  SurfaceAheadProbe probe(model, 0.01);
  const Case cases[] = {
      {"above the top face", {0.003, 0.0, 0.002}, Eigen::Vector3d::UnitZ(), 0.002},
      // Tool beside the bar (y from 23 to 43 mm), its bottom 5 mm below the top face.
      {"beside the side face", {0.0, 0.023, -0.005}, Eigen::Vector3d::UnitY(), 0.003},
      // Tool beyond the clamped end x = 100 mm (x from 104 to 124 mm), its bottom 5 mm below
      // the top face.
      {"beyond the end face", {0.064, 0.0, -0.005}, Eigen::Vector3d::UnitX(), 0.004},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    ASSERT_TRUE(ForceAt(model, c.start_m).isZero()) << "the start pose must be separated";
    const SurfaceAhead& ahead = probe.Probe(c.start_m);
    ASSERT_TRUE(ahead.found);
    EXPECT_NEAR(ahead.gap_m, c.expected_gap_m, 1e-9);
    EXPECT_NEAR(ahead.normal_device.dot(c.expected_normal), 1.0, 1e-9);
    // Full steps: just short of the gap no force, just past it a force along the normal.
    const Eigen::Vector3d before = ForceAt(model, c.start_m - (ahead.gap_m - kEpsilonM) * ahead.normal_device);
    const Eigen::Vector3d after = ForceAt(model, c.start_m - (ahead.gap_m + kEpsilonM) * ahead.normal_device);
    EXPECT_TRUE(before.isZero()) << before.transpose();
    ASSERT_GT(after.norm(), 0.0);
    EXPECT_GT(after.normalized().dot(ahead.normal_device), 0.9) << after.transpose();
  }
}

TEST(SurfaceAhead, NothingWithinReachIsNotFound) {
  const TwoBodyModel model(testing::CoarseTestScene(0.3));
  SurfaceAheadProbe probe(model, 0.005);
  EXPECT_FALSE(probe.Probe(Eigen::Vector3d(0.0, 0.0, 0.008)).found);  // 8 mm above, reach 5 mm
  EXPECT_TRUE(probe.Probe(Eigen::Vector3d(0.0, 0.0, 0.004)).found);
  EXPECT_FALSE(probe.Probe(Eigen::Vector3d(0.0, 0.0, std::nan(""))).found);
}

TEST(SurfaceAhead, TheLocalModelCarriesItOnlyWithoutContactForce) {
  const TwoBodyModel model(testing::CoarseTestScene(0.3));
  TwoBodySession session(model);
  LocalModelBuilder builder;
  session.Step(Eigen::Vector3d(0.0, 0.0, 0.003));
  const LocalContactModel& apart = builder.Linearize(session);
  EXPECT_TRUE(apart.surface_ahead);
  EXPECT_NEAR(apart.surface_gap_m, 0.003, 1e-9);
  EXPECT_NEAR(apart.surface_normal.z(), 1.0, 1e-9);
  session.Step(Eigen::Vector3d(0.0, 0.0, -0.0005));
  const LocalContactModel& pressed = builder.Linearize(session);
  EXPECT_FALSE(pressed.surface_ahead);
  EXPECT_GT(pressed.device_force_n.z(), 0.0);
  // A builder with no reach never probes.
  LocalModelBuilder without(0.0);
  session.Step(Eigen::Vector3d(0.0, 0.0, 0.003));
  EXPECT_FALSE(without.Linearize(session).surface_ahead);
}

TEST(SurfaceAhead, TheBuildersReusedSearchAgreesWithAFreshOne) {
  // The builder searches again only every 0.5 mm or 20 steps and translates the last result in
  // between: along a hovering path with 0.1 mm steps (above the top face, then beside the side
  // face) its gap equals a fresh search at every pose.
  const TwoBodyModel model(testing::CoarseTestScene(0.3));
  TwoBodySession session(model);
  LocalModelBuilder builder;
  SurfaceAheadProbe fresh(model, LocalModelBuilder::kDefaultSurfaceReachM);
  std::vector<Eigen::Vector3d> path;
  for (int k = 0; k <= 60; ++k) path.emplace_back(1e-4 * k, 0.0, 0.004 - 5e-5 * k);  // 4 -> 1 mm above
  for (int k = 0; k <= 50; ++k) path.emplace_back(0.0, 0.026 - 1e-4 * k, -0.005);     // 6 -> 1 mm beside
  int steps = 0;
  for (const Eigen::Vector3d& d : path) {
    session.Step(d);
    const LocalContactModel& m = builder.Linearize(session);
    const SurfaceAhead& f = fresh.Probe(d);
    ASSERT_TRUE(f.found) << d.transpose();
    ASSERT_TRUE(m.surface_ahead) << d.transpose();
    EXPECT_NEAR(m.surface_gap_m, f.gap_m, 1e-12) << d.transpose();
    EXPECT_NEAR((m.surface_normal - f.normal_device).norm(), 0.0, 1e-12);
    ++steps;
  }
  EXPECT_EQ(steps, 112);
}

}  // namespace
}  // namespace hapco::sim
