#pragma once
// The local friction-contact problem at m contact points (algorithms.md §2):
//
//     u = W r + ũ,      r_α ∈ K_μα,  Signorini + Coulomb at every α,
//
// in local coordinates ordered [normal, t1, t2] per contact. This is plain data that can be
// saved (FCLIB) and replayed (design.md, example 6).
#include <Eigen/Dense>

namespace hapco::contact {

struct ContactProblem {
  // Flexibility (Delassus) operator W = Σ_b H_b K_b⁻¹ H_bᵀ, 3m × 3m, in m/N. Symmetric
  // positive semi-definite. Block (α, β) couples the force at β to the displacement at α.
  Eigen::MatrixXd flexibility_m_per_n;
  // Free relative displacement ũ (all contact forces zero), 3m, in m. ũ_n > 0 is a gap.
  Eigen::VectorXd free_displacement_m;
  // Coulomb friction coefficient μ_α ≥ 0 per contact, dimensionless, size m.
  Eigen::VectorXd friction_coefficient;

  int num_contacts() const { return static_cast<int>(friction_coefficient.size()); }
};

// Throws hapco::InputError naming the first inconsistency: sizes that do not match 3m,
// non-finite entries, μ < 0, an asymmetric W (relative 1e-8), or a non-positive W_ii.
void ValidateProblem(const ContactProblem& problem);

}  // namespace hapco::contact
