#pragma once
// Multirate answering (issue 13): the contact physics on some poses, the step's local model on
// the poses between, every pose answered at the device's 1 kHz.
//
// Why: a physics step of benchmark 1 costs 100-230 us (docs/performance.md) and a 2-core server
// carries 4-8 sessions stepped on every pose, where the DDS path alone carries 16-24. Haptic
// rendering of deformable bodies has long run the deformation slower than the device and bridged
// the gap with a local linear model of the contact (Astley & Hayward 1998; Cavusoglu & Tendick,
// "Multirate simulation for high fidelity haptic interaction with deformable objects", ICRA
// 2000). Here the bridge is the LocalContactModel every step already builds for the clients
// (local_model.h): F(d) = F(d_k) + K (d - d_k) for the step's active set.
//
// A pose is answered by the model only where the model is valid; otherwise it gets a step:
//  - at most `physics_every - 1` model answers in a row (1 = a step on every pose: no change);
//  - the device within `max_model_distance_m` of the pose the last step answered;
//  - in contact: a model exists (a contact pushes, finite K) and the answer still pushes along
//    its normal (else contacts open: the active set changes, which a linear model does not
//    know). Friction is a return mapping on the resultant (Simo & Hughes, ch. 1-2, applied to
//    the device force): the force with every touching contact stuck (K of the contacts held
//    at u = 0, LocalModelBuilder::Sliding::kAsSticking), its part across the normal cut back to
//    the friction cone. A slide continues on the cone, a reversal sticks first, a turn turns
//    the friction, as a step would; the clients' model, linearized on the cone along the old
//    slip direction, knows none of that (9 % of the peak off at a turn of benchmark 1's path).
//  - apart: the answer is zero only when it is exactly zero, i.e. no contact can have formed.
//    Nothing is loaded, so only the tool moves, rigidly with d: every gap shrinks by at most
//    |d - d_k|, so with the nearest surface g_k ahead (or none within the search's reach) the
//    force is zero while |d - d_k| < g_k (resp. the reach), less a margin.
// The session's state (displacements, friction history) moves only on steps, so a model answer
// changes nothing, and a step after n model answers sees the device n poses further: the
// increments of the quasi-static path are coarser, which docs/load-and-network.md measures
// against stepping every pose.
#include <Eigen/Dense>

#include "sim/local_model.h"
#include "sim/step_pipeline.h"

namespace hapco::sim {

struct MultirateParameters {
  int physics_every = 1;               // a physics step on at least every this many poses (>= 1)
  double max_model_distance_m = 2e-4;  // a step once the device is this far from the last step's pose, m
  // Apart: the zero answer holds while the tool stays this much short of the nearest surface, m
  // (the surface search's own rounding, surface_ahead.h).
  double apart_margin_m = 1e-5;
};

// Checks the parameters (physics_every >= 1, finite non-negative distances); throws
// InputError naming the one to fix.
void ValidateMultirateParameters(const MultirateParameters& parameters);

enum class AnswerSource {
  kStep,   // a physics step at this pose
  kModel,  // the last step's local model at this pose (in contact)
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

 private:
  bool ModelAnswers(const Eigen::Vector3d& device_translation_m, MultirateAnswer* answer) const;

  TwoBodySession* session_;
  LocalModelBuilder* builder_;
  // The model's stiffness with sliding contacts stuck (the return mapping's trial), no surface
  // search: only with physics_every > 1.
  LocalModelBuilder stick_builder_{0.0, LocalModelBuilder::Sliding::kAsSticking};
  MultirateParameters parameters_;
  bool have_model_ = false;  // a step has run since construction or Reset
  int model_answers_in_a_row_ = 0;
};

const char* AnswerSourceName(AnswerSource source);

}  // namespace hapco::sim
