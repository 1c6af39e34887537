// The local contact model (sim/local_model.h) against finite differences of full steps: from
// the same previous state, a step to d_k + h e_j changes the device force by about K h e_j.
// Frictionless (every active contact slides with r_t = 0) and mu = 10 (every active contact
// sticks) presses, in all six directions; the error is measured against |K| h (the spectral
// norm), so a direction the model calls stiffless is not divided by zero. The lateral error of
// the sticking press (about 1 %) is the slope of the deformed obstacle under the moving contact
// points, which the model leaves out (local_model.h).
#include "sim/local_model.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include "contact/solver.h"
#include "sim/step_pipeline.h"
#include "coarse_test_scene.h"

namespace hapco::sim {
namespace {

SceneSpec CoarseScene(double friction) {
  SceneSpec scene = testing::CoarseTestScene(friction);
  scene.solver = contact::SolverKind::kReferenceNsgs;
  scene.solver_parameters.global_tolerance_m = 1e-13;  // far below h = 1e-7 m times |W| / |W|
  scene.solver_parameters.fc3d_tolerance = 1e-12;
  scene.solver_parameters.max_iterations = 100000;
  scene.solver_parameters.warm_start = true;
  return scene;
}

// Press 0.5 mm in 20 steps, then slide +x by `slide_steps` steps of 20 um.
std::vector<Eigen::Vector3d> PressAndSlide(int slide_steps) {
  std::vector<Eigen::Vector3d> path;
  for (int k = 1; k <= 20; ++k) path.emplace_back(0, 0, -2.5e-5 * k);
  for (int k = 1; k <= slide_steps; ++k) path.emplace_back(2e-5 * k, 0, -5e-4);
  return path;
}

// The force of the last step of `path` with its last pose moved by `offset_m`, from the same
// previous state (a fresh session replays the others).
Eigen::Vector3d ForceWithLastPoseMoved(const TwoBodyModel& model, const std::vector<Eigen::Vector3d>& path,
                                       const Eigen::Vector3d& offset_m) {
  TwoBodySession session(model);
  for (std::size_t k = 0; k + 1 < path.size(); ++k) session.Step(path[k]);
  const StepOutput& out = session.Step(path.back() + offset_m);
  EXPECT_EQ(out.status, contact::SolverStatus::kConverged);
  return out.device_force_n;
}

struct Linearized {
  LocalContactModel model;
  int contacts = 0;
};

Linearized LinearizeAt(const TwoBodyModel& model, const std::vector<Eigen::Vector3d>& path) {
  TwoBodySession session(model);
  for (const Eigen::Vector3d& d : path) session.Step(d);
  EXPECT_EQ(session.last_output().status, contact::SolverStatus::kConverged);
  return {LinearizeLastStep(session), session.last_output().num_contacts};
}

// |F(d + h e) - F(d) - K h e| relative to |K h e| for the 6 directions ±x, ±y, ±z.
void ExpectMatchesFiniteDifferences(const TwoBodyModel& model, const std::vector<Eigen::Vector3d>& path,
                                    const LocalContactModel& local, double h_m, double tolerance) {
  double worst = 0;
  for (int j = 0; j < 3; ++j) {
    for (double sign : {1.0, -1.0}) {
      const Eigen::Vector3d offset = sign * h_m * Eigen::Vector3d::Unit(j);
      const Eigen::Vector3d full = ForceWithLastPoseMoved(model, path, offset);
      const Eigen::Vector3d predicted = local.ForceAt(path.back() + offset);
      const double scale = local.stiffness_n_per_m.jacobiSvd().singularValues()(0) * h_m;
      EXPECT_LT((full - predicted).norm(), tolerance * scale)
          << "direction " << j << " sign " << sign << ": full " << full.transpose() << ", model "
          << predicted.transpose() << ", K h e " << (local.stiffness_n_per_m * offset).transpose();
      worst = std::max(worst, (full - predicted).norm() / scale);
    }
  }
  std::printf("largest |F_full - F_model| / (|K| h) over +-x, +-y, +-z: %.2e (|K| = %.4g N/m)\n", worst,
              local.stiffness_n_per_m.jacobiSvd().singularValues()(0));
}

TEST(LocalContactModel, FrictionlessPressMatchesFiniteDifferencesAndIsASymmetricSpring) {
  const TwoBodyModel model(CoarseScene(0.0));
  const auto path = PressAndSlide(0);
  const Linearized at = LinearizeAt(model, path);
  ASSERT_GT(at.model.sliding, 0);
  EXPECT_EQ(at.model.sticking, 0);
  const Eigen::Matrix3d& k = at.model.stiffness_n_per_m;
  EXPECT_LT(k(2, 2), 0.0) << "pressing further must push back harder:\n" << k;
  EXPECT_LT((k - k.transpose()).norm(), 1e-8 * k.norm()) << k;
  EXPECT_LE(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(0.5 * (k + k.transpose())).eigenvalues().maxCoeff(),
            1e-9 * k.norm())
      << "negative semi-definite:\n" << k;
  ExpectMatchesFiniteDifferences(model, path, at.model, 1e-7, 5e-3);  // measured 0.12 %
  // A straight press on the top face: the device is pushed up, and the resultant's normal
  // says so independently of the force (it is built from the contact normals and r_n).
  EXPECT_GT(at.model.device_force_n.z(), 0.0);
  EXPECT_GT(at.model.normal_device.z(), 0.999) << at.model.normal_device.transpose();
  EXPECT_NEAR(at.model.normal_device.norm(), 1.0, 1e-12);
  EXPECT_EQ(at.model.friction_coefficient, 0.0);
}

TEST(LocalContactModel, TheBuilderGivesTheOneOffModelAndKeepsItsBuffers) {
  // The server keeps one builder per session: same model as the one-off call, step after step.
  const TwoBodyModel model(CoarseScene(0.3));
  TwoBodySession session(model);
  LocalModelBuilder builder;
  for (const Eigen::Vector3d& d : PressAndSlide(10)) {
    session.Step(d);
    const LocalContactModel& kept = builder.Linearize(session);
    const LocalContactModel fresh = LinearizeLastStep(session);
    EXPECT_EQ(kept.stiffness_n_per_m, fresh.stiffness_n_per_m);
    EXPECT_EQ(kept.normal_device, fresh.normal_device);
    EXPECT_EQ(kept.sticking + kept.sliding, fresh.sticking + fresh.sliding);
  }
  EXPECT_EQ(builder.model().friction_coefficient, 0.3);
  EXPECT_GT(builder.model().sticking + builder.model().sliding, 0) << "the slide ends in contact";
}

TEST(LocalContactModel, StickingPressMatchesFiniteDifferencesInEveryDirection) {
  const TwoBodyModel model(CoarseScene(10.0));
  const auto path = PressAndSlide(0);
  const Linearized at = LinearizeAt(model, path);
  ASSERT_GT(at.model.sticking, 0);
  EXPECT_LE(at.model.sliding, 1) << "mu = 10: at most a contact at the edge with almost no force slides";
  const Eigen::Matrix3d& k = at.model.stiffness_n_per_m;
  EXPECT_LT(k(0, 0), 0.0) << "a sticking contact resists a sideways push:\n" << k;
  EXPECT_LT(k(1, 1), 0.0) << k;
  ExpectMatchesFiniteDifferences(model, path, at.model, 1e-7, 0.03);  // measured 1.2 %
}

TEST(LocalContactModel, ThePressModelPredictsAFurtherPressFarBetterThanHoldingTheForce) {
  // What a client gains: 5 um further in, the model's force against the held force.
  const TwoBodyModel model(CoarseScene(10.0));
  const auto path = PressAndSlide(0);
  const Linearized at = LinearizeAt(model, path);
  const Eigen::Vector3d further(0, 0, -5e-6);
  const Eigen::Vector3d full = ForceWithLastPoseMoved(model, path, further);
  const double held_error = (full - at.model.device_force_n).norm();
  const double model_error = (full - at.model.ForceAt(path.back() + further)).norm();
  EXPECT_GT(held_error, 0.01) << "5 um must change the force measurably";
  EXPECT_LT(model_error, 0.05 * held_error) << "model " << model_error << " N, held " << held_error << " N";
}

TEST(LocalContactModel, ContactForcesPerDeviceTranslationMatchTheStepsProblemSolvedAtAMovedPose) {
  // dr/dd (what multirate answers start their solve from). Frictionless, every contact stays on
  // the cone's axis and the solution is linear in d: against the step's own contact problem
  // solved again with its free displacement moved by +-G h e_j. With mu = 10 (sticking, but one
  // contact at the edge sits on its cone's rim, so the solution has a kink there and the tight
  // reference solves do not always converge) dr/dd summed onto the device must be the model's
  // stiffness, which StickingPressMatchesFiniteDifferencesInEveryDirection checks.
  for (const double friction : {0.0, 10.0}) {
    const TwoBodyModel model(CoarseScene(friction));
    TwoBodySession session(model);
    for (const Eigen::Vector3d& d : PressAndSlide(0)) session.Step(d);
    LocalModelBuilder builder;
    const LocalContactModel& local = builder.Linearize(session);
    const int m = session.last_output().num_contacts;
    ASSERT_GT(m, 0);
    Eigen::MatrixXd dr_dd, g;
    builder.ContactForcePerDeviceTranslation(m, &dr_dd);
    ASSERT_EQ(dr_dd.rows(), 3 * m);
    ASSERT_EQ(dr_dd.cols(), 3);
    ASSERT_GT(dr_dd.norm(), 0.0);
    if (friction == 0.0) {
      FreeDisplacementPerDeviceTranslation(session, &g);
      const double h_m = 1e-6;  // the 1e-13 m solves resolve it to ~1e-5 of |dr/dd| h
      double worst = 0;
      for (int j = 0; j < 3; ++j) {
        for (const double sign : {1.0, -1.0}) {
          contact::ContactProblem moved = session.last_problem();
          moved.free_displacement_m += sign * h_m * g.col(j);
          contact::SolverResult result;
          result.force_n = session.last_result().force_n;
          contact::SolverWorkspace workspace;
          ASSERT_EQ(contact::Solve(session.solver, moved, session.parameters, &workspace, &result),
                    contact::SolverStatus::kConverged);
          const Eigen::VectorXd finite_difference = (result.force_n - session.last_result().force_n) / (sign * h_m);
          const double error = (finite_difference - dr_dd.col(j)).norm() / dr_dd.norm();
          EXPECT_LT(error, 1e-4) << "direction " << j << " sign " << sign;
          worst = std::max(worst, error);
        }
      }
      std::printf("frictionless, %d contacts: largest |dr/dd - finite difference| / |dr/dd| %.2e\n", m, worst);
    }
    Eigen::Matrix3d stiffness = Eigen::Matrix3d::Zero();
    for (int alpha = 0; alpha < m; ++alpha) {
      const StepContact& c = session.contacts()[static_cast<std::size_t>(alpha)];
      double weight = 0.0;
      for (int k = 0; k < c.num_tool; ++k) weight += c.tool_coefficients[static_cast<std::size_t>(k)];
      stiffness += model.scene().force_gain * weight * c.frame.transpose() * dr_dd.middleRows<3>(3 * alpha);
    }
    EXPECT_LT((stiffness - local.stiffness_n_per_m).norm(), 1e-9 * local.stiffness_n_per_m.norm()) << "mu " << friction;
  }
}

TEST(LocalContactModel, ATouchWithoutForceGivesNoContactModel) {
  // The tool on the bar to round-off (1e-15 m in, as a device's encoder grid can land it): the
  // step finds the contacts, and the solver leaves ~1e-11 N on them, every one separating.
  // No contact pushes, so there is no contact model: a normal without a stiffness would make a
  // client replay the next forces uncapped and unchanged wherever it moves
  // (client/phantom/force_renderer.h), and multirate answers would follow it (multirate.h).
  for (const double friction : {0.0, 0.3}) {
    const TwoBodyModel model(testing::CoarseTestScene(friction));  // the scenes' global Uzawa
    TwoBodySession session(model);
    const StepOutput& out = session.Step(Eigen::Vector3d(0, 0, -1e-15));  // 1e-15 m in: round-off forces
    ASSERT_GT(out.num_contacts, 0) << "resting on the bar: contacts at zero gap";
    ASSERT_LT(out.device_force_n.norm(), 1e-9);
    const LocalContactModel local = LinearizeLastStep(session);
    EXPECT_EQ(local.sticking + local.sliding, 0);
    EXPECT_EQ(local.normal_device, Eigen::Vector3d::Zero()) << "mu " << friction << ": " << local.normal_device.transpose()
                                                            << " from a force of " << out.device_force_n.norm() << " N";
    EXPECT_EQ(local.stiffness_n_per_m, Eigen::Matrix3d::Zero());
  }
}

TEST(LocalContactModel, NoContactGivesNoStiffness) {
  const TwoBodyModel model(CoarseScene(0.3));
  TwoBodySession session(model);
  session.Step(Eigen::Vector3d(0, 0, 0.004));  // lifted 4 mm: nothing within reach
  const LocalContactModel local = LinearizeLastStep(session);
  EXPECT_EQ(local.stiffness_n_per_m, Eigen::Matrix3d::Zero());
  EXPECT_EQ(local.device_force_n, Eigen::Vector3d::Zero());
  EXPECT_EQ(local.normal_device, Eigen::Vector3d::Zero()) << "no contact force, no normal";
}

}  // namespace
}  // namespace hapco::sim
