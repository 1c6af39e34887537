// Stub: API only; the implementation follows.
#include "contact/solver.h"

#include <string>

#include "common/error.h"

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
  stats.residual_history.reserve(static_cast<std::size_t>(max_iterations));
}

void SolverWorkspace::Reserve(int max_contacts, int /*max_iterations*/) {
  u_.resize(3 * max_contacts);
  r_previous_.resize(3 * max_contacts);
  rho_per_contact_.resize(max_contacts);
}

SolverStatus Solve(SolverKind, const ContactProblem& problem, const SolverParameters&,
                   SolverWorkspace*, SolverResult* result) {
  const Eigen::Index n = 3 * problem.num_contacts();
  result->force_n = Eigen::VectorXd::Zero(n);
  result->displacement_m = problem.free_displacement_m;
  result->stats = SolverStats{};
  return result->stats.status;
}

double Fc3dError(const ContactProblem&, const Eigen::VectorXd&) { return 0.0; }

}  // namespace hapco::contact
