#include "passivity.h"

#include <algorithm>

#include "common/error.h"

namespace hapco::phantom {

PassivityController::PassivityController(double max_damping_n_s_per_m) : max_damping_(max_damping_n_s_per_m) {
  if (!(max_damping_n_s_per_m > 0)) throw InputError("passivity controller: the damping cap must be > 0 N s/m");
}

Eigen::Vector3d PassivityController::Filter(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s,
                                            double tick_s) {
  const double alpha = Damping(force_n, velocity_m_per_s, tick_s);
  const Eigen::Vector3d rendered = force_n - alpha * velocity_m_per_s;
  Account(force_n, rendered, velocity_m_per_s, tick_s, alpha);
  return rendered;
}

double PassivityController::Damping(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s,
                                    double tick_s) const {
  const double candidate_j = energy_j_ - force_n.dot(velocity_m_per_s) * tick_s;
  const double speed_squared = velocity_m_per_s.squaredNorm();
  if (candidate_j >= 0 || !(speed_squared * tick_s > 0)) return 0.0;
  // -α v on the device puts α |v|² Δt into the hand's account: α = -E / (|v|² Δt) makes E = 0.
  return std::min(-candidate_j / (speed_squared * tick_s), max_damping_);
}

void PassivityController::Account(const Eigen::Vector3d& force_n, const Eigen::Vector3d& rendered_n,
                                  const Eigen::Vector3d& velocity_m_per_s, double tick_s, double alpha_n_s_per_m) {
  observed_j_ += -force_n.dot(velocity_m_per_s) * tick_s;
  energy_j_ += -rendered_n.dot(velocity_m_per_s) * tick_s;
  last_damping_ = alpha_n_s_per_m;
  if (alpha_n_s_per_m > 0) {
    dissipated_j_ += alpha_n_s_per_m * velocity_m_per_s.squaredNorm() * tick_s;
    ++active_ticks_;
  }
}

void PassivityController::Reset() {
  energy_j_ = observed_j_ = dissipated_j_ = last_damping_ = 0;
  active_ticks_ = 0;
}

}  // namespace hapco::phantom
