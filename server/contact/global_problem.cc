#include "contact/global_problem.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include "common/error.h"
#include "contact/projection.h"

namespace hapco::contact {
namespace {

bool AllFinite(const Eigen::SparseMatrix<double>& a) {
  for (Eigen::Index k = 0; k < a.nonZeros(); ++k) {
    if (!std::isfinite(a.valuePtr()[k])) return false;
  }
  return true;
}

}  // namespace

double SparseRelativeAsymmetry(const Eigen::SparseMatrix<double>& m) {
  if (m.nonZeros() == 0) return 0.0;
  const double scale = m.coeffs().cwiseAbs().maxCoeff();
  if (!(scale > 0.0)) return 0.0;
  const Eigen::SparseMatrix<double> skew = m - Eigen::SparseMatrix<double>(m.transpose());
  return skew.nonZeros() > 0 ? skew.coeffs().cwiseAbs().maxCoeff() / scale : 0.0;
}

void ValidateGlobalProblem(const GlobalContactProblem& p) {
  std::ostringstream msg;
  const Eigen::Index n = p.m.rows();
  const Eigen::Index nc = p.mu.size();
  auto fail = [&] { throw InputError("global contact problem: " + msg.str()); };
  if (nc < 1) {
    msg << "no contacts (mu is empty)";
    fail();
  }
  if (p.m.cols() != n || n < 1) {
    msg << "M is " << p.m.rows() << "x" << p.m.cols() << "; it must be square and non-empty";
    fail();
  }
  if (p.h.rows() != n || p.h.cols() != 3 * nc) {
    msg << "H is " << p.h.rows() << "x" << p.h.cols() << " but M (" << n << " dofs) and mu ("
        << nc << " contacts) need " << n << "x" << 3 * nc;
    fail();
  }
  if (p.f.size() != n) {
    msg << "f has size " << p.f.size() << ", M needs " << n;
    fail();
  }
  if (p.w.size() != 3 * nc) {
    msg << "w has size " << p.w.size() << ", " << nc << " contacts need " << 3 * nc;
    fail();
  }
  if (!AllFinite(p.m) || !AllFinite(p.h) || !p.f.allFinite() || !p.w.allFinite() || !p.mu.allFinite()) {
    msg << "M, H, f, w and mu must hold finite values only";
    fail();
  }
  if (p.mu.minCoeff() < 0.0) {
    Eigen::Index worst = 0;
    p.mu.minCoeff(&worst);
    msg << "friction coefficient of contact " << worst << " is " << p.mu(worst) << "; it must be >= 0";
    fail();
  }
  const Eigen::VectorXd diagonal = p.m.diagonal();
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!(diagonal(i) > 0.0)) {
      msg << "M(" << i << "," << i << ") = " << diagonal(i)
          << "; a symmetric positive definite M has a positive diagonal";
      fail();
    }
  }
  const double asymmetry = SparseRelativeAsymmetry(p.m);
  if (asymmetry > kMaxMassRelativeAsymmetry) {
    msg << "M is not symmetric: max|M - M^T| / max|M| = " << asymmetry << " (round-off is accepted up to "
        << kMaxMassRelativeAsymmetry << "; was only one triangle stored?)";
    fail();
  }
}

GlobalResidual ComputeGlobalResidual(const GlobalContactProblem& p, const Eigen::VectorXd& v,
                                     const Eigen::VectorXd& r) {
  ValidateGlobalProblem(p);
  if (v.size() != p.m.rows() || r.size() != p.h.cols()) {
    throw InputError("global residual: v has size " + std::to_string(v.size()) + " and r " +
                     std::to_string(r.size()) + "; the problem needs " + std::to_string(p.m.rows()) +
                     " and " + std::to_string(p.h.cols()));
  }
  GlobalResidual out;
  const Eigen::VectorXd mv = p.m * v;
  const Eigen::VectorXd hr = p.h * r;
  const double momentum_scale = std::max({p.f.norm(), hr.norm(), mv.norm()});
  const double momentum = (mv - hr - p.f).norm();
  out.momentum = momentum_scale > 0.0 ? momentum / momentum_scale : momentum;
  out.u = p.h.transpose() * v + p.w;
  // Natural map of the cone complementarity C*_μ ∋ û ⊥ r ∈ C_μ (fclib.h), ρ = 1.
  double numerator2 = 0.0;
  for (int a = 0; a < p.num_contacts(); ++a) {
    const Eigen::Vector3d ra = r.segment<3>(3 * a);
    const Eigen::Vector3d ua = out.u.segment<3>(3 * a);
    Eigen::Vector3d u_hat = ua;
    u_hat(0) += p.mu(a) * std::sqrt(ua(1) * ua(1) + ua(2) * ua(2));
    numerator2 += (ra - ProjectOnCoulombCone(ra - u_hat, p.mu(a))).squaredNorm();
  }
  const double scale = std::max({p.w.norm(), r.norm(), out.u.norm()});
  out.complementarity = scale > 0.0 ? std::sqrt(numerator2) / scale : std::sqrt(numerator2);
  return out;
}

}  // namespace hapco::contact
