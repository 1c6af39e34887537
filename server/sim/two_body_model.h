#pragma once
// The per-scene precomputation of algorithms.md §6 ("model no more than the scene needs"):
// both bodies factored once, and the only operators a haptic step needs, restricted to the
// surfaces that can ever touch — chosen from the geometry and the device workspace, never from
// a scripted trajectory (docs/free-interaction.md):
//   - the obstacle's contact surface: every boundary face within `SceneSpec::reach_m` of the
//     tool's home box (top, sides, ends, bottom: the user moves freely);
//   - the tool's contact surface: all of its boundary;
//   - the dense compliance K⁻¹ among each surface's nodes (the inverse of their Schur
//     complement, which the body's factor holds last: ElasticBody::ComplianceBlockInto), with a
//     per-node bound on how far a unit force there can move any surface node (the step's
//     broad phase uses it to know which part of the obstacle can be near the tool);
//   - the tool's free displacement at its surface nodes per unit device translation;
//   - the obstacle's feature nodes (sharp edges and corners) for the reverse contact pass.
// Immutable after construction; one model serves any number of sessions (design.md ex. 4).
#include <Eigen/Dense>
#include <array>
#include <string>
#include <vector>

#include "fem/elastic_body.h"
#include "sim/blocked_compliance.h"
#include "sim/box_tree.h"
#include "sim/collision.h"
#include "sim/scene.h"
#include "sim/tetrahedron_locator.h"

namespace hapco::sim {

// Adjacent boundary faces whose normals differ by more than this make a sharp (feature) edge,
// rad: the box edges (90°) are, the flat triangulation's diagonals (0°) are not.
inline constexpr double kFeatureEdgeAngleRad = 0.5235987755982988;  // 30°

// A body's candidate contact surface and its operators.
struct ContactSurface {
  std::vector<fem::SurfaceTriangle> triangles;      // outward right-hand normals
  // Empty, or (scene quadratic_face_search FOUR_SUBTRIANGLES on a Tet10 body) one per
  // triangle: `triangles` are then the four flat sub-triangles of each 6-node face, and this
  // names each one's face (the contact keeps the face's quadratic weights; ContactDetector).
  std::vector<SubtriangleOfFace> subtriangle_faces;
  // Contact frame (rows n, t1, t2) of each face in the reference configuration.
  // Small-displacement theory: the contact normal is the undeformed face normal, so W, ũ and
  // the force directions stay consistent with the linear model (a frictionless press gives
  // no side force); the deformed geometry only decides where a node sits.
  std::vector<Eigen::Matrix3d> triangle_frames;
  // Per face and edge k (corners k, k+1): true when that edge is a sharp edge of the body.
  std::vector<std::array<bool, 3>> sharp_edges;
  std::vector<int> nodes;       // sorted node ids carrying the faces (corners and midsides)
  std::vector<int> node_index;  // node id -> position in `nodes`, -1 if absent
  // Outward unit normal per node: angle-weighted mean of the adjacent face normals (corners),
  // plain mean for midsides (Thürmer & Wüthrich pseudo-normals).
  std::vector<Eigen::Vector3d> node_normals;
  std::vector<char> on_sharp_edge;  // per node: lies on a sharp edge or corner
  // Compliance among the surface nodes (3n x 3n, m/N), ordered as `nodes`, stored as one
  // contiguous 3x3 block per node pair for the 1 kHz step (BlockedCompliance).
  BlockedCompliance compliance_m_per_n;
  double longest_edge_m = 0.0;  // longest edge of the searched triangles, m
  // Reference bounding box of each face, m, and a tree over them (the broad phase's query).
  std::vector<Eigen::Vector3d> triangle_min_m, triangle_max_m;
  StaticBoxTree triangle_tree;
  // Broad-phase bound (rigorous, per axis): the surface's nodes are binned into a grid of
  // cells; for cell c, axis a and node j, cell_axis_bound_m_per_n(3c + a, j) is the largest
  // ||C(3i + a, 3j..3j+2)|| over the nodes i of c. Under nodal forces f_j no node of c moves
  // along a by more than Σ_j cell_axis_bound(3c + a, j)·|f_j| (Cauchy-Schwarz), m/N.
  Eigen::MatrixXd cell_axis_bound_m_per_n;  // 3·cells x n
  std::vector<int> node_cell;               // per node: its cell
  int num_cells = 0;
  // Banded compliance (SceneSpec::compliance_range_m): `nodes` are ordered along
  // `range_axis` and C(i, j) is stored for |x_i - x_j| <= range_m along it; else -1 and 0.
  int range_axis = -1;
  double range_m = 0.0;
  // Per node j: the largest ||C(3i + a, 3j..3j+2)|| over the rows i beyond the range (m/N), so
  // the broad phase stays rigorous without those blocks: under forces f no node moves by
  // more than Σ_j far_bound(j)·|f_j| through the pairs not stored. Empty when not banded.
  std::vector<double> far_bound_m_per_n;
};

struct TwoBodyModelStats {
  double build_seconds = 0.0;       // meshing, assembly, factorization of both bodies, s
  double compliance_seconds = 0.0;  // both compliance blocks, s
  double total_seconds = 0.0;
  std::size_t operator_bytes = 0;   // memory held by the precomputed dense operators, bytes
  // Whether the obstacle's compliance range was chosen because its dense blocks did not fit
  // (SceneSpec::compliance_range_m = 0).
  bool range_chosen_automatically = false;
  // Obstacle boundary faces within the tool's reach that the scene's contact_groups leave out
  // (a tool pressed there meets no contact and passes through them), of all within reach.
  int faces_in_reach = 0, faces_in_reach_without_contact = 0;
};

class TwoBodyModel {
 public:
  // The dense compliance blocks grow as (3n)² in the surface node count n (72 n² bytes), and
  // the bodies' factors hold about as much again: by default a scene is refused, before
  // either body is factored, when its blocks exceed half of the memory this process can still
  // take (AvailableMemoryBytes: the machine's, or its container's limit).
  static constexpr std::size_t kOperatorsWithinAvailableMemory = 0;

  // Throws InputError when the scene cannot be built (see BuildBody), no obstacle face is
  // within reach, the tool starts inside the obstacle (the message names the depth), or the
  // dense operators would exceed max_operator_bytes, bytes (the message gives the estimate
  // and how to shrink it).
  explicit TwoBodyModel(SceneSpec scene, std::size_t max_operator_bytes = kOperatorsWithinAvailableMemory);

  const SceneSpec& scene() const { return scene_; }
  const fem::ElasticBody& obstacle() const { return obstacle_; }
  const fem::ElasticBody& tool() const { return tool_; }

  const ContactSurface& obstacle_surface() const { return obstacle_surface_; }
  const ContactSurface& tool_surface() const { return tool_surface_; }

  // Shorthands kept for the callers of the first wave.
  const std::vector<fem::SurfaceTriangle>& obstacle_triangles() const { return obstacle_surface_.triangles; }
  const std::vector<Eigen::Matrix3d>& obstacle_reference_frames() const { return obstacle_surface_.triangle_frames; }
  const std::vector<int>& obstacle_candidates() const { return obstacle_surface_.nodes; }
  const std::vector<int>& obstacle_candidate_index() const { return obstacle_surface_.node_index; }
  const std::vector<int>& tool_candidates() const { return tool_surface_.nodes; }
  const std::vector<int>& tool_candidate_index() const { return tool_surface_.node_index; }
  const std::vector<Eigen::Vector3d>& tool_candidate_normals() const { return tool_surface_.node_normals; }
  const BlockedCompliance& obstacle_compliance_m_per_n() const { return obstacle_surface_.compliance_m_per_n; }
  const BlockedCompliance& tool_compliance_m_per_n() const { return tool_surface_.compliance_m_per_n; }

  // The slaves of the reverse pass (obstacle node against tool face; ids, sorted) with their
  // normals: the obstacle's nodes on sharp edges and corners, which catch an obstacle edge or
  // corner pressing into a flat tool face where no tool node is; with the scene's
  // reverse_pass_slaves ALL_SURFACE_NODES, every obstacle candidate node.
  const std::vector<int>& obstacle_reverse_slaves() const { return obstacle_reverse_slaves_; }
  const std::vector<Eigen::Vector3d>& obstacle_reverse_slave_normals() const { return obstacle_reverse_slave_normals_; }

  // Tool surface displacement per unit device translation (3n_t x 3, m/m).
  const Eigen::MatrixXd& tool_unit_fields() const { return tool_unit_fields_; }

  // Smallest extent of each body's bounding box, m. A *new* contact deeper than about half of
  // it would be matched to the far side of the body, which bounds the detector's search for
  // contacts without history (persistent contacts have no depth limit).
  double obstacle_thickness_m() const { return obstacle_thickness_m_; }
  double tool_thickness_m() const { return tool_thickness_m_; }
  // Smallest gap between the tool surface and the obstacle in the reference configuration
  // (tool nodes against obstacle faces), m; +inf when no tool node faces an obstacle face.
  double initial_gap_m() const { return initial_gap_m_; }

  // Compliance given to a contact whose own W_αα is (near) zero, m/N: a driven tool node
  // against a clamped obstacle node is rigid against rigid, which the flexibility method
  // cannot resolve (W_αα = 0). Such a contact gets the compliance of the stiffest free node of
  // either surface (the smallest positive diagonal entry), so it pushes back hard but finitely.
  double rigid_contact_compliance_m_per_n() const { return rigid_contact_compliance_m_per_n_; }

  const TwoBodyModelStats& stats() const { return stats_; }

  // True when the undeformed tool moved by d (m) has a surface node inside the obstacle's
  // volume (its tetrahedra) and farther than 1 % of the obstacle's thickness from its contact
  // faces (touching is not inside). Used on a session's first step and on a step that lost
  // its last contact (TwoBodySession::Step); at most ~7 us for benchmark 1 (the tool touching
  // the bar: every node tested), well under 1 us when apart or inside.
  bool ToolInsideObstacle(const Eigen::Vector3d& device_translation_m) const;
  // True when the undeformed tool moved by d (m) is clear of the undeformed obstacle: its
  // bounding box meets the box of no obstacle contact face, and it is not wholly inside the
  // obstacle. Conservative (boxes): false may still be clear. Then no contact can hold: with
  // every gap of the rigid configuration open, the linear contact problem's only solution is
  // zero force (contact forces push the bodies apart, r·Wr > 0), whatever the bodies' last
  // deformation (TwoBodySession::StepOnce releases it). A few µs, no allocation.
  bool RigidToolClearOfObstacle(const Eigen::Vector3d& device_translation_m) const;
  // The mean outward normal of the obstacle faces nearest the tool at the start (unit; zero
  // when the tool faces none within reach): the direction a session's approach presses along.
  const Eigen::Vector3d& approach_normal() const { return approach_normal_; }

 private:
  struct Parts;  // the scene, its bodies and their candidate faces, made before the members
  static Parts MakeParts(SceneSpec scene, std::size_t max_operator_bytes);
  // The range chosen when the dense blocks do not fit: this many times the tool's largest
  // extent (the step's region spans the tool and its search margins).
  static constexpr double kAutomaticRangeToolExtents = 3.0;
  explicit TwoBodyModel(Parts parts);

  SceneSpec scene_;
  fem::ElasticBody obstacle_;
  fem::ElasticBody tool_;
  ContactSurface obstacle_surface_, tool_surface_;
  std::vector<int> obstacle_reverse_slaves_;
  std::vector<Eigen::Vector3d> obstacle_reverse_slave_normals_;
  Eigen::MatrixXd tool_unit_fields_;
  double obstacle_thickness_m_ = 0.0;
  double tool_thickness_m_ = 0.0;
  double initial_gap_m_ = 0.0;
  double rigid_contact_compliance_m_per_n_ = 0.0;
  TwoBodyModelStats stats_;
  TetrahedronLocator obstacle_locator_;  // the obstacle's volume (start check, ToolInsideObstacle)
  Eigen::Vector3d approach_normal_ = Eigen::Vector3d::Zero();
  // Bounding box of the undeformed tool, m (RigidToolClearOfObstacle).
  Eigen::Vector3d tool_lo_m_ = Eigen::Vector3d::Zero(), tool_hi_m_ = Eigen::Vector3d::Zero();
};

// A note for the user when the tool does not touch the obstacle at the start (its gap exceeds
// the activation gap): how far, so "no force yet" is not mistaken for a fault. Empty otherwise.
std::string StartingPositionNote(const TwoBodyModel& model);

// "" when every obstacle face within reach can hold a contact; else a note that the scene's
// contact_groups leave some out and where the contact faces are: a tool that slides off them
// sinks into the obstacle with no force (a helper session's Hertz scene, slid 8 mm off its
// 4 mm contact disc: 0 N while 0.3 mm deep).
std::string ContactGroupsNote(const TwoBodyModel& model);

// A note when the device may move farther from its start (device_reach_m, m: the server's
// --workspace-m, or the farthest pose of a trajectory; `what` names it) than the scene's
// contact.reach_m: obstacle faces beyond reach_m of the tool's start are no contact candidates,
// so the tool passes through them there (a helper session's reach_m 5 mm scene slid 28 mm:
// 13.1 N where 41.0 N is right, without a word). Empty otherwise.
std::string ReachNote(const TwoBodyModel& model, double device_reach_m, const std::string& what);

// A note when a Tet4 body's material is nearly incompressible (Poisson's ratio above 0.45):
// linear tetrahedra lock there and come out many times too stiff (a helper session's cantilever
// at 0.4999: 18 times the force at 0.3, without a word); Tet10 elements do not. Empty otherwise.
std::string LockingNote(const TwoBodyModel& model);

// A note when a body has no free node: every node clamped (obstacle) or driven (tool), so it is
// rigid and the contact's compliance is the other body's alone. Usually a group naming the
// body's volume where its base was meant (a helper session clamped all 6 560 nodes of a
// cylinder without a word). Empty otherwise.
std::string RigidBodyNote(const TwoBodyModel& model);

}  // namespace hapco::sim
