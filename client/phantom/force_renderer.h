#pragma once
// What a device renders each servo tick from the forces that arrive over the network (issue 12,
// docs/network-haptics.md), before the safety filter (phantom.h) applies the device's limits:
//
//   direct       the newest force, held until the next one (as the paper's client does);
//   local-model  the newest local model evaluated at the device's *current* position every
//                tick (model-mediated teleoperation: Mitra & Niemeyer 2008; Schuwerk et al.,
//                WHC 2015): in contact, the contact model F0 + K (x - x0); apart, the surface
//                ahead (the nearest obstacle face as a plane, sim/surface_ahead.h), so the
//                first contact is felt where the device meets it, not a round trip later;
//   + passivity  either of them, with the time-domain passivity controller (passivity.h):
//                a damper exactly when the energy the device has rendered would go negative
//                (a delay generating energy), rate limited and clamped by the safety filter
//                like the rest of the force (render_chain.h).
//
// A contact model is rendered as a plane with friction on the device, not as the linear model
// itself (an intermediate representation: Mark et al., SIGGRAPH 1996; the friction cone of
// Salisbury et al. 1995):
//   normal  F_n = s (F0·n − k (x − x0)·n) along the model's normal n, k = −nᵀKn its normal
//           stiffness, s = min(1, cap / k): a contact stiffer than the device can render
//           (max_stiffness_n_per_m) is the same wall made softer, at the same place;
//   across  a Coulomb anchor on the device: a spring of the contact's tangential stiffness
//           (capped) that slips at μ F_n; the model's tangential force only places the anchor
//           when a contact begins.
// Why, measured (docs/network-haptics.md, network_haptics_study): with the linear model
// F0 + K (x − x0), every part of the force that is not a fixed function of x acts on the
// delayed pose x0. Capping K alone (the first version) left (1 − s) K acting one round trip
// late, and K's stiffest direction was a sticking contact's tangential one (7.6 kN/m along a
// bar clamped at both ends, 1.7 kN/m into it), so the wall itself was rendered at 40 % with the
// rest delayed: the device rang at 100 and 200 ms. The model's tangential force and its
// cross terms (normal force against lateral motion: friction and the slope of the deformed
// obstacle) are state the server carries along the path, and extrapolated over the few mm a
// device moves in a round trip they drove a 25 Hz wobble during slides at 200 ms. A plane and
// a local friction law are fixed functions of x and of the device's own history: passive.
// A surface ahead is rendered with the stiffness of the last contact model (capped), or the cap
// before any contact.
//
// Other bounds the network cannot break: a model is evaluated at most max_extrapolation_m
// (contact) or max_surface_extrapolation_m (surface ahead) from the pose it answered; it never
// pulls (contacts only push: no force against its normal); its part across the normal stays in
// the Coulomb cone of the scene's friction coefficient. A new model takes over from the
// previous one over blend_ticks ticks, so switching models never makes the force jump. An
// answer without a contact model at a pose where the model in use gives no force either keeps
// a contact model (it knows the contact's stiffness; the server's answer for where the device
// is now is a round trip away); an answer that contradicts it (no contact where it pushes)
// replaces it.
#include <Eigen/Dense>

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "passivity.h"

namespace hapco::phantom {

enum class RenderMode { kDirect, kLocalModel };
enum class ContactRendering { kPlane, kLinear };

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
  // Without contact (valid false): the surface ahead, gap(x) = surface_gap_m +
  // surface_normal·(x - position_m), m; a contact there pushes along surface_normal (unit).
  bool surface_ahead = false;
  double surface_gap_m = 0.0;
  Eigen::Vector3d surface_normal = Eigen::Vector3d::Zero();
};

struct RendererParameters {
  RenderMode mode = RenderMode::kDirect;
  bool passivity = false;
  // The model's stiffness is scaled so that its largest singular value is at most this, N/m.
  // 3000 N/m: a PHANToM Premium's rated maximum (~3.5 N/mm) with margin; with the device's
  // mass and the hand's damping (phantom.h) the 1 kHz loop stays passive well above it.
  double max_stiffness_n_per_m = 3000.0;
  double max_extrapolation_m = 0.005;  // |x - x0| beyond this is not extrapolated further, m
  // A surface ahead is used up to this far from the pose it answered, m (the server looks
  // 10 mm ahead: sim::LocalModelBuilder::kDefaultSurfaceReachM).
  double max_surface_extrapolation_m = 0.010;
  // Render the surface ahead (false: nothing until the first contact model arrives).
  bool surface_ahead = true;
  // How a contact model is rendered: kPlane (above), or kLinear, the first version (F0 +
  // K (x - x0) with K capped by its stiffest direction and the model's own tangential force;
  // kept to measure the difference: a residual delayed spring, docs/network-haptics.md).
  ContactRendering contact_rendering = ContactRendering::kPlane;
  int blend_ticks = 5;                 // a new model replaces the old one over this many ticks
  // The passivity controller's cap, N s/m (passivity.h). An explicit damper α on the device's
  // effective mass m at the servo period T is stable only for α < 2 m/T and stops flipping
  // sign tick to tick below m/T; half of that, m/(2T), for a PHANToM's ~0.05 kg at 1 kHz. The
  // old cap, 2 m/T = 100, chattered at 500 Hz (docs/network-haptics.md).
  double max_damping_n_s_per_m = 25.0;
  // The passivity controller's rules with a local model (passivity.h); direct rendering uses
  // PassivityRules::Strict().
  PassivityRules local_model_passivity = PassivityRules::ForLocalModel();
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
  uint64_t surfaces_received = 0;    // surfaces ahead taken
  uint64_t surface_ticks = 0;        // ticks rendered from a surface ahead
  uint64_t extrapolation_capped = 0; // ticks evaluated at the max_extrapolation_m bound
  uint64_t pull_prevented = 0;       // ticks where the model would have pulled: zero force
  uint64_t cone_limited = 0;         // ticks where the tangential part was cut to the cone
};

class ForceRenderer {
 public:
  explicit ForceRenderer(const RendererParameters& parameters = {});

  // One tick. fresh: a new stepped force arrived this tick (force_n as received, model its
  // FeedbackForce.model). position_m: the device now. Returns the force to hand to the
  // safety filter (N, not yet limited; RenderChain adds the passivity damper to it). A
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

  // The passivity controller (with --passivity; else nothing): PassivityDamper is the damper
  // -α v (N) the energy books ask for this tick, for the force command_n the environment asks;
  // RenderChain adds it to the command before the safety filter, so the rate limit and the
  // clamp hold for the sum. AccountRendered books what the device then rendered.
  Eigen::Vector3d PassivityDamper(const Eigen::Vector3d& command_n, const Eigen::Vector3d& velocity_m_per_s,
                                  double tick_s);
  void AccountRendered(const Eigen::Vector3d& command_n, const Eigen::Vector3d& rendered_n,
                       const Eigen::Vector3d& velocity_m_per_s, double tick_s);
  const RendererParameters& parameters() const { return parameters_; }
  const RendererStats& stats() const { return stats_; }
  const PassivityController& passivity() const { return passivity_; }

 private:
  enum class ModelKind { kNone, kContact, kSurface };
  struct ActiveModel {
    ModelKind kind = ModelKind::kNone;
    bool valid() const { return kind != ModelKind::kNone; }
    Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // as received (kNone: rendered as is)
    ReceivedModel model;
    double scale = 1.0;                     // s above (kContact, kPlane)
    double normal_stiffness_n_per_m = 0.0;  // k above, unscaled (kContact, kPlane)
    double surface_stiffness_n_per_m = 0;  // kSurface
  };
  // The received answer as a model to render (kind kNone when it carries none).
  ActiveModel Take(const Eigen::Vector3d& force_n, const ReceivedModel& model);
  // The friction limit μ of a contact model: the scene's, or the server's own ratio at x0.
  static double FrictionLimit(const ActiveModel& active);
  // The local friction's force at position_m for the normal force of this tick's command
  // (slips the anchor when beyond the cone), and at the last tick's position from the anchor
  // before this tick's slip, within the cone (*at_last_position_n, for motion_change_n).
  Eigen::Vector3d LocalFriction(const Eigen::Vector3d& normal_force_n, const Eigen::Vector3d& position_m,
                                Eigen::Vector3d* at_last_position_n);
  // The model's force at x, within the bounds above (count: into stats_).
  Eigen::Vector3d Evaluate(const ActiveModel& active, const Eigen::Vector3d& position_m, bool count = true);

  RendererParameters parameters_;
  RendererStats stats_;
  PassivityController passivity_;
  double passivity_alpha_n_s_per_m_ = 0.0;  // asked this tick (PassivityDamper), N s/m
  Eigen::Vector3d held_force_n_ = Eigen::Vector3d::Zero();  // newest finite force
  ActiveModel current_, previous_;
  int blend_tick_ = 0;  // ticks since current_ took over from previous_
  // Stiffness along the normal of the last contact model, as rendered (scaled), N/m; 0 before.
  double last_normal_stiffness_n_per_m_ = 0.0;
  // Local friction: the anchor (m, valid while in contact) and its spring, N/m.
  Eigen::Vector3d anchor_m_ = Eigen::Vector3d::Zero();
  bool anchor_valid_ = false;
  double tangential_stiffness_n_per_m_ = 0.0;
  Eigen::Vector3d last_position_m_ = Eigen::Vector3d::Constant(std::nan(""));  // the previous tick's
  Eigen::Vector3d motion_change_n_ = Eigen::Vector3d::Zero();
};

}  // namespace hapco::phantom
