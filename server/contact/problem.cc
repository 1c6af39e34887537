#include "contact/problem.h"

#include <cmath>
#include <sstream>

#include "common/error.h"

namespace hapco::contact {

void ValidateProblem(const ContactProblem& problem) {
  const Eigen::Index m = problem.friction_coefficient.size();
  const Eigen::Index n = 3 * m;
  const auto& w = problem.flexibility_m_per_n;
  std::ostringstream msg;
  if (w.rows() != n || w.cols() != n) {
    msg << "contact problem: flexibility W is " << w.rows() << "x" << w.cols() << " but " << m
        << " friction coefficients need 3m x 3m = " << n << "x" << n;
    throw InputError(msg.str());
  }
  if (problem.free_displacement_m.size() != n) {
    msg << "contact problem: free displacement has size " << problem.free_displacement_m.size()
        << " but " << m << " contacts need 3m = " << n;
    throw InputError(msg.str());
  }
  for (Eigen::Index a = 0; a < m; ++a) {
    const double mu = problem.friction_coefficient(a);
    if (!std::isfinite(mu) || mu < 0.0) {
      msg << "contact problem: friction coefficient of contact " << a << " is " << mu
          << "; it must be finite and >= 0";
      throw InputError(msg.str());
    }
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!std::isfinite(problem.free_displacement_m(i))) {
      msg << "contact problem: free displacement entry " << i << " is not finite";
      throw InputError(msg.str());
    }
  }
  if (!w.allFinite()) {
    for (Eigen::Index j = 0; j < n; ++j) {
      for (Eigen::Index i = 0; i < n; ++i) {
        if (!std::isfinite(w(i, j))) {
          msg << "contact problem: flexibility W(" << i << "," << j << ") is not finite";
          throw InputError(msg.str());
        }
      }
    }
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!(w(i, i) > 0.0)) {
      msg << "contact problem: flexibility diagonal W(" << i << "," << i << ") = " << w(i, i)
          << " m/N; it must be > 0 (a contact direction with no compliance)";
      throw InputError(msg.str());
    }
  }
  // Symmetry relative to the largest entry (the matrix scale), tolerance 1e-8.
  const double scale = w.cwiseAbs().maxCoeff();
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index i = j + 1; i < n; ++i) {
      if (std::abs(w(i, j) - w(j, i)) > 1e-8 * scale) {
        msg << "contact problem: flexibility W is not symmetric: W(" << i << "," << j
            << ") = " << w(i, j) << " but W(" << j << "," << i << ") = " << w(j, i)
            << " (relative tolerance 1e-8)";
        throw InputError(msg.str());
      }
    }
  }
}

}  // namespace hapco::contact
