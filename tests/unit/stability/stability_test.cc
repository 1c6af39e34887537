// Regression tests for the cases where a method fails (docs/stability.md): the failure must be
// REPORTED (a status other than converged, finite forces, the session carries on), and the
// shipped default configuration (local Uzawa, warm start, ε₁ = 1e-6 m, ε₂ = 1e-7 m, paper ρ)
// must stay converged and close to an independent reference on the same case.
//
// Why the failures are expected, independently of the code under test: the Uzawa step
// r ← Proj(r − ρ (W r + ũ + …)) is, in the sticking regime, a gradient step on the quadratic
// ½ rᵀW r + ũᵀr, which converges only when ρ λ_max < 2 for the operator the step sees:
//   - Jacobi order (all contacts at once): λ_max(W);
//   - Gauss-Seidel order / the local Uzawa inner loop (one contact at a time): λ_max(W_αα).
// The tests compute these eigenvalues with Eigen from the assembled problem and check the
// condition before asserting the outcome.
//
// Coarse meshes (obstacle 10 x 2 x 2, tool 2 x 2 x 1 Tet10 cells: 25 candidate contacts) and
// short trajectories keep the whole file at a few seconds.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "contact/solver.h"
#include "sim/scene.h"
#include "sim/step_pipeline.h"
#include "sim/two_body_model.h"

namespace hapco::sim {
namespace {

using contact::RhoRule;
using contact::SolverKind;
using contact::SolverParameters;
using contact::SolverStatus;

// The paper's scene (algorithms.md §1) on coarse meshes: press 1 mm in 10 steps, then slide
// +x 2 mm in 10 steps. `clamp_both_ends` false is benchmark 2.
SceneSpec CoarseBenchmark(bool clamp_both_ends, double mu) {
  SceneSpec scene;
  scene.name = clamp_both_ends ? "coarse-benchmark1" : "coarse-benchmark2";
  scene.obstacle.name = "red";
  scene.obstacle.box = {Eigen::Vector3d::Zero(), Eigen::Vector3d(0.10, 0.02, 0.02),
                        Eigen::Vector3i(10, 2, 2), fem::ElementOrder::kTet10};
  scene.obstacle.material = {3.0e6, 0.3};
  scene.obstacle.clamped_faces = {fem::BoxFace::kXMin};
  if (clamp_both_ends) scene.obstacle.clamped_faces.push_back(fem::BoxFace::kXMax);
  scene.tool.name = "green";
  scene.tool.box = {Eigen::Vector3d(0.04, 0.0, 0.02), Eigen::Vector3d(0.02, 0.02, 0.01),
                    Eigen::Vector3i(2, 2, 1), fem::ElementOrder::kTet10};
  scene.tool.material = {8.0e7, 0.3};
  scene.tool.driven_face = fem::BoxFace::kZMax;
  scene.friction_coefficient = mu;
  scene.activation_gap_m = 5e-4;
  // The shipped scene files' solver block (proto/scenes/benchmark1.txtpb).
  scene.solver = SolverKind::kLocalUzawa;
  scene.solver_parameters.global_tolerance_m = 1e-6;
  scene.solver_parameters.local_tolerance_m = 1e-7;
  scene.solver_parameters.max_iterations = 1000;
  scene.solver_parameters.warm_start = true;
  scene.trajectory = {{"press", {0, 0, -0.001}, 10}, {"slide+x", {0.002, 0, 0}, 10}};
  return scene;
}

// The paper's setting (section 3.3.3): cold start, paper ρ times `rho_scale`, ε₁ = ε₂.
SolverParameters PaperParameters(double rho_scale) {
  SolverParameters p;
  p.global_tolerance_m = 1e-6;
  p.local_tolerance_m = 1e-6;
  p.max_iterations = 300;  // failing runs stop here; converging ones need < 150 on this mesh
  p.max_inner_iterations = 100;
  p.rho_rule = RhoRule::kPaperGlobalMin;
  p.rho_scale = rho_scale;
  p.warm_start = false;
  return p;
}

struct Trace {
  std::vector<Eigen::Vector3d> force_n;
  std::vector<SolverStatus> status;
  std::vector<int> contacts;
  int not_converged = 0;
};

Trace RunTrajectory(const TwoBodyModel& model, SolverKind kind, const SolverParameters& parameters) {
  TwoBodySession session(model);
  session.solver = kind;
  session.parameters = parameters;
  Trace trace;
  for (int step = 1; step <= model.scene().total_steps(); ++step) {
    const StepOutput& out = session.Step(model.scene().DeviceTranslationAtStep(step));
    trace.force_n.push_back(out.contact_force_n);
    trace.status.push_back(out.status);
    trace.contacts.push_back(out.num_contacts);
    if (out.status != SolverStatus::kConverged) ++trace.not_converged;
  }
  return trace;
}

// Exact-local-solve NSGS (kReferenceNsgs) at ε₁ = 1e-11 m: a different algorithm from the
// Uzawa solvers under test.
Trace Reference(const TwoBodyModel& model) {
  SolverParameters p;
  p.global_tolerance_m = 1e-11;
  p.max_iterations = 100000;
  p.warm_start = true;
  return RunTrajectory(model, SolverKind::kReferenceNsgs, p);
}

double Peak(const Trace& t) {
  double peak = 0.0;
  for (const auto& f : t.force_n) peak = std::max(peak, f.norm());
  return peak;
}

double MaxDifference(const Trace& a, const Trace& b) {
  double worst = 0.0;
  for (std::size_t k = 0; k < a.force_n.size(); ++k) {
    worst = std::max(worst, (a.force_n[k] - b.force_n[k]).norm());
  }
  return worst;
}

void ExpectFinite(const Trace& t) {
  for (std::size_t k = 0; k < t.force_n.size(); ++k) {
    ASSERT_TRUE(t.force_n[k].allFinite()) << "step " << k + 1;
  }
}

// The shipped configuration on the same case: every step converged and within 1% of the peak
// force of the reference (the full-trajectory study measures < 0.1%, docs/stability.md).
void ExpectDefaultConvergedAndAccurate(const TwoBodyModel& model, const Trace& reference) {
  const Trace run = RunTrajectory(model, model.scene().solver, model.scene().solver_parameters);
  EXPECT_EQ(run.not_converged, 0);
  ExpectFinite(run);
  const double peak_n = Peak(reference);
  ASSERT_GT(peak_n, 0.5);  // the press really loads the contact (about 1 N per 0.1 mm)
  EXPECT_LT(MaxDifference(run, reference), 1e-2 * peak_n) << "reference peak " << peak_n << " N";
  // (The active-contact count is not compared: tool nodes lying exactly on the obstacle's
  // top-face edges are found or not depending on round-off, 22-25 contacts for equally
  // converged solvers; the forces agree regardless.)
}

// λ_max of W and the largest λ_max(W_αα) of the first pressed step's contact problem, and the
// paper's ρ = min 1/W_ii there.
struct Spectrum {
  double rho_paper_n_per_m = 0.0;
  double lambda_w = 0.0;
  double lambda_block = 0.0;
};

Spectrum FirstStepSpectrum(const TwoBodyModel& model) {
  TwoBodySession session(model);
  session.Step(model.scene().DeviceTranslationAtStep(1));
  const Eigen::MatrixXd& w = session.last_problem().flexibility_m_per_n;
  Spectrum s;
  s.rho_paper_n_per_m = 1.0 / w.diagonal().maxCoeff();
  s.lambda_w = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(w, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff();
  for (Eigen::Index a = 0; a < w.rows() / 3; ++a) {
    const Eigen::Matrix3d block = w.block<3, 3>(3 * a, 3 * a);
    s.lambda_block = std::max(
        s.lambda_block, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(block).eigenvalues().maxCoeff());
  }
  return s;
}

class StabilityTest : public ::testing::TestWithParam<bool> {};  // clamp both ends?

// Jacobi order at the paper's ρ: the contacts are strongly coupled through the soft obstacle,
// so λ_max(W) is many times max W_ii and ρ λ_max(W) > 2; the iteration 2-cycles. At 0.1 ρ it
// is below 2 and converges.
TEST_P(StabilityTest, JacobiOrderAtThePaperRhoIsReportedAndConvergesAtATenthOfIt) {
  const TwoBodyModel model(CoarseBenchmark(GetParam(), 0.3));
  const Spectrum s = FirstStepSpectrum(model);
  ASSERT_GT(s.rho_paper_n_per_m * s.lambda_w, 2.0);        // theory: must fail at 1x
  ASSERT_LT(0.1 * s.rho_paper_n_per_m * s.lambda_w, 2.0);  // theory: may converge at 0.1x

  const Trace failing = RunTrajectory(model, SolverKind::kGlobalUzawaJacobi, PaperParameters(1.0));
  EXPECT_NE(failing.status.front(), SolverStatus::kConverged);
  EXPECT_GT(failing.not_converged, 0);
  ExpectFinite(failing);

  const Trace reference = Reference(model);
  const Trace working = RunTrajectory(model, SolverKind::kGlobalUzawaJacobi, [] {
    SolverParameters p = PaperParameters(0.1);
    p.max_iterations = 5000;  // 10x smaller steps need ~10x the sweeps
    return p;
  }());
  EXPECT_EQ(working.not_converged, 0);
  EXPECT_LT(MaxDifference(working, reference), 1e-2 * Peak(reference));

  ExpectDefaultConvergedAndAccurate(model, reference);
}

// The one-contact Uzawa step (local Uzawa's inner loop, global Uzawa's Gauss-Seidel sweep) at
// 10x the paper's ρ: ρ λ_max(W_αα) > 2 for the stiffest-coupled contact, so neither method
// can converge; both must say so.
TEST_P(StabilityTest, TenTimesThePaperRhoIsReportedForBothGaussSeidelMethods) {
  const TwoBodyModel model(CoarseBenchmark(GetParam(), 0.3));
  const Spectrum s = FirstStepSpectrum(model);
  ASSERT_GT(10.0 * s.rho_paper_n_per_m * s.lambda_block, 2.0);

  for (SolverKind kind : {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel}) {
    SCOPED_TRACE(std::string(contact::SolverName(kind)));
    const Trace failing = RunTrajectory(model, kind, PaperParameters(10.0));
    EXPECT_NE(failing.status.front(), SolverStatus::kConverged);
    ExpectFinite(failing);
  }
  ExpectDefaultConvergedAndAccurate(model, Reference(model));
}

// The paper's own setting (ρ x1, cold start, ε₁ = ε₂ = 1e-6 m) converges with both Gauss-
// Seidel methods on both benchmarks, and agrees with the reference.
TEST_P(StabilityTest, PaperSettingConvergesForBothGaussSeidelMethods) {
  const TwoBodyModel model(CoarseBenchmark(GetParam(), 0.6));
  const Trace reference = Reference(model);
  for (SolverKind kind : {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel}) {
    SCOPED_TRACE(std::string(contact::SolverName(kind)));
    const Trace run = RunTrajectory(model, kind, PaperParameters(1.0));
    EXPECT_EQ(run.not_converged, 0);
    EXPECT_LT(MaxDifference(run, reference), 1e-2 * Peak(reference));
  }
}

INSTANTIATE_TEST_SUITE_P(Benchmarks, StabilityTest, ::testing::Values(true, false),
                         [](const ::testing::TestParamInfo<bool>& param_info) {
                           return param_info.param ? "Benchmark1" : "Benchmark2";
                         });

}  // namespace
}  // namespace hapco::sim
