#include "delassus/delassus.h"

#include <algorithm>
#include <sstream>
#include <string>

// GCC's -Wnull-dereference fires inside Eigen's CHOLMOD view of a sparse matrix (an inlined
// path for an empty matrix that cannot occur here: M has n >= 1 columns).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <Eigen/CholmodSupport>
#pragma GCC diagnostic pop

#include "common/error.h"
#include "common/timer.h"

namespace hapco::delassus {

struct GlobalToLocal::Factor {
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> llt;
};

GlobalToLocal::~GlobalToLocal() = default;

GlobalToLocal::GlobalToLocal(const contact::GlobalContactProblem& problem, std::size_t max_operator_bytes)
    : h_(problem.h), f_(problem.f), factor_(std::make_unique<Factor>()) {
  contact::ValidateGlobalProblem(problem);
  const Eigen::Index n = problem.m.rows();
  const Eigen::Index n_local = problem.h.cols();
  const double w_bytes = static_cast<double>(n_local) * static_cast<double>(n_local) * sizeof(double);
  if (w_bytes > static_cast<double>(max_operator_bytes)) {
    std::ostringstream msg;
    msg << "the Delassus operator W of " << problem.num_contacts() << " contacts would need "
        << w_bytes / (1 << 20) << " MiB dense, more than the " << max_operator_bytes / (1 << 20)
        << " MiB allowed";
    throw InputError(msg.str());
  }

  Stopwatch factor_clock;
  const Eigen::SparseMatrix<double> symmetric =
      0.5 * (problem.m + Eigen::SparseMatrix<double>(problem.m.transpose()));
  factor_->llt.cholmod().print = 0;  // our InputError says it; CHOLMOD would also print a warning
  factor_->llt.compute(symmetric);
  if (factor_->llt.info() != Eigen::Success) {
    throw InputError("global contact problem: CHOLMOD could not factor M (" + std::to_string(n) + "x" +
                     std::to_string(n) + "): it is not positive definite");
  }
  stats_.factorization_seconds = factor_clock.ElapsedSeconds();
  stats_.factor_nonzeros = static_cast<long>(factor_->llt.cholmod().lnz);
  stats_.factor_bytes = static_cast<std::size_t>(stats_.factor_nonzeros) * (sizeof(double) + sizeof(int));

  Stopwatch operator_clock;
  constexpr double kBatchBytes = 64.0 * (1 << 20);
  const int batch = static_cast<int>(std::clamp<double>(kBatchBytes / (8.0 * static_cast<double>(n)), 1.0,
                                                        static_cast<double>(n_local)));
  stats_.rhs_per_batch = batch;
  local_.flexibility_m_per_n.resize(n_local, n_local);
  const Eigen::SparseMatrix<double> h_transposed = problem.h.transpose();
  for (Eigen::Index first = 0; first < n_local; first += batch) {
    const Eigen::Index count = std::min<Eigen::Index>(batch, n_local - first);
    const Eigen::MatrixXd rhs = Eigen::MatrixXd(problem.h.middleCols(first, count));
    const Eigen::MatrixXd x = factor_->llt.solve(rhs);  // M⁻¹ H_cols
    if (factor_->llt.info() != Eigen::Success || !x.allFinite()) {
      throw InputError("global contact problem: the solves with M failed (M nearly singular?)");
    }
    local_.flexibility_m_per_n.middleCols(first, count).noalias() = h_transposed * x;
    ++stats_.solve_batches;
  }
  // Round-off makes the two triangles of Hᵀ (M⁻¹ H) differ; W is symmetric by construction.
  Eigen::MatrixXd& w = local_.flexibility_m_per_n;
  for (Eigen::Index j = 0; j < n_local; ++j) {
    for (Eigen::Index i = j + 1; i < n_local; ++i) {
      const double mean = 0.5 * (w(i, j) + w(j, i));
      w(i, j) = mean;
      w(j, i) = mean;
    }
  }
  const Eigen::VectorXd m_inv_f = factor_->llt.solve(problem.f);
  local_.free_displacement_m = problem.h.transpose() * m_inv_f + problem.w;
  local_.friction_coefficient = problem.mu;
  stats_.operator_seconds = operator_clock.ElapsedSeconds();
  stats_.operator_bytes = static_cast<std::size_t>(w_bytes);
  contact::ValidateProblem(local_);
}

Eigen::VectorXd GlobalToLocal::GlobalVelocity(const Eigen::VectorXd& force) const {
  if (force.size() != h_.cols()) {
    throw InputError("GlobalVelocity: r has size " + std::to_string(force.size()) + ", the problem needs " +
                     std::to_string(h_.cols()));
  }
  const Eigen::VectorXd rhs = h_ * force + f_;
  return factor_->llt.solve(rhs);
}

}  // namespace hapco::delassus
