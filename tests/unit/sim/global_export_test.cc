// A step of a HapCo scene written as a global problem (M = K, H = contact Jacobian, sim/
// global_export.h) and solved by the flexibility method on it (CHOLMOD on M, W = H^T M^-1 H)
// gives the step's own W, ũ and forces (the precomputed surface compliance path), and the
// global velocity v = M^-1 (H r + f) is both bodies' displacement from the full FEM solve.
// The global problem also survives an FCLIB file.
#include "sim/global_export.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "common/error.h"
#include "contact/solver.h"
#include "delassus/delassus.h"
#include "fclib/fclib_io.h"
#include "sim/step_pipeline.h"
#include "coarse_test_scene.h"

namespace hapco::sim {
namespace {

SceneSpec CoarseScene() {
  SceneSpec scene = testing::CoarseTestScene(0.3);
  scene.solver = contact::SolverKind::kReferenceNsgs;
  scene.solver_parameters.global_tolerance_m = 1e-14;
  scene.solver_parameters.fc3d_tolerance = 1e-13;
  scene.solver_parameters.max_iterations = 20000;
  scene.trajectory = {{"press", {0, 0, -0.003}, 6}, {"slide+x", {0.010, 0, 0}, 10}};
  return scene;
}

double MaxAbs(const Eigen::MatrixXd& a) { return a.cwiseAbs().maxCoeff(); }

TEST(GlobalExport, TheStepsGlobalProblemGivesTheLocalPathsProblemForcesAndDisplacements) {
  const TwoBodyModel model(CoarseScene());
  TwoBodySession session(model, SolveMode::kPrecomputed);
  int checked = 0;
  for (int step = 1; step <= model.scene().total_steps(); ++step) {
    const StepOutput& out = session.Step(model.scene().DeviceTranslationAtStep(step));
    if (out.num_contacts == 0 || step % 3 != 0) continue;
    SCOPED_TRACE("step " + std::to_string(step));
    const StepGlobalProblem exported = GlobalProblemOfStep(session);
    const delassus::GlobalToLocal reduction(exported.problem);
    const contact::ContactProblem& sim = session.last_problem();
    EXPECT_LT(MaxAbs(reduction.local().flexibility_m_per_n - sim.flexibility_m_per_n),
              1e-9 * MaxAbs(sim.flexibility_m_per_n));
    EXPECT_LT(MaxAbs(reduction.local().free_displacement_m - sim.free_displacement_m),
              1e-9 * MaxAbs(sim.free_displacement_m));

    contact::SolverParameters params = model.scene().solver_parameters;
    params.warm_start = false;
    contact::SolverWorkspace workspace;
    contact::SolverResult result;
    ASSERT_EQ(contact::Solve(contact::SolverKind::kReferenceNsgs, reduction.local(), params, &workspace, &result),
              contact::SolverStatus::kConverged);
    const Eigen::VectorXd& sim_force = session.last_result().force_n;
    EXPECT_LT((result.force_n - sim_force).norm(), 1e-7 * sim_force.norm()) << sim_force.norm() << " N";

    // v against the full FEM solve with the step's nodal contact forces.
    const Eigen::VectorXd v = reduction.GlobalVelocity(sim_force);
    Eigen::VectorXd obstacle_m, tool_m;
    session.FullDisplacements(&obstacle_m, &tool_m);
    const std::size_t n_tool = exported.tool_dofs.size();
    double worst = 0.0, scale = 0.0;
    for (std::size_t i = 0; i < n_tool; ++i) {
      worst = std::max(worst, std::abs(v(static_cast<Eigen::Index>(i)) - tool_m(exported.tool_dofs[i])));
      scale = std::max(scale, std::abs(tool_m(exported.tool_dofs[i])));
    }
    for (std::size_t i = 0; i < exported.obstacle_dofs.size(); ++i) {
      worst = std::max(worst, std::abs(v(static_cast<Eigen::Index>(n_tool + i)) - obstacle_m(exported.obstacle_dofs[i])));
    }
    EXPECT_LT(worst, 1e-9 * scale) << "largest displacement " << scale << " m";
    const contact::GlobalResidual residual = contact::ComputeGlobalResidual(exported.problem, v, sim_force);
    EXPECT_LT(residual.momentum, 1e-12);
    EXPECT_LT(residual.complementarity, 1e-8);
    ++checked;

    if (checked == 1) {  // the FCLIB file holds the same problem
      const std::string path = (std::filesystem::path(::testing::TempDir()) / "hapco_step_global.hdf5").string();
      fclib::WriteFclibGlobalProblem(path, exported.problem, {"coarse scene step", "", ""});
      const contact::GlobalContactProblem back = fclib::ReadFclibGlobalProblem(path);
      EXPECT_EQ(Eigen::MatrixXd(back.m), Eigen::MatrixXd(exported.problem.m));
      EXPECT_EQ(Eigen::MatrixXd(back.h), Eigen::MatrixXd(exported.problem.h));
      EXPECT_EQ(back.f, exported.problem.f);
      EXPECT_EQ(back.w, exported.problem.w);
      std::filesystem::remove(path);
    }
  }
  EXPECT_GE(checked, 3);
}

TEST(GlobalExport, AStepWithoutContactIsRefused) {
  const TwoBodyModel model(CoarseScene());
  TwoBodySession session(model, SolveMode::kPrecomputed);
  session.Step(Eigen::Vector3d(0, 0, 0.002));  // lifted off
  ASSERT_EQ(session.last_output().num_contacts, 0);
  EXPECT_THROW(GlobalProblemOfStep(session), InputError);
}

}  // namespace
}  // namespace hapco::sim
