#pragma once
// One servo tick of what a device renders from the network's arrivals, in the order the
// device needs it (docs/network-haptics.md): the renderer (the newest force, or a local model
// at the current position) -> the safety filter (7.9 N, 250 N/s beyond the model's response to
// the device's own motion, the timeout ramp), with the passivity controller's damper (which
// only takes energy out) joining the command before the filter so it is rate limited too.
// hapco-phantom, hapco-loadtest and the offline network study (network_haptics_study) all
// render through this, so what is measured offline is what the clients do.
#include <Eigen/Dense>

#include "force_renderer.h"
#include "phantom.h"

namespace hapco::phantom {

class RenderChain {
 public:
  RenderChain(const RendererParameters& renderer, const SafetyParameters& safety);

  // fresh: a stepped force arrived this tick (raw_n as received, possibly non-finite; model
  // the one it carries). now_s: monotonic time of the tick, s. Returns the force to render, N.
  Eigen::Vector3d Tick(bool fresh, const Eigen::Vector3d& raw_n, const ReceivedModel& model,
                       const Eigen::Vector3d& position_m, const Eigen::Vector3d& velocity_m_per_s, double now_s);

  const Eigen::Vector3d& command_n() const { return command_n_; }  // the renderer's, before the limits
  const ForceRenderer& renderer() const { return renderer_; }
  const SafetyFilter& safety() const { return safety_; }

 private:
  SafetyParameters safety_parameters_;
  ForceRenderer renderer_;
  SafetyFilter safety_;
  Eigen::Vector3d command_n_ = Eigen::Vector3d::Zero();
};

}  // namespace hapco::phantom
