// Many-contact problems: every solver against the reference, the contact law per contact,
// stopping, divergence, time budget, warm start, names and input errors.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>
#include <tuple>

#include "common/error.h"
#include "contact/solver.h"
#include "test_problems.h"

namespace hapco::contact {
namespace {

using testing::FoundationPunchProblem;
using testing::MatrixProblems;
using testing::NamedProblem;
using testing::RandomSpdProblem;

const SolverKind kAllKinds[] = {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel,
                                SolverKind::kGlobalUzawaJacobi, SolverKind::kReferenceNsgs};

SolverParameters Tight() {
  SolverParameters p;
  p.global_tolerance_m = 1e-13;
  p.local_tolerance_m = 1e-14;
  p.max_iterations = 20000;
  p.max_inner_iterations = 200;
  return p;
}

SolverResult RunSolver(SolverKind kind, const ContactProblem& problem, const SolverParameters& params) {
  SolverWorkspace ws;
  SolverResult result;
  Solve(kind, problem, params, &ws, &result);
  return result;
}

// Signorini + Coulomb per contact (algorithms.md §2) with tolerances relative to the scales.
void ExpectContactLaw(const ContactProblem& p, const SolverResult& res, const std::string& what) {
  const double u_scale = p.free_displacement_m.cwiseAbs().maxCoeff();
  const double r_scale = std::max(res.force_n.cwiseAbs().maxCoeff(), 1e-300);
  const double utol = 1e-6 * u_scale, rtol = 1e-6 * r_scale;
  for (int a = 0; a < p.num_contacts(); ++a) {
    const Eigen::Vector3d r = res.force_n.segment<3>(3 * a);
    const Eigen::Vector3d u = res.displacement_m.segment<3>(3 * a);
    const double mu = p.friction_coefficient(a);
    const double rt = std::hypot(r(1), r(2)), ut = std::hypot(u(1), u(2));
    EXPECT_GE(u(0), -utol) << what << " contact " << a << ": interpenetration";
    EXPECT_GE(r(0), -rtol) << what << " contact " << a;
    EXPECT_LE(rt, mu * r(0) + rtol) << what << " contact " << a << ": outside the cone";
    EXPECT_LE(std::abs(r(0) * u(0)), rtol * utol * 1e3) << what << " contact " << a
                                                        << ": Signorini complementarity";
    if (ut > utol && r(0) > rtol) {  // sliding: on the boundary, force opposing the slip
      EXPECT_NEAR(rt, mu * r(0), rtol) << what << " contact " << a;
      EXPECT_LE(r(1) * u(1) + r(2) * u(2), -0.999 * rt * ut) << what << " contact " << a;
    }
  }
}

// Reference solutions, computed once per problem.
const SolverResult& Reference(const NamedProblem& np) {
  static std::map<std::string, SolverResult> cache;
  auto it = cache.find(np.name);
  if (it == cache.end()) {
    SolverParameters params = Tight();
    params.global_tolerance_m = 1e-15;
    it = cache.emplace(np.name, RunSolver(SolverKind::kReferenceNsgs, np.problem, params)).first;
  }
  return it->second;
}

// ---- data × solver matrix (design.md example 8) ----------------------------------------------
class SolverMatrixTest : public ::testing::TestWithParam<std::tuple<SolverKind, int>> {};

TEST_P(SolverMatrixTest, AgreesWithReferenceAndSatisfiesContactLaw) {
  const auto [kind, index] = GetParam();
  static const std::vector<NamedProblem> problems = MatrixProblems();
  const NamedProblem& np = problems[static_cast<std::size_t>(index)];
  const SolverResult& ref = Reference(np);
  ASSERT_EQ(ref.stats.status, SolverStatus::kConverged) << np.name;
  ExpectContactLaw(np.problem, ref, np.name + "/reference");

  const SolverResult res = RunSolver(kind, np.problem, Tight());
  const std::string what = np.name + "/" + std::string(SolverName(kind));
  EXPECT_EQ(res.stats.status, SolverStatus::kConverged) << what;
  EXPECT_TRUE(res.force_n.allFinite());
  const double rel = (res.force_n - ref.force_n).norm() / ref.force_n.norm();
  EXPECT_LT(rel, 1e-6) << what;
  EXPECT_LT(res.stats.fc3d_error, 1e-8) << what;
  EXPECT_NEAR(res.stats.fc3d_error, Fc3dError(np.problem, res.force_n), 1e-15);
  EXPECT_LT(res.stats.paper_error_m, 1e-13) << what;
  // Returned u is exactly W r + ũ.
  const Eigen::VectorXd u = np.problem.flexibility_m_per_n * res.force_n +
                            np.problem.free_displacement_m;
  EXPECT_LT((u - res.displacement_m).norm(), 1e-15 + 1e-12 * u.norm());
  ExpectContactLaw(np.problem, res, what);
  // State counts cover every contact.
  EXPECT_EQ(res.stats.state_counts[0] + res.stats.state_counts[1] + res.stats.state_counts[2],
            np.problem.num_contacts());
}

std::string MatrixName(const ::testing::TestParamInfo<std::tuple<SolverKind, int>>& info) {
  static const std::vector<NamedProblem> problems = MatrixProblems();
  std::string kind(SolverName(std::get<0>(info.param)));
  for (char& c : kind) {
    if (c == '-') c = '_';
  }
  return kind + "__" + problems[static_cast<std::size_t>(std::get<1>(info.param))].name;
}

INSTANTIATE_TEST_SUITE_P(
    AllSolversAllProblems, SolverMatrixTest,
    ::testing::Combine(::testing::ValuesIn(kAllKinds),
                       ::testing::Range(0, static_cast<int>(MatrixProblems().size()))),
    MatrixName);

// ---- problem set sanity: the problems really mix the three states ----------------------------
TEST(SolverProblemsTest, ReferenceSolutionsMixStates) {
  for (const NamedProblem& np : MatrixProblems()) {
    if (np.problem.num_contacts() < 10) continue;
    const auto& counts = Reference(np).stats.state_counts;
    EXPECT_GT(counts[0], 0) << np.name << " separating";
    EXPECT_GT(counts[1], 0) << np.name << " sticking";
    EXPECT_GT(counts[2], 0) << np.name << " sliding";
  }
}

// ---- stopping and residuals ------------------------------------------------------------------
TEST(SolverTest, ResidualGoesDown) {
  const ContactProblem p = RandomSpdProblem(30, 3u);
  for (SolverKind kind : kAllKinds) {
    const SolverResult res = RunSolver(kind, p, Tight());
    const auto& h = res.stats.residual_history;
    ASSERT_GE(h.size(), 3u) << SolverName(kind);
    EXPECT_EQ(static_cast<int>(h.size()), res.stats.iterations);
    EXPECT_LT(h.back(), 1e-6 * h.front()) << SolverName(kind);
    // Decreasing overall: every later quarter ends below the previous quarter's end.
    const std::size_t q = h.size() / 4;
    if (q > 0) {
      EXPECT_LT(h[2 * q], h[q]) << SolverName(kind);
      EXPECT_LT(h[3 * q], h[2 * q]) << SolverName(kind);
    }
  }
}

TEST(SolverTest, PaperToleranceStopsEarlierThanTightOne) {
  const ContactProblem p = RandomSpdProblem(30, 3u);
  SolverParameters loose = Tight();
  loose.global_tolerance_m = 1e-8;
  for (SolverKind kind : kAllKinds) {
    const SolverResult a = RunSolver(kind, p, loose), b = RunSolver(kind, p, Tight());
    EXPECT_EQ(a.stats.status, SolverStatus::kConverged);
    EXPECT_LT(a.stats.paper_error_m, 1e-8);
    EXPECT_LT(a.stats.iterations, b.stats.iterations) << SolverName(kind);
  }
}

TEST(SolverTest, Fc3dToleranceStops) {
  const ContactProblem p = RandomSpdProblem(30, 3u);
  SolverParameters params = Tight();
  params.global_tolerance_m = 1e-30;  // unreachable: only the fc3d test can stop
  params.fc3d_tolerance = 1e-6;
  for (SolverKind kind : kAllKinds) {
    const SolverResult res = RunSolver(kind, p, params);
    EXPECT_EQ(res.stats.status, SolverStatus::kConverged) << SolverName(kind);
    EXPECT_LT(res.stats.fc3d_error, 1e-6) << SolverName(kind);
  }
}

TEST(SolverTest, IterationCapIsReported) {
  const ContactProblem p = RandomSpdProblem(30, 3u);
  SolverParameters params = Tight();
  params.max_iterations = 2;
  for (SolverKind kind : kAllKinds) {
    const SolverResult res = RunSolver(kind, p, params);
    EXPECT_EQ(res.stats.status, SolverStatus::kMaxIterations) << SolverName(kind);
    EXPECT_EQ(res.stats.iterations, 2);
    EXPECT_GT(res.stats.paper_error_m, 0.0);
    EXPECT_GT(res.stats.fc3d_error, 0.0);  // always reported, not a solution yet
  }
}

// Jacobi order with ρ far too large on a strongly coupled W: the fixed point is unstable.
TEST(SolverTest, JacobiWithHugeRhoDivergesWithFiniteForces) {
  const ContactProblem p = RandomSpdProblem(30, 9u, 8.0, 0.5);
  SolverParameters params = Tight();
  params.rho_scale = 20.0;
  const SolverResult res = RunSolver(SolverKind::kGlobalUzawaJacobi, p, params);
  EXPECT_EQ(res.stats.status, SolverStatus::kDiverged);
  EXPECT_TRUE(res.force_n.allFinite());
  EXPECT_TRUE(res.displacement_m.allFinite());
  EXPECT_TRUE(std::isfinite(res.stats.fc3d_error));
  EXPECT_LT(res.stats.iterations, params.max_iterations);
}

// Local Uzawa with ρ far too large: each inner loop oscillates (r -> big -> 0 -> ...) and can
// end where it started, so ‖Δr‖/ρ = 0 although nothing is solved. Must not pass as converged.
TEST(SolverTest, LocalUzawaWithHugeRhoIsNotReportedConverged) {
  const ContactProblem p = RandomSpdProblem(30, 9u, 8.0, 0.5);
  SolverParameters params = Tight();
  params.rho_scale = 20.0;
  params.max_iterations = 50;
  const SolverResult res = RunSolver(SolverKind::kLocalUzawa, p, params);
  EXPECT_NE(res.stats.status, SolverStatus::kConverged);
  EXPECT_GT(res.stats.inner_limit_hits, 0);
  EXPECT_TRUE(res.force_n.allFinite());
  EXPECT_GT(res.stats.fc3d_error, 1e-3);  // and the residual says so
}

TEST(SolverTest, TinyTimeBudgetIsReportedWithFiniteIterate) {
  const ContactProblem p = RandomSpdProblem(60, 4u);
  SolverParameters params = Tight();
  params.time_budget_s = 1e-9;
  for (SolverKind kind : kAllKinds) {
    const SolverResult res = RunSolver(kind, p, params);
    EXPECT_EQ(res.stats.status, SolverStatus::kTimeBudgetExceeded) << SolverName(kind);
    EXPECT_GE(res.stats.iterations, 1);
    EXPECT_TRUE(res.force_n.allFinite());
    EXPECT_GT(res.stats.fc3d_error, 0.0);
  }
}

TEST(SolverTest, WarmStartFromSolutionConvergesImmediately) {
  const ContactProblem p = FoundationPunchProblem(25, 4e-4);
  for (SolverKind kind : kAllKinds) {
    SolverParameters params = Tight();
    params.global_tolerance_m = 1e-11;
    SolverWorkspace ws;
    SolverResult res;
    ASSERT_EQ(Solve(kind, p, params, &ws, &res), SolverStatus::kConverged);
    const int cold = res.stats.iterations;
    params.warm_start = true;
    ASSERT_EQ(Solve(kind, p, params, &ws, &res), SolverStatus::kConverged) << SolverName(kind);
    EXPECT_LE(res.stats.iterations, 2) << SolverName(kind);
    EXPECT_LT(res.stats.iterations, cold) << SolverName(kind);
  }
}

TEST(SolverTest, PerContactRhoAlsoConverges) {
  const NamedProblem np{"random_spd_12", RandomSpdProblem(12, 7u)};
  SolverParameters params = Tight();
  params.rho_rule = RhoRule::kPerContact;
  for (SolverKind kind : kAllKinds) {
    const SolverResult res = RunSolver(kind, np.problem, params);
    EXPECT_EQ(res.stats.status, SolverStatus::kConverged) << SolverName(kind);
    EXPECT_LT((res.force_n - Reference(np).force_n).norm() / Reference(np).force_n.norm(), 1e-6);
    // ρ_α = 1/λ_max(W_αα) <= 1/max diag W_αα: never above the paper's ρ for that block.
    EXPECT_GT(res.stats.rho, 0.0);
  }
}

TEST(SolverTest, RhoFollowsThePaperRule) {
  const ContactProblem p = RandomSpdProblem(5, 1u);
  SolverParameters params;
  params.rho_scale = 0.5;
  const SolverResult res = RunSolver(SolverKind::kGlobalUzawaGaussSeidel, p, params);
  EXPECT_DOUBLE_EQ(res.stats.rho, 0.5 / p.flexibility_m_per_n.diagonal().maxCoeff());
}

TEST(SolverTest, NoContactsIsTriviallyConverged) {
  ContactProblem p;
  p.flexibility_m_per_n.resize(0, 0);
  p.free_displacement_m.resize(0);
  p.friction_coefficient.resize(0);
  const SolverResult res = RunSolver(SolverKind::kLocalUzawa, p, SolverParameters{});
  EXPECT_EQ(res.stats.status, SolverStatus::kConverged);
  EXPECT_EQ(res.force_n.size(), 0);
}

// ---- Anderson acceleration (SolverParameters::anderson_depth) ---------------------------------
const SolverKind kGaussSeidelKinds[] = {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel,
                                        SolverKind::kReferenceNsgs};

SolverParameters Accelerated(SolverParameters p, int depth = 5) {
  p.anderson_depth = depth;
  p.anderson_start = 3;
  return p;
}

// The accelerated sweeps reach the reference solution of every matrix problem (the same fixed
// point, the same contact law), and never need more sweeps than the paper's iteration.
TEST(AndersonTest, ReachesTheReferenceInNoMoreSweeps) {
  for (const NamedProblem& np : MatrixProblems()) {
    const SolverResult& ref = Reference(np);
    for (SolverKind kind : kGaussSeidelKinds) {
      const std::string what = np.name + "/" + std::string(SolverName(kind));
      const SolverResult plain = RunSolver(kind, np.problem, Tight());
      const SolverResult fast = RunSolver(kind, np.problem, Accelerated(Tight()));
      ASSERT_EQ(fast.stats.status, SolverStatus::kConverged) << what;
      EXPECT_LT((fast.force_n - ref.force_n).norm() / ref.force_n.norm(), 1e-6) << what;
      ExpectContactLaw(np.problem, fast, what + "/anderson");
      EXPECT_LE(fast.stats.iterations, plain.stats.iterations) << what;
    }
  }
}

// Where Gauss-Seidel crawls: a punch sliding over a soft foundation under a 20x stiffer skin
// (every contact's displacement depends on all the others' forces; 28 of 40 points slide, as
// under the organ scene's instrument tip), the extrapolation cuts the sweeps several-fold, to
// the same forces.
TEST(AndersonTest, CutsTheSweepsOnAStronglyCoupledProblem) {
  const NamedProblem np{"coupled_punch_40", FoundationPunchProblem(40, 1e-3, 20000.0)};
  for (SolverKind kind : {SolverKind::kGlobalUzawaGaussSeidel, SolverKind::kReferenceNsgs}) {
    SolverParameters params = Tight();
    params.global_tolerance_m = 1e-10;
    const SolverResult plain = RunSolver(kind, np.problem, params);
    const SolverResult fast = RunSolver(kind, np.problem, Accelerated(params));
    ASSERT_EQ(plain.stats.status, SolverStatus::kConverged) << SolverName(kind);
    ASSERT_EQ(fast.stats.status, SolverStatus::kConverged) << SolverName(kind);
    EXPECT_GT(fast.stats.accelerated_iterations, 0);
    // The paper's global Uzawa (the shipped solver) takes ~170 sweeps here; exact local solves
    // (NSGS) ~55, where the extrapolation has less to remove.
    if (kind == SolverKind::kGlobalUzawaGaussSeidel) {
      EXPECT_LT(3 * fast.stats.iterations, plain.stats.iterations)
          << SolverName(kind) << ": " << fast.stats.iterations << " vs " << plain.stats.iterations;
    } else {
      EXPECT_LT(fast.stats.iterations, plain.stats.iterations) << SolverName(kind);
    }
    EXPECT_LT((fast.force_n - Reference(np).force_n).norm() / Reference(np).force_n.norm(), 1e-5);
  }
}

// Whatever sweep the solve stops at (cap, time budget, convergence), the force returned is a
// sweep's projected output: every contact force inside its friction cone, never an
// extrapolated iterate (which may leave the cones).
TEST(AndersonTest, EveryExitReturnsForcesInsideTheCones) {
  const ContactProblem p = RandomSpdProblem(40, 11u, 8.0, 0.5);
  for (int cap = 1; cap <= 60; ++cap) {
    SolverParameters params = Accelerated(Tight(), 8);
    params.anderson_start = 1;
    params.max_iterations = cap;
    const SolverResult res = RunSolver(SolverKind::kGlobalUzawaGaussSeidel, p, params);
    for (int a = 0; a < p.num_contacts(); ++a) {
      const Eigen::Vector3d r = res.force_n.segment<3>(3 * a);
      EXPECT_GE(r(0), 0.0) << "cap " << cap << " contact " << a;
      EXPECT_LE(std::hypot(r(1), r(2)), p.friction_coefficient(a) * r(0) * (1 + 1e-12) + 1e-300)
          << "cap " << cap << " contact " << a;
    }
  }
}

// A sweep from an extrapolated iterate that meets the stop test is confirmed by a plain sweep
// before the solve stops: with the loose haptic tolerance, the accelerated answer is as close
// to the reference as the paper's iteration's (or closer), never a spurious early stop.
TEST(AndersonTest, LooseToleranceIsAsAccurateAsThePapersIteration) {
  for (const NamedProblem& np : MatrixProblems()) {
    SolverParameters loose = Tight();
    loose.global_tolerance_m = 1e-6 * np.problem.free_displacement_m.cwiseAbs().maxCoeff();
    const SolverResult plain = RunSolver(SolverKind::kGlobalUzawaGaussSeidel, np.problem, loose);
    const SolverResult fast = RunSolver(SolverKind::kGlobalUzawaGaussSeidel, np.problem, Accelerated(loose));
    const Eigen::VectorXd& ref = Reference(np).force_n;
    const double plain_error = (plain.force_n - ref).norm(), fast_error = (fast.force_n - ref).norm();
    EXPECT_LE(fast_error, 3.0 * plain_error + 1e-9 * ref.norm())
        << np.name << ": accelerated " << fast_error << " N, plain " << plain_error << " N";
  }
}

TEST(AndersonTest, BadDepthOrStartThrows) {
  const ContactProblem p = RandomSpdProblem(3, 1u);
  SolverWorkspace ws;
  SolverResult res;
  SolverParameters params;
  params.anderson_depth = SolverParameters::kMaxAndersonDepth + 1;
  EXPECT_THROW(Solve(SolverKind::kGlobalUzawaGaussSeidel, p, params, &ws, &res), InputError);
  params.anderson_depth = -1;
  EXPECT_THROW(Solve(SolverKind::kGlobalUzawaGaussSeidel, p, params, &ws, &res), InputError);
  params.anderson_depth = 3;
  params.anderson_start = 0;
  EXPECT_THROW(Solve(SolverKind::kGlobalUzawaGaussSeidel, p, params, &ws, &res), InputError);
}

// ---- names and input errors -----------------------------------------------------------------
TEST(SolverNamesTest, RoundTripAndErrorListsValidNames) {
  for (SolverKind kind : kAllKinds) EXPECT_EQ(ParseSolverKind(SolverName(kind)), kind);
  EXPECT_EQ(SolverName(SolverKind::kReferenceNsgs), "reference");
  EXPECT_EQ(StatusName(SolverStatus::kTimeBudgetExceeded), "time-budget-exceeded");
  try {
    ParseSolverKind("gauss");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("gauss"), std::string::npos);
    EXPECT_NE(msg.find("global-uzawa-jacobi"), std::string::npos);
    EXPECT_NE(msg.find("reference"), std::string::npos);
  }
}

TEST(SolverInputTest, BadInputThrows) {
  const ContactProblem p = RandomSpdProblem(3, 1u);
  SolverWorkspace ws;
  SolverResult res;
  SolverParameters params;
  params.rho_scale = 0.0;
  EXPECT_THROW(Solve(SolverKind::kLocalUzawa, p, params, &ws, &res), InputError);
  params = SolverParameters{};
  params.max_iterations = 0;
  EXPECT_THROW(Solve(SolverKind::kLocalUzawa, p, params, &ws, &res), InputError);
  params = SolverParameters{};
  params.warm_start = true;
  res.force_n = Eigen::VectorXd::Zero(4);  // wrong size for 3 contacts
  EXPECT_THROW(Solve(SolverKind::kLocalUzawa, p, params, &ws, &res), InputError);
  ContactProblem bad = p;
  bad.free_displacement_m.resize(5);
  EXPECT_THROW(Solve(SolverKind::kLocalUzawa, bad, SolverParameters{}, &ws, &res), InputError);
  bad = p;
  bad.flexibility_m_per_n(4, 4) = 0.0;
  EXPECT_THROW(Solve(SolverKind::kGlobalUzawaJacobi, bad, SolverParameters{}, &ws, &res),
               InputError);
}

}  // namespace
}  // namespace hapco::contact
