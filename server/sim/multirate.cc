#include "sim/multirate.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "common/error.h"

namespace hapco::sim {

void ValidateMultirateParameters(const MultirateParameters& parameters) {
  if (parameters.physics_every < 1) {
    throw InputError("physics every " + std::to_string(parameters.physics_every) +
                     " poses: give 1 (a step on every pose) or more");
  }
  if (!std::isfinite(parameters.max_model_distance_m) || parameters.max_model_distance_m < 0) {
    throw InputError("the model's distance must be finite and >= 0 m");
  }
  if (!std::isfinite(parameters.apart_margin_m) || parameters.apart_margin_m < 0) {
    throw InputError("the apart margin must be finite and >= 0 m");
  }
}

MultirateAnswerer::MultirateAnswerer(TwoBodySession& session, LocalModelBuilder& builder,
                                     MultirateParameters parameters)
    : session_(&session), builder_(&builder), parameters_(parameters) {
  ValidateMultirateParameters(parameters_);
}

bool MultirateAnswerer::ModelAnswers(const Eigen::Vector3d& d, MultirateAnswer* answer) const {
  if (!have_model_ || model_answers_in_a_row_ + 1 >= parameters_.physics_every) return false;
  const LocalContactModel& model = builder_->model();
  const Eigen::Vector3d offset_m = d - model.device_translation_m;
  const double distance_m = offset_m.norm();
  if (!(distance_m <= parameters_.max_model_distance_m)) return false;  // (also NaN)
  const StepOutput& last = session_->last_output();
  if (last.num_contacts == 0 || model.normal_device.isZero()) {
    // Apart (or touching without force): zero only if no gap can have closed.
    if (!model.normal_device.isZero() || !last.device_force_n.isZero()) return false;
    if (!model.surface_ahead) return false;  // none within reach, or already through: step
    if (distance_m + parameters_.apart_margin_m >= model.surface_gap_m) return false;
    answer->device_force_n.setZero();
    answer->source = AnswerSource::kApart;
    return true;
  }
  const LocalContactModel& trial = stick_builder_.model();
  if (!trial.stiffness_n_per_m.allFinite() || !model.device_force_n.allFinite()) return false;
  // Return mapping on the resultant: the trial force with every touching contact stuck, its
  // part across the normal cut back to the cone. The cone's coefficient is the scene's, or the
  // resultant's own ratio at the step when larger (contacts with different normals add up to
  // more across than one cone), so that the answer at the step's own pose is the step's force.
  const Eigen::Vector3d& normal = model.normal_device;
  const Eigen::Vector3d trial_n = trial.ForceAt(d);
  const double normal_n = trial_n.dot(normal);
  if (!(normal_n > 0)) return false;  // the contacts would pull: they open, a step decides
  Eigen::Vector3d across_n = trial_n - normal_n * normal;
  const double step_normal_n = model.device_force_n.dot(normal);
  const double step_across_n = (model.device_force_n - step_normal_n * normal).norm();
  const double mu = std::max(model.friction_coefficient, step_normal_n > 0 ? step_across_n / step_normal_n : 0.0);
  const double across_norm_n = across_n.norm();
  if (across_norm_n > mu * normal_n) across_n *= mu * normal_n / across_norm_n;
  const Eigen::Vector3d force = normal_n * normal + across_n;
  answer->device_force_n = force;
  answer->source = AnswerSource::kModel;
  return true;
}

MultirateAnswer MultirateAnswerer::Answer(const Eigen::Vector3d& device_translation_m) {
  MultirateAnswer answer;
  if (ModelAnswers(device_translation_m, &answer)) {
    ++model_answers_in_a_row_;
    return answer;
  }
  const StepOutput& out = session_->Step(device_translation_m);
  builder_->Linearize(*session_);
  if (parameters_.physics_every > 1) stick_builder_.Linearize(*session_);
  have_model_ = true;
  model_answers_in_a_row_ = 0;
  answer.device_force_n = out.device_force_n;
  answer.source = AnswerSource::kStep;
  return answer;
}

const char* AnswerSourceName(AnswerSource source) {
  switch (source) {
    case AnswerSource::kStep: return "step";
    case AnswerSource::kModel: return "model";
    case AnswerSource::kApart: return "apart";
  }
  return "?";
}

}  // namespace hapco::sim
