// Cross-check of HapCo's error measure (contact::Fc3dError) against libfclib's independent
// implementation (fclib_merit_local, MERIT_1) on problems read from FCLIB files.
//
// Normalisation relation (both use ρ = 1 and the same natural-map numerator N(r)):
//     Fc3dError(r)  = N(r) / max(‖q‖, ‖r‖, ‖u‖)
//     fclib merit   = N(r) / (1 + sqrt(‖q‖))
// so merit · (1 + sqrt(‖q‖)) = Fc3dError · max(‖q‖, ‖r‖, ‖u‖), u = W r + q.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "contact/solver.h"
#include "fclib/fclib_io.h"
#include "fclib_test_util.h"

namespace hapco::fclib {
namespace {

using testing::DataFile;

TEST(FclibMerit, NormalisationByHandOnOneContact) {
  // W = diag(4, 2, 3), q = (-4, 0, 0), r = 0: u = q, r − (u + μ‖u_t‖n) = (4, 0, 0) lies in
  // the cone, so N = ‖0 − (4, 0, 0)‖ = 4; ‖q‖ = 4 gives 4 / (1 + sqrt 4) = 4/3 (and not
  // 4 / (1 + 4) = 0.8, which the formula in the FCLIB paper would suggest).
  contact::ContactProblem p;
  p.flexibility_m_per_n = Eigen::Vector3d(4.0, 2.0, 3.0).asDiagonal();
  p.free_displacement_m = Eigen::Vector3d(-4.0, 0.0, 0.0);
  p.friction_coefficient = Eigen::VectorXd::Constant(1, 0.5);
  EXPECT_NEAR(FclibMeritLocal(p, Eigen::Vector3d::Zero()), 4.0 / 3.0, 1e-15);
  // r = (1, 0, 0) is the exact solution (u = 0, sticking): both measures vanish.
  EXPECT_EQ(FclibMeritLocal(p, Eigen::Vector3d(1.0, 0.0, 0.0)), 0.0);
  EXPECT_EQ(contact::Fc3dError(p, Eigen::Vector3d(1.0, 0.0, 0.0)), 0.0);
  // Fc3dError at r = 0: N = 4, max(‖q‖, ‖r‖, ‖u‖) = 4.
  EXPECT_NEAR(contact::Fc3dError(p, Eigen::Vector3d::Zero()), 1.0, 1e-15);
}

double Fc3dScale(const contact::ContactProblem& p, const Eigen::VectorXd& r) {
  const Eigen::VectorXd u = p.flexibility_m_per_n * r + p.free_displacement_m;
  return std::max({p.free_displacement_m.norm(), r.norm(), u.norm()});
}

TEST(FclibMerit, AgreesWithFc3dErrorAtSolutionAndPerturbedPoints) {
  const contact::ContactProblem problem =
      ReadFclibLocalProblem(DataFile("siconos_dense_csr.hdf5"));
  contact::SolverParameters params;
  params.fc3d_tolerance = 1e-13;
  params.global_tolerance_m = 1e-14;
  params.max_iterations = 10000;
  contact::SolverWorkspace workspace;
  contact::SolverResult result;
  const auto status = contact::Solve(contact::SolverKind::kReferenceNsgs, problem, params,
                                     &workspace, &result);
  ASSERT_EQ(status, contact::SolverStatus::kConverged);
  const Eigen::VectorXd& r = result.force_n;
  const double q_term = 1.0 + std::sqrt(problem.free_displacement_m.norm());

  // At the solution both are tiny.
  const double merit_at_solution = FclibMeritLocal(problem, r);
  const double fc3d_at_solution = contact::Fc3dError(problem, r);
  EXPECT_LT(fc3d_at_solution, 1e-10);
  EXPECT_LT(merit_at_solution, 1e-10);
  EXPECT_NEAR(merit_at_solution * q_term, fc3d_at_solution * Fc3dScale(problem, r), 1e-12);

  // Away from it they are not, and they differ by exactly the normalisation.
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss(0.0, 0.3);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd r_perturbed = r + Eigen::VectorXd::NullaryExpr(r.size(), [&] {
                                          return gauss(rng);
                                        });
    const double merit = FclibMeritLocal(problem, r_perturbed);
    const double fc3d = contact::Fc3dError(problem, r_perturbed);
    EXPECT_GT(fc3d, 1e-3) << "trial " << trial;
    EXPECT_NEAR(merit * q_term / (fc3d * Fc3dScale(problem, r_perturbed)), 1.0, 1e-12)
        << "trial " << trial;
  }
}

TEST(FclibMerit, EverySolverReachesASolutionLibfclibAccepts) {
  const contact::ContactProblem problem = ReadFclibLocalProblem(DataFile("siconos_triplet.hdf5"));
  for (auto kind : {contact::SolverKind::kLocalUzawa, contact::SolverKind::kGlobalUzawaGaussSeidel,
                    contact::SolverKind::kGlobalUzawaJacobi,
                    contact::SolverKind::kReferenceNsgs}) {
    contact::SolverParameters params;
    params.fc3d_tolerance = 1e-9;
    params.max_iterations = 100000;
    contact::SolverWorkspace workspace;
    contact::SolverResult result;
    const auto status = contact::Solve(kind, problem, params, &workspace, &result);
    EXPECT_EQ(status, contact::SolverStatus::kConverged) << contact::SolverName(kind);
    EXPECT_LT(FclibMeritLocal(problem, result.force_n), 1e-6) << contact::SolverName(kind);
  }
}

// 30 rigid spheres (scripts/make_fclib_collection.py, Siconos layout; 91 contacts on 180 body
// dofs: W singular). Anderson extrapolation stalls here (its residual stopped shrinking at
// ~2e-5 for 250 000 sweeps before the guard), while the plain sweeps converge slowly: the
// guard hands the solve back to them, so it converges in no more sweeps than they need, and
// libfclib accepts the answer. On the 10-sphere file it cuts the sweeps ~10x.
TEST(FclibMerit, AndersonOnGranularFilesConvergesWhereThePlainSweepsDo) {
  const contact::ContactProblem problem = ReadFclibLocalProblem(DataFile("granular_n30_local_blockcsr.hdf5"));
  contact::SolverParameters params;
  params.fc3d_tolerance = 1e-6;
  params.global_tolerance_m = 1e-300;  // the fc3d test only
  params.max_iterations = 300000;
  contact::SolverWorkspace workspace;
  contact::SolverResult plain, accelerated;
  ASSERT_EQ(contact::Solve(contact::SolverKind::kGlobalUzawaGaussSeidel, problem, params, &workspace, &plain),
            contact::SolverStatus::kConverged);
  params.anderson_depth = 5;
  ASSERT_EQ(contact::Solve(contact::SolverKind::kGlobalUzawaGaussSeidel, problem, params, &workspace, &accelerated),
            contact::SolverStatus::kConverged);
  EXPECT_TRUE(accelerated.stats.acceleration_stalled);
  EXPECT_GT(accelerated.stats.accelerated_iterations, 0);
  EXPECT_LE(accelerated.stats.iterations, plain.stats.iterations + plain.stats.iterations / 20)
      << "plain " << plain.stats.iterations;
  EXPECT_LT(FclibMeritLocal(problem, accelerated.force_n), 1e-5);
  EXPECT_LT(contact::Fc3dError(problem, accelerated.force_n), 1e-6);
}

}  // namespace
}  // namespace hapco::fclib
