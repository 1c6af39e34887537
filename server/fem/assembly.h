#pragma once
// Global stiffness assembly and consistent nodal loads.
#include <span>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "fem/mesh.h"

namespace hapco::fem {

// Global stiffness K (3N x 3N, N/m), dof = 3*node + axis, both triangles stored.
// Tet4: closed form; Tet10: isoparametric with the exact 4-point rule (element_stiffness.h).
// Validates the mesh and the material first (InputError).
Eigen::SparseMatrix<double> AssembleStiffness(const Mesh& mesh, const Material& material);

// Consistent nodal forces (3N, N) of a uniform surface traction t (Pa) on the given boundary
// triangles: f_i = t * integral(N_i dA). Linear triangle: A/3 at each corner. Straight-edged
// quadratic triangle: 0 at the corners and A/3 at each midside (the corner shape functions
// integrate to zero on a 6-node triangle).
Eigen::VectorXd UniformTractionLoads(const Mesh& mesh, std::span<const SurfaceTriangle> faces,
                                     const Eigen::Vector3d& traction_pa);

// Area of a boundary triangle from its corners, m^2.
double TriangleArea(const Mesh& mesh, const SurfaceTriangle& face);

}  // namespace hapco::fem
