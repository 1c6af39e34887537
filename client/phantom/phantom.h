#pragma once
// The device side of hapco-phantom, free of DDS so it can be unit-tested: position
// quantisation (an encoder), a hand that drags the device along a target path, and the force
// safety filter that stands between the network and the motors. SI units throughout.
#include <Eigen/Dense>

#include <cstdint>
#include <vector>

namespace hapco::phantom {

// Position resolution of the simulated device's encoders, m (0.023 mm, a Phantom-class arm).
inline constexpr double kPositionQuantumM = 0.023e-3;

// Nearest multiple of quantum_m per axis (quantum_m > 0).
Eigen::Vector3d Quantize(const Eigen::Vector3d& position_m, double quantum_m = kPositionQuantumM);

// Force safety between the received force and the motors, applied once per servo tick.
// Why: the network may deliver a NaN, an absurd value, a step, or nothing at all; none of
// these may reach the hand (design.md, "never trusted input").
struct SafetyParameters {
  double max_force_n = 7.9;       // magnitude clamp: the device's peak continuous force, N
  // Largest change of the rendered force vector per tick, N. 0.25 N/tick = 250 N/s at 1 kHz:
  // 0 -> 7.9 N in 32 ms, slow enough to avoid a felt "click", fast enough for contact onset.
  double max_change_per_tick_n = 0.25;
  double timeout_s = 0.050;       // no new force for longer than this -> ramp to zero
  // Duration of that ramp from the force at timeout to zero, s: linear in time from the
  // timeout's expiry (zero at a known time while the ticks run), at least |F| / (250 N/s) so
  // it respects the rate limit (7.9 N -> 31.6 ms). Ticks that come late (this process stalled)
  // still change the force by at most max_change_per_tick_n each: never a jump.
  double ramp_s = 0.020;
  double tick_s = 0.001;          // servo period, s
  // An answer to a pose sampled longer ago than this is not rendered, s. After a link outage
  // the network delivered answers to poses 3 s old: the device, lifted meanwhile, rendered
  // 1.5-2 N in free air for 11-15 ticks as "forces resumed" (a helper session). 0.5 s is
  // above the round trips HapCo is documented for (200 ms, docs/network-haptics.md).
  double max_answer_age_s = 0.5;
};

class SafetyFilter {
 public:
  explicit SafetyFilter(const SafetyParameters& parameters = {});

  // One tick at time now_s (monotonic, s). `fresh` = a new force sample arrived this tick
  // with value raw_n (may be NaN/Inf: then it is ignored and counted). Returns the force to
  // render, N: finite, |F| <= max_force_n, |F - previous| <= max_change_per_tick_n on every
  // tick, late ticks and the timeout ramp included.
  Eigen::Vector3d Update(bool fresh, const Eigen::Vector3d& raw_n, double now_s);
  // The same, where motion_n of the change is explained by the device's own motion through
  // a local contact model (force_renderer.h: F_model(x_now) - F_model(x_before), a spring of at
  // most the renderer's stiffness cap): that part is not rate limited (a stiff wall must push
  // back as fast as the hand moves into it), the rest is; the magnitude clamp holds for all.
  // motion_n = 0 is Update above.
  Eigen::Vector3d Update(bool fresh, const Eigen::Vector3d& raw_n, double now_s, const Eigen::Vector3d& motion_n);

  // A new target between arrivals (a local model evaluated at the current position, or a
  // passivity damper: force_renderer.h), taken by the next Update(false, ...): clamped like a
  // fresh force, but it does not restart the timeout (only arrivals prove the server is
  // there) and it is ignored during a timeout ramp and before the first force. A non-finite
  // target is ignored and counted.
  void Retarget(const Eigen::Vector3d& target_n);

  bool stale() const { return stale_; }            // currently in (or after) a timeout ramp
  uint64_t rejected_non_finite() const { return rejected_non_finite_; }
  uint64_t clamped() const { return clamped_; }
  uint64_t stale_ticks() const { return stale_ticks_; }
  const Eigen::Vector3d& rendered() const { return rendered_; }

 private:
  SafetyParameters parameters_;
  Eigen::Vector3d target_n_ = Eigen::Vector3d::Zero();    // last good (clamped) force
  Eigen::Vector3d rendered_ = Eigen::Vector3d::Zero();
  double last_fresh_s_ = 0.0;
  bool have_fresh_ = false;
  bool stale_ = false;
  double ramp_start_s_ = 0.0, ramp_duration_s_ = 0.0;       // the timeout ramp, s
  Eigen::Vector3d ramp_from_n_ = Eigen::Vector3d::Zero();  // force when it began, N
  uint64_t rejected_non_finite_ = 0, clamped_ = 0, stale_ticks_ = 0;
};

// A hand holding the device: a spring-damper between the hand (which follows the target
// path exactly) and the device mass, plus viscous damping of the device's own mechanism.
//   m a = k_h (x_target - x) + c_h (v_target - v) - c_d v + F_rendered
// Semi-implicit Euler at the servo period (stable: dt * sqrt(k_h/m) = 0.08 << 2).
struct HandParameters {
  double device_mass_kg = 0.05;                 // effective mass at the tip of a Phantom arm
  double hand_stiffness_n_per_m = 300.0;        // a relaxed grip
  double hand_damping_n_s_per_m = 6.0;          // ~0.8 of critical (2 sqrt(k m) = 7.7)
  double device_damping_n_s_per_m = 0.5;        // mechanism friction, viscous model
};

class HandModel {
 public:
  explicit HandModel(const HandParameters& parameters = {},
                     const Eigen::Vector3d& start_m = Eigen::Vector3d::Zero());
  // Advances dt_s toward target_m (moving at target_velocity_m_per_s) with the force the
  // device renders on the hand, which pushes the device back. Returns the device position.
  const Eigen::Vector3d& Step(const Eigen::Vector3d& target_m,
                              const Eigen::Vector3d& target_velocity_m_per_s,
                              const Eigen::Vector3d& rendered_force_n, double dt_s);
  const Eigen::Vector3d& position_m() const { return position_m_; }
  const Eigen::Vector3d& velocity_m_per_s() const { return velocity_m_per_s_; }

 private:
  HandParameters parameters_;
  Eigen::Vector3d position_m_;
  Eigen::Vector3d velocity_m_per_s_ = Eigen::Vector3d::Zero();
};

}  // namespace hapco::phantom
