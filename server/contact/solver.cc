// Solvers of algorithms.md §4 (paper section 3.3). Layout of every sweep:
// - u = W r + ũ is kept current in the workspace. Gauss-Seidel sweeps update it incrementally
//   after each contact, u += W_{:,α} Δr_α: three contiguous columns of the column-major W, so
//   a full sweep costs about one dense W·r product and contacts that do not move cost nothing.
// - Jacobi recomputes u = W r + ũ once per sweep (one product).
// u is recomputed exactly at exit, so incremental round-off never reaches the result.
#include "contact/solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "common/error.h"
#include "common/timer.h"
#include "contact/local_solver.h"
#include "contact/projection.h"

namespace hapco::contact {

std::string_view SolverName(SolverKind kind) {
  switch (kind) {
    case SolverKind::kLocalUzawa: return "local-uzawa";
    case SolverKind::kGlobalUzawaGaussSeidel: return "global-uzawa-gs";
    case SolverKind::kGlobalUzawaJacobi: return "global-uzawa-jacobi";
    case SolverKind::kReferenceNsgs: return "reference";
  }
  return "unknown";
}

SolverKind ParseSolverKind(std::string_view name) {
  for (SolverKind k : {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel,
                       SolverKind::kGlobalUzawaJacobi, SolverKind::kReferenceNsgs}) {
    if (SolverName(k) == name) return k;
  }
  throw InputError("unknown solver '" + std::string(name) +
                   "'; valid names: local-uzawa, global-uzawa-gs, global-uzawa-jacobi, reference");
}

std::string_view StatusName(SolverStatus status) {
  switch (status) {
    case SolverStatus::kConverged: return "converged";
    case SolverStatus::kMaxIterations: return "max-iterations";
    case SolverStatus::kTimeBudgetExceeded: return "time-budget-exceeded";
    case SolverStatus::kDiverged: return "diverged";
  }
  return "unknown";
}

void SolverResult::Reserve(int num_contacts, int max_iterations) {
  force_n = Eigen::VectorXd::Zero(3 * num_contacts);
  displacement_m = Eigen::VectorXd::Zero(3 * num_contacts);
  stats.residual_history.reserve(static_cast<std::size_t>(std::max(max_iterations, 0)));
}

void SolverWorkspace::Reserve(int max_contacts, int /*max_iterations*/) {
  // The residual history lives in SolverResult (SolverResult::Reserve); max_iterations is
  // accepted here so that callers size everything from the same two numbers.
  if (max_contacts > reserved_contacts()) {
    u_.resize(3 * max_contacts);
    r_previous_.resize(3 * max_contacts);
    rho_per_contact_.resize(max_contacts);
    anderson_df_.resize(3 * max_contacts, SolverParameters::kMaxAndersonDepth);
    anderson_dg_.resize(3 * max_contacts, SolverParameters::kMaxAndersonDepth);
    anderson_f_.resize(3 * max_contacts);
    anderson_g_.resize(3 * max_contacts);
  }
}

struct SolverInternals {
  static Eigen::VectorXd& U(SolverWorkspace* w) { return w->u_; }
  static Eigen::VectorXd& RPrevious(SolverWorkspace* w) { return w->r_previous_; }
  static Eigen::VectorXd& Rho(SolverWorkspace* w) { return w->rho_per_contact_; }
  static Eigen::MatrixXd& AndersonDf(SolverWorkspace* w) { return w->anderson_df_; }
  static Eigen::MatrixXd& AndersonDg(SolverWorkspace* w) { return w->anderson_dg_; }
  static Eigen::VectorXd& AndersonF(SolverWorkspace* w) { return w->anderson_f_; }
  static Eigen::VectorXd& AndersonG(SolverWorkspace* w) { return w->anderson_g_; }
};

namespace {

void CheckParameters(const SolverParameters& p) {
  auto fail = [](const std::string& what) { throw InputError("solver parameters: " + what); };
  if (!(p.global_tolerance_m > 0.0)) fail("global_tolerance_m must be > 0 (metres)");
  if (!(p.local_tolerance_m > 0.0)) fail("local_tolerance_m must be > 0 (metres)");
  if (!(p.fc3d_tolerance >= 0.0)) fail("fc3d_tolerance must be >= 0 (0 = off)");
  if (p.max_iterations < 1) fail("max_iterations must be >= 1");
  if (p.max_inner_iterations < 1) fail("max_inner_iterations must be >= 1");
  if (!(p.time_budget_s >= 0.0) || !std::isfinite(p.time_budget_s)) {
    fail("time_budget_s must be finite and >= 0 (0 = no budget)");
  }
  if (!(p.rho_scale > 0.0) || !std::isfinite(p.rho_scale)) fail("rho_scale must be finite and > 0");
  if (!(p.divergence_factor > 1.0)) fail("divergence_factor must be > 1");
  if (p.anderson_depth < 0 || p.anderson_depth > SolverParameters::kMaxAndersonDepth) {
    fail("anderson_depth must be in 0.." + std::to_string(SolverParameters::kMaxAndersonDepth) + " (0 = off)");
  }
  if (p.anderson_start < 1) fail("anderson_start must be >= 1");
}

// Fc3d error (algorithms.md §4) from r, u = W r + ũ and ũ, without allocating.
double Fc3dFromState(const Eigen::VectorXd& mu, const Eigen::Ref<const Eigen::VectorXd>& r,
                     const Eigen::Ref<const Eigen::VectorXd>& u,
                     const Eigen::VectorXd& u_free) {
  double numerator2 = 0.0;
  for (Eigen::Index a = 0; a < mu.size(); ++a) {
    const Eigen::Vector3d ra = r.segment<3>(3 * a);
    const Eigen::Vector3d ua = u.segment<3>(3 * a);
    numerator2 += (ra - UzawaPredictorCorrector(ra, ua, mu(a), 1.0)).squaredNorm();
  }
  const double numerator = std::sqrt(numerator2);
  const double denominator = std::max({u_free.norm(), r.norm(), u.norm()});
  return denominator > 0.0 ? numerator / denominator : numerator;
}

// ρ_α for every contact (algorithms.md §4 "ρ"); returns the smallest.
double ComputeRho(const ContactProblem& problem, const SolverParameters& p,
                  Eigen::Ref<Eigen::VectorXd> rho) {
  const auto& w = problem.flexibility_m_per_n;
  const Eigen::Index m = problem.num_contacts();
  const Eigen::Index n = 3 * m;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!(w(i, i) > 0.0)) {
      throw InputError("contact problem: flexibility diagonal W(" + std::to_string(i) + "," +
                       std::to_string(i) + ") = " + std::to_string(w(i, i)) +
                       " m/N must be > 0 (run ValidateProblem for a full check)");
    }
  }
  if (p.rho_rule == RhoRule::kPaperGlobalMin) {
    // Paper 3.3.3: ρ = min_i 1/W_ii, i = 1..3m.
    const double rho_min = p.rho_scale / w.diagonal().maxCoeff();
    rho.setConstant(rho_min);
    return rho_min;
  }
  double rho_min = std::numeric_limits<double>::infinity();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  for (Eigen::Index a = 0; a < m; ++a) {
    const Eigen::Matrix3d block = w.block<3, 3>(3 * a, 3 * a);
    eig.computeDirect(block, Eigen::EigenvaluesOnly);
    const double lambda_max = eig.eigenvalues()(2);  // ascending order
    HAPCO_ASSERT(lambda_max > 0.0, "positive diagonal implies a positive largest eigenvalue");
    rho(a) = p.rho_scale / lambda_max;
    rho_min = std::min(rho_min, rho(a));
  }
  return rho_min;
}

// The local Uzawa inner loop of one contact (paper 3.3.1, algorithms.md §4) on scalars:
//     u = A r + q,  r ← Proj_Kμ(r − ρ (u + μ‖u_t‖ n)),  until ‖Δr‖/ρ < ε₂ or max_steps.
// Same formulas as UzawaPredictorCorrector / ProjectOnCoulombCone (algorithms.md §3), inlined
// with sqrt instead of hypot (forces and displacements are far from overflow) and the stop
// test squared (‖Δr‖² < (ρ ε₂)², no sqrt or division per step). *r holds the start on entry
// and the last iterate on exit; returns whether ε₂ was met (false also on NaN).
bool LocalUzawaInner(const Eigen::Matrix3d& a, const Eigen::Vector3d& q, double mu, double rho,
                     double tolerance_m, int max_steps, Eigen::Vector3d* r, int* steps) {
  const double a00 = a(0, 0), a01 = a(0, 1), a02 = a(0, 2);
  const double a10 = a(1, 0), a11 = a(1, 1), a12 = a(1, 2);
  const double a20 = a(2, 0), a21 = a(2, 1), a22 = a(2, 2);
  const double q0 = q(0), q1 = q(1), q2 = q(2);
  const double tol_n = rho * tolerance_m;
  const double tol2 = tol_n * tol_n;
  const double mu2p1 = 1.0 + mu * mu;
  double r0 = (*r)(0), r1 = (*r)(1), r2 = (*r)(2);
  bool met = false;
  int j = 0;
  while (j < max_steps) {
    const double u0 = a00 * r0 + a01 * r1 + a02 * r2 + q0;
    const double u1 = a10 * r0 + a11 * r1 + a12 * r2 + q1;
    const double u2 = a20 * r0 + a21 * r1 + a22 * r2 + q2;
    // Predictor r* = r − ρ (u + μ‖u_t‖ n).
    const double sn = r0 - rho * (u0 + mu * std::sqrt(u1 * u1 + u2 * u2));
    const double s1 = r1 - rho * u1;
    const double s2 = r2 - rho * u2;
    // Corrector: projection on K_μ (cases of algorithms.md §3).
    const double at = std::sqrt(s1 * s1 + s2 * s2);
    double n0, n1, n2;
    if (sn >= 0.0 && at <= mu * sn) {  // inside: sticking
      n0 = sn;
      n1 = s1;
      n2 = s2;
    } else if (mu * at <= -sn) {  // polar cone: separating
      n0 = 0.0;
      n1 = 0.0;
      n2 = 0.0;
    } else {  // boundary: sliding
      n0 = (sn + mu * at) / mu2p1;
      const double scale = at > 0.0 ? mu * n0 / at : 0.0;
      n1 = scale * s1;
      n2 = scale * s2;
    }
    ++j;
    const double d0 = n0 - r0, d1 = n1 - r1, d2 = n2 - r2;
    const double step2 = d0 * d0 + d1 * d1 + d2 * d2;
    r0 = n0;
    r1 = n1;
    r2 = n2;
    if (!(step2 >= tol2)) {  // also stops on NaN (caught by the caller)
      met = step2 < tol2;
      break;
    }
  }
  (*r)(0) = r0;
  (*r)(1) = r1;
  (*r)(2) = r2;
  *steps = j;
  return met;
}

// One Gauss-Seidel sweep (paper 3.3.1 / 3.3.2, or exact local solves). Updates r and u in
// place; returns Σ ‖Δr_α‖²/ρ_α², adds the local iteration count to *inner and the number of
// local Uzawa loops stopped by max_inner_iterations to *inner_limit_hits.
double GaussSeidelSweep(SolverKind kind, const ContactProblem& problem,
                        const SolverParameters& p, const Eigen::Ref<const Eigen::VectorXd>& rho,
                        Eigen::VectorXd& r, Eigen::Ref<Eigen::VectorXd> u, int* inner,
                        int* inner_limit_hits) {
  const auto& w = problem.flexibility_m_per_n;
  const Eigen::Index m = problem.num_contacts();
  double sum = 0.0;
  for (Eigen::Index a = 0; a < m; ++a) {
    const Eigen::Index i = 3 * a;
    const double mu = problem.friction_coefficient(a);
    const double rho_a = rho(a);
    const Eigen::Matrix3d waa = w.block<3, 3>(i, i);
    const Eigen::Vector3d r_old = r.segment<3>(i);
    // q = ᵅᵝu + ũ_α: coupling with the newest values of the others plus the free part.
    const Eigen::Vector3d q = u.segment<3>(i) - waa * r_old;
    Eigen::Vector3d r_new = r_old;
    switch (kind) {
      case SolverKind::kGlobalUzawaGaussSeidel:
        // Paper 3.3.2: one predictor-corrector with the current u_α.
        r_new = UzawaPredictorCorrector(r_old, u.segment<3>(i), mu, rho_a);
        *inner += 1;
        break;
      case SolverKind::kLocalUzawa: {
        // Paper 3.3.1 inner loop: predictor, corrector, back-up u = W_αα r + ᵅᵝu + ũ_α,
        // until ‖Δr_α‖/ρ < ε₂. Started from the current r_α rather than the paper's 0, so
        // that a warm start carries through the inner loop too. The loop runs on scalars in
        // registers (LocalUzawaInner): it dominates the sweep for small m.
        int steps = 0;
        const bool met = LocalUzawaInner(waa, q, mu, rho_a, p.local_tolerance_m,
                                         p.max_inner_iterations, &r_new, &steps);
        *inner += steps;
        // An inner loop cut by the cap may even end where it started (a 2-cycle when ρ is
        // too large), which would fool the outer test ‖Δr‖/ρ < ε₁: count it.
        if (!met) *inner_limit_hits += 1;
        break;
      }
      case SolverKind::kReferenceNsgs:
        r_new = SolveSingleContactExact(waa, q, mu);
        *inner += 1;
        break;
      case SolverKind::kGlobalUzawaJacobi:
        HAPCO_ASSERT(false, "Jacobi order has no Gauss-Seidel sweep");
        r_new = r_old;
        break;
    }
    const Eigen::Vector3d d = r_new - r_old;
    if (d(0) != 0.0 || d(1) != 0.0 || d(2) != 0.0) {
      r.segment<3>(i) = r_new;
      // u += W_{:,α} Δr_α over three contiguous columns (W symmetric, column-major).
      u.noalias() += w.col(i) * d(0) + w.col(i + 1) * d(1) + w.col(i + 2) * d(2);
      sum += d.squaredNorm() / (rho_a * rho_a);
    }
  }
  return sum;
}

// One Jacobi sweep (De Saxcé fixed point): every contact from the same u(k) = W r(k) + ũ.
double JacobiSweep(const ContactProblem& problem, const Eigen::Ref<const Eigen::VectorXd>& rho,
                   Eigen::VectorXd& r, const Eigen::Ref<const Eigen::VectorXd>& u, int* inner) {
  const Eigen::Index m = problem.num_contacts();
  double sum = 0.0;
  for (Eigen::Index a = 0; a < m; ++a) {
    const Eigen::Index i = 3 * a;
    const Eigen::Vector3d r_old = r.segment<3>(i);
    const Eigen::Vector3d r_new = UzawaPredictorCorrector(
        r_old, u.segment<3>(i), problem.friction_coefficient(a), rho(a));
    r.segment<3>(i) = r_new;
    sum += (r_new - r_old).squaredNorm() / (rho(a) * rho(a));
  }
  *inner += static_cast<int>(m);
  return sum;
}

// Anderson acceleration of the sweep map G (SolverParameters::anderson_depth; Walker & Ni,
// "Anderson acceleration for fixed-point iterations", SIAM J. Numer. Anal. 49, 2011). With
// x⁽ᵏ⁾ the sweep's input, G(x⁽ᵏ⁾) its output and f⁽ᵏ⁾ = (G(x⁽ᵏ⁾) − x⁽ᵏ⁾)/ρ (per contact) the
// stop test's residual, the next input is G(x⁽ᵏ⁾) − ΔG γ with γ = argmin ‖f⁽ᵏ⁾ − ΔF γ‖ over
// the differences of the last `depth` sweeps. Gauss-Seidel on the Coulomb cones slows down
// to hundreds of sweeps when many contacts slide on coupled, soft surfaces (an organ under an
// instrument tip): the residual then shrinks along a few slow directions, which the
// extrapolation removes. No allocation: the history lives in the workspace.
class AndersonAcceleration {
 public:
  AndersonAcceleration(int depth, Eigen::Ref<Eigen::MatrixXd> df, Eigen::Ref<Eigen::MatrixXd> dg,
                       Eigen::Ref<Eigen::VectorXd> f_previous, Eigen::Ref<Eigen::VectorXd> g_previous)
      : depth_(depth), df_(df), dg_(dg), f_previous_(f_previous), g_previous_(g_previous) {}

  // Right after a sweep that started from an extrapolated iterate: if its stop-test value
  // `error` (m) is larger than the plain sweep's before it, the extrapolation is rejected:
  // r goes back to that plain sweep's output (projected, in the cones), u = W r + ũ again, and
  // the history restarts (the safeguard: never worse than the paper's iteration, one sweep
  // lost). Returns true if it rejected.
  bool RejectWorse(const ContactProblem& problem, double error, Eigen::VectorXd& r, Eigen::Ref<Eigen::VectorXd> u,
                   int* restarts) {
    if (!extrapolated_ || (error <= previous_error_ && std::isfinite(error))) return false;
    ++sweeps_since_best_;
    r = g_previous_;
    u.noalias() = problem.flexibility_m_per_n * r;
    u += problem.free_displacement_m;
    extrapolated_ = false;
    count_ = 0;
    has_previous_ = false;
    ++*restarts;
    return true;
  }

  // A sweep from an extrapolated iterate met the stop test: that is not enough, since the
  // extrapolation can land where one sweep barely moves without being near the solution (seen
  // next to a clamped edge, where 1 um of residual is hundreds of newtons). Returns true if
  // the stop must wait for a plain sweep from the current output to meet the test too.
  bool ConfirmBeforeStop() {
    if (!extrapolated_) return false;
    confirm_ = true;
    return true;
  }

  // True once the stagnation guard has handed the solve back to plain sweeps.
  bool stopped() const { return stopped_; }

  // After an accepted sweep that moved `input` to `r` with stop-test value `error` (m):
  // records the sweep and, when there is history, replaces r by the extrapolated next input
  // and makes u = W r + ũ again. Returns true if it extrapolated.
  bool Apply(const ContactProblem& problem, const Eigen::Ref<const Eigen::VectorXd>& rho,
             const Eigen::Ref<const Eigen::VectorXd>& input, double error, Eigen::VectorXd& r,
             Eigen::Ref<Eigen::VectorXd> u) {
    const Eigen::Index n = r.size();
    // Stagnation guard: on problems with many redundant contacts (rigid grains: W singular)
    // the extrapolation can creep along directions the residual barely sees while plain sweeps
    // would still converge (the FCLIB collection's granular problems, docs/stability.md). If
    // the best residual has not dropped by 1 % in kStallSweeps sweeps, the rest of this solve
    // is the paper's iteration.
    if (error < 0.99 * best_error_) {
      best_error_ = error;
      sweeps_since_best_ = 0;
    } else if (++sweeps_since_best_ >= kStallSweeps) {
      stopped_ = true;
    }
    if (stopped_) {
      extrapolated_ = false;
      return false;
    }
    const bool plain_next = confirm_;
    confirm_ = false;
    extrapolated_ = false;
    previous_error_ = error;
    for (Eigen::Index i = 0; i < n; ++i) {
      const double f = (r(i) - input(i)) / rho(i / 3);
      if (has_previous_) {
        df_(i, next_) = f - f_previous_(i);
        dg_(i, next_) = r(i) - g_previous_(i);
      }
      f_previous_(i) = f;
      g_previous_(i) = r(i);
    }
    if (has_previous_) {
      next_ = (next_ + 1) % depth_;
      count_ = std::min(count_ + 1, depth_);
    }
    has_previous_ = true;
    if (count_ == 0 || plain_next) return false;
    // Normal equations (count × count, at most 8 × 8: no heap), Tikhonov-regularized so that
    // nearly parallel differences (a stalled direction) cannot blow γ up.
    using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, SolverParameters::kMaxAndersonDepth,
                                SolverParameters::kMaxAndersonDepth>;
    using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, SolverParameters::kMaxAndersonDepth, 1>;
    const auto df = df_.leftCols(count_);
    Small normal = df.transpose() * df;
    const SmallVector rhs = df.transpose() * f_previous_;
    normal.diagonal().array() += 1e-10 * normal.diagonal().maxCoeff() + std::numeric_limits<double>::min();
    const SmallVector gamma = normal.ldlt().solve(rhs);
    if (!gamma.allFinite()) return false;  // r stays the plain sweep's output
    r.noalias() -= dg_.leftCols(count_) * gamma;
    u.noalias() = problem.flexibility_m_per_n * r;
    u += problem.free_displacement_m;
    extrapolated_ = true;
    return true;
  }

 private:
  int depth_;
  Eigen::Ref<Eigen::MatrixXd> df_, dg_;
  Eigen::Ref<Eigen::VectorXd> f_previous_, g_previous_;
  int count_ = 0;  // columns of df_/dg_ in use
  int next_ = 0;   // ring position of the next difference
  static constexpr int kStallSweeps = 50;
  bool has_previous_ = false;
  bool stopped_ = false;       // stagnated: plain sweeps for the rest of the solve
  double best_error_ = std::numeric_limits<double>::infinity();
  int sweeps_since_best_ = 0;
  bool extrapolated_ = false;  // the current sweep input is an extrapolation
  bool confirm_ = false;       // the next sweep starts from a plain output (ConfirmBeforeStop)
  double previous_error_ = std::numeric_limits<double>::infinity();
};

}  // namespace

SolverStatus Solve(SolverKind kind, const ContactProblem& problem,
                   const SolverParameters& parameters, SolverWorkspace* workspace,
                   SolverResult* result) {
  Stopwatch clock;
  HAPCO_ASSERT(workspace != nullptr && result != nullptr, "Solve needs a workspace and a result");
  CheckParameters(parameters);
  const int m = problem.num_contacts();
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(m);
  const auto& w = problem.flexibility_m_per_n;
  const auto& u_free = problem.free_displacement_m;
  if (w.rows() != n || w.cols() != n || u_free.size() != n) {
    throw InputError("contact problem: W is " + std::to_string(w.rows()) + "x" +
                     std::to_string(w.cols()) + " and ũ has size " +
                     std::to_string(u_free.size()) + ", but " + std::to_string(m) +
                     " friction coefficients need 3m = " + std::to_string(n));
  }
  workspace->Reserve(m, parameters.max_iterations);  // no-op once reserved
  auto u = SolverInternals::U(workspace).head(n);
  auto r_previous = SolverInternals::RPrevious(workspace).head(n);
  auto rho = SolverInternals::Rho(workspace).head(m);

  SolverStats& stats = result->stats;
  stats.status = SolverStatus::kMaxIterations;
  stats.iterations = 0;
  stats.inner_iterations = 0;
  stats.inner_limit_hits = 0;
  stats.accelerated_iterations = 0;
  stats.acceleration_restarts = 0;
  stats.acceleration_stalled = false;
  stats.paper_error_m = 0.0;
  stats.fc3d_error = 0.0;
  stats.residual_history.clear();  // keeps its capacity
  stats.state_counts = {0, 0, 0};

  Eigen::VectorXd& r = result->force_n;
  if (parameters.warm_start) {
    if (r.size() != n) {
      throw InputError("warm_start: result->force_n has size " + std::to_string(r.size()) +
                       " but the problem has 3m = " + std::to_string(n) + " force components");
    }
    if (!r.allFinite()) throw InputError("warm_start: result->force_n is not finite");
  } else if (r.size() != n) {
    r = Eigen::VectorXd::Zero(n);  // allocates only when m changed since the last call
  } else {
    r.setZero();
  }

  // ρ_α per contact (also checks W_ii > 0).
  stats.rho = m > 0 ? ComputeRho(problem, parameters, rho) : 0.0;

  // u(0) = W r(0) + ũ.
  if (parameters.warm_start) {
    u.noalias() = w * r;
    u += u_free;
  } else {
    u = u_free;
  }

  const bool accelerate = parameters.anderson_depth > 0 && kind != SolverKind::kGlobalUzawaJacobi;
  AndersonAcceleration anderson(
      std::max(parameters.anderson_depth, 1),
      SolverInternals::AndersonDf(workspace).topRows(n), SolverInternals::AndersonDg(workspace).topRows(n),
      SolverInternals::AndersonF(workspace).head(n), SolverInternals::AndersonG(workspace).head(n));

  double min_error = std::numeric_limits<double>::infinity();
  const double eps1 = parameters.global_tolerance_m;
  int iteration = 0;
  while (m > 0) {
    r_previous = r;
    double sum;
    int sweep_limit_hits = 0;
    if (kind == SolverKind::kGlobalUzawaJacobi) {
      sum = JacobiSweep(problem, rho, r, u, &stats.inner_iterations);
      u.noalias() = w * r;
      u += u_free;
    } else {
      sweep_limit_hits = 0;
      sum = GaussSeidelSweep(kind, problem, parameters, rho, r, u, &stats.inner_iterations,
                             &sweep_limit_hits);
      stats.inner_limit_hits += sweep_limit_hits;
    }
    ++iteration;
    const double error = std::sqrt(sum);
    if (accelerate && anderson.RejectWorse(problem, error, r, u, &stats.acceleration_restarts)) {
      stats.residual_history.push_back(error);  // the rejected sweep still counts
      if (iteration >= parameters.max_iterations) {
        stats.status = SolverStatus::kMaxIterations;
        break;
      }
      continue;
    }
    if (!std::isfinite(error) || !r.allFinite()) {
      // Divergence: go back to the last finite iterate (never return a NaN force).
      r = r_previous;
      stats.status = SolverStatus::kDiverged;
      break;
    }
    stats.paper_error_m = error;
    stats.residual_history.push_back(error);
    min_error = std::min(min_error, error);
    // The paper test is only meaningful once every local problem met ε₂ (paper 3.3.1).
    bool converged = error < eps1 && sweep_limit_hits == 0;
    if (!converged && parameters.fc3d_tolerance > 0.0) {
      converged = Fc3dFromState(problem.friction_coefficient, r, u, u_free) <
                  parameters.fc3d_tolerance;
    }
    if (converged && accelerate && anderson.ConfirmBeforeStop()) converged = false;
    if (converged) {
      stats.status = SolverStatus::kConverged;
      break;
    }
    if (error > parameters.divergence_factor * std::max(min_error, eps1)) {
      stats.status = SolverStatus::kDiverged;
      break;
    }
    if (parameters.time_budget_s > 0.0 && clock.ElapsedSeconds() > parameters.time_budget_s) {
      stats.status = SolverStatus::kTimeBudgetExceeded;
      break;
    }
    if (iteration >= parameters.max_iterations) {
      stats.status = SolverStatus::kMaxIterations;
      break;
    }
    if (accelerate && iteration >= parameters.anderson_start &&
        anderson.Apply(problem, rho, r_previous, error, r, u)) {
      ++stats.accelerated_iterations;
    }
  }
  if (m == 0) stats.status = SolverStatus::kConverged;
  stats.iterations = iteration;
  stats.acceleration_stalled = accelerate && anderson.stopped();

  // Exact u for the returned r (removes incremental round-off), then the exit measures.
  Eigen::VectorXd& u_out = result->displacement_m;
  if (u_out.size() != n) u_out.resize(n);  // allocates only when m changed
  u_out.noalias() = w * r;
  u_out += u_free;
  stats.fc3d_error = m > 0 ? Fc3dFromState(problem.friction_coefficient, r, u_out, u_free) : 0.0;
  for (int a = 0; a < m; ++a) {
    const ContactState s = ClassifyContact(r.segment<3>(3 * a), u_out.segment<3>(3 * a),
                                           rho(a) * eps1, eps1);
    ++stats.state_counts[static_cast<std::size_t>(s)];
  }
  stats.seconds = clock.ElapsedSeconds();
  return stats.status;
}

double Fc3dError(const ContactProblem& problem, const Eigen::VectorXd& force_n) {
  const Eigen::Index n = 3 * static_cast<Eigen::Index>(problem.num_contacts());
  if (force_n.size() != n || problem.flexibility_m_per_n.rows() != n ||
      problem.flexibility_m_per_n.cols() != n || problem.free_displacement_m.size() != n) {
    throw InputError("Fc3dError: force, W and ũ must all be sized for 3m = " +
                     std::to_string(n) + " components");
  }
  const Eigen::VectorXd u = problem.flexibility_m_per_n * force_n + problem.free_displacement_m;
  return Fc3dFromState(problem.friction_coefficient, force_n, u, problem.free_displacement_m);
}

}  // namespace hapco::contact
