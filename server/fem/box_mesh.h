#pragma once
// Structured tetrahedral meshes of an axis-aligned box (the paper's parallelepipeds).
#include <vector>

#include <Eigen/Core>

#include "fem/mesh.h"

namespace hapco::fem {

struct BoxMeshSpec {
  Eigen::Vector3d min_corner_m = Eigen::Vector3d::Zero();  // lowest corner, m
  Eigen::Vector3d size_m = Eigen::Vector3d::Ones();        // edge lengths along x, y, z, m
  Eigen::Vector3i divisions = Eigen::Vector3i::Ones();     // hex cells along x, y, z
  ElementOrder order = ElementOrder::kTet4;
};

// Each hex cell is split into 6 tetrahedra around its main diagonal (Kuhn / Freudenthal
// split). Every cell is split the same way, so shared faces of neighbouring cells are cut
// along the same diagonal and the mesh is conforming. Tet10 adds one node at the midpoint of
// every edge, shared by all elements on that edge. Corner nodes come first, numbered
// i + (nx+1) (j + (ny+1) k). All elements are right-handed.
// Throws InputError for a size <= 0 (or non-finite) or divisions < 1.
Mesh MakeBoxMesh(const BoxMeshSpec& spec);

enum class BoxFace { kXMin, kXMax, kYMin, kYMax, kZMin, kZMax };

// Sorted ids of the nodes (corners and, for Tet10, midsides) lying on one face of the box,
// with a tolerance of 1e-6 of the smallest cell edge.
std::vector<int> NodesOnBoxFace(const Mesh& mesh, const BoxMeshSpec& spec, BoxFace face);

}  // namespace hapco::fem
