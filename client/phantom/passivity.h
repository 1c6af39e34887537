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
//
// With a local contact model four relaxations keep the damper from acting where a user feels
// it and nothing needs it (PassivityRules::ForLocalModel; all found by a helper session,
// docs/network-haptics.md). There the rendered field is passive between answers, so a debt is
// a one-off event (a new model, a server stall), not a loop generating energy on every tick:
//   - no damper while the environment asks for no force: it does no work there. (After a
//     server stall a debt kept the damper at its cap: 1.8 N of drag 3-6 mm above the surface.)
//   - a dead band: E may go down to -dead_band_j before the damper acts, and the damper brings
//     it back to -dead_band_j, not to 0.
//   - no damper below still_speed: a device held still dissipates almost nothing, and damping
//     its tremor at the cap made the force reverse tick to tick (163 times in 0.5 s of a hold
//     after a server stall, 0 without the controller; force_renderer_test.cc).
//   - a debt is forgiven with time constant debt_time_constant_s: E < 0 decays towards 0. A
//     stall left -0.01 to -0.02 J that the capped damper could not take out of a device held
//     still, so it damped for the rest of the run. Passivity then holds over windows of about
//     that time constant, not over the whole run.
// Direct rendering keeps the strict controller (PassivityRules::Strict): there the delay
// makes the loop active on every bounce, in the air too, and each relaxation let the bounce
// grow back (the delayed wall at 50 ms: 10.9 mm forgiving, 38 mm undamped in the air, against
// 2.2 mm).
#include <Eigen/Dense>

#include <limits>

namespace hapco::phantom {

struct PassivityRules {
  double dead_band_j = 0.0;                 // J, >= 0
  double still_speed_m_per_s = 0.0;         // m/s, >= 0
  double debt_time_constant_s = std::numeric_limits<double>::infinity();  // s, > 0
  bool damp_in_free_space = true;
  // Hannaford & Ryu's controller as published.
  static PassivityRules Strict() { return {}; }
  // 1e-4 J: the load tests' passivity tolerance (docs/load-and-network.md); 5 mm/s: at the
  // 25 N s/m cap the damper dissipates at most 0.6 mW below it; 0.5 s: a debt halves in
  // 0.35 s, so a stall's debt is gone within about 2 s.
  static PassivityRules ForLocalModel() { return {1e-4, 5e-3, 0.5, false}; }
};

class PassivityController {
 public:
  // max_damping_n_s_per_m > 0: the largest damper the device may add (stability of the
  // damper itself on the device, and the force limit, bound it).
  explicit PassivityController(double max_damping_n_s_per_m, const PassivityRules& rules = PassivityRules::Strict());

  // One tick: the force the environment asks for (N, on the device), the device velocity
  // (m/s) and the tick (s). Returns the force to render: the same, plus the damper if needed.
  // Damping and Account in one, for a device that renders exactly what it is given.
  Eigen::Vector3d Filter(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s, double tick_s);

  // The damper α this tick needs (N s/m; 0 when the books stay >= -dead_band with force_n, or
  // force_n is zero; at most the cap): the device adds -α v to force_n. Does not change the
  // books.
  double Damping(const Eigen::Vector3d& force_n, const Eigen::Vector3d& velocity_m_per_s, double tick_s) const;
  // The books after the tick: force_n the environment asked for, rendered_n what the device
  // rendered (with the damper, after any rate limit and clamp), alpha the damping asked for.
  void Account(const Eigen::Vector3d& force_n, const Eigen::Vector3d& rendered_n,
               const Eigen::Vector3d& velocity_m_per_s, double tick_s, double alpha_n_s_per_m);

  double energy_j() const { return energy_j_; }             // E(n) of what the device rendered, J
  double observed_energy_j() const { return observed_j_; }  // E of what the environment asked, J
  double dissipated_j() const { return dissipated_j_; }     // Σ α |v|² Δt asked of the damper, J
  double forgiven_j() const { return forgiven_j_; }         // debt forgiven by the time constant, J
  double min_energy_j() const { return min_energy_j_; }     // lowest E(n) so far, J
  long active_ticks() const { return active_ticks_; }       // ticks with α > 0
  double last_damping_n_s_per_m() const { return last_damping_; }
  void Reset();

 private:
  double max_damping_;
  PassivityRules rules_;
  double energy_j_ = 0, observed_j_ = 0, dissipated_j_ = 0, forgiven_j_ = 0, min_energy_j_ = 0, last_damping_ = 0;
  long active_ticks_ = 0;
};

}  // namespace hapco::phantom
