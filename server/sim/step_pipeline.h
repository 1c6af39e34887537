#pragma once
// One haptic step of the two-body contact simulation (algorithms.md §2, §5, §6):
//   device translation d_k → broad phase → two-pass collision detection → ũ and W for the
//   active contacts → contact solve → contact forces, surface displacements and the force on
//   the device.
//
// Two-pass node-to-face (docs/free-interaction.md): every tool surface node against the
// obstacle faces (pass 1), and the obstacle's sharp-edge nodes against the tool faces
// (pass 2), so an obstacle edge or corner pressing into a flat tool face is a contact too.
// Each contact is a relative displacement g = Σ_p c_p x_p over the nodes of both bodies
// (slave node c = +1, master face nodes c = −w, w the face's shape-function weights) in a
// frame whose normal points from the master face towards the slave node.
//
// Incremental friction (algorithms.md §2): Signorini acts on the total gap, Coulomb on the
// slip increment of the step, both evaluated with the current contact geometry:
//   ũ_n = n·Σ_p c_p (X_p + U_free,p(d_k))        (total)
//   ũ_t = T·Σ_p c_p (U_free,p(d_k) − U_p,k−1)      (increment)
// U_free is the tool's displacement for a rigid device translation with no contact force (0
// on the obstacle).
//
// Broad phase: the obstacle's displacement U = C f is evaluated only on the faces near the
// tool's predicted box, each grown by a rigorous per-axis bound on how far the last forces
// can have moved its nodes (ContactSurface::cell_axis_bound_m_per_n) plus the step's travel,
// so a step costs what the active contacts cost, not what the surface costs.
//
// Two modes give the same forces (a test checks 1e-9 relative):
//   kPrecomputed: W gathered from the per-scene compliance blocks, U from them;
//                 the cost does not depend on the mesh size (algorithms.md §6).
//   kFullSolve:   the paper's per-step sparse solves: compliance columns of the active nodes
//                 and full displacement fields solved with the factors every step. The
//                 speed baseline and the check.
#include <Eigen/Dense>
#include <array>
#include <cstdint>
#include <vector>

#include "contact/problem.h"
#include "contact/projection.h"
#include "contact/solver.h"
#include "sim/collision.h"
#include "sim/compliance_kernels.h"
#include "sim/two_body_model.h"

namespace hapco::sim {

enum class SolveMode { kPrecomputed, kFullSolve };

// Which node pressed into which face.
enum class ContactPass {
  kToolNode,      // a tool surface node against an obstacle face (pass 1)
  kObstacleNode,  // an obstacle sharp-edge node against a tool face (pass 2)
};

// One contact of a step, both sides as weighted surface nodes (slots into the bodies'
// ContactSurface::nodes).
struct StepContact {
  ContactPass pass = ContactPass::kToolNode;
  // Stable while the pair persists: the tool node id (pass 1), or tool node count + the
  // obstacle node id (pass 2).
  int id = -1;
  int slave_node = -1;       // node id of the slave (tool node, or obstacle node)
  int master_triangle = -1;  // index into the master surface's triangles
  // Rows n, t1, t2 (world): n is the master face's reference normal, towards the slave.
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();
  int num_tool = 0, num_obstacle = 0;
  std::array<int, 6> tool_slots{}, obstacle_slots{};
  std::array<double, 6> tool_coefficients{}, obstacle_coefficients{};  // dimensionless
  Eigen::Vector3d obstacle_point_m = Eigen::Vector3d::Zero();  // obstacle side, predicted, m
  double predicted_gap_m = 0.0;  // signed normal gap before the solve, m (< 0 penetrating)
};

struct StepOutput {
  int step = 0;                                                   // 1-based step count
  Eigen::Vector3d device_translation_m = Eigen::Vector3d::Zero();  // d_k, m
  // Resultant of the contact forces on the tool, world axes, N. The tool is held only by its
  // driven nodes, so this is minus the reaction there: the force the tool pushes the device
  // with, which the device renders on the hand (pressing down gives +z).
  Eigen::Vector3d contact_force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d device_force_n = Eigen::Vector3d::Zero();  // force_gain × contact_force_n, N
  int num_contacts = 0;
  int num_edge_contacts = 0;  // of which pass 2 (obstacle edge node on a tool face)
  std::array<int, 3> state_counts{0, 0, 0};  // separating, sticking, sliding
  contact::SolverStatus status = contact::SolverStatus::kConverged;
  int iterations = 0;
  int inner_iterations = 0;
  double paper_error_m = 0.0;
  double fc3d_error = 0.0;
  int region_nodes = 0;           // obstacle surface nodes the broad phase kept
  // Banded obstacle compliance (SceneSpec::compliance_range_m): the step needed a node pair
  // beyond the range, which reads as zero (raise the range). Always false when dense.
  bool compliance_out_of_range = false;
  // A first pose deep inside (TwoBodySession::Step): the approach's steps run in this call, and
  // whether the answer is still at a pose on the way (true) rather than at the device's.
  int approach_steps = 0;
  bool approaching = false;
  // The rigid tool at this pose was clear of the obstacle while the last step still had
  // contacts: their state (forces, both bodies' deformation) was dropped before this step
  // (TwoBodySession::Release).
  bool released = false;
  // With `released`: |contact force| of the step before, the state dropped, N. After a push
  // far past small strain it is kN; after a plain lift it is the solver's round-off (1e-6 of
  // the peak at the scenes' tolerances), which a summary need not report.
  double released_force_n = 0.0;
  // The step lost its last contacts with the tool inside the obstacle (passed into it): the
  // session re-enters by an approach from above (TwoBodySession::Step), `approaching` until
  // it reaches the device's pose.
  bool reentered = false;
  double detect_seconds = 0.0;    // broad phase (incl. the obstacle displacement there) + both passes
  double assemble_seconds = 0.0;  // ũ and W
  double solve_seconds = 0.0;
  double update_seconds = 0.0;    // displacements of the tool surface
  double total_seconds = 0.0;
};

// One active contact after a step, in world axes (for recordings, DDS frames, VTK).
struct ContactSample {
  int tool_node = -1;                                        // StepContact::id (stable)
  ContactPass pass = ContactPass::kToolNode;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();      // obstacle-side point
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();         // unit, from the obstacle towards the tool
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();         // contact force on the tool
  double gap_m = 0.0;                                        // u_n after the solve
  double slip_m = 0.0;                                       // ||u_t||, slip increment of the step
  contact::ContactState state = contact::ContactState::kSeparating;
};

// The mutable state of one simulated interaction on an immutable model (design.md ex. 4).
class TwoBodySession {
 public:
  explicit TwoBodySession(const TwoBodyModel& model, SolveMode mode = SolveMode::kPrecomputed);

  // Back to the reference configuration (no displacement, no force, step 0).
  void Reset();

  const TwoBodyModel& model() const { return model_; }

  // Runs one step for the device translation d (m, from the device's home position).
  // A session's first step at a pose more than 2 mm from home with the tool inside the
  // obstacle (TwoBodyModel::ToolInsideObstacle) starts an approach from home in small steps
  // (1 mm apart, 0.25 mm in contact): lift 1 mm along the start's contact normal, across, then
  // press in along it (TwoBodyModel::approach_normal) to that pose, then follow the device in
  // the same steps if it has moved meanwhile. Detection without
  // history finds contacts only within half a body's thickness, and a client resumed mid-press
  // on another server, 11 mm into benchmark 1's bar, got 0 N until it had lifted to 1 mm (over
  // a side edge, 4 N of 76; a helper session). The approach is spread over the session's calls,
  // about two contact steps each (kApproachBudget), so sessions sharing a stepping thread are
  // not held up (all at once it held the thread for 30-40 ms for 12 mm); each call answers the
  // force at the pose the approach has reached (StepOutput::approaching), rising as it presses
  // in, until it reaches the device's pose. Calls count one `step` each. Later in a session,
  // a step that loses its last contact with the tool inside the obstacle (a path far past
  // small strain: the deformed configuration no longer meets the tool) re-enters the same way,
  // from 1 mm above the pose (StepOutput::reentered). And a step whose undeformed tool is clear
  // of the obstacle drops the last contacts' state first (StepOutput::released).
  const StepOutput& Step(const Eigen::Vector3d& device_translation_m);
  // An approach (above) is still on its way to the device's pose.
  bool approaching() const { return approach_.num_waypoints > 0; }

  // Solver choice and parameters, initialised from the scene; change them between steps.
  contact::SolverKind solver = contact::SolverKind::kLocalUzawa;
  contact::SolverParameters parameters;
  // Build of the step's compliance sums (compliance_kernels.h): the fastest this CPU runs.
  ComplianceKernel compliance_kernel = FastestComplianceKernel();

  const StepOutput& last_output() const { return output_; }
  const std::vector<StepContact>& contacts() const { return contacts_; }
  // Obstacle surface slots whose U = C f the last step computed (the broad phase's region,
  // precomputed mode; model().obstacle_surface().nodes[slot] is the mesh node).
  const std::vector<int>& broad_phase_region() const { return region_; }
  // The contact problem of the last step (plain data: save it, replay it) and its solution.
  const contact::ContactProblem& last_problem() const { return problem_; }
  const contact::SolverResult& last_result() const { return result_; }
  // Contact alpha of the last step (0 <= alpha < contacts().size()). The state uses the
  // solver's tolerances (force ρ·ε₁, slip ε₁), so the samples add up to
  // StepOutput::state_counts (exactly with the paper's single ρ; with per-contact ρ the
  // smallest ρ_α is used).
  ContactSample SampleContact(int alpha) const;

  // Full displacement fields (3N each, m) of the current state: one solve per body with the
  // stored factors. For visualisation and checks, not for the haptic loop.
  void FullDisplacements(Eigen::VectorXd* obstacle_m, Eigen::VectorXd* tool_m) const;
  // Nodal contact forces (3N each, N) of the current state on each body.
  void NodalContactForces(Eigen::VectorXd* obstacle_n, Eigen::VectorXd* tool_n) const;

 private:
  const StepOutput& StepOnce(const Eigen::Vector3d& device_translation_m);
  // A first pose within this of home is stepped directly (the server's jump limit), m.
  static constexpr double kDirectFirstStepM = 2e-3;
  // The approach's work per call, in steps with contacts; a step without contacts (no
  // detection hits, no solve) counts a quarter: about three steps' cost a call.
  static constexpr double kApproachBudget = 2.0, kApproachApartCost = 0.25;
  // The approach's waypoints (the last is the first pose) and where it is.
  struct Approach {
    std::array<Eigen::Vector3d, 3> waypoints;
    int num_waypoints = 0;  // 0: no approach running
    int next = 0;
    Eigen::Vector3d at_m = Eigen::Vector3d::Zero();
  };
  // from_above: mid-session, the tool passed into the obstacle (Step): it starts 1 mm above
  // the pose along the approach normal, undeformed, and presses in.
  void StartApproach(const Eigen::Vector3d& device_translation_m, bool from_above = false);
  const StepOutput& ContinueApproach(const Eigen::Vector3d& device_translation_m);
  void BroadPhase(const Eigen::Vector3d& increment_m);
  // U = C f of the last forces on the region slots (kPrecomputed).
  void ObstacleDisplacementOnRegion();
  // Drops the last contacts' forces and both bodies' deformation: the tool back to its free
  // (rigid) displacement at the last pose, the obstacle undeformed. Allocation-free.
  void Release();
  static void SlotRuns(const std::vector<int>& slots, std::vector<std::pair<int, int>>* runs);
  void DetectContacts(const Eigen::Vector3d& device_translation_m);
  void CompleteContactDisplacements();
  bool WithinComplianceRange() const;
  // W and ũ; pair_blocks(a, b) gives Σ_pq c_ap c_bq C(p, q) over both bodies (world, m/N).
  template <typename PairBlocks>
  void AssembleProblem(const PairBlocks& pair_blocks);
  // From the precomputed surface compliances (slots are their nodes).
  void AssembleBlocked(const BlockedCompliance& tool, const BlockedCompliance& obstacle);
  // From per-step dense blocks among the active slots: *_rows maps a surface slot to its
  // block row in the given matrix (kFullSolve).
  void AssembleDense(const Eigen::MatrixXd& tool, const std::vector<int>& tool_rows, const Eigen::MatrixXd& obstacle,
                     const std::vector<int>& obstacle_rows);
  void UpdatePrecomputed();
  void UpdateFullSolve();

  const TwoBodyModel& model_;
  SolveMode mode_;
  const ContactSurface& tool_surface_;
  const ContactSurface& obstacle_surface_;
  Eigen::Vector3d device_translation_m_ = Eigen::Vector3d::Zero();
  // Tool surface displacement after the last step (3n_t, m) and its free part for d_k.
  Eigen::VectorXd tool_displacement_m_;
  Eigen::VectorXd tool_free_m_;
  // Obstacle surface displacement after the last step (3n_o, m); in kPrecomputed valid on
  // the broad phase's region slots only.
  Eigen::VectorXd obstacle_displacement_m_;
  // Forces of the last step, per loaded surface slot (world, N): what U = C f is made of.
  std::vector<int> tool_loaded_, obstacle_loaded_;
  Eigen::VectorXd tool_slot_force_n_, obstacle_slot_force_n_;  // 3 per slot, valid on loaded
  std::vector<char> tool_slot_loaded_, obstacle_slot_loaded_;
  // Positions for collision detection (reference + last displacement [+ rigid increment]), m.
  Eigen::Matrix<double, Eigen::Dynamic, 3> obstacle_positions_m_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> tool_positions_m_;
  // Broad phase: region slots of the obstacle surface, per-slot flag, enabled faces/edge nodes.
  std::vector<int> region_;
  std::vector<int> region_free_;  // region slots that carry no load
  std::vector<std::pair<int, int>> region_runs_, loaded_runs_;  // [begin, end) runs of region_free_, obstacle_loaded_
  std::vector<int> tool_free_;  // tool slots without load, ascending
  std::vector<std::pair<int, int>> tool_free_runs_, tool_loaded_runs_;  // runs of tool_free_, tool_loaded_
  std::vector<char> in_region_, obstacle_triangle_enabled_, edge_node_enabled_;
  std::vector<int> enabled_triangles_;  // the faces flagged in obstacle_triangle_enabled_
  std::vector<int> near_triangles_, tree_stack_;  // broad-phase tree query: hits, scratch
  Eigen::VectorXd cell_moved_m_;  // per cell and axis: bound on the last displacement, m
  // Tool nodes grouped by the direction of their reference normal (one of the 26 directions of
  // a cube's faces, edges and corners), with each group's box of predicted positions, and per
  // obstacle face the groups holding a node that can meet it (bit k: group k has a node n
  // with -n_face·n_node >= min_normal_opposition). A face no such group's box comes near
  // cannot hold a contact (ContactDetector tests normals first), so the broad phase leaves it
  // out, and with it its nodes' U = C f: on the benchmarks, the bar's side faces below a tool
  // pressing the top (a quarter of the region).
  std::vector<int> tool_normal_group_;            // per tool surface slot
  std::vector<std::uint32_t> face_reachable_groups_;  // per obstacle triangle
  std::vector<Eigen::Vector3d> group_lo_m_, group_hi_m_;  // per group, this step, m
  // Pass 1: tool nodes vs obstacle faces; pass 2: obstacle edge nodes vs tool faces.
  CollisionParameters tool_pass_parameters_, edge_pass_parameters_;
  ContactDetector tool_pass_, edge_pass_;
  std::vector<ContactPoint> tool_pass_points_, edge_pass_points_;
  std::vector<int> tool_previous_triangle_, edge_previous_triangle_;
  std::vector<int> edge_node_slot_;  // edge node index -> obstacle surface slot
  double last_residual_penetration_m_ = 0.0;  // deepest u_n < 0 left by the last solve, m
  double max_new_depth_obstacle_m_ = 0.0, max_new_depth_tool_m_ = 0.0;  // half-body bounds, m
  // Each obstacle surface slot's position at the detection it was last placed for (m) and that
  // detection's number (detection_count_ then; 0: never), and per triangle how far its nodes
  // moved outwards along its reference normal since the last detection (m, >= 0; DetectContacts).
  std::vector<Eigen::Vector3d> obstacle_detected_m_;
  std::vector<std::uint64_t> obstacle_detected_stamp_;
  std::uint64_t detection_count_ = 1;  // detections so far + 1, + 2 at each reset or release
  std::vector<double> face_rise_m_;
  std::vector<char> tool_is_slave_;  // per tool slot: a pass-1 slave this step
  std::vector<StepContact> contacts_;
  // Last world contact force per contact id (3 per id, N): the warm start; zero for ids not
  // in contact at the last step (previous_ids_).
  Eigen::VectorXd force_by_id_n_;
  std::vector<int> previous_ids_;
  contact::ContactProblem problem_;
  contact::SolverWorkspace workspace_;
  contact::SolverResult result_;
  StepOutput output_;
  Approach approach_;
  int max_contacts_ = 0;
  // kFullSolve scratch: active slots per body and their row blocks in the per-step blocks.
  std::vector<int> active_tool_, active_obstacle_;
  std::vector<int> active_tool_rows_, active_obstacle_rows_;
};

}  // namespace hapco::sim
