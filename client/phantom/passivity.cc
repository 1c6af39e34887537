#include "passivity.h"

#include <algorithm>
#include <cmath>

#include "common/error.h"

namespace hapco::phantom {

PassivityController::PassivityController(double max_damping_n_s_per_m, const PassivityRules& rules)
    : max_damping_(max_damping_n_s_per_m), rules_(rules) {
  if (!(max_damping_n_s_per_m > 0)) throw InputError("passivity controller: the damping cap must be > 0 N s/m");
  if (!(rules.dead_band_j >= 0) || !(rules.still_speed_m_per_s >= 0) || !(rules.debt_time_constant_s > 0)) {
    throw InputError("passivity controller: dead band >= 0 J, still speed >= 0 m/s, debt time constant > 0 s");
  }
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
  if (!rules_.damp_in_free_space && force_n.isZero(0.0)) return 0.0;  // the environment does no work
  const double candidate_j = energy_j_ - force_n.dot(velocity_m_per_s) * tick_s;
  const double speed_squared = velocity_m_per_s.squaredNorm();
  const double band_j = rules_.dead_band_j;
  if (candidate_j >= -band_j || !(speed_squared * tick_s > 0) ||
      speed_squared <= rules_.still_speed_m_per_s * rules_.still_speed_m_per_s) {
    return 0.0;
  }
  // -α v on the device puts α |v|² Δt into the hand's account: α = (-band - E) / (|v|² Δt)
  // brings E back to -band.
  return std::min((-band_j - candidate_j) / (speed_squared * tick_s), max_damping_);
}

void PassivityController::Account(const Eigen::Vector3d& force_n, const Eigen::Vector3d& rendered_n,
                                  const Eigen::Vector3d& velocity_m_per_s, double tick_s, double alpha_n_s_per_m) {
  observed_j_ += -force_n.dot(velocity_m_per_s) * tick_s;
  energy_j_ += -rendered_n.dot(velocity_m_per_s) * tick_s;
  min_energy_j_ = std::min(min_energy_j_, energy_j_);
  if (energy_j_ < 0 && std::isfinite(rules_.debt_time_constant_s)) {
    const double kept_j = energy_j_ * std::exp(-tick_s / rules_.debt_time_constant_s);
    forgiven_j_ += kept_j - energy_j_;
    energy_j_ = kept_j;
  }
  last_damping_ = alpha_n_s_per_m;
  if (alpha_n_s_per_m > 0) {
    dissipated_j_ += alpha_n_s_per_m * velocity_m_per_s.squaredNorm() * tick_s;
    ++active_ticks_;
  }
}

void PassivityController::Reset() {
  energy_j_ = observed_j_ = dissipated_j_ = forgiven_j_ = min_energy_j_ = last_damping_ = 0;
  active_ticks_ = 0;
}

}  // namespace hapco::phantom
