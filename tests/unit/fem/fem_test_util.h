#pragma once
// Helpers shared by the fem unit tests (meshes and exact fields; no code under test reused
// for expected values).
#include <random>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "fem/box_mesh.h"
#include "fem/mesh.h"

namespace hapco::fem::testing {

// Test-name suffix for suites parameterised by element order.
inline std::string OrderName(const ::testing::TestParamInfo<ElementOrder>& param) {
  return ToString(param.param);
}

inline BoxMeshSpec Box(double sx, double sy, double sz, int nx, int ny, int nz, ElementOrder order) {
  BoxMeshSpec spec;
  spec.min_corner_m = Eigen::Vector3d(0.01, -0.02, 0.03);  // off the origin on purpose
  spec.size_m = Eigen::Vector3d(sx, sy, sz);
  spec.divisions = Eigen::Vector3i(nx, ny, nz);
  spec.order = order;
  return spec;
}

// All nodes on the box surface (union of the six faces), sorted.
inline std::vector<int> BoundaryNodes(const Mesh& mesh, const BoxMeshSpec& spec) {
  std::set<int> ids;
  for (int f = 0; f < 6; ++f)
    for (int n : NodesOnBoxFace(mesh, spec, static_cast<BoxFace>(f))) ids.insert(n);
  return {ids.begin(), ids.end()};
}

// Moves interior corner nodes randomly by up to `fraction` of the smallest cell edge (fixed
// seed) and puts Tet10 midside nodes back at their edge midpoints (straight edges).
inline void Distort(Mesh& mesh, const BoxMeshSpec& spec, double fraction, unsigned seed) {
  const std::vector<int> boundary = BoundaryNodes(mesh, spec);
  const std::set<int> fixed(boundary.begin(), boundary.end());
  const double h = spec.size_m.cwiseQuotient(spec.divisions.cast<double>()).minCoeff();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-fraction * h, fraction * h);
  const int corners = (spec.divisions.x() + 1) * (spec.divisions.y() + 1) * (spec.divisions.z() + 1);
  for (int n = 0; n < corners; ++n) {
    if (fixed.count(n)) continue;
    for (int a = 0; a < 3; ++a) mesh.nodes_m(n, a) += uniform(rng);
  }
  if (mesh.order == ElementOrder::kTet10) {
    for (int e = 0; e < mesh.num_elements(); ++e)
      for (int k = 0; k < 6; ++k)
        mesh.nodes_m.row(mesh.elements(e, 4 + k)) =
            0.5 * (mesh.nodes_m.row(mesh.elements(e, kTet10EdgeCorners[k][0])) +
                   mesh.nodes_m.row(mesh.elements(e, kTet10EdgeCorners[k][1])));
  }
}

// Evaluates a displacement field u(x) (m) at every node into a 3N vector.
template <typename Field>
Eigen::VectorXd Interpolate(const Mesh& mesh, Field field) {
  Eigen::VectorXd u(3 * mesh.num_nodes());
  for (int n = 0; n < mesh.num_nodes(); ++n)
    u.segment<3>(3 * n) = field(Eigen::Vector3d(mesh.nodes_m.row(n).transpose()));
  return u;
}

}  // namespace hapco::fem::testing
