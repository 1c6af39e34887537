#include "force_renderer.h"

#include <algorithm>
#include <cmath>

#include "common/error.h"

namespace hapco::phantom {

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
    : parameters_(parameters), passivity_(parameters.max_damping_n_s_per_m) {
  HAPCO_ASSERT(parameters.max_stiffness_n_per_m > 0 && parameters.max_extrapolation_m >= 0 &&
                   parameters.blend_ticks >= 1,
               "ForceRenderer: bad parameters");
}

Eigen::Vector3d ForceRenderer::Evaluate(const ActiveModel& active, const Eigen::Vector3d& position_m, bool count) {
  if (!active.valid) return active.force_n;  // no contact model: the force as it came
  const ReceivedModel& m = active.model;
  Eigen::Vector3d offset = position_m - m.position_m;
  const double distance = offset.norm();
  if (distance > parameters_.max_extrapolation_m) {
    offset *= parameters_.max_extrapolation_m / distance;
    if (count) ++stats_.extrapolation_capped;
  }
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
  const double at_pose_normal = active.force_n.dot(m.normal);
  const double at_pose_ratio =
      at_pose_normal > 0.0 ? (active.force_n - at_pose_normal * m.normal).norm() / at_pose_normal : 0.0;
  const double limit = std::max(m.friction_coefficient, at_pose_ratio) * normal_n;
  const double tangential_n = tangential.norm();
  if (tangential_n > limit) {
    tangential *= limit / tangential_n;
    if (count) ++stats_.cone_limited;
  }
  return normal_n * m.normal + tangential;
}

Eigen::Vector3d ForceRenderer::Command(bool fresh, const Eigen::Vector3d& force_n, const ReceivedModel& model,
                                       const Eigen::Vector3d& position_m, const Eigen::Vector3d& /*velocity_m_per_s*/,
                                       double /*tick_s*/) {
  const bool force_ok = fresh && force_n.allFinite();
  if (force_ok) held_force_n_ = force_n;
  Eigen::Vector3d command = held_force_n_;
  if (parameters_.mode == RenderMode::kLocalModel) {
    if (force_ok) {
      ActiveModel next;
      next.force_n = force_n;
      next.valid = model.valid && model.position_m.allFinite() && model.stiffness_n_per_m.allFinite() &&
                   model.normal.allFinite() && std::abs(model.normal.norm() - 1.0) < 1e-6 &&
                   std::isfinite(model.friction_coefficient) && model.friction_coefficient >= 0.0;
      if (next.valid) {
        next.model = model;
        ++stats_.models_received;
        // The stiffness the device can render: scaled, direction kept.
        const double largest = model.stiffness_n_per_m.jacobiSvd().singularValues()(0);
        if (largest > parameters_.max_stiffness_n_per_m) {
          next.model.stiffness_n_per_m *= parameters_.max_stiffness_n_per_m / largest;
          ++stats_.stiffness_capped;
        }
      }
      // An answer without a model (no contact at the pose it answered) that the current model
      // agrees with (it gives no force there either: that pose was outside its surface) keeps
      // the model: it still knows where the surface is when the device comes back to it,
      // before the server's answer for that can arrive. Otherwise the model is dropped.
      const bool agrees = !next.valid && current_.valid && model.position_m.allFinite() &&
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
    if (last_position_m_.allFinite() && (current_.valid || previous_.valid)) {
      motion_change_n_ = command - blended(last_position_m_, false);
    }
    if (blend_tick_ < parameters_.blend_ticks) ++blend_tick_;
    if (current_.valid) ++stats_.model_ticks;
  }
  last_position_m_ = position_m;
  return command;
}

Eigen::Vector3d ForceRenderer::Damp(const Eigen::Vector3d& rendered_n, const Eigen::Vector3d& velocity_m_per_s,
                                    double tick_s, double max_force_n) {
  if (!parameters_.passivity) return rendered_n;
  Eigen::Vector3d out = passivity_.Filter(rendered_n, velocity_m_per_s, tick_s);
  const double magnitude = out.norm();
  if (magnitude > max_force_n) out *= max_force_n / magnitude;
  return out.allFinite() ? out : rendered_n;
}

}  // namespace hapco::phantom
