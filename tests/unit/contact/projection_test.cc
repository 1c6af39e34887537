// Cone projection (algorithms.md §3): the three cases, idempotence, optimality against a
// brute-force minimisation over the cone, and the Moreau decomposition.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "contact/projection.h"

namespace hapco::contact {
namespace {

bool InCone(const Eigen::Vector3d& x, double mu, double tol) {
  return std::hypot(x(1), x(2)) <= mu * x(0) + tol && x(0) >= -tol;
}

TEST(ProjectionTest, InsideIsUnchanged) {
  const Eigen::Vector3d r(2.0, 0.3, -0.4);  // ‖r_t‖ = 0.5 <= 0.5 · 2
  EXPECT_TRUE(ProjectOnCoulombCone(r, 0.5).isApprox(r, 0.0));
}

TEST(ProjectionTest, PolarConeGoesToZero) {
  // μ a <= −r_n: a = 0.5, μ = 0.5 -> 0.25 <= 1.
  EXPECT_EQ(ProjectOnCoulombCone(Eigen::Vector3d(-1.0, 0.3, 0.4), 0.5), Eigen::Vector3d::Zero());
  EXPECT_EQ(ProjectOnCoulombCone(Eigen::Vector3d(-1.0, 0.0, 0.0), 0.0), Eigen::Vector3d::Zero());
}

TEST(ProjectionTest, BoundaryCaseMatchesHandComputation) {
  // r = (1, 3, 4), μ = 0.5: a = 5, normal = (1 + 2.5)/1.25 = 2.8, tangential 1.4 along (0.6, 0.8).
  const Eigen::Vector3d p = ProjectOnCoulombCone(Eigen::Vector3d(1.0, 3.0, 4.0), 0.5);
  EXPECT_NEAR(p(0), 2.8, 1e-14);
  EXPECT_NEAR(p(1), 1.4 * 0.6, 1e-14);
  EXPECT_NEAR(p(2), 1.4 * 0.8, 1e-14);
}

TEST(ProjectionTest, FrictionlessIsHalfLine) {
  const Eigen::Vector3d p = ProjectOnCoulombCone(Eigen::Vector3d(0.7, 3.0, -4.0), 0.0);
  EXPECT_EQ(p, Eigen::Vector3d(0.7, 0.0, 0.0));
}

// Brute force, independent of the closed form: the nearest cone point is r itself when r is
// in the cone; otherwise it lies on the boundary, a union of rays t d(φ), d(φ) = (1, μ cos φ,
// μ sin φ), t >= 0 (the apex is t = 0). The nearest point of one ray is elementary
// (t = max(0, d·r/‖d‖²)); φ is scanned densely, then refined by ternary search.
double BruteForceDistance(const Eigen::Vector3d& target, double mu) {
  if (target(0) >= 0.0 && std::hypot(target(1), target(2)) <= mu * target(0)) return 0.0;
  auto ray_distance = [&](double phi) {
    const Eigen::Vector3d d(1.0, mu * std::cos(phi), mu * std::sin(phi));
    const double t = std::max(0.0, d.dot(target) / d.squaredNorm());
    return (t * d - target).norm();
  };
  constexpr int kScan = 3600;
  const double h = 2.0 * std::numbers::pi / kScan;
  double best_phi = 0.0, best = ray_distance(0.0);
  for (int k = 1; k < kScan; ++k) {
    const double d = ray_distance(k * h);
    if (d < best) { best = d; best_phi = k * h; }
  }
  double lo = best_phi - h, hi = best_phi + h;
  for (int k = 0; k < 200; ++k) {
    const double m1 = lo + (hi - lo) / 3.0, m2 = hi - (hi - lo) / 3.0;
    if (ray_distance(m1) < ray_distance(m2)) hi = m2; else lo = m1;
  }
  return std::min(best, ray_distance(0.5 * (lo + hi)));
}

TEST(ProjectionTest, OptimalAgainstBruteForceOnRandomInputs) {
  std::mt19937 rng(20261121u);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> mu_dist(0.0, 1.5);
  int boundary_cases = 0, inside_cases = 0, polar_cases = 0;
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d r(normal(rng), normal(rng), normal(rng));
    const double mu = mu_dist(rng);
    const Eigen::Vector3d p = ProjectOnCoulombCone(r, mu);
    ASSERT_TRUE(InCone(p, mu, 1e-12)) << "k=" << k;
    const double d_proj = (p - r).norm();
    const double d_brute = BruteForceDistance(r, mu);
    // The projection is never farther than any cone point found, and the search finds it.
    EXPECT_LE(d_proj, d_brute + 1e-12) << "k=" << k;
    EXPECT_NEAR(d_proj, d_brute, 1e-10 * (1.0 + r.norm())) << "k=" << k;
    if (p == r) ++inside_cases;
    else if (p.isZero(0.0)) ++polar_cases;
    else ++boundary_cases;
  }
  // The random set exercised all three cases.
  EXPECT_GT(inside_cases, 50);
  EXPECT_GT(polar_cases, 50);
  EXPECT_GT(boundary_cases, 50);
}

TEST(ProjectionTest, IdempotentAndMoreauDecomposition) {
  std::mt19937 rng(5u);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> mu_dist(0.0, 2.0);
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d r(normal(rng), normal(rng), normal(rng));
    const double mu = mu_dist(rng);
    const Eigen::Vector3d p = ProjectOnCoulombCone(r, mu);
    EXPECT_TRUE(ProjectOnCoulombCone(p, mu).isApprox(p, 1e-14) ||
                (p.isZero(0.0) && ProjectOnCoulombCone(p, mu).isZero(0.0)));
    const Eigen::Vector3d y = r - p;
    // (r − P r) ⟂ P r ...
    EXPECT_NEAR(y.dot(p), 0.0, 1e-12 * (1.0 + r.squaredNorm()));
    // ... and lies in the polar cone K° = { y : μ ‖y_t‖ <= −y_n }.
    EXPECT_LE(mu * std::hypot(y(1), y(2)), -y(0) + 1e-12 * (1.0 + r.norm()));
  }
}

TEST(ProjectionTest, ClassifyAndCountStates) {
  const double ftol = 1e-9, dtol = 1e-9;
  EXPECT_EQ(ClassifyContact(Eigen::Vector3d::Zero(), Eigen::Vector3d(1e-3, 0, 0), ftol, dtol),
            ContactState::kSeparating);
  EXPECT_EQ(ClassifyContact(Eigen::Vector3d(1, 0.1, 0), Eigen::Vector3d::Zero(), ftol, dtol),
            ContactState::kSticking);
  EXPECT_EQ(ClassifyContact(Eigen::Vector3d(1, 0.5, 0), Eigen::Vector3d(0, -1e-4, 0), ftol, dtol),
            ContactState::kSliding);
  Eigen::VectorXd r(9), u(9);
  r << 0, 0, 0, 1, 0.1, 0, 1, 0.5, 0;
  u << 1e-3, 0, 0, 0, 0, 0, 0, -1e-4, 0;
  const auto counts = CountContactStates(r, u, ftol, dtol);
  EXPECT_EQ(counts[0], 1);
  EXPECT_EQ(counts[1], 1);
  EXPECT_EQ(counts[2], 1);
  EXPECT_EQ(ContactStateName(ContactState::kSliding), "sliding");
}

}  // namespace
}  // namespace hapco::contact
