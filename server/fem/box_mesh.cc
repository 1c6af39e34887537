#include "fem/box_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>

#include <Eigen/Geometry>

#include "common/error.h"

namespace hapco::fem {

Mesh MakeBoxMesh(const BoxMeshSpec& spec) {
  for (int a = 0; a < 3; ++a) {
    const char* axis = a == 0 ? "x" : (a == 1 ? "y" : "z");
    if (!std::isfinite(spec.size_m[a]) || !(spec.size_m[a] > 0.0)) {
      throw InputError(std::string("box size along ") + axis + " must be > 0 m, got " +
                       std::to_string(spec.size_m[a]));
    }
    if (spec.divisions[a] < 1) {
      throw InputError(std::string("box divisions along ") + axis + " must be >= 1, got " +
                       std::to_string(spec.divisions[a]));
    }
    if (!std::isfinite(spec.min_corner_m[a])) throw InputError("box min corner is not finite");
  }
  const int nx = spec.divisions.x(), ny = spec.divisions.y(), nz = spec.divisions.z();
  const Eigen::Vector3d h = spec.size_m.cwiseQuotient(spec.divisions.cast<double>());
  const auto grid_id = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };

  const int num_corners = (nx + 1) * (ny + 1) * (nz + 1);
  std::vector<Eigen::Vector3d> nodes(static_cast<std::size_t>(num_corners));
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        nodes[static_cast<std::size_t>(grid_id(i, j, k))] =
            spec.min_corner_m + Eigen::Vector3d(i * h.x(), j * h.y(), k * h.z());

  // Kuhn split: one tet per axis permutation (a, b, c), path 0 -> e_a -> e_a+e_b -> 1 along
  // the cell's main diagonal. Local cell vertex v has offsets (v&1, (v>>1)&1, (v>>2)&1).
  constexpr std::array<std::array<int, 3>, 6> kPermutations = {
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  std::vector<std::array<int, 4>> tets;
  tets.reserve(static_cast<std::size_t>(6) * nx * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const auto vertex = [&](int v) {
          return grid_id(i + (v & 1), j + ((v >> 1) & 1), k + ((v >> 2) & 1));
        };
        for (const auto& p : kPermutations) {
          std::array<int, 4> t = {vertex(0), vertex(1 << p[0]), vertex((1 << p[0]) | (1 << p[1])),
                                  vertex(7)};
          // Odd permutations give left-handed tets: swap two corners to make them right-handed.
          const Eigen::Vector3d& x0 = nodes[static_cast<std::size_t>(t[0])];
          const double vol = (nodes[static_cast<std::size_t>(t[1])] - x0)
                                 .cross(nodes[static_cast<std::size_t>(t[2])] - x0)
                                 .dot(nodes[static_cast<std::size_t>(t[3])] - x0);
          if (vol < 0.0) std::swap(t[1], t[2]);
          tets.push_back(t);
        }
      }

  Mesh mesh;
  mesh.order = spec.order;
  const int width = NodesPerElement(spec.order);
  mesh.elements.resize(static_cast<Eigen::Index>(tets.size()), width);
  std::unordered_map<std::int64_t, int> edge_node;  // key: min * num_corners + max
  for (std::size_t e = 0; e < tets.size(); ++e) {
    const auto row = static_cast<Eigen::Index>(e);
    for (int c = 0; c < 4; ++c) mesh.elements(row, c) = tets[e][static_cast<std::size_t>(c)];
    if (spec.order != ElementOrder::kTet10) continue;
    for (int m = 0; m < 6; ++m) {
      const int a = tets[e][static_cast<std::size_t>(kTet10EdgeCorners[m][0])];
      const int b = tets[e][static_cast<std::size_t>(kTet10EdgeCorners[m][1])];
      const std::int64_t key =
          static_cast<std::int64_t>(std::min(a, b)) * num_corners + std::max(a, b);
      auto [it, inserted] = edge_node.try_emplace(key, static_cast<int>(nodes.size()));
      if (inserted) {
        nodes.push_back(0.5 * (nodes[static_cast<std::size_t>(a)] +
                               nodes[static_cast<std::size_t>(b)]));
      }
      mesh.elements(row, 4 + m) = it->second;
    }
  }
  mesh.nodes_m.resize(static_cast<Eigen::Index>(nodes.size()), 3);
  for (std::size_t n = 0; n < nodes.size(); ++n)
    mesh.nodes_m.row(static_cast<Eigen::Index>(n)) = nodes[n].transpose();
  return mesh;
}

std::vector<int> NodesOnBoxFace(const Mesh& mesh, const BoxMeshSpec& spec, BoxFace face) {
  const int axis = static_cast<int>(face) / 2;
  const bool is_max = static_cast<int>(face) % 2 == 1;
  const double plane_m = spec.min_corner_m[axis] + (is_max ? spec.size_m[axis] : 0.0);
  const double tolerance_m =
      1e-6 * spec.size_m.cwiseQuotient(spec.divisions.cast<double>()).minCoeff();
  std::vector<int> ids;
  for (int n = 0; n < mesh.num_nodes(); ++n) {
    if (std::abs(mesh.nodes_m(n, axis) - plane_m) <= tolerance_m) ids.push_back(n);
  }
  return ids;  // ascending by construction
}

}  // namespace hapco::fem
