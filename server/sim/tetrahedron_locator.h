#pragma once
// Which tetrahedron of a mesh (its straight corner tetrahedra) holds a point: the checks that
// a body lies inside another (TwoBodyModel: at the start, on a session's first step, and on a
// step that lost its last contact, TwoBodySession::Step). A tree over the tetrahedra's boxes
// finds the few that may hold the point (brute force over all of them, ToolInsideObstacle
// took 46 us for benchmark 1's tool touching the bar, now 7 us: it runs on the 1 kHz path).
#include <Eigen/Dense>

#include <vector>

#include "fem/mesh.h"
#include "sim/box_tree.h"

namespace hapco::sim {

class TetrahedronLocator {
 public:
  TetrahedronLocator() = default;
  explicit TetrahedronLocator(const fem::Mesh& mesh) {
    const auto count = static_cast<std::size_t>(mesh.num_elements());
    lo_m_.resize(count);
    hi_m_.resize(count);
    origin_m_.resize(count);
    to_barycentric_.resize(count);
    usable_.assign(count, 0);
    for (int e = 0; e < mesh.num_elements(); ++e) {
      const auto k = static_cast<std::size_t>(e);
      const Eigen::Vector3d x0 = mesh.nodes_m.row(mesh.elements(e, 0)).transpose();
      Eigen::Matrix3d edges;
      Eigen::Vector3d lo = x0, hi = x0;
      for (int c = 1; c < 4; ++c) {
        const Eigen::Vector3d x = mesh.nodes_m.row(mesh.elements(e, c)).transpose();
        edges.col(c - 1) = x - x0;
        lo = lo.cwiseMin(x);
        hi = hi.cwiseMax(x);
      }
      lo_m_[k] = lo;
      hi_m_[k] = hi;
      origin_m_[k] = x0;
      bool invertible = false;
      edges.computeInverseWithCheck(to_barycentric_[k], invertible);
      usable_[k] = invertible ? 1 : 0;
    }
    if (mesh.num_nodes() > 0) {
      mesh_lo_m_ = mesh.nodes_m.colwise().minCoeff().transpose();
      mesh_hi_m_ = mesh.nodes_m.colwise().maxCoeff().transpose();
    }
    tree_ = StaticBoxTree(lo_m_, hi_m_);
  }

  // x (m) lies in one of the tetrahedra; on a face, edge or corner counts (as nodes of
  // matching grids do), within a barycentric slack of 1e-9.
  bool Contains(const Eigen::Vector3d& x) const {
    if (!InBox(x, mesh_lo_m_, mesh_hi_m_)) return false;
    constexpr double kOnTetrahedron = 1e-9;
    return tree_.AnyContaining(x, [&](int e) {
      const auto k = static_cast<std::size_t>(e);
      if (!usable_[k]) return false;
      const Eigen::Vector3d l = to_barycentric_[k] * (x - origin_m_[k]);
      return l.minCoeff() >= -kOnTetrahedron && l.sum() <= 1.0 + kOnTetrahedron;
    });
  }

 private:
  static bool InBox(const Eigen::Vector3d& x, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    return (x.array() >= lo.array()).all() && (x.array() <= hi.array()).all();
  }

  std::vector<Eigen::Vector3d> lo_m_, hi_m_, origin_m_;  // per tetrahedron: box, first corner, m
  std::vector<Eigen::Matrix3d> to_barycentric_;          // (x - origin) -> barycentric 1..3
  std::vector<char> usable_;                             // 0: degenerate, skipped
  StaticBoxTree tree_;                                   // over the tetrahedra's boxes
  Eigen::Vector3d mesh_lo_m_ = Eigen::Vector3d::Zero(), mesh_hi_m_ = -Eigen::Vector3d::Ones();
};

}  // namespace hapco::sim
