#pragma once
// The flexibility method of the paper (§3) on a global problem: with M factored once, the
// local problem follows from
//     W = Hᵀ M⁻¹ H        (the Delassus operator, 3n_c × 3n_c, dense here)
//     q = Hᵀ M⁻¹ f + w
// so that u = W r + q (contact::ContactProblem), and the global velocity from the contact
// forces r by v = M⁻¹ (H r + f) (fclib.h's sign convention, contact/global_problem.h).
//
// M is factored with CHOLMOD (supernodal LLᵀ of (M + Mᵀ)/2, fill-reducing ordering), once; W
// is formed from batched solves M X = H_cols, a block of columns of H at a time, W_cols =
// Hᵀ X. The batch is sized so X stays under ~64 MB.
#include <Eigen/Dense>

#include <cstddef>
#include <memory>

#include "contact/global_problem.h"
#include "contact/problem.h"

namespace hapco::delassus {

struct DelassusStats {
  double factorization_seconds = 0.0;  // CHOLMOD analyse + numeric factorization of M, s
  double operator_seconds = 0.0;       // the solves and products forming W and q, s
  long factor_nonzeros = 0;            // nonzeros of L (CHOLMOD lnz)
  std::size_t factor_bytes = 0;        // ≈ memory of L: lnz doubles + their row indices, bytes
  std::size_t operator_bytes = 0;      // W dense: (3n_c)² doubles, bytes
  int solve_batches = 0;               // batched solves with columns of H
  int rhs_per_batch = 0;
};

class GlobalToLocal {
 public:
  // Validates the problem (contact::ValidateGlobalProblem), factors M and forms the local
  // problem. Throws InputError when M is not positive definite (CHOLMOD's verdict) or when
  // the dense W would need more than max_operator_bytes.
  explicit GlobalToLocal(const contact::GlobalContactProblem& problem,
                         std::size_t max_operator_bytes = std::size_t{2} << 30);
  ~GlobalToLocal();
  GlobalToLocal(const GlobalToLocal&) = delete;
  GlobalToLocal& operator=(const GlobalToLocal&) = delete;

  // W = Hᵀ M⁻¹ H (exactly symmetrised: the two triangles of a product computed in floating
  // point differ by round-off) and q = Hᵀ M⁻¹ f + w; μ copied.
  const contact::ContactProblem& local() const { return local_; }

  // v = M⁻¹ (H r + f). r has size 3n_c.
  Eigen::VectorXd GlobalVelocity(const Eigen::VectorXd& force) const;

  const DelassusStats& stats() const { return stats_; }

 private:
  struct Factor;
  Eigen::SparseMatrix<double> h_;  // copies: the problem passed need not outlive this
  Eigen::VectorXd f_;
  std::unique_ptr<Factor> factor_;
  contact::ContactProblem local_;
  DelassusStats stats_;
};

}  // namespace hapco::delassus
