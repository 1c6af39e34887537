#pragma once
// A scene in plain C++ types (no file format): two elastic bodies, contact, solver settings
// and the device trajectory (algorithms.md §1). io/scene_file.h reads it from a scene file.
#include <Eigen/Dense>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "contact/solver.h"
#include "fem/box_mesh.h"
#include "fem/elastic_body.h"

namespace hapco::sim {

// A body from an imported mesh (io reads it with mesh_import): nodes in m, node sets as ids.
struct MeshBody {
  std::string source;  // the file it came from, for messages
  // One line for tools' reports: file, how it was meshed, the groups used.
  std::string summary;
  fem::Mesh mesh;
  std::vector<int> clamped_nodes;  // sorted; fixed
  std::vector<int> driven_nodes;   // sorted; follow the device translation
  std::vector<int> contact_nodes;  // sorted; faces with all corners here may touch (empty: all)
};

struct BodySpec {
  std::string name;
  fem::BoxMeshSpec box;  // the geometry unless `mesh` is set (then only box.order is used)
  fem::Material material;
  std::vector<fem::BoxFace> clamped_faces;   // box bodies: fixed nodes
  std::optional<fem::BoxFace> driven_face;   // box bodies: nodes that follow the device
  // Set for a mesh body (shared: scenes are copied, meshes can be large).
  std::shared_ptr<const MeshBody> mesh;
};

// `steps` equal device increments that add up to `displacement_m`.
struct TrajectoryPhase {
  std::string name;
  Eigen::Vector3d displacement_m = Eigen::Vector3d::Zero();
  int steps = 0;
};

struct SceneSpec {
  std::string name;
  std::string description;
  BodySpec obstacle;  // the paper's red body
  BodySpec tool;      // the paper's green body, driven by the device
  double friction_coefficient = 0.3;  // Coulomb μ, dimensionless
  double activation_gap_m = 5e-4;     // candidate contacts closer than this are active
  // Device workspace radius, m: obstacle faces within this distance of the tool's home box
  // are contact candidates (TwoBodyModel), independent of the trajectory.
  double reach_m = 0.1;
  // The obstacle's compliance is stored only between surface nodes within this distance
  // along its surface's longest axis (BlockedCompliance::Banded); 0 = every pair, or
  // automatic when the dense blocks do not fit (TwoBodyModel). m.
  double compliance_range_m = 0.0;
  // Pair nodes with a 6-node face on its four flat sub-triangles (through the midside nodes)
  // instead of the flat triangle of its corners (scene.proto QuadraticFaceSearch).
  bool quadratic_face_subtriangles = false;
  // Every obstacle candidate node is a reverse-pass slave (against the tool's faces), not only
  // those on its sharp edges (scene.proto ReversePassSlaves).
  bool reverse_pass_all_nodes = false;
  contact::SolverKind solver = contact::SolverKind::kLocalUzawa;
  contact::SolverParameters solver_parameters;
  std::vector<TrajectoryPhase> trajectory;
  double force_gain = 1.0;  // device force = gain × reaction at the driven nodes

  int total_steps() const;
  // Device translation (m) after `step` increments (0 = start), following the phases.
  Eigen::Vector3d DeviceTranslationAtStep(int step) const;
  // DeviceTranslationAtStep(k) for k = 0..total_steps(): the device path one point per step.
  std::vector<Eigen::Vector3d> DeviceTrajectory() const;
  // Index of the phase that step `step` (1-based) belongs to.
  int PhaseOfStep(int step) const;
};

// What building a body will hold, estimated from its box alone (before anything is
// allocated). The sparse Cholesky factor dominates: its size follows a fit to CHOLMOD's
// measured factors of box meshes (nested-dissection fill grows with the cross-section):
// within -6 % / +33 % of the measured peak for bodies of 40 MB to 3 GB (docs/fuzzing.md).
struct BodyBuildEstimate {
  long long nodes = 0;
  long long elements = 0;
  double factor_nonzeros = 0.0;
  double bytes = 0.0;  // peak resident bytes of BuildBody, approximately
};
BodyBuildEstimate EstimateBodyBuild(const fem::BoxMeshSpec& box);
// The same for a mesh from its node count and bounding box: CHOLMOD's fill follows the
// equivalent box (same node count, same aspect ratios), which holds for the convex, compact
// bodies of haptic scenes; a long thin mesh is estimated high, never low.
BodyBuildEstimate EstimateMeshBuild(const fem::Mesh& mesh);
// "12000 nodes (Tet10) would need about N GiB to build, more than ...".
std::string DescribeOverLimit(const fem::Mesh& mesh, const BodyBuildEstimate& estimate);
// "400 x 80 x 80 Tet4 cells (2627721 nodes) would need about N GiB to build, more than ...".
std::string DescribeOverLimit(const fem::BoxMeshSpec& box, const BodyBuildEstimate& estimate);

// A body whose estimate exceeds this is refused before it is built (a scene file cannot ask
// for more memory than a server has; the dense contact operators are checked against the
// memory available, TwoBodyModel).
inline constexpr double kMaxBodyBuildBytes = 4.0 * 1024 * 1024 * 1024;

// The largest trajectory a scene may describe (steps over all phases), so that step counts
// stay far from int overflow and DeviceTrajectory() from exhausting memory.
inline constexpr long long kMaxTrajectorySteps = 100'000'000;
// Largest Coulomb coefficient a scene (and hapco-sim --mu) accepts, dimensionless.
inline constexpr double kMaxFrictionCoefficient = 10.0;

// The body's mesh: its imported mesh, or its box meshed. Throws InputError, before allocating,
// when the estimated build exceeds kMaxBodyBuildBytes.
fem::Mesh BodyMesh(const BodySpec& body);
// Gathers the Dirichlet nodes of `mesh` (BodyMesh(body)) and factors its stiffness once, with
// the dofs of `compliance_nodes` (the scene's contact candidates) ordered last so their
// compliance block needs no second factorization (fem::ElasticBody::Spec).
fem::ElasticBody BuildBody(const BodySpec& body, fem::Mesh mesh, std::vector<int> compliance_nodes);
// BuildBody(body, BodyMesh(body), {}).
fem::ElasticBody BuildBody(const BodySpec& body);

}  // namespace hapco::sim
