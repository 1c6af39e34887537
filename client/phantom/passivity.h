#pragma once
// Time-domain passivity observer and controller (Hannaford & Ryu, IEEE Trans. Robotics and
// Automation 18(1), 2002; Ryu, Kwon & Hannaford 2004), for a device rendering forces that come
// from a remote, delayed environment (issue 12, item 2). The observer sums the energy the
// hand has put into the environment, E(n) = E(n-1) - f(n)·v(n) Δt (the loadtest's
// convention, loadtest_metrics.h: a passive environment keeps E >= 0); when the next tick
// would make E negative, the controller adds a damper -α v, with α just large enough to bring
// E back to 0 (capped at max_damping), so the device dissipates exactly the energy the delay
// generated and nothing when the environment is passive. No model of the environment needed.
//
// On a device the damper goes through the safety filter's rate limit (render_chain.h): the
// controller asks for α (Damping), the device renders what the filter lets through, and the
// books take that (Account). An energy debt the rate limit or the force clamp left is paid on
// the next ticks, so the damper never adds a jump (a helper session saw it flip 0.07 <-> 2.2 N
// tick to tick at the old cap of 2 m/T, the explicit damper's stability limit;
// docs/network-haptics.md, "The passivity controller's chatter").
#include <Eigen/Dense>

namespace hapco::phantom {

class PassivityController {
 public:
  // max_damping_n_s_per_m > 0: the largest damper the device may add (stability of the
  // damper itself on the device, and the force limit, bound it).
  explicit PassivityController(double max_damping_n_s_per_m);

  // One tick: the force the environment asks for (N, on the device), the device velocity
  // (m/s) and the tick (s). Returns the force to render: the same, plus the damper if needed.
  // Damping and Account in one, for a device that renders exactly what it is given.
  Eigen::Vector3d Filter(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s, double tick_s);

  // The damper α this tick needs (N s/m, 0 when the books stay >= 0 with force_n, at most
  // the cap): the device adds -α v to force_n. Does not change the books.
  double Damping(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s, double tick_s) const;
  // The books after the tick: force_n the environment asked for, rendered_n what the device
  // rendered (with the damper, after any rate limit and clamp), alpha the damping asked for.
  void Account(const Eigen::Vector3d& force_n, const Eigen::Vector3d& rendered_n,
               const Eigen::Vector3d& velocity_m_per_s, double tick_s, double alpha_n_s_per_m);

  double energy_j() const { return energy_j_; }             // E(n) of what the device rendered, J
  double observed_energy_j() const { return observed_j_; }  // E of what the environment asked, J
  double dissipated_j() const { return dissipated_j_; }     // Σ α |v|² Δt asked of the damper, J
  double max_damping_n_s_per_m() const { return max_damping_; }
  long active_ticks() const { return active_ticks_; }       // ticks with α > 0
  double last_damping_n_s_per_m() const { return last_damping_; }
  void Reset();

 private:
  double max_damping_;
  double energy_j_ = 0, observed_j_ = 0, dissipated_j_ = 0, last_damping_ = 0;
  long active_ticks_ = 0;
};

}  // namespace hapco::phantom
