#include "passivity.h"

#include <algorithm>

#include "common/error.h"

namespace hapco::phantom {

PassivityController::PassivityController(double max_damping_n_s_per_m) : max_damping_(max_damping_n_s_per_m) {
  if (!(max_damping_n_s_per_m > 0)) throw InputError("passivity controller: the damping cap must be > 0 N s/m");
}

Eigen::Vector3d PassivityController::Filter(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s,
                                            double tick_s) {
  const double environment_j = -force_n.dot(velocity_m_per_s) * tick_s;  // energy into the environment
  observed_j_ += environment_j;
  const double candidate_j = energy_j_ + environment_j;
  const double speed_squared = velocity_m_per_s.squaredNorm();
  last_damping_ = 0;
  if (candidate_j >= 0 || speed_squared * tick_s <= 0) {
    energy_j_ = candidate_j;
    return force_n;
  }
  // -α v on the device puts α |v|² Δt into the hand's account: α = -E / (|v|² Δt) makes E = 0.
  last_damping_ = std::min(-candidate_j / (speed_squared * tick_s), max_damping_);
  const double damper_j = last_damping_ * speed_squared * tick_s;
  dissipated_j_ += damper_j;
  energy_j_ = candidate_j + damper_j;
  ++active_ticks_;
  return force_n - last_damping_ * velocity_m_per_s;
}

void PassivityController::Reset() {
  energy_j_ = observed_j_ = dissipated_j_ = last_damping_ = 0;
  active_ticks_ = 0;
}

}  // namespace hapco::phantom
