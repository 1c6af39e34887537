#include "sim/multirate.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "common/error.h"

namespace hapco::sim {

namespace {

// cos 60 degrees: a turn sharper than this between steps gets a step at the turning pose.
constexpr double kTurnCosine = 0.5;


}  // namespace

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

bool MultirateAnswerer::ModelAnswers(const Eigen::Vector3d& d, MultirateAnswer* answer) {
  if (!have_model_ || model_answers_in_a_row_ + 1 >= parameters_.physics_every) return false;
  const LocalContactModel& model = builder_->model();
  const double distance_m = (d - model.device_translation_m).norm();
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
  // A tool lifted clear of the obstacle gets a step, which lets go of the contacts
  // (TwoBodySession::Release): the last step's contacts would otherwise be solved again at a
  // pose where none can hold (a helper session: 2 kN on three clear poses after a push into a
  // clamped end, 7.3 N after sliding off a side face, with --physics-every 4).
  if (!last.device_force_n.isZero() && session_->model().RigidToolClearOfObstacle(d)) return false;
  const bool answered = parameters_.between_steps == BetweenSteps::kFrozenContacts
                            ? FrozenContactsAnswer(d, &answer->device_force_n)
                            : ReturnMappingAnswers(d, &answer->device_force_n);
  if (!answered) return false;
  answer->source = AnswerSource::kModel;
  return true;
}

bool MultirateAnswerer::ReturnMappingAnswers(const Eigen::Vector3d& d, Eigen::Vector3d* force_n) const {
  const LocalContactModel& model = builder_->model();
  const LocalContactModel& trial = stick_builder_.model();
  if (!trial.stiffness_n_per_m.allFinite() || !model.device_force_n.allFinite()) return false;
  // No contact in the active set (a force of round-off): nothing to extrapolate, a step decides.
  if (trial.sticking + trial.sliding == 0) return false;
  // The trial force with every touching contact stuck, its part across the normal cut back to
  // the cone. The cone's coefficient is the scene's, or the resultant's own ratio at the step
  // when larger (contacts with different normals add up to more across than one cone), so
  // that the answer at the step's own pose is the step's force.
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
  *force_n = normal_n * normal + across_n;
  return true;
}

void MultirateAnswerer::FreezeLastStep() {
  const std::vector<StepContact>& contacts = session_->contacts();
  const int m = static_cast<int>(contacts.size());
  const contact::ContactProblem& problem = session_->last_problem();
  const contact::SolverResult& result = session_->last_result();
  if (m == 0 || problem.num_contacts() != m || result.force_n.size() != 3 * m ||
      result.displacement_m.size() != 3 * m) {
    frozen_.friction_coefficient.resize(0);  // nothing to freeze: FrozenContactsAnswer steps
    return;
  }
  frozen_.flexibility_m_per_n = problem.flexibility_m_per_n;
  frozen_.friction_coefficient = problem.friction_coefficient;
  frozen_.free_displacement_m = problem.free_displacement_m;
  // From the step's end state, not from the state before it: u = W r + ũ has the normal gap
  // absolute and the tangential part as the slip increment of the step (algorithms.md §2), so
  // the increment to a pose d starts where the step's own ended, ũ_t - u_t,k.
  step_free_m_ = problem.free_displacement_m;
  for (int alpha = 0; alpha < m; ++alpha) {
    step_free_m_.segment<2>(3 * alpha + 1) -= result.displacement_m.segment<2>(3 * alpha + 1);
  }
  step_force_n_ = result.force_n;
  FreeDisplacementPerDeviceTranslation(*session_, &free_per_device_);
  builder_->ContactForcePerDeviceTranslation(m, &force_per_device_);
  // The device force of contact forces r (local frames): gain Σ_α (Σ_p c_αp) R_αᵀ r_α over the
  // contact's tool nodes, as the step sums it (step_pipeline.cc, "Forces back to the bodies").
  const double gain = session_->model().scene().force_gain;
  device_share_.resize(static_cast<std::size_t>(m));
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& c = contacts[static_cast<std::size_t>(alpha)];
    double weight = 0.0;
    for (int k = 0; k < c.num_tool; ++k) weight += c.tool_coefficients[static_cast<std::size_t>(k)];
    device_share_[static_cast<std::size_t>(alpha)] = (gain * weight) * c.frame.transpose();
  }
  workspace_.Reserve(m, session_->parameters.max_iterations);
  result_.Reserve(m, session_->parameters.max_iterations);
}

bool MultirateAnswerer::FrozenContactsAnswer(const Eigen::Vector3d& d, Eigen::Vector3d* force_n) {
  const int m = frozen_.num_contacts();
  if (m == 0) return false;
  const Eigen::Vector3d offset_m = d - session_->last_output().device_translation_m;
  frozen_.free_displacement_m.noalias() = free_per_device_ * offset_m;
  frozen_.free_displacement_m += step_free_m_;
  // Warm start (parameters.warm_start) from the last answer's forces, one pose away, or from the
  // step's after a step, moved to this pose along the step's dr/dd: exact while every contact
  // keeps its state and sticks, so the solve mostly only confirms it: on benchmark 1's scene path
  // (K = 8) 3.9 sweeps an answer against 5.8 from the last answer's forces, 16 against 22 us.
  if (model_answers_in_a_row_ == 0 || result_.force_n.size() != step_force_n_.size()) {
    result_.force_n = step_force_n_;
    answered_pose_m_ = session_->last_output().device_translation_m;
  }
  result_.force_n.noalias() += force_per_device_ * (d - answered_pose_m_);
  answered_pose_m_ = d;
  const contact::SolverStatus status =
      contact::Solve(session_->solver, frozen_, session_->parameters, &workspace_, &result_);
  if (status != contact::SolverStatus::kConverged) return false;
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  for (int alpha = 0; alpha < m; ++alpha) {
    force.noalias() += device_share_[static_cast<std::size_t>(alpha)] * result_.force_n.segment<3>(3 * alpha);
  }
  if (!force.allFinite()) return false;
  *force_n = force;
  return true;
}

void MultirateAnswerer::StepAt(const Eigen::Vector3d& device_translation_m) {
  session_->Step(device_translation_m);
  model_answers_in_a_row_ = 0;
  // An approach's step (TwoBodySession::Step) is at a pose on the way, not at this one: no
  // model to answer this pose's neighbours from, so the next pose is stepped too.
  have_model_ = !session_->last_output().approaching;
  if (!have_model_) return;
  builder_->Linearize(*session_);
  if (parameters_.physics_every > 1) {
    if (parameters_.between_steps == BetweenSteps::kReturnMapping) {
      stick_builder_.Linearize(*session_);
    } else {
      FreezeLastStep();
    }
  }
}

MultirateAnswer MultirateAnswerer::Answer(const Eigen::Vector3d& device_translation_m) {
  MultirateAnswer answer;
  if (have_model_ && model_answers_in_a_row_ > 0) {
    // Turned since the last step (more than 60 degrees between the motion since the step and
    // the motion to this pose): step at the turning pose first (the class comment).
    const Eigen::Vector3d since_step_m = previous_pose_m_ - session_->last_output().device_translation_m;
    const Eigen::Vector3d now_m = device_translation_m - previous_pose_m_;
    if (since_step_m.dot(now_m) < kTurnCosine * since_step_m.norm() * now_m.norm()) {
      StepAt(previous_pose_m_);
      ++turn_steps_;
    }
  }
  previous_pose_m_ = device_translation_m;
  if (ModelAnswers(device_translation_m, &answer)) {
    ++model_answers_in_a_row_;
    return answer;
  }
  StepAt(device_translation_m);
  answer.device_force_n = session_->last_output().device_force_n;
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
