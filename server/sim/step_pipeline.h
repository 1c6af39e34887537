#pragma once
// One haptic step of the two-body contact simulation (algorithms.md §2, §5, §6):
//   device translation d_k → collision detection → ũ and W for the active contacts →
//   contact solve → contact forces, candidate displacements and the force on the device.
//
// Incremental friction (algorithms.md §2): Signorini acts on the total gap, Coulomb on the
// slip increment of the step, both evaluated with the current contact geometry:
//   ũ_n = n·[(X_a + U_free,a(d_k)) − Σ w_i X_i]                       (total)
//   ũ_t = T·[(U_free,a(d_k) − U_a,k−1) + Σ w_i U_i,k−1]                (increment)
// where a is the tool node, i the obstacle face nodes with weights w, U_free the tool's
// displacement for a rigid device translation with no contact force.
//
// Two modes give the same forces (a test checks 1e-9 relative):
//   kPrecomputed: W gathered from the per-scene compliance blocks, U updated from them;
//                 the cost does not depend on the mesh size (algorithms.md §6).
//   kFullSolve:   the paper's per-step sparse solves: compliance columns of the active nodes
//                 and full displacement fields solved with the factors every step. The
//                 speed baseline and the check.
#include <Eigen/Dense>
#include <array>
#include <vector>

#include "contact/problem.h"
#include "contact/projection.h"
#include "contact/solver.h"
#include "sim/collision.h"
#include "sim/two_body_model.h"

namespace hapco::sim {

enum class SolveMode { kPrecomputed, kFullSolve };

struct StepOutput {
  int step = 0;                                                   // 1-based step count
  Eigen::Vector3d device_translation_m = Eigen::Vector3d::Zero();  // d_k, m
  // Resultant of the contact forces on the tool, world axes, N. The tool is held only by its
  // driven nodes, so this is minus the reaction there: the force the tool pushes the device
  // with, which the device renders on the hand (pressing down gives +z).
  Eigen::Vector3d contact_force_n = Eigen::Vector3d::Zero();
  Eigen::Vector3d device_force_n = Eigen::Vector3d::Zero();  // force_gain × contact_force_n, N
  int num_contacts = 0;
  std::array<int, 3> state_counts{0, 0, 0};  // separating, sticking, sliding
  contact::SolverStatus status = contact::SolverStatus::kConverged;
  int iterations = 0;
  int inner_iterations = 0;
  double paper_error_m = 0.0;
  double fc3d_error = 0.0;
  double detect_seconds = 0.0;
  double assemble_seconds = 0.0;  // ũ and W
  double solve_seconds = 0.0;
  double update_seconds = 0.0;    // displacements of the candidate nodes
  double total_seconds = 0.0;
};

// One active contact after a step, in world axes (for recordings, DDS frames, VTK).
struct ContactSample {
  int tool_node = -1;                                        // stable while the pair persists
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();      // obstacle point
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();         // unit, towards the tool
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
  const StepOutput& Step(const Eigen::Vector3d& device_translation_m);

  // Solver choice and parameters, initialised from the scene; change them between steps.
  contact::SolverKind solver = contact::SolverKind::kLocalUzawa;
  contact::SolverParameters parameters;

  const StepOutput& last_output() const { return output_; }
  const std::vector<ContactPoint>& contacts() const { return contacts_; }
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
  void AssembleProblem(const Eigen::MatrixXd& tool_compliance, const std::vector<int>& tool_map,
                       const Eigen::MatrixXd& obstacle_compliance,
                       const std::vector<int>& obstacle_map);
  void UpdatePrecomputed();
  void UpdateFullSolve();

  const TwoBodyModel& model_;
  SolveMode mode_;
  Eigen::Vector3d device_translation_m_ = Eigen::Vector3d::Zero();
  // Displacements of the candidate nodes after the last step (3n, m), candidate order.
  Eigen::VectorXd obstacle_candidate_displacement_m_;
  Eigen::VectorXd tool_candidate_displacement_m_;
  // The tool's candidate displacement for d_k with no contact force (3n_t, m).
  Eigen::VectorXd tool_free_candidate_m_;
  // Last contact force on each tool candidate node, world axes (3n_t, N): the warm start.
  Eigen::VectorXd tool_candidate_force_n_;
  // Positions for collision detection (reference + last displacement), m.
  Eigen::Matrix<double, Eigen::Dynamic, 3> obstacle_positions_m_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> tool_positions_m_;
  CollisionParameters collision_;
  ContactDetector detector_;
  std::vector<ContactPoint> contacts_;
  contact::ContactProblem problem_;
  contact::SolverWorkspace workspace_;
  contact::SolverResult result_;
  StepOutput output_;
  // kFullSolve scratch: the active nodes and their per-step compliance blocks.
  std::vector<int> active_obstacle_nodes_, active_tool_nodes_;
  std::vector<int> active_obstacle_map_, active_tool_map_;
  // Haptic-path workspaces, sized once for max_contacts_ (see AssembleProblem).
  int max_contacts_ = 0;
  // Obstacle compliance spread by each contact's weights, world axes (rows: the compliance
  // given to AssembleProblem, 3 columns per contact), m/N.
  Eigen::MatrixXd spread_;
  // Per contact: positions of its obstacle nodes in that compliance.
  std::vector<std::array<int, 6>> obstacle_slots_;
  // Minus the world contact force of each contact (3m_max, N): the obstacle's share.
  Eigen::VectorXd world_forces_n_;
  // This step's W gather: spread (true) or pairs (false), see AssembleProblem.
  bool use_spread_ = false;
  // kPrecomputed update without the spread: nodal obstacle forces (3n_o, N, valid on the
  // loaded slots only), a loaded flag per candidate slot and the list of loaded slots.
  Eigen::VectorXd obstacle_force_n_;
  std::vector<char> slot_loaded_;
  std::vector<int> active_slots_;
};

}  // namespace hapco::sim
