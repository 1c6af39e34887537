#pragma once
// VTK XML export for ParaView: deformed meshes (.vtu), contact points (.vtu of vertices) and a
// .pvd collection that lists them per step, so ParaView opens a whole run as a time series.
// ASCII format: readable, diffable, and small enough at visual rates (every N haptic steps).
#include <Eigen/Dense>
#include <string>
#include <vector>

#include "fem/mesh.h"

namespace hapco::io {

// Writes one body: reference node positions, displacement (m) and nodal force (N) as point
// data, so ParaView's "Warp By Vector" shows the deformed shape. Tet4 → VTK_TETRA (10),
// Tet10 → VTK_QUADRATIC_TETRA (24, same node order as fem::Mesh). Throws InputError when
// the file cannot be written or the field sizes do not match the mesh.
void WriteBodyVtu(const std::string& path, const fem::Mesh& mesh,
                  const Eigen::VectorXd& displacement_m, const Eigen::VectorXd& nodal_force_n);

struct ContactPointRecord {
  Eigen::Vector3d position_m;  // world
  Eigen::Vector3d normal;      // unit, world
  Eigen::Vector3d force_n;     // on the tool, world
  int state = 0;               // 0 separating, 1 sticking, 2 sliding (contact::ContactState)
  double gap_m = 0.0;
};

// Writes the contact points as VTK vertices with normal, force, state and gap arrays.
void WriteContactsVtu(const std::string& path, const std::vector<ContactPointRecord>& contacts);

// A ParaView collection (.pvd) that grows step by step; Finish() writes the file (it is also
// rewritten after every Add so a run that stops early still leaves a readable collection).
class VtkCollection {
 public:
  explicit VtkCollection(std::string path);
  // Adds a dataset file (relative to the .pvd's folder) at time `time` and part `part`.
  void Add(double time, int part, const std::string& relative_file);

 private:
  void Write() const;
  struct Entry {
    double time;
    int part;
    std::string file;
  };
  std::string path_;
  std::vector<Entry> entries_;
};

}  // namespace hapco::io
