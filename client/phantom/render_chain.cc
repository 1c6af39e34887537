#include "render_chain.h"

namespace hapco::phantom {

RenderChain::RenderChain(const RendererParameters& renderer, const SafetyParameters& safety)
    : safety_parameters_(safety), renderer_(renderer), safety_(safety) {}

Eigen::Vector3d RenderChain::Tick(bool fresh, const Eigen::Vector3d& raw_n, const ReceivedModel& model,
                                  const Eigen::Vector3d& position_m, const Eigen::Vector3d& velocity_m_per_s,
                                  double now_s) {
  const double tick_s = safety_parameters_.tick_s;
  command_n_ = renderer_.Command(fresh, raw_n, model, position_m, velocity_m_per_s, tick_s);
  // The passivity damper joins the command before the safety filter: its changes are rate
  // limited and the sum clamped like any other force (after the filter it flipped up to 2.2 N
  // tick to tick; docs/network-haptics.md). Zero without --passivity.
  // Not during a timeout ramp, which renders no target: a damper asked for there is never
  // rendered (it was counted as dissipated all the same).
  const Eigen::Vector3d damper_n =
      safety_.stale() ? Eigen::Vector3d::Zero() : renderer_.PassivityDamper(command_n_, velocity_m_per_s, tick_s);
  Eigen::Vector3d rendered;
  // A local model changes the command every tick, and so does a damper; direct rendering
  // without one renders arrivals as they come (the safety filter holds them between arrivals).
  const bool every_tick = renderer_.changes_between_arrivals() || renderer_.parameters().passivity;
  if (every_tick && (!fresh || raw_n.allFinite())) {
    const Eigen::Vector3d target_n = command_n_ + damper_n;
    if (!fresh) safety_.Retarget(target_n);
    rendered = safety_.Update(fresh, target_n, now_s, renderer_.motion_change_n());
  } else {
    rendered = safety_.Update(fresh, raw_n, now_s);  // direct, or a non-finite arrival (rejected, counted)
  }
  renderer_.AccountRendered(command_n_, rendered, velocity_m_per_s, tick_s);
  return rendered;
}

}  // namespace hapco::phantom
