#pragma once
// Element matrices of isotropic linear elasticity on tetrahedra (small strain).
// Voigt order for strain/stress: [xx, yy, zz, xy, yz, zx], engineering shear strains.
#include <array>

#include <Eigen/Core>

#include "fem/mesh.h"

namespace hapco::fem {

// Isotropic elasticity matrix D (Pa): sigma = D * epsilon.
Eigen::Matrix<double, 6, 6> ElasticityMatrix(const Material& material);

// Tet4 stiffness (N/m), closed form K = V B^T D B with the constant strain-displacement
// matrix B. Local dof = 3*local_node + axis. Corners must be right-handed (positive volume).
Eigen::Matrix<double, 12, 12> Tet4Stiffness(const Eigen::Matrix<double, 4, 3>& nodes_m,
                                            const Material& material);

// Quadrature for Tet10: the symmetric 4-point rule on the tetrahedron, exact for polynomials
// of degree 2 (Hammer, Marlowe & Stroud 1956, Math. Tables Aids Comput. 10:130-137; also
// Keast 1986, CMAME 55:339-348, rule 2). Points in barycentric coordinates
// (a, b, b, b) and permutations, a = (5 + 3 sqrt 5)/20, b = (5 - sqrt 5)/20, equal weights
// 1/4 of the element volume. For straight-edged Tet10 the stiffness integrand B^T D B is of
// degree 2, so the rule is exact.
struct TetQuadraturePoint {
  std::array<double, 4> barycentric;  // L0..L3, sum 1
  double weight;                      // fraction of the element volume
};
const std::array<TetQuadraturePoint, 4>& Tet4PointRule();

// Derivatives of the ten Tet10 shape functions with respect to the reference coordinates
// (xi, eta, zeta) = (L1, L2, L3), L0 = 1 - xi - eta - zeta; rows = local nodes (VTK order).
Eigen::Matrix<double, 10, 3> Tet10ReferenceGradients(const std::array<double, 4>& barycentric);

// Smallest Jacobian determinant det(dx/dxi) of an isoparametric Tet10 over the quadrature
// points (6 x volume for a straight-edged element), m^3.
double Tet10MinJacobian(const Eigen::Matrix<double, 10, 3>& nodes_m);

// Tet10 stiffness (N/m), isoparametric, integrated with Tet4PointRule().
Eigen::Matrix<double, 30, 30> Tet10Stiffness(const Eigen::Matrix<double, 10, 3>& nodes_m,
                                             const Material& material);

}  // namespace hapco::fem
