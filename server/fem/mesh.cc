#include "fem/mesh.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <string>

#include <Eigen/Geometry>

#include "common/error.h"
#include "fem/element_stiffness.h"

namespace hapco::fem {
namespace {

// Outward faces of a right-handed tetrahedron (local corners), see BoundaryTriangles.
constexpr std::array<std::array<int, 3>, 4> kOutwardFaces = {
    {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}};

// Local Tet10 midside index (4..9) for local corners i != j.
int LocalMidside(int i, int j) {
  for (int k = 0; k < 6; ++k) {
    const auto& e = kTet10EdgeCorners[k];
    if ((e[0] == i && e[1] == j) || (e[0] == j && e[1] == i)) return 4 + k;
  }
  HAPCO_ASSERT(false, "not a tetrahedron edge");
  return -1;
}

std::string FormatDouble(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

}  // namespace

int NodesPerElement(ElementOrder order) { return order == ElementOrder::kTet4 ? 4 : 10; }

const char* ToString(ElementOrder order) {
  return order == ElementOrder::kTet4 ? "Tet4" : "Tet10";
}

double ElementVolume(const Mesh& mesh, int element) {
  const auto p = [&](int k) -> Eigen::Vector3d {
    return mesh.nodes_m.row(mesh.elements(element, k)).transpose();
  };
  const Eigen::Vector3d p0 = p(0);
  return (p(1) - p0).cross(p(2) - p0).dot(p(3) - p0) / 6.0;
}

std::vector<SurfaceTriangle> BoundaryTriangles(const Mesh& mesh) {
  // Key: sorted corner ids. Value: (count, the face as seen from its element).
  std::map<std::array<int, 3>, std::pair<int, SurfaceTriangle>> faces;
  const bool quadratic = mesh.order == ElementOrder::kTet10;
  for (int e = 0; e < mesh.num_elements(); ++e) {
    // An inverted element would give inward normals: swap two corners' roles for it.
    const bool flip = ElementVolume(mesh, e) < 0.0;
    for (auto local : kOutwardFaces) {
      if (flip) std::swap(local[1], local[2]);
      SurfaceTriangle tri{};
      for (int k = 0; k < 3; ++k) {
        tri.corners[k] = mesh.elements(e, local[k]);
        tri.midsides[k] =
            quadratic ? mesh.elements(e, LocalMidside(local[k], local[(k + 1) % 3])) : -1;
      }
      std::array<int, 3> key = tri.corners;
      std::sort(key.begin(), key.end());
      auto [it, inserted] = faces.try_emplace(key, 0, tri);
      ++it->second.first;
    }
  }
  std::vector<SurfaceTriangle> result;
  for (const auto& [key, value] : faces) {
    if (value.first == 1) result.push_back(value.second);
  }
  return result;
}

void ValidateMesh(const Mesh& mesh) {
  const int width = NodesPerElement(mesh.order);
  if (mesh.num_nodes() == 0) throw InputError("mesh has no nodes");
  if (mesh.num_elements() == 0) throw InputError("mesh has no elements");
  if (mesh.elements.cols() != width) {
    throw InputError(std::string("mesh elements have ") + std::to_string(mesh.elements.cols()) +
                     " columns but a " + ToString(mesh.order) + " mesh needs " +
                     std::to_string(width));
  }
  if (!mesh.nodes_m.allFinite()) throw InputError("mesh has a non-finite node coordinate");
  for (int e = 0; e < mesh.num_elements(); ++e) {
    for (int k = 0; k < width; ++k) {
      const int n = mesh.elements(e, k);
      if (n < 0 || n >= mesh.num_nodes()) {
        throw InputError("element " + std::to_string(e) + " refers to node " +
                         std::to_string(n) + ", outside 0.." +
                         std::to_string(mesh.num_nodes() - 1));
      }
      for (int j = 0; j < k; ++j) {
        if (mesh.elements(e, j) == n) {
          throw InputError("element " + std::to_string(e) + " uses node " + std::to_string(n) +
                           " twice (degenerate element)");
        }
      }
    }
    // Degenerate: volume tiny compared with the cube of the longest edge (relative test, so
    // it works at any length scale).
    double longest_edge_m = 0.0;
    for (int i = 0; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j) {
        longest_edge_m = std::max(longest_edge_m, (mesh.nodes_m.row(mesh.elements(e, i)) -
                                                   mesh.nodes_m.row(mesh.elements(e, j)))
                                                      .norm());
      }
    }
    const double volume = ElementVolume(mesh, e);
    const double tolerance = 1e-10 * longest_edge_m * longest_edge_m * longest_edge_m;
    bool bad = !(volume > tolerance);
    if (!bad && mesh.order == ElementOrder::kTet10) {
      Eigen::Matrix<double, 10, 3> x;
      for (int k = 0; k < 10; ++k) x.row(k) = mesh.nodes_m.row(mesh.elements(e, k));
      bad = !(Tet10MinJacobian(x) > 6.0 * tolerance);
    }
    if (bad) {
      throw InputError("element " + std::to_string(e) + " is degenerate or inverted: volume " +
                       FormatDouble(volume) + " m^3 (corners must be right-handed, " +
                       "nodes distinct and not coplanar)");
    }
  }
}

void ValidateMaterial(const Material& material) {
  const double e = material.youngs_modulus_pa;
  const double nu = material.poisson_ratio;
  if (!std::isfinite(e) || !(e > 0.0)) {
    throw InputError("youngs_modulus_pa must be finite and > 0 Pa, got " + FormatDouble(e));
  }
  if (!std::isfinite(nu) || !(nu > -1.0 && nu < 0.5)) {
    throw InputError("poisson_ratio must satisfy -1 < nu < 0.5 (0.5 is incompressible, "
                     "which displacement elements cannot represent), got " +
                     FormatDouble(nu));
  }
}

}  // namespace hapco::fem
