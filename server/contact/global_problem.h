#pragma once
// The global friction-contact problem as FCLIB defines it (fclib.h, "GM3DFC"), spacedim 3 and
// without equality constraints (G, b):
//
//     M v = H r + f,      u = Hᵀ v + w,      r_α ∈ K_μα, Signorini/Coulomb on
//     û_α = u_α + [μ_α ‖u_α,t‖, 0, 0]      (local coordinates [normal, t1, t2] per contact).
//
// Sign convention, as fclib.h states it and Siconos reads it (its q = f, b = w): the contact
// forces enter the momentum balance with +H r, so v = M⁻¹ (H r + f).
// Units are the writer's: for a HapCo scene M is a stiffness (N/m), v and u displacements (m),
// r and f forces (N); for a time-stepping code M is a mass (kg), v and u velocities (m/s), r and
// f impulses (N s). Plain data, like ContactProblem (paper §3: the flexibility method reduces
// this problem to the local one, delassus/delassus.h).
#include <Eigen/Dense>
#include <Eigen/SparseCore>

namespace hapco::contact {

struct GlobalContactProblem {
  Eigen::SparseMatrix<double> m;  // n × n, symmetric positive definite (both triangles stored)
  Eigen::SparseMatrix<double> h;  // n × 3 n_c, column 3α+k: direction k of contact α
  Eigen::VectorXd f;              // n
  Eigen::VectorXd w;              // 3 n_c
  Eigen::VectorXd mu;             // n_c, Coulomb coefficients ≥ 0

  int num_dofs() const { return static_cast<int>(m.rows()); }
  int num_contacts() const { return static_cast<int>(mu.size()); }
};

// Largest accepted max|M − Mᵀ| / max|M| (round-off of the writer; see fclib_io.h's
// kMaxRelativeAsymmetry for the argument). The Delassus operator uses (M + Mᵀ)/2.
inline constexpr double kMaxMassRelativeAsymmetry = 1e-4;

// max|M − Mᵀ| / max|M| of a square sparse matrix (0 for M = 0), dimensionless.
double SparseRelativeAsymmetry(const Eigen::SparseMatrix<double>& m);

// Throws hapco::InputError naming the first inconsistency: sizes (M n×n, H n×3n_c, f n, w 3n_c,
// μ n_c, n_c ≥ 1), non-finite entries, μ < 0, an asymmetric M beyond the tolerance above, or a
// non-positive diagonal entry of M. Positive definiteness is checked by the factorization.
void ValidateGlobalProblem(const GlobalContactProblem& problem);

// The residual of a candidate solution (v, r) of the global problem, computed from the global
// data only (no Delassus operator, no local solve):
//   momentum        ‖M v − H r − f‖ / max(‖f‖, ‖H r‖, ‖M v‖)      (0 when all three are 0)
//   complementarity Fc3d of (r, u = Hᵀ v + w): ‖r − Proj_K(r − û)‖ / max(‖w‖, ‖r‖, ‖u‖),
//                   the local measure of contact/solver.h applied to the global u
struct GlobalResidual {
  double momentum = 0.0;
  double complementarity = 0.0;
  Eigen::VectorXd u;  // Hᵀ v + w
};
GlobalResidual ComputeGlobalResidual(const GlobalContactProblem& problem, const Eigen::VectorXd& v,
                                     const Eigen::VectorXd& r);

}  // namespace hapco::contact
