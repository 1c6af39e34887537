#include "render_chain.h"

namespace hapco::phantom {

RenderChain::RenderChain(const RendererParameters& renderer, const SafetyParameters& safety)
    : safety_parameters_(safety), renderer_(renderer), safety_(safety) {}

Eigen::Vector3d RenderChain::Tick(bool fresh, const Eigen::Vector3d& raw_n, const ReceivedModel& model,
                                  const Eigen::Vector3d& position_m, const Eigen::Vector3d& velocity_m_per_s,
                                  double now_s) {
  const double tick_s = safety_parameters_.tick_s;
  command_n_ = renderer_.Command(fresh, raw_n, model, position_m, velocity_m_per_s, tick_s);
  Eigen::Vector3d rendered;
  // Direct mode renders arrivals as they come (the safety filter holds them between
  // arrivals); a local model changes the command every tick.
  if (renderer_.changes_between_arrivals() && (!fresh || raw_n.allFinite())) {
    if (!fresh) safety_.Retarget(command_n_);
    rendered = safety_.Update(fresh, command_n_, now_s, renderer_.motion_change_n());
  } else {
    rendered = safety_.Update(fresh, raw_n, now_s);  // direct, or a non-finite arrival (rejected, counted)
  }
  return renderer_.Damp(rendered, velocity_m_per_s, tick_s, safety_parameters_.max_force_n);
}

}  // namespace hapco::phantom
