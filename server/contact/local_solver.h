#pragma once
// Single-contact building blocks shared by the solvers (algorithms.md §3-4). Local coordinates
// [n, t1, t2]; A = W_αα (m/N, 3×3 symmetric positive definite), q = Σ_{β≠α} W_αβ r_β + ũ_α (m),
// so that u_α = A r_α + q.
#include <Eigen/Dense>

#include <cmath>

namespace hapco::contact {

// The De Saxcé modified displacement u + μ‖u_t‖ n (algorithms.md §3), m.
inline Eigen::Vector3d ModifiedDisplacement(const Eigen::Vector3d& u, double mu) {
  Eigen::Vector3d v = u;
  v(0) += mu * std::sqrt(u(1) * u(1) + u(2) * u(2));
  return v;
}

// One predictor-corrector (paper 3.3.1-3.3.2): Proj_Kμ(r − ρ (u + μ‖u_t‖ n)), N; ρ in N/m.
Eigen::Vector3d UzawaPredictorCorrector(const Eigen::Vector3d& r, const Eigen::Vector3d& u,
                                        double mu, double rho_n_per_m);

// Local natural-map residual ‖r − Proj_Kμ(r − ρ (u + μ‖u_t‖ n))‖, N, with u = A r + q; for
// ρ = 1 it is the fc3d numerator of one contact (algorithms.md §4). Zero exactly at a solution.
double LocalResidual(const Eigen::Matrix3d& a, const Eigen::Vector3d& q,
                     const Eigen::Vector3d& r, double mu, double rho_n_per_m = 1.0);

// Exact solve of one contact by case enumeration, independent of Uzawa (reference NSGS):
//   1. separating: q_n >= 0          -> r = 0 (u = q is an admissible gap);
//   2. sticking:   r = −A⁻¹q ∈ K_μ   -> u = 0;
//   3. frictionless (μ = 0):          r = (−q_n/A_nn, 0, 0);
//   4. sliding:    r = r_n (1, μ cos θ, μ sin θ) with u_n = 0, which fixes r_n(θ) = −q_n /
//      (A d(θ))_n, and u_t antiparallel to (cos θ, sin θ): a 1-D root of
//      f(θ) = u_t(θ) × (cos θ, sin θ) with u_t · (cos θ, sin θ) < 0, bracketed by sampling
//      θ on [0, 2π) and refined by bisection to round-off.
// If round-off leaves no case satisfied exactly, returns the candidate with the smallest
// LocalResidual. Allocation-free; about 60 + 64 evaluations of a 3×3 product in the worst case.
Eigen::Vector3d SolveSingleContactExact(const Eigen::Matrix3d& a, const Eigen::Vector3d& q,
                                        double mu);

}  // namespace hapco::contact
