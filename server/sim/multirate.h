#pragma once
// Multirate answering (issue 13): a contact step on some poses, a cheaper answer from the last
// step on the poses between, every pose answered at the device's 1 kHz.
//
// Why: a physics step of benchmark 1 costs 100-230 us (docs/performance.md) and a 2-core server
// carries 4-8 sessions stepped on every pose, where the DDS path alone carries 16-24. Haptic
// rendering of deformable bodies has long run the deformation slower than the device and bridged
// the gap with a local model of the contact (Astley & Hayward 1998; Cavusoglu & Tendick,
// "Multirate simulation for high fidelity haptic interaction with deformable objects", ICRA
// 2000). Here the bridge is the last step's own contact problem (below).
//
// Between steps, a pose in contact is answered in one of two ways (BetweenSteps):
//  - kFrozenContacts (default): the last step's contact problem, contacts and W unchanged,
//    with the free relative displacement moved to this pose, ũ(d) = ũ_k - (u_t)_k + G (d - d_k)
//    (the slip counted from the step's end; exact for those contacts: the tool's free
//    displacement is linear in d, algorithms.md §6), solved again warm from the step's forces.
//    Each contact keeps its own Coulomb law, so stick/slip changes, reversals and contacts
//    opening come out as a step would give them; what it does not see is geometry: a contact
//    closing elsewhere, a contact point moving on its face. Costs one solve (no detection, no
//    assembly), started from the previous answer moved along the step's dr/dd: 14-17 us on
//    benchmark 1 against 220-280 us a step (multirate_study's us/model and us/step).
//  - kReturnMapping: the force of a linear model, F_k + K (d - d_k) with every touching
//    contact stuck (LocalModelBuilder::Sliding::kAsSticking), its part across the resultant's
//    normal cut back to the friction cone (a return mapping on the resultant, Simo & Hughes
//    ch. 1-2). About 1 us, less exact where contacts partly slip.
// Either way a pose gets a step instead when:
//  - a step is due: at most `physics_every - 1` answers between steps (1 = every pose a step);
//  - the device is farther than `max_model_distance_m` from the pose of the last step;
//  - in contact, the answer is not a converged solve (frozen) or would pull (return mapping);
//  - apart (no contact force at the last step), unless the answer is exactly zero: nothing is
//    loaded, so only the tool moves, rigidly with d, and every gap shrinks by at most
//    |d - d_k|: with the nearest surface g_k ahead the force is zero while |d - d_k| < g_k
//    less a margin (without a surface within the search's reach, a step).
// Friction makes the quasi-static path matter: a step that jumps over the pose where the device
// turned back (a reversal, or a turn of more than 60 degrees) misses the friction's reversal
// there (the coarse test bar: the step after a reversal 1.1 N off, 9.6 % of the peak). So when the
// device turns between steps, the session first steps at the turning pose (answered already,
// by the model), then answers the new pose from that step: `turn_steps()` counts those.
// The session's state (displacements, friction history) moves only on steps, so an answer
// between steps changes nothing, and a step after n of them sees the device n poses further:
// the increments of the quasi-static path are coarser, which multirate_study measures against
// a step on every pose (docs/load-and-network.md, "Multirate").
#include <Eigen/Dense>

#include <vector>

#include "contact/problem.h"
#include "contact/solver.h"
#include "sim/local_model.h"
#include "sim/step_pipeline.h"

namespace hapco::sim {

enum class BetweenSteps { kFrozenContacts, kReturnMapping };

struct MultirateParameters {
  int physics_every = 1;               // a physics step on at least every this many poses (>= 1)
  BetweenSteps between_steps = BetweenSteps::kFrozenContacts;  // how a pose in contact is answered
  double max_model_distance_m = 5e-4;  // a step once the device is this far from the last step's pose, m
  // Apart: the zero answer holds while the tool stays this much short of the nearest surface, m
  // (the surface search's own rounding, surface_ahead.h).
  double apart_margin_m = 1e-5;
};

// Checks the parameters (physics_every >= 1, finite non-negative distances); throws
// InputError naming the one to fix.
void ValidateMultirateParameters(const MultirateParameters& parameters);

enum class AnswerSource {
  kStep,   // a physics step at this pose
  kModel,  // the last step's contacts at this pose (in contact): frozen solve or return mapping
  kApart,  // zero: no contact can have formed since the last step (apart)
};

struct MultirateAnswer {
  Eigen::Vector3d device_force_n = Eigen::Vector3d::Zero();  // N
  AnswerSource source = AnswerSource::kStep;
};

// One session's answers. Borrows the session and the builder (the server's Session owns both);
// the builder must not be used by anyone else between answers, since its model is the last
// step's.
class MultirateAnswerer {
 public:
  MultirateAnswerer(TwoBodySession& session, LocalModelBuilder& builder, MultirateParameters parameters = {});

  // The force for this device translation (m). A step runs session.Step and then the builder's
  // Linearize, so the builder's model() is always that of the last step.
  MultirateAnswer Answer(const Eigen::Vector3d& device_translation_m);

  // After session.Reset(): the next pose gets a step.
  void Reset() { have_model_ = false; }

  const MultirateParameters& parameters() const { return parameters_; }
  // Steps taken at turning poses (above), beside the answers' own.
  long turn_steps() const { return turn_steps_; }

 private:
  bool ModelAnswers(const Eigen::Vector3d& device_translation_m, MultirateAnswer* answer);
  bool ReturnMappingAnswers(const Eigen::Vector3d& device_translation_m, Eigen::Vector3d* force_n) const;
  bool FrozenContactsAnswer(const Eigen::Vector3d& device_translation_m, Eigen::Vector3d* force_n);
  void FreezeLastStep();  // after a step: its problem, G and forces for kFrozenContacts
  void StepAt(const Eigen::Vector3d& device_translation_m);  // a step, then its model

  TwoBodySession* session_;
  LocalModelBuilder* builder_;
  // The model's stiffness with sliding contacts stuck (the return mapping's trial), no surface
  // search: only with physics_every > 1.
  LocalModelBuilder stick_builder_{0.0, LocalModelBuilder::Sliding::kAsSticking};
  // kFrozenContacts: the last step's problem (ũ rewritten per answer), ũ_k, G, r_k, and
  // per contact the tool's share of its force in world axes (w_α R_αᵀ, 3 x 3).
  contact::ContactProblem frozen_;
  Eigen::VectorXd step_free_m_, step_force_n_;
  Eigen::MatrixXd free_per_device_;
  // dr/dd of the step's active set (LocalModelBuilder::ContactForcePerDeviceTranslation, 3m x 3,
  // N/m), and the pose whose answer result_.force_n holds, m: each solve starts from that
  // answer moved along dr/dd to the new pose.
  Eigen::MatrixXd force_per_device_;
  Eigen::Vector3d answered_pose_m_ = Eigen::Vector3d::Zero();
  std::vector<Eigen::Matrix3d> device_share_;
  contact::SolverWorkspace workspace_;
  contact::SolverResult result_;
  MultirateParameters parameters_;
  bool have_model_ = false;  // a step has run since construction or Reset
  int model_answers_in_a_row_ = 0;
  Eigen::Vector3d previous_pose_m_ = Eigen::Vector3d::Zero();  // the last pose answered, m
  long turn_steps_ = 0;
};

const char* AnswerSourceName(AnswerSource source);

}  // namespace hapco::sim
