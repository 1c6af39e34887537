#include "fem/element_stiffness.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/LU>

#include "common/error.h"

namespace hapco::fem {
namespace {

// Fills the 6 rows of B for one node from its spatial gradient g = dN/dx (1/m).
template <typename BMatrix>
void FillB(BMatrix& b, int node, const Eigen::Vector3d& g) {
  const int c = 3 * node;
  b(0, c + 0) = g.x();
  b(1, c + 1) = g.y();
  b(2, c + 2) = g.z();
  b(3, c + 0) = g.y();
  b(3, c + 1) = g.x();
  b(4, c + 1) = g.z();
  b(4, c + 2) = g.y();
  b(5, c + 0) = g.z();
  b(5, c + 2) = g.x();
}

}  // namespace

Eigen::Matrix<double, 6, 6> ElasticityMatrix(const Material& material) {
  const double e = material.youngs_modulus_pa;
  const double nu = material.poisson_ratio;
  const double lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
  const double mu = e / (2.0 * (1.0 + nu));
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
  d.topLeftCorner<3, 3>().setConstant(lambda);
  d.topLeftCorner<3, 3>().diagonal().array() += 2.0 * mu;
  d.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
  return d;
}

Eigen::Matrix<double, 12, 12> Tet4Stiffness(const Eigen::Matrix<double, 4, 3>& nodes_m,
                                            const Material& material) {
  // Barycentric gradients: rows 1..3 of inverse([1 x y z]) give dL_i/dx.
  Eigen::Matrix4d a;
  a.col(0).setOnes();
  a.rightCols<3>() = nodes_m;
  const double volume = a.determinant() / 6.0;
  HAPCO_ASSERT(volume > 0.0, "Tet4Stiffness needs a right-handed element");
  const Eigen::Matrix4d inv = a.inverse();
  Eigen::Matrix<double, 6, 12> b = Eigen::Matrix<double, 6, 12>::Zero();
  for (int i = 0; i < 4; ++i) FillB(b, i, inv.block<3, 1>(1, i));
  return volume * b.transpose() * ElasticityMatrix(material) * b;
}

const std::array<TetQuadraturePoint, 4>& Tet4PointRule() {
  static const std::array<TetQuadraturePoint, 4> rule = [] {
    const double a = (5.0 + 3.0 * std::sqrt(5.0)) / 20.0;
    const double b = (5.0 - std::sqrt(5.0)) / 20.0;
    std::array<TetQuadraturePoint, 4> r{};
    for (int q = 0; q < 4; ++q) {
      r[q].barycentric = {b, b, b, b};
      r[q].barycentric[q] = a;
      r[q].weight = 0.25;
    }
    return r;
  }();
  return rule;
}

Eigen::Matrix<double, 10, 3> Tet10ReferenceGradients(const std::array<double, 4>& l) {
  // dL_i/dxi for L0 = 1 - xi - eta - zeta, L1 = xi, L2 = eta, L3 = zeta.
  static const Eigen::Matrix<double, 4, 3> dl =
      (Eigen::Matrix<double, 4, 3>() << -1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1).finished();
  Eigen::Matrix<double, 10, 3> g;
  for (int i = 0; i < 4; ++i) g.row(i) = (4.0 * l[i] - 1.0) * dl.row(i);  // L(2L-1)
  for (int k = 0; k < 6; ++k) {                                           // 4 La Lb
    const int i = kTet10EdgeCorners[k][0];
    const int j = kTet10EdgeCorners[k][1];
    g.row(4 + k) = 4.0 * (l[j] * dl.row(i) + l[i] * dl.row(j));
  }
  return g;
}

double Tet10MinJacobian(const Eigen::Matrix<double, 10, 3>& nodes_m) {
  double min_det = std::numeric_limits<double>::infinity();
  for (const auto& qp : Tet4PointRule()) {
    const Eigen::Matrix3d jac = nodes_m.transpose() * Tet10ReferenceGradients(qp.barycentric);
    min_det = std::min(min_det, jac.determinant());
  }
  return min_det;
}

Eigen::Matrix<double, 30, 30> Tet10Stiffness(const Eigen::Matrix<double, 10, 3>& nodes_m,
                                             const Material& material) {
  const Eigen::Matrix<double, 6, 6> d = ElasticityMatrix(material);
  Eigen::Matrix<double, 30, 30> k = Eigen::Matrix<double, 30, 30>::Zero();
  Eigen::Matrix<double, 6, 30> b = Eigen::Matrix<double, 6, 30>::Zero();
  for (const auto& qp : Tet4PointRule()) {
    const Eigen::Matrix<double, 10, 3> dn_dxi = Tet10ReferenceGradients(qp.barycentric);
    const Eigen::Matrix3d jac = nodes_m.transpose() * dn_dxi;  // J_ij = dx_i/dxi_j
    const double det = jac.determinant();
    HAPCO_ASSERT(det > 0.0, "Tet10Stiffness needs a positive Jacobian");
    const Eigen::Matrix<double, 10, 3> dn_dx = dn_dxi * jac.inverse();
    for (int n = 0; n < 10; ++n) FillB(b, n, dn_dx.row(n).transpose());
    // Reference tetrahedron volume 1/6.
    k.noalias() += (qp.weight * det / 6.0) * (b.transpose() * d * b);
  }
  return k;
}

}  // namespace hapco::fem
