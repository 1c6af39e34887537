#pragma once
// Tetrahedral meshes: the data type, boundary extraction and validation (design.md, `fem`).
#include <array>
#include <vector>

#include <Eigen/Core>

namespace hapco::fem {

// Tet4: linear 4-node tetrahedron. Tet10: quadratic 10-node tetrahedron, node order as VTK
// (VTK_QUADRATIC_TETRA): corners 0..3, then midsides on edges (0,1) (1,2) (0,2) (0,3) (1,3) (2,3).
enum class ElementOrder { kTet4, kTet10 };

int NodesPerElement(ElementOrder order);  // 4 or 10
const char* ToString(ElementOrder order);  // "Tet4" / "Tet10"

struct Mesh {
  Eigen::Matrix<double, Eigen::Dynamic, 3> nodes_m;               // N x 3 node positions, m
  Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic> elements;    // E x 4 (Tet4) or E x 10 (Tet10)
  ElementOrder order = ElementOrder::kTet4;

  int num_nodes() const { return static_cast<int>(nodes_m.rows()); }
  int num_elements() const { return static_cast<int>(elements.rows()); }
};

// Local corner pairs of the six Tet10 midside nodes 4..9 (VTK order).
inline constexpr std::array<std::array<int, 2>, 6> kTet10EdgeCorners = {
    {{0, 1}, {1, 2}, {0, 2}, {0, 3}, {1, 3}, {2, 3}}};

// A face on the boundary of the body. midsides[k] lies on edge (corners[k], corners[(k+1)%3])
// (-1 for Tet4); corners are ordered so that the right-hand normal points OUT of the body.
struct SurfaceTriangle {
  std::array<int, 3> corners;
  std::array<int, 3> midsides;
};

// Faces that belong to exactly one element.
std::vector<SurfaceTriangle> BoundaryTriangles(const Mesh& mesh);

// Signed volume of element e from its corner nodes, m^3 (positive = right-handed).
double ElementVolume(const Mesh& mesh, int element);

// Throws InputError for: wrong element width for the order, no nodes/elements, non-finite
// coordinates, node indices out of range, repeated nodes in an element, degenerate or
// inverted elements (for Tet10 also a non-positive Jacobian at any quadrature point).
void ValidateMesh(const Mesh& mesh);

// Isotropic linear elastic material.
struct Material {
  double youngs_modulus_pa = 0.0;  // E, Pa
  double poisson_ratio = 0.0;      // nu, dimensionless
};

// E > 0 and finite, -1 < nu < 0.5, else InputError naming the field.
void ValidateMaterial(const Material& material);

}  // namespace hapco::fem
