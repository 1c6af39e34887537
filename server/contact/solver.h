#pragma once
// Frictional contact solvers for u = W r + ũ, r_α ∈ K_μα + Signorini/Coulomb (algorithms.md
// §2-4, paper section 3.3). Four types plus one call (design.md example 1):
//   SolverParameters, SolverStats, SolverResult, SolverStatus;
//   Solve(kind, problem, parameters, workspace, result).
// Not converging is a status; bad input throws hapco::InputError (design.md example 2).
//
// Allocation: Solve allocates nothing once `workspace->Reserve(m_max, k_max)` and
// `result->Reserve(m, k_max)` were called for the problem size m <= m_max and
// max_iterations <= k_max (design.md example 4: the 1 kHz path allocates nothing).
// Without them, Solve grows the buffers it needs (allocating) and still works.
#include <Eigen/Dense>

#include <array>
#include <string_view>
#include <vector>

#include "contact/problem.h"
#include "contact/projection.h"

namespace hapco::contact {

enum class SolverKind {
  kLocalUzawa,              // paper 3.3.1: Gauss-Seidel sweep, inner Uzawa loop per contact
  kGlobalUzawaGaussSeidel,  // paper 3.3.2: one predictor-corrector per contact, newest values
  kGlobalUzawaJacobi,       // De Saxcé fixed point: all contacts from u(k) = W r(k) + ũ
  kReferenceNsgs,           // Gauss-Seidel with an exact local solve (case enumeration)
};

// "local-uzawa", "global-uzawa-gs", "global-uzawa-jacobi", "reference".
std::string_view SolverName(SolverKind kind);
// Inverse of SolverName; throws hapco::InputError listing the valid names.
SolverKind ParseSolverKind(std::string_view name);

// How the Uzawa step ρ (a stiffness, N/m) is chosen (algorithms.md §4 "ρ").
enum class RhoRule {
  // ρ = min_i 1/W_ii over all 3m diagonal entries (paper 3.3.3): one ρ for every contact.
  kPaperGlobalMin,
  // ρ_α = 1/λ_max(W_αα) per contact: the smallest stiffness of the 3×3 block, i.e. the
  // paper's "ρ smaller than the smallest local stiffness" applied contact by contact.
  kPerContact,
};

struct SolverParameters {
  // ε₁, m. Outer stop (paper 3.3.1-3.3.3): converged at outer iteration k+1 when
  //     sqrt( Σ_α ‖r_α⁽ᵏ⁺¹⁾ − r_α⁽ᵏ⁾‖² / ρ_α² ) < ε₁
  // which is ‖r⁽ᵏ⁺¹⁾ − r⁽ᵏ⁾‖/ρ < ε₁ for the paper's single ρ. Range > 0.
  double global_tolerance_m = 1e-7;
  // ε₂, m. Local Uzawa inner stop (paper 3.3.1): ‖r_α⁽ʲ⁺¹⁾ − r_α⁽ʲ⁾‖/ρ_α < ε₂. Range > 0.
  // Only used by kLocalUzawa.
  double local_tolerance_m = 1e-8;
  // Optional extra stop on the scale-free residual (algorithms.md §4, see Fc3dError):
  //     fc3d(r⁽ᵏ⁺¹⁾) < fc3d_tolerance    (dimensionless; 0 = off).
  // When > 0, the solve stops as soon as EITHER test passes. Cost O(m) per iteration.
  double fc3d_tolerance = 0.0;
  // Cap on outer iterations (sweeps). Range >= 1.
  int max_iterations = 1000;
  // Cap on inner Uzawa iterations per contact per sweep (kLocalUzawa only). Range >= 1.
  int max_inner_iterations = 100;
  // Wall-clock budget, s, checked once per sweep (the haptic deadline, design.md example 5).
  // 0 = none. Range >= 0.
  double time_budget_s = 0.0;
  RhoRule rho_rule = RhoRule::kPaperGlobalMin;
  // ρ is multiplied by this (stability sweeps 0.1..10). Range > 0, dimensionless.
  double rho_scale = 1.0;
  // Start from result->force_n (must then have size 3m) instead of r⁽⁰⁾ = 0 (algorithms.md §4).
  bool warm_start = false;
  // Anderson acceleration of the Gauss-Seidel sweeps (not in the paper; Walker & Ni 2011;
  // docs/stability.md "Anderson acceleration"): from sweep `anderson_start` on, the next iterate is the
  // combination of the last `anderson_depth` + 1 sweeps' outputs whose residuals r⁽ᵏ⁺¹⁾ − r⁽ᵏ⁾
  // cancel best (least squares in the stop test's ρ-weighted norm); a growing residual resets
  // the history. The stop test and the returned force are a plain sweep's (projected, so in the
  // cones), so the converged forces meet the same ε₁. 0 = off (the paper's iteration).
  // Range 0..kMaxAndersonDepth; anderson_start >= 1. Not used by kGlobalUzawaJacobi.
  int anderson_depth = 0;
  int anderson_start = 10;
  static constexpr int kMaxAndersonDepth = 8;
  // Diverged when the outer residual exceeds
  //     divergence_factor × max(min residual so far, ε₁),
  // or any value becomes non-finite. Range > 1, dimensionless.
  double divergence_factor = 1e4;
};

enum class SolverStatus { kConverged, kMaxIterations, kTimeBudgetExceeded, kDiverged };
// "converged", "max-iterations", "time-budget-exceeded", "diverged".
std::string_view StatusName(SolverStatus status);

struct SolverStats {
  SolverStatus status = SolverStatus::kMaxIterations;
  int iterations = 0;        // outer iterations (sweeps) performed
  int inner_iterations = 0;  // total local updates (Uzawa inner steps, predictor-correctors or
                             // exact local solves)
  // kLocalUzawa: inner loops stopped by max_inner_iterations before meeting ε₂ (all sweeps).
  // A sweep with such a loop is never declared converged.
  int inner_limit_hits = 0;
  // Anderson acceleration: sweeps started from an extrapolated iterate, and history resets.
  int accelerated_iterations = 0;
  int acceleration_restarts = 0;
  // The extrapolation stopped improving the residual (1 % in 50 sweeps) and the solve went on
  // with plain sweeps.
  bool acceleration_stalled = false;
  // Always set at exit: the outer test value sqrt(Σ ‖Δr_α‖²/ρ_α²) of the last iteration, m.
  double paper_error_m = 0.0;
  // Always set at exit: Fc3dError of the returned force (dimensionless).
  double fc3d_error = 0.0;
  double seconds = 0.0;  // wall-clock time of Solve, s
  // ρ used, N/m: the single ρ for kPaperGlobalMin, the smallest ρ_α for kPerContact.
  double rho = 0.0;
  // paper_error_m after each outer iteration, m (capacity reserved by SolverResult::Reserve).
  std::vector<double> residual_history;
  // Contacts per state at exit, indexed by ContactState {separating, sticking, sliding}, with
  // tolerances force ρ·ε₁ (N) and slip ε₁ (m) (see ClassifyContact in projection.h).
  std::array<int, 3> state_counts{0, 0, 0};
};

struct SolverResult {
  Eigen::VectorXd force_n;         // r, 3m, N; the input when warm_start is set
  Eigen::VectorXd displacement_m;  // u = W r + ũ, 3m, m (recomputed exactly at exit)
  SolverStats stats;
  // Sizes force_n/displacement_m to 3m (zero) and reserves the residual history.
  void Reserve(int num_contacts, int max_iterations);
};

// Scratch memory, sized once (design.md example 4). Not thread-safe: one per solving thread.
class SolverWorkspace {
 public:
  // Makes Solve allocation-free for problems with up to max_contacts contacts.
  void Reserve(int max_contacts, int max_iterations);
  int reserved_contacts() const { return static_cast<int>(rho_per_contact_.size()); }

 private:
  friend struct SolverInternals;  // solver.cc
  Eigen::VectorXd u_;                // W r + ũ, 3 m_max
  Eigen::VectorXd r_previous_;       // last accepted (finite) iterate, 3 m_max
  Eigen::VectorXd rho_per_contact_;  // ρ_α, m_max
  // Anderson acceleration (SolverParameters::anderson_depth): differences of the last sweeps'
  // ρ-weighted residuals and outputs, 3 m_max × kMaxAndersonDepth each (a ring), and the
  // previous sweep's residual and output.
  Eigen::MatrixXd anderson_df_, anderson_dg_;
  Eigen::VectorXd anderson_f_, anderson_g_;
};

// Solves the problem with the chosen method; fills *result (forces, displacements, stats)
// and returns result->stats.status. On kDiverged the last finite iterate is returned, never
// a NaN force. Throws hapco::InputError on inconsistent sizes, a non-positive W_ii, or
// parameters out of range. Full consistency checks: ValidateProblem (problem.h), once per
// problem, outside the haptic loop.
SolverStatus Solve(SolverKind kind, const ContactProblem& problem,
                   const SolverParameters& parameters, SolverWorkspace* workspace,
                   SolverResult* result);

// Scale-free residual of algorithms.md §4 (the Siconos/FCLIB fc3d error), zero at a solution:
//     err(r) = ‖ r − Proj_Kμ( r − (u + μ‖u_t‖ n) ) ‖ / max(‖ũ‖, ‖r‖, ‖u‖),  u = W r + ũ,
// the projection taken contact by contact (the numerator alone if the denominator is 0).
// Allocates one 3m vector (not for the 1 kHz path; Solve uses an internal version).
double Fc3dError(const ContactProblem& problem, const Eigen::VectorXd& force_n);

}  // namespace hapco::contact
