#include "phantom.h"

#include <algorithm>
#include <cmath>

#include "common/error.h"

namespace hapco::phantom {

Eigen::Vector3d Quantize(const Eigen::Vector3d& position_m, double quantum_m) {
  HAPCO_ASSERT(quantum_m > 0, "Quantize: quantum must be > 0");
  Eigen::Vector3d out;
  for (int i = 0; i < 3; ++i) out[i] = std::round(position_m[i] / quantum_m) * quantum_m;
  return out;
}

SafetyFilter::SafetyFilter(const SafetyParameters& parameters) : parameters_(parameters) {
  HAPCO_ASSERT(parameters.max_force_n > 0 && parameters.max_change_per_tick_n > 0 &&
                   parameters.timeout_s > 0 && parameters.ramp_s > 0 && parameters.tick_s > 0,
               "SafetyFilter: parameters must be > 0");
}

void SafetyFilter::Retarget(const Eigen::Vector3d& target_n) {
  if (stale_ || !have_fresh_) return;
  if (!target_n.allFinite()) {
    ++rejected_non_finite_;
    return;
  }
  target_n_ = target_n;
  const double magnitude = target_n_.norm();
  if (magnitude > parameters_.max_force_n) {
    target_n_ *= parameters_.max_force_n / magnitude;
    ++clamped_;
  }
}

Eigen::Vector3d SafetyFilter::Update(bool fresh, const Eigen::Vector3d& raw_n, double now_s) {
  return Update(fresh, raw_n, now_s, Eigen::Vector3d::Zero());
}

Eigen::Vector3d SafetyFilter::Update(bool fresh, const Eigen::Vector3d& raw_n, double now_s,
                                     const Eigen::Vector3d& motion_n) {
  if (fresh && !raw_n.allFinite()) {
    ++rejected_non_finite_;
    fresh = false;  // a NaN is no news: keep the last good target
  }
  if (fresh) {
    Eigen::Vector3d target = raw_n;
    const double magnitude = target.norm();
    if (magnitude > parameters_.max_force_n) {
      target *= parameters_.max_force_n / magnitude;
      ++clamped_;
    }
    target_n_ = target;
    last_fresh_s_ = now_s;
    have_fresh_ = true;
    stale_ = false;
  } else if (have_fresh_ && !stale_ && now_s - last_fresh_s_ > parameters_.timeout_s) {
    // Timeout: ramp from the force rendered now to zero, linear in time from the moment the
    // timeout expired (not from this tick, which may come late if the client process
    // stalled), so the force is zero by last force + timeout + ramp, always.
    // Never faster than the rate limit: at least |F| / (max_change_per_tick / tick) long.
    stale_ = true;
    ramp_start_s_ = last_fresh_s_ + parameters_.timeout_s;
    ramp_from_n_ = rendered_;
    const double rate_n_per_s = parameters_.max_change_per_tick_n / parameters_.tick_s;
    ramp_duration_s_ = std::max(parameters_.ramp_s, rendered_.norm() / rate_n_per_s);
    target_n_.setZero();
  }
  const double max_step = parameters_.max_change_per_tick_n;
  if (stale_) {
    ++stale_ticks_;
    const double remaining = 1.0 - (now_s - ramp_start_s_) / ramp_duration_s_;
    // The ramp only decreases what is rendered (never increases after a reset).
    Eigen::Vector3d ramp_n = rendered_;
    if (remaining <= 1e-9) {  // (the end of the ramp, not a rounding residue)
      ramp_n.setZero();
    } else if (rendered_.norm() > remaining * ramp_from_n_.norm()) {
      ramp_n = ramp_from_n_ * remaining;
    }
    // Still at most max_step per tick: after a stall of this process (ticks late, the motors
    // holding the last force meanwhile) the line may be far below what the hand feels, and
    // jumping to it is the click the rate limit exists to prevent. The ramp then ends up to
    // |F| / max_step ticks after the stall instead of on time.
    const Eigen::Vector3d delta = ramp_n - rendered_;
    const double delta_norm = delta.norm();
    rendered_ = delta_norm > max_step ? Eigen::Vector3d(rendered_ + delta * (max_step / delta_norm)) : ramp_n;
    return rendered_;
  }
  if (motion_n.allFinite()) rendered_ += motion_n;  // the device's own motion: not limited
  const Eigen::Vector3d delta = target_n_ - rendered_;
  const double delta_norm = delta.norm();
  if (delta_norm > max_step) {
    rendered_ += delta * (max_step / delta_norm);
  } else {
    rendered_ = target_n_;
  }
  const double magnitude = rendered_.norm();
  if (magnitude > parameters_.max_force_n) rendered_ *= parameters_.max_force_n / magnitude;
  return rendered_;
}

HandModel::HandModel(const HandParameters& parameters, const Eigen::Vector3d& start_m)
    : parameters_(parameters), position_m_(start_m) {
  HAPCO_ASSERT(parameters.device_mass_kg > 0, "HandModel: mass must be > 0");
}

const Eigen::Vector3d& HandModel::Step(const Eigen::Vector3d& target_m,
                                       const Eigen::Vector3d& target_velocity_m_per_s,
                                       const Eigen::Vector3d& rendered_force_n, double dt_s) {
  const Eigen::Vector3d force_n =
      parameters_.hand_stiffness_n_per_m * (target_m - position_m_) +
      parameters_.hand_damping_n_s_per_m * (target_velocity_m_per_s - velocity_m_per_s_) -
      parameters_.device_damping_n_s_per_m * velocity_m_per_s_ + rendered_force_n;
  velocity_m_per_s_ += dt_s / parameters_.device_mass_kg * force_n;
  position_m_ += dt_s * velocity_m_per_s_;
  return position_m_;
}

}  // namespace hapco::phantom
