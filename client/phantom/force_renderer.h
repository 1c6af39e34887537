#pragma once
// What a device renders each servo tick from the forces that arrive over the network (issue 12,
// docs/network-haptics.md), before the safety filter (phantom.h) applies the device's limits:
//
//   direct       the newest force, held until the next one (as the paper's client does);
//   local-model  the newest local contact model (FeedbackForce.model, sim/local_model.h)
//                evaluated at the device's *current* position every tick: F0 + K (x - x0), so
//                the stiffness the hand feels is the contact's, not a stale force's (model-
//                mediated teleoperation: Mitra & Niemeyer 2008; Schuwerk et al., WHC 2015);
//   + passivity  either of them, then the time-domain passivity controller (passivity.h) on
//                what the safety filter lets through: damping exactly when the energy the
//                device has received goes negative (a delay generating energy).
//
// The model is used within bounds the network cannot break: its stiffness is scaled down to
// what the device can render stably (max_stiffness_n_per_m), it is evaluated at most
// max_extrapolation_m from the pose it answered, it never pulls (contacts only push: no force
// against its normal) and its part across the normal stays in the Coulomb cone of the scene's
// friction coefficient. A new model takes over from the previous one over blend_ticks ticks,
// so switching models never makes the force jump. An answer "no contact" at a pose where the
// model gives no force either keeps the model: it still holds the surface where the device
// will meet it again (the server's answer for that pose is a round trip away); an answer that
// contradicts the model (no contact where it pushes) drops it.
#include <Eigen/Dense>

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "passivity.h"

namespace hapco::phantom {

enum class RenderMode { kDirect, kLocalModel };

// "direct", "local-model"; false for anything else.
bool ParseRenderMode(std::string_view name, RenderMode* mode);
const char* RenderModeName(RenderMode mode);

// FeedbackForce.model as received (scene frame, SI units).
struct ReceivedModel {
  bool valid = false;  // stiffness, normal and friction are meaningful
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();        // the pose it answered, m (also when not valid)
  Eigen::Matrix3d stiffness_n_per_m = Eigen::Matrix3d::Zero();  // dF/dx, N/m
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();             // unit, resultant normal force
  double friction_coefficient = 0.0;
};

struct RendererParameters {
  RenderMode mode = RenderMode::kDirect;
  bool passivity = false;
  // The model's stiffness is scaled so that its largest singular value is at most this, N/m.
  // 3000 N/m: a PHANToM Premium's rated maximum (~3.5 N/mm) with margin; with the device's
  // mass and the hand's damping (phantom.h) the 1 kHz loop stays passive well above it.
  double max_stiffness_n_per_m = 3000.0;
  double max_extrapolation_m = 0.005;  // |x - x0| beyond this is not extrapolated further, m
  int blend_ticks = 5;                 // a new model replaces the old one over this many ticks
  double max_damping_n_s_per_m = 100.0;  // the passivity controller's cap, N s/m (passivity.h)
};

// The --render value ("direct", "direct+passivity", "local-model", "local-model+passivity", or
// "auto": direct for a kinematic device, local-model+passivity for a hand-held one) into
// parameters->mode and ->passivity; false for anything else.
struct RendererParameters;
bool ParseRendering(std::string_view name, bool hand_held, RendererParameters* parameters);
// "local-model+passivity" and the like.
std::string RenderingName(const RendererParameters& parameters);

struct RendererStats {
  uint64_t model_ticks = 0;          // ticks rendered from a model
  uint64_t models_received = 0;      // valid models taken
  uint64_t models_kept = 0;          // answers without contact that the model agreed with (kept)
  uint64_t stiffness_capped = 0;     // models whose stiffness was scaled down
  uint64_t extrapolation_capped = 0; // ticks evaluated at the max_extrapolation_m bound
  uint64_t pull_prevented = 0;       // ticks where the model would have pulled: zero force
  uint64_t cone_limited = 0;         // ticks where the tangential part was cut to the cone
};

class ForceRenderer {
 public:
  explicit ForceRenderer(const RendererParameters& parameters = {});

  // One tick. fresh: a new stepped force arrived this tick (force_n as received, model its
  // FeedbackForce.model). position_m: the device now. Returns the force to hand to the
  // safety filter (N, not yet limited); the passivity controller comes after it (Damp). A
  // non-finite force or model is ignored (the previous one stays).
  Eigen::Vector3d Command(bool fresh, const Eigen::Vector3d& force_n, const ReceivedModel& model,
                          const Eigen::Vector3d& position_m, const Eigen::Vector3d& velocity_m_per_s,
                          double tick_s);

  // The part of the last command's change explained by the device's motion through the model
  // in use: F_model(x_now) - F_model(x_before), N (zero in direct mode and when the model
  // changed this tick). For SafetyFilter::Update's motion_n.
  const Eigen::Vector3d& motion_change_n() const { return motion_change_n_; }

  // The command changes between arrivals (local-model): the safety filter must take it every
  // tick (SafetyFilter::Retarget), not only on arrivals.
  bool changes_between_arrivals() const { return parameters_.mode == RenderMode::kLocalModel; }

  // The passivity controller on the force the safety filter lets through (with --passivity;
  // else the force unchanged): the observer sees exactly what the device renders, the damper
  // -α v is added after the rate limit (a damper only takes energy out) and the sum is clamped
  // to max_force_n (when the clamp binds, E may go below 0 by what it cut).
  Eigen::Vector3d Damp(const Eigen::Vector3d& rendered_n, const Eigen::Vector3d& velocity_m_per_s, double tick_s,
                       double max_force_n);
  const RendererParameters& parameters() const { return parameters_; }
  const RendererStats& stats() const { return stats_; }
  const PassivityController& passivity() const { return passivity_; }

 private:
  struct ActiveModel {
    bool valid = false;
    Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
    ReceivedModel model;
  };
  // The model's force at x, within the bounds above (count: into stats_).
  Eigen::Vector3d Evaluate(const ActiveModel& active, const Eigen::Vector3d& position_m, bool count = true);

  RendererParameters parameters_;
  RendererStats stats_;
  PassivityController passivity_;
  Eigen::Vector3d held_force_n_ = Eigen::Vector3d::Zero();  // newest finite force
  ActiveModel current_, previous_;
  int blend_tick_ = 0;  // ticks since current_ took over from previous_
  Eigen::Vector3d last_position_m_ = Eigen::Vector3d::Constant(std::nan(""));  // the previous tick's
  Eigen::Vector3d motion_change_n_ = Eigen::Vector3d::Zero();
};

}  // namespace hapco::phantom
