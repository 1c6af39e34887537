#include "force_renderer.h"

#include <algorithm>
#include <cmath>

#include "common/error.h"

namespace hapco::phantom {
namespace {

// Rows n, t1, t2: n and any two unit vectors completing it to a right-handed orthonormal frame.
Eigen::Matrix3d TangentFrame(const Eigen::Vector3d& n) {
  const Eigen::Vector3d seed = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = (seed - seed.dot(n) * n).normalized();
  Eigen::Matrix3d frame;
  frame.row(0) = n.transpose();
  frame.row(1) = t1.transpose();
  frame.row(2) = n.cross(t1).transpose();
  return frame;
}

}  // namespace

bool ParseRenderMode(std::string_view name, RenderMode* mode) {
  if (name == "direct") {
    *mode = RenderMode::kDirect;
  } else if (name == "local-model") {
    *mode = RenderMode::kLocalModel;
  } else {
    return false;
  }
  return true;
}

const char* RenderModeName(RenderMode mode) { return mode == RenderMode::kDirect ? "direct" : "local-model"; }

bool ParseRendering(std::string_view name, bool hand_held, RendererParameters* parameters) {
  if (name == "auto") name = hand_held ? "local-model+passivity" : "direct";
  constexpr std::string_view kPassivity = "+passivity";
  const bool passivity = name.size() > kPassivity.size() && name.substr(name.size() - kPassivity.size()) == kPassivity;
  if (passivity) name.remove_suffix(kPassivity.size());
  if (!ParseRenderMode(name, &parameters->mode)) return false;
  parameters->passivity = passivity;
  return true;
}

std::string RenderingName(const RendererParameters& parameters) {
  return std::string(RenderModeName(parameters.mode)) + (parameters.passivity ? "+passivity" : "");
}

ForceRenderer::ForceRenderer(const RendererParameters& parameters)
    : parameters_(parameters),
      // Relaxed rules only with a local model (passivity.h).
      passivity_(parameters.max_damping_n_s_per_m, parameters.mode == RenderMode::kLocalModel
                                                       ? parameters.local_model_passivity
                                                       : PassivityRules::Strict()) {
  HAPCO_ASSERT(parameters.max_stiffness_n_per_m > 0 && parameters.max_extrapolation_m >= 0 &&
                   parameters.blend_ticks >= 1,
               "ForceRenderer: bad parameters");
}

Eigen::Vector3d ForceRenderer::Evaluate(const ActiveModel& active, const Eigen::Vector3d& position_m, bool count) {
  if (active.kind == ModelKind::kNone) return active.force_n;  // no model: the force as it came
  const ReceivedModel& m = active.model;
  Eigen::Vector3d offset = position_m - m.position_m;
  const double distance = offset.norm();
  if (active.kind == ModelKind::kSurface) {
    // The plane ahead: nothing beyond its reach (the server looked no farther), a spring of
    // the rendered contact stiffness once the device is through it.
    if (distance > parameters_.max_surface_extrapolation_m) return Eigen::Vector3d::Zero();
    const double gap_m = m.surface_gap_m + m.surface_normal.dot(offset);
    if (gap_m >= 0.0) return Eigen::Vector3d::Zero();
    if (count) ++stats_.surface_ticks;
    return (-gap_m * active.surface_stiffness_n_per_m) * m.surface_normal;
  }
  if (distance > parameters_.max_extrapolation_m) {
    offset *= parameters_.max_extrapolation_m / distance;
    if (count) ++stats_.extrapolation_capped;
  }
  if (parameters_.contact_rendering == ContactRendering::kPlane) {
    // The contact's plane: its normal force at x0, its normal stiffness (scaled whole to the
    // cap), nothing across (the device's own friction adds that in Command).
    const double normal_n = active.scale * (active.force_n.dot(m.normal) - active.normal_stiffness_n_per_m *
                                                                                m.normal.dot(offset));
    if (!(normal_n > 0.0)) {
      if (count) ++stats_.pull_prevented;
      return Eigen::Vector3d::Zero();
    }
    return normal_n * m.normal;
  }
  // The linear model (the first version): F0 + K (x - x0), K capped by its stiffest direction.
  const Eigen::Vector3d force = active.force_n + m.stiffness_n_per_m * offset;
  // Contacts only push: nothing against the resultant normal (the model's contacts open).
  const double normal_n = force.dot(m.normal);
  if (!(normal_n > 0.0)) {
    if (count) ++stats_.pull_prevented;
    return Eigen::Vector3d::Zero();
  }
  // Coulomb on the resultant: the tangential part within μ times the normal part (or within
  // the server's own ratio at x0, which the limit must never change).
  Eigen::Vector3d tangential = force - normal_n * m.normal;
  const double limit = FrictionLimit(active) * normal_n;
  const double tangential_n = tangential.norm();
  if (tangential_n > limit) {
    tangential *= limit / tangential_n;
    if (count) ++stats_.cone_limited;
  }
  return normal_n * m.normal + tangential;
}

double ForceRenderer::FrictionLimit(const ActiveModel& active) {
  // μ, or the server's own ratio at x0 when larger (an edge contact can tilt the resultant).
  const ReceivedModel& m = active.model;
  const double at_pose_normal = active.force_n.dot(m.normal);
  const double at_pose_ratio =
      at_pose_normal > 0.0 ? (active.force_n - at_pose_normal * m.normal).norm() / at_pose_normal : 0.0;
  return std::max(m.friction_coefficient, at_pose_ratio);
}

Eigen::Vector3d ForceRenderer::LocalFriction(const Eigen::Vector3d& normal_force_n, const Eigen::Vector3d& position_m,
                                             Eigen::Vector3d* at_last_position_n) {
  at_last_position_n->setZero();
  const ActiveModel* contact = current_.kind == ModelKind::kContact    ? &current_
                               : previous_.kind == ModelKind::kContact ? &previous_
                                                                       : nullptr;
  const double normal_n = contact != nullptr ? normal_force_n.dot(contact->model.normal) : 0.0;
  if (contact == nullptr || !(normal_n > 0.0)) {
    anchor_valid_ = false;  // out of contact: the next contact sticks where it begins
    return Eigen::Vector3d::Zero();
  }
  const ReceivedModel& m = contact->model;
  const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - m.normal * m.normal.transpose();
  // Before any sticking contact: the normal stiffness, else the cap.
  const double k = tangential_stiffness_n_per_m_ > 0.0    ? tangential_stiffness_n_per_m_
                   : last_normal_stiffness_n_per_m_ > 0.0 ? last_normal_stiffness_n_per_m_
                                                          : parameters_.max_stiffness_n_per_m;
  if (!anchor_valid_) {
    // Continuity: the anchor where the spring gives the model's own tangential force here.
    const Eigen::Vector3d offset = position_m - m.position_m;
    const Eigen::Vector3d model_force = contact->force_n + m.stiffness_n_per_m * offset;
    Eigen::Vector3d tangential = across * model_force;
    const double limit = FrictionLimit(*contact) * normal_n;
    if (tangential.norm() > limit) tangential *= limit / tangential.norm();
    anchor_m_ = position_m + tangential / k;
    anchor_valid_ = true;
  }
  Eigen::Vector3d spring = -k * (across * (position_m - anchor_m_));
  const double limit = FrictionLimit(*contact) * normal_n;
  // What the same law gave at the last tick's position from the anchor as it was, before this
  // tick's slip (for motion_change_n): while sticking, the spring's -k dx is the device's own
  // motion; while slipping, the force stays at the cone's edge and the motion changes nothing.
  // (Through the slipped anchor it read -k dx on every slipping tick, which the safety filter
  // let through on top of its rate limit: a drag that grew without bound during a slide.)
  if (last_position_m_.allFinite()) {
    Eigen::Vector3d before = -k * (across * (last_position_m_ - anchor_m_));
    if (before.norm() > limit) before *= limit / before.norm();
    *at_last_position_n = before;
  }
  const double magnitude = spring.norm();
  if (magnitude > limit) {
    // Slip: the anchor follows the device so the spring holds the cone's edge (Coulomb).
    spring *= limit / magnitude;
    anchor_m_ = position_m + spring / k;
    ++stats_.cone_limited;
  }
  return spring;
}

ForceRenderer::ActiveModel ForceRenderer::Take(const Eigen::Vector3d& force_n, const ReceivedModel& model) {
  ActiveModel next;
  next.force_n = force_n;
  const bool contact = model.valid && model.position_m.allFinite() && model.stiffness_n_per_m.allFinite() &&
                       model.normal.allFinite() && std::abs(model.normal.norm() - 1.0) < 1e-6 &&
                       std::isfinite(model.friction_coefficient) && model.friction_coefficient >= 0.0;
  if (contact) {
    next.kind = ModelKind::kContact;
    next.model = model;
    ++stats_.models_received;
    // Stiffness along the contact's normal (a push: F grows along n as x moves along -n).
    const double normal_k = std::max(0.0, -model.normal.dot(model.stiffness_n_per_m * model.normal));
    const double cap = parameters_.max_stiffness_n_per_m;
    if (parameters_.contact_rendering == ContactRendering::kPlane) {
      // Normal: the whole normal part scaled to the cap (header). Across: the device's own
      // friction, whose spring is the contact's tangential stiffness while it sticks (sliding
      // contacts have none: the last sticking value stays), capped.
      next.normal_stiffness_n_per_m = normal_k;
      if (normal_k > cap) next.scale = cap / normal_k;
      const Eigen::Matrix3d frame = TangentFrame(model.normal);  // rows n, t1, t2
      const Eigen::Matrix2d across =
          (frame * model.stiffness_n_per_m * frame.transpose()).bottomRightCorner<2, 2>();
      const double tangential_k = across.jacobiSvd().singularValues()(0);
      if (tangential_k > 0.1 * normal_k) tangential_stiffness_n_per_m_ = std::min(tangential_k, cap);
      if (normal_k > cap || tangential_k > cap) ++stats_.stiffness_capped;
      if (normal_k > 0.0) last_normal_stiffness_n_per_m_ = std::min(normal_k, cap);
      return next;
    }
    // The first version: the stiffness alone, by its stiffest direction (header).
    const double largest = model.stiffness_n_per_m.jacobiSvd().singularValues()(0);
    if (largest > cap) {
      next.model.stiffness_n_per_m *= cap / largest;
      ++stats_.stiffness_capped;
    }
    const double rendered_normal_k = -model.normal.dot(next.model.stiffness_n_per_m * model.normal);
    if (rendered_normal_k > 0.0) last_normal_stiffness_n_per_m_ = std::min(rendered_normal_k, cap);
    return next;
  }
  const bool surface = parameters_.surface_ahead && !model.valid && model.surface_ahead &&
                       model.position_m.allFinite() && std::isfinite(model.surface_gap_m) &&
                       model.surface_gap_m >= 0.0 && model.surface_normal.allFinite() &&
                       std::abs(model.surface_normal.norm() - 1.0) < 1e-6;
  if (surface) {
    next.kind = ModelKind::kSurface;
    next.model = model;
    next.surface_stiffness_n_per_m =
        last_normal_stiffness_n_per_m_ > 0.0 ? last_normal_stiffness_n_per_m_ : parameters_.max_stiffness_n_per_m;
    ++stats_.surfaces_received;
  }
  return next;
}

Eigen::Vector3d ForceRenderer::Command(bool fresh, const Eigen::Vector3d& force_n, const ReceivedModel& model,
                                       const Eigen::Vector3d& position_m, const Eigen::Vector3d& /*velocity_m_per_s*/,
                                       double /*tick_s*/) {
  const bool force_ok = fresh && force_n.allFinite();
  if (force_ok) held_force_n_ = force_n;
  Eigen::Vector3d command = held_force_n_;
  if (parameters_.mode == RenderMode::kLocalModel) {
    if (force_ok) {
      ActiveModel next = Take(force_n, model);
      // An answer without a contact model (no contact at the pose it answered) that the
      // contact model in use agrees with (it gives no force there either: that pose was
      // outside its surface) keeps that model: it still knows where the surface is and how
      // stiff, when the device comes back to it before the server's answer for that can
      // arrive. Otherwise the answer's model (a surface ahead, or none) replaces it.
      // A surface ahead is kept the same way by an answer that carries nothing (the surface
      // is farther than the server looks), and replaced by a newer surface ahead.
      const bool keepable = (next.kind == ModelKind::kSurface && current_.kind == ModelKind::kContact) ||
                            (next.kind == ModelKind::kNone && current_.valid());
      const bool agrees = keepable && model.position_m.allFinite() &&
                          Evaluate(current_, model.position_m, /*count=*/false).isZero();
      if (!agrees) {
        previous_ = current_;
        current_ = next;
        blend_tick_ = 0;
      } else {
        ++stats_.models_kept;
      }
    }
    const int blend = blend_tick_;
    const auto blended = [&](const Eigen::Vector3d& x, bool count) -> Eigen::Vector3d {
      const Eigen::Vector3d now = Evaluate(current_, x, count);
      if (blend >= parameters_.blend_ticks) return now;
      const double a = static_cast<double>(blend + 1) / parameters_.blend_ticks;
      return (1.0 - a) * Evaluate(previous_, x, count) + a * now;
    };
    command = blended(position_m, true);
    // What the motion since the last tick explains, through this tick's (blended) model: the
    // change a new model brings at the same position is not motion, and stays rate limited
    // by the safety filter.
    motion_change_n_.setZero();
    const bool modelled = current_.valid() || previous_.valid();
    if (last_position_m_.allFinite() && modelled) motion_change_n_ = command - blended(last_position_m_, false);
    if (parameters_.contact_rendering == ContactRendering::kPlane) {
      Eigen::Vector3d friction_before = Eigen::Vector3d::Zero();
      const Eigen::Vector3d friction = LocalFriction(command, position_m, &friction_before);
      command += friction;
      if (last_position_m_.allFinite() && modelled) motion_change_n_ += friction - friction_before;
    }
    // The safety filter lets this part through unlimited on the promise that it is a spring
    // of at most the stiffness cap. A field with an edge breaks that promise: the surface
    // ahead ends 10 mm from the pose it answered, and a device 2 mm under it crossing that
    // edge went 0 -> 6 N (7.9 N, the clamp) in one tick (a helper session, 200 ms round trip).
    // Beyond the cap's spring the change is rate limited like any other.
    if (last_position_m_.allFinite()) {
      const double spring_n = parameters_.max_stiffness_n_per_m * (position_m - last_position_m_).norm();
      const double motion_n = motion_change_n_.norm();
      if (motion_n > spring_n) motion_change_n_ *= spring_n / motion_n;
    }
    if (blend_tick_ < parameters_.blend_ticks) ++blend_tick_;
    if (current_.kind == ModelKind::kContact) ++stats_.model_ticks;
  }
  last_position_m_ = position_m;
  return command;
}

Eigen::Vector3d ForceRenderer::PassivityDamper(const Eigen::Vector3d& command_n,
                                               const Eigen::Vector3d& velocity_m_per_s, double tick_s) {
  passivity_alpha_n_s_per_m_ = 0.0;
  if (!parameters_.passivity || !command_n.allFinite() || !velocity_m_per_s.allFinite()) return Eigen::Vector3d::Zero();
  passivity_alpha_n_s_per_m_ = passivity_.Damping(command_n, velocity_m_per_s, tick_s);
  return -passivity_alpha_n_s_per_m_ * velocity_m_per_s;
}

void ForceRenderer::AccountRendered(const Eigen::Vector3d& command_n, const Eigen::Vector3d& rendered_n,
                                    const Eigen::Vector3d& velocity_m_per_s, double tick_s) {
  const double alpha = passivity_alpha_n_s_per_m_;
  passivity_alpha_n_s_per_m_ = 0.0;  // asked for this tick only
  if (!parameters_.passivity || !command_n.allFinite() || !velocity_m_per_s.allFinite()) return;
  passivity_.Account(command_n, rendered_n, velocity_m_per_s, tick_s, alpha);
}

}  // namespace hapco::phantom
