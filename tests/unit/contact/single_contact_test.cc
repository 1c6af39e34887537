// One contact with closed-form answers (design.md example 7: stick/slip thresholds), for the
// exact local solve and for every solver through Solve.
#include <gtest/gtest.h>

#include <cmath>

#include "contact/local_solver.h"
#include "contact/solver.h"

namespace hapco::contact {
namespace {

const SolverKind kAllKinds[] = {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel,
                                SolverKind::kGlobalUzawaJacobi, SolverKind::kReferenceNsgs};

ContactProblem OneContact(const Eigen::Matrix3d& w, const Eigen::Vector3d& u_free, double mu) {
  ContactProblem p;
  p.flexibility_m_per_n = w;
  p.free_displacement_m = u_free;
  p.friction_coefficient = Eigen::VectorXd::Constant(1, mu);
  return p;
}

Eigen::Vector3d SolveWith(SolverKind kind, const ContactProblem& p, SolverStats* stats = nullptr) {
  SolverParameters params;
  params.global_tolerance_m = 1e-14;
  params.local_tolerance_m = 1e-15;
  params.max_iterations = 20000;
  params.max_inner_iterations = 1000;
  SolverWorkspace ws;
  SolverResult result;
  const SolverStatus status = Solve(kind, p, params, &ws, &result);
  EXPECT_EQ(status, SolverStatus::kConverged) << SolverName(kind);
  if (stats) *stats = result.stats;
  return result.force_n;
}

// Decoupled block diag(w_n, w_t, w_t), ũ = (−p, s1, s2) (a press plus a tangential push):
// stick force (p/w_n, −s/w_t) is admissible iff ‖s‖/w_t <= μ p/w_n.
TEST(SingleContactTest, DiagonalStickMatchesClosedForm) {
  const double wn = 1e-3, wt = 2e-3, mu = 0.5, p = 1e-3;
  const Eigen::Vector3d s(0.0, 3e-4, -4e-4);  // ‖s‖ = 5e-4: 0.25 N tangential vs 0.5 N cone
  const Eigen::Matrix3d w = Eigen::Vector3d(wn, wt, wt).asDiagonal();
  const Eigen::Vector3d u_free(-p, s(1), s(2));
  const Eigen::Vector3d expected(p / wn, -s(1) / wt, -s(2) / wt);
  EXPECT_TRUE(SolveSingleContactExact(w, u_free, mu).isApprox(expected, 1e-12));
  for (SolverKind kind : kAllKinds) {
    SolverStats stats;
    EXPECT_TRUE(SolveWith(kind, OneContact(w, u_free, mu), &stats).isApprox(expected, 1e-9))
        << SolverName(kind);
    EXPECT_EQ(stats.state_counts[static_cast<int>(ContactState::kSticking)], 1);
  }
}

// Same block, push beyond the threshold: r_n = p/w_n (u_n = 0), r_t = −μ r_n s/‖s‖, and the
// slip u_t = s (1 − w_t μ r_n/‖s‖) is along s, i.e. antiparallel to r_t.
TEST(SingleContactTest, DiagonalSlideMatchesClosedForm) {
  const double wn = 1e-3, wt = 2e-3, mu = 0.3, p = 1e-3;
  const Eigen::Vector2d s(1.5e-3, -0.5e-3);
  const Eigen::Matrix3d w = Eigen::Vector3d(wn, wt, wt).asDiagonal();
  const Eigen::Vector3d u_free(-p, s(0), s(1));
  const double rn = p / wn;
  ASSERT_GT(s.norm() / wt, mu * rn);  // really beyond the cone
  const Eigen::Vector2d rt = -mu * rn * s / s.norm();
  const Eigen::Vector3d expected(rn, rt(0), rt(1));
  EXPECT_TRUE(SolveSingleContactExact(w, u_free, mu).isApprox(expected, 1e-12));
  for (SolverKind kind : kAllKinds) {
    SolverStats stats;
    const Eigen::Vector3d r = SolveWith(kind, OneContact(w, u_free, mu), &stats);
    EXPECT_TRUE(r.isApprox(expected, 1e-9)) << SolverName(kind) << ": " << r.transpose();
    EXPECT_EQ(stats.state_counts[static_cast<int>(ContactState::kSliding)], 1);
  }
}

TEST(SingleContactTest, GapSeparates) {
  Eigen::Matrix3d w;
  w << 1.0, 0.2, -0.1, 0.2, 1.5, 0.1, -0.1, 0.1, 2.0;
  w *= 1e-3;
  const Eigen::Vector3d u_free(2e-4, 5e-4, -1e-4);  // ũ_n > 0: a gap
  EXPECT_TRUE(SolveSingleContactExact(w, u_free, 0.5).isZero(0.0));
  for (SolverKind kind : kAllKinds) {
    SolverStats stats;
    EXPECT_TRUE(SolveWith(kind, OneContact(w, u_free, 0.5), &stats).isZero(1e-12))
        << SolverName(kind);
    EXPECT_EQ(stats.state_counts[static_cast<int>(ContactState::kSeparating)], 1);
  }
}

Eigen::Matrix3d CoupledBlock() {
  // SPD with normal-tangential coupling (eigenvalues all positive: diagonally dominant).
  Eigen::Matrix3d w;
  w << 1.0, 0.25, -0.15, 0.25, 1.6, 0.2, -0.15, 0.2, 1.3;
  return 1e-3 * w;
}

// Coupled block, stick: the closed form is r = −W⁻¹ũ (u = 0), inside the cone.
TEST(SingleContactTest, CoupledStickIsMinusInverseTimesFreeDisplacement) {
  const Eigen::Matrix3d w = CoupledBlock();
  const Eigen::Vector3d u_free(-1e-3, 1e-4, 2e-4);
  const double mu = 0.6;
  const Eigen::Vector3d expected = -w.inverse() * u_free;
  ASSERT_LT(std::hypot(expected(1), expected(2)), mu * expected(0));  // a stick case indeed
  for (SolverKind kind : kAllKinds) {
    EXPECT_TRUE(SolveWith(kind, OneContact(w, u_free, mu)).isApprox(expected, 1e-9))
        << SolverName(kind);
  }
}

// Coupled block, slide, built backwards: choose r on the cone boundary and a slip u_t
// antiparallel to r_t with u_n = 0, then ũ = u − W r. That (r, u) satisfies the contact law by
// construction, so it is the expected answer.
TEST(SingleContactTest, CoupledSlideRecoversConstructedSolution) {
  const Eigen::Matrix3d w = CoupledBlock();
  const double mu = 0.4;
  for (double theta : {0.3, 1.9, 3.5, 5.2}) {
    const double rn = 0.8;  // N
    const Eigen::Vector3d r(rn, mu * rn * std::cos(theta), mu * rn * std::sin(theta));
    const double slip = 4e-4;  // m
    const Eigen::Vector3d u(0.0, -slip * std::cos(theta), -slip * std::sin(theta));
    const Eigen::Vector3d u_free = u - w * r;
    EXPECT_TRUE(SolveSingleContactExact(w, u_free, mu).isApprox(r, 1e-10)) << theta;
    for (SolverKind kind : kAllKinds) {
      const Eigen::Vector3d got = SolveWith(kind, OneContact(w, u_free, mu));
      EXPECT_TRUE(got.isApprox(r, 1e-8)) << SolverName(kind) << " θ=" << theta << ": "
                                          << got.transpose();
      // The law itself: on the cone boundary, u_n = 0, u_t antiparallel to r_t.
      const Eigen::Vector3d ug = w * got + u_free;
      EXPECT_NEAR(std::hypot(got(1), got(2)), mu * got(0), 1e-8);
      EXPECT_NEAR(ug(0), 0.0, 1e-11);
      EXPECT_LT(ug(1) * got(1) + ug(2) * got(2), 0.0);
      EXPECT_NEAR(ug(1) * got(2) - ug(2) * got(1), 0.0, 1e-11);
    }
  }
}

TEST(SingleContactTest, FrictionlessSlidesFreely) {
  const Eigen::Matrix3d w = CoupledBlock();
  const Eigen::Vector3d u_free(-1e-3, 3e-4, 0.0);
  // μ = 0: r = (r_n, 0, 0) with u_n = W_nn r_n + ũ_n = 0.
  const Eigen::Vector3d expected(1e-3 / w(0, 0), 0.0, 0.0);
  EXPECT_TRUE(SolveSingleContactExact(w, u_free, 0.0).isApprox(expected, 1e-12));
  for (SolverKind kind : kAllKinds) {
    EXPECT_TRUE(SolveWith(kind, OneContact(w, u_free, 0.0)).isApprox(expected, 1e-9))
        << SolverName(kind);
  }
}

}  // namespace
}  // namespace hapco::contact
