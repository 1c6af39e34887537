#include "contact/local_solver.h"

#include <numbers>

#include "contact/projection.h"

namespace hapco::contact {

Eigen::Vector3d UzawaPredictorCorrector(const Eigen::Vector3d& r, const Eigen::Vector3d& u,
                                        double mu, double rho_n_per_m) {
  return ProjectOnCoulombCone(r - rho_n_per_m * ModifiedDisplacement(u, mu), mu);
}

double LocalResidual(const Eigen::Matrix3d& a, const Eigen::Vector3d& q,
                     const Eigen::Vector3d& r, double mu, double rho_n_per_m) {
  const Eigen::Vector3d u = a * r + q;
  return (r - UzawaPredictorCorrector(r, u, mu, rho_n_per_m)).norm();
}

namespace {

// Sliding candidate at angle θ: r = r_n (1, μ cos θ, μ sin θ) with u_n = 0 (case 4).
struct SlideSample {
  bool valid = false;       // (A d)_n > 0, so that r_n > 0 exists
  double cross = 0.0;       // f(θ) = u_t × e(θ), zero when u_t ∥ e(θ)
  double along = 0.0;       // u_t · e(θ), must be < 0 (antiparallel)
  Eigen::Vector3d r = Eigen::Vector3d::Zero();
};

SlideSample EvaluateSlide(const Eigen::Matrix3d& a, const Eigen::Vector3d& q, double mu,
                          double theta) {
  SlideSample s;
  const double c = std::cos(theta);
  const double sn = std::sin(theta);
  const Eigen::Vector3d d(1.0, mu * c, mu * sn);
  const Eigen::Vector3d ad = a * d;
  if (!(ad(0) > 0.0)) return s;
  const double rn = -q(0) / ad(0);  // q_n < 0 here, so r_n > 0
  s.valid = true;
  s.r = rn * d;
  const double ut1 = rn * ad(1) + q(1);
  const double ut2 = rn * ad(2) + q(2);
  s.cross = ut1 * sn - ut2 * c;
  s.along = ut1 * c + ut2 * sn;
  return s;
}

}  // namespace

Eigen::Vector3d SolveSingleContactExact(const Eigen::Matrix3d& a, const Eigen::Vector3d& q,
                                        double mu) {
  // 1. Separating: r = 0 leaves the gap u = q, admissible when q_n >= 0.
  if (q(0) >= 0.0) return Eigen::Vector3d::Zero();
  // 2. Sticking: u = 0 -> r = −A⁻¹q, admissible inside the cone (round-off slack 1e-12).
  const Eigen::Vector3d stick = -a.inverse() * q;
  const double stick_t = std::hypot(stick(1), stick(2));
  if (stick(0) > 0.0 && stick_t <= mu * stick(0) * (1.0 + 1e-12)) return stick;
  // 3. Frictionless: only u_n = 0 matters.
  if (mu == 0.0) return Eigen::Vector3d(-q(0) / a(0, 0), 0.0, 0.0);

  // 4. Sliding. Candidates are ranked by the local residual with ρ = 1/A_nn, which makes
  // the force and displacement parts commensurate.
  const double rho = 1.0 / a(0, 0);
  Eigen::Vector3d best = ProjectOnCoulombCone(stick, mu);
  double best_residual = LocalResidual(a, q, best, mu, rho);

  constexpr int kSamples = 64;
  constexpr double kStep = 2.0 * std::numbers::pi / kSamples;
  SlideSample first = EvaluateSlide(a, q, mu, 0.0);
  SlideSample left = first;
  for (int i = 0; i < kSamples; ++i) {
    const double theta0 = i * kStep;
    const SlideSample right = (i + 1 == kSamples) ? first : EvaluateSlide(a, q, mu, theta0 + kStep);
    if (left.valid && right.valid && (left.cross <= 0.0) != (right.cross <= 0.0)) {
      // Bisection keeps the sign change bracketed; 60 halvings reach round-off in θ.
      double lo = theta0;
      double hi = theta0 + kStep;
      const bool lo_nonpositive = left.cross <= 0.0;
      SlideSample mid = left;
      for (int k = 0; k < 60; ++k) {
        const double t = 0.5 * (lo + hi);
        mid = EvaluateSlide(a, q, mu, t);
        if (!mid.valid) break;
        if ((mid.cross <= 0.0) == lo_nonpositive) {
          lo = t;
        } else {
          hi = t;
        }
      }
      if (mid.valid && mid.along <= 0.0) {
        const double residual = LocalResidual(a, q, mid.r, mu, rho);
        if (residual < best_residual) {
          best_residual = residual;
          best = mid.r;
        }
      }
    }
    left = right;
  }
  return best;
}

}  // namespace hapco::contact
