#pragma once
// Tetrahedral meshes from Gmsh files (issue 17, docs/mesh-scenes.md): a `.msh` is read, a
// `.geo` is meshed at load with a given element size and cached by content hash. Gmsh's own
// C++ API (libgmsh, Debian) does all parsing and meshing; this library only turns its element
// blocks into an fem::Mesh (node order as VTK), its named physical groups into node sets, and
// refuses what a body cannot be built from with one clear line naming the file.
#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "fem/mesh.h"

namespace hapco::mesh_import {

struct MeshRequest {
  std::string path;  // a .msh (any MSH version Gmsh reads) or a .geo
  fem::ElementOrder order = fem::ElementOrder::kTet4;  // a .msh must hold this element type
  double length_unit_m = 1.0;  // metres per length unit of the file (0.001 for millimetres)
  // .geo only: the largest element edge, in the file's length unit (0: the .geo's own sizes).
  double mesh_size = 0.0;
  Eigen::Vector3d offset_m = Eigen::Vector3d::Zero();  // added after scaling, m
  // A mesh with more nodes is refused, before a .geo is meshed (estimated from its bounding box
  // and mesh_size) and right after a .msh is read (before any FEM allocation).
  long long max_nodes = 2'000'000;
  // Where meshed .geo files are kept (<dir>/<hash>.msh); empty: DefaultCacheDirectory().
  // When the directory cannot be written the mesh is made in memory every time.
  std::string cache_dir;
};

struct ImportedMesh {
  fem::Mesh mesh;  // nodes in m (scaled and offset), elements as fem::Mesh (VTK node order)
  // Named physical groups of any dimension -> sorted 0-based ids of the mesh's nodes in them
  // (nodes that belong to no tetrahedron are dropped, so ids are those of `mesh`).
  std::map<std::string, std::vector<int>> group_nodes;
  std::string meshed_file;  // the .msh read: `path` itself, or the cache file of a .geo
  bool from_cache = false;  // a .geo whose mesh was found in the cache
  int gmsh_element_type = 0;  // 4 (Tet4) or 11 (Tet10)
};

// Reads or meshes the file. Throws InputError "<path>: <what is wrong>" for: a missing or
// unreadable file, another extension, Gmsh errors (with Gmsh's first message), no tetrahedra
// of the requested order (naming the element types the file has), tetrahedra of another order
// mixed in, too many nodes, disconnected pieces, and inverted or degenerate elements (with the
// element's Gmsh tag). Not thread-safe with other users of Gmsh in the process (Gmsh keeps one
// global model); calls from several threads are serialised.
ImportedMesh ImportMesh(const MeshRequest& request);

// $XDG_CACHE_HOME/hapco/meshes, else $HOME/.cache/hapco/meshes, else "" (no cache).
std::string DefaultCacheDirectory();

// Gmsh element type of a tetrahedron order: 4 (Tet4) or 11 (Tet10).
int GmshTetrahedronType(fem::ElementOrder order);

}  // namespace hapco::mesh_import
