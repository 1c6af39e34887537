#include "fem/assembly.h"

#include <algorithm>
#include <array>
#include <vector>

#include <Eigen/Geometry>

#include "common/error.h"
#include "fem/element_stiffness.h"

namespace hapco::fem {

Eigen::SparseMatrix<double> AssembleStiffness(const Mesh& mesh, const Material& material) {
  ValidateMesh(mesh);
  ValidateMaterial(material);
  const int num_nodes = mesh.num_nodes();
  const int width = NodesPerElement(mesh.order);

  // Sparsity pattern at node level: neighbours[n] = sorted nodes sharing an element with n.
  // Building the CSC arrays directly avoids a triplet list of 900 entries per Tet10 element.
  std::vector<std::vector<int>> neighbours(static_cast<std::size_t>(num_nodes));
  for (int e = 0; e < mesh.num_elements(); ++e)
    for (int i = 0; i < width; ++i)
      for (int j = 0; j < width; ++j)
        neighbours[static_cast<std::size_t>(mesh.elements(e, i))].push_back(mesh.elements(e, j));
  std::vector<int> outer(static_cast<std::size_t>(3 * num_nodes + 1), 0);
  for (int n = 0; n < num_nodes; ++n) {
    auto& list = neighbours[static_cast<std::size_t>(n)];
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    const int column_nnz = 3 * static_cast<int>(list.size());
    for (int b = 0; b < 3; ++b)
      outer[static_cast<std::size_t>(3 * n + b + 1)] =
          outer[static_cast<std::size_t>(3 * n + b)] + column_nnz;
  }
  const auto nnz = static_cast<std::size_t>(outer.back());
  std::vector<int> inner(nnz);
  std::vector<double> values(nnz, 0.0);
  for (int n = 0; n < num_nodes; ++n) {
    const auto& list = neighbours[static_cast<std::size_t>(n)];
    for (int b = 0; b < 3; ++b) {
      auto pos = static_cast<std::size_t>(outer[static_cast<std::size_t>(3 * n + b)]);
      for (const int m : list)
        for (int a = 0; a < 3; ++a) inner[pos++] = 3 * m + a;
    }
  }

  const auto scatter = [&](const auto& ke, const auto& element_nodes) {
    const int local = static_cast<int>(element_nodes.size());
    for (int j = 0; j < local; ++j) {
      const int n = element_nodes[static_cast<std::size_t>(j)];
      const auto& list = neighbours[static_cast<std::size_t>(n)];
      for (int i = 0; i < local; ++i) {
        const int m = element_nodes[static_cast<std::size_t>(i)];
        const auto p = static_cast<int>(std::lower_bound(list.begin(), list.end(), m) - list.begin());
        for (int b = 0; b < 3; ++b) {
          const auto base = static_cast<std::size_t>(outer[static_cast<std::size_t>(3 * n + b)] + 3 * p);
          for (int a = 0; a < 3; ++a) values[base + static_cast<std::size_t>(a)] += ke(3 * i + a, 3 * j + b);
        }
      }
    }
  };

  if (mesh.order == ElementOrder::kTet4) {
    Eigen::Matrix<double, 4, 3> x;
    std::array<int, 4> ids{};
    for (int e = 0; e < mesh.num_elements(); ++e) {
      for (int k = 0; k < 4; ++k) {
        ids[static_cast<std::size_t>(k)] = mesh.elements(e, k);
        x.row(k) = mesh.nodes_m.row(ids[static_cast<std::size_t>(k)]);
      }
      scatter(Tet4Stiffness(x, material), ids);
    }
  } else {
    Eigen::Matrix<double, 10, 3> x;
    std::array<int, 10> ids{};
    for (int e = 0; e < mesh.num_elements(); ++e) {
      for (int k = 0; k < 10; ++k) {
        ids[static_cast<std::size_t>(k)] = mesh.elements(e, k);
        x.row(k) = mesh.nodes_m.row(ids[static_cast<std::size_t>(k)]);
      }
      scatter(Tet10Stiffness(x, material), ids);
    }
  }

  const int dofs = 3 * num_nodes;
  return Eigen::Map<const Eigen::SparseMatrix<double>>(dofs, dofs, static_cast<Eigen::Index>(nnz),
                                                       outer.data(), inner.data(), values.data());
}

double TriangleArea(const Mesh& mesh, const SurfaceTriangle& face) {
  const Eigen::Vector3d a = mesh.nodes_m.row(face.corners[0]).transpose();
  const Eigen::Vector3d b = mesh.nodes_m.row(face.corners[1]).transpose();
  const Eigen::Vector3d c = mesh.nodes_m.row(face.corners[2]).transpose();
  return 0.5 * (b - a).cross(c - a).norm();
}

Eigen::VectorXd UniformTractionLoads(const Mesh& mesh, std::span<const SurfaceTriangle> faces,
                                     const Eigen::Vector3d& traction_pa) {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * mesh.num_nodes());
  for (const SurfaceTriangle& face : faces) {
    const Eigen::Vector3d share_n = traction_pa * (TriangleArea(mesh, face) / 3.0);
    const bool quadratic = mesh.order == ElementOrder::kTet10;
    for (int k = 0; k < 3; ++k) {
      const int node = quadratic ? face.midsides[static_cast<std::size_t>(k)]
                                 : face.corners[static_cast<std::size_t>(k)];
      HAPCO_ASSERT(node >= 0 && node < mesh.num_nodes(), "surface triangle node out of range");
      f.segment<3>(3 * node) += share_n;
    }
  }
  return f;
}

}  // namespace hapco::fem
