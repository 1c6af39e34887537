#pragma once
// A local model of the contact around the pose a step answered (issue 12, item 1): the device
// force there and its derivative with respect to the device translation, for the step's own
// active set. A client that renders from it at its current position between (or instead of
// late) server forces stays on the contact's stiffness instead of on a stale force.
//
// Derivation (algorithms.md §2, flexibility method): the step solves u = W r + q(d) with
// q(d) = q_k + G (d - d_k); G_α = R_α Σ_p c_αp U_p, R_α the contact frame (rows n, t1, t2),
// c_αp the signed weights of the contact's tool nodes and U_p their free displacement per
// unit device translation (the tool's unit fields, 3x3, m/m; the obstacle side does not move
// with d within a step). For the active set of the solution, the contact law is linear:
//   sticking  α: u_α = 0                      (3 equations), r_α free   (3 unknowns)
//   sliding   α: u_α,n = 0                    (1 equation),  r_α = r_n (e_n + μ ŝ_α), ŝ_α the
//                                                             solution's slip direction
//   separating α: r_α = 0
// so r = B z with E (W B z + q) = 0, i.e. dz/dd = -(E W B)^-1 E G, dr/dd = B dz/dd, and the
// device force F = gain Σ_α Σ_p c_αp R_αᵀ r_α has dF/dd = gain Σ_α Σ_p c_αp R_αᵀ dr_α/dd.
// The model ignores what changes the active set (a contact closing or opening, stick <-> slip)
// and the geometry: a contact point that moves over the deformed obstacle sees its slope,
// which is not in G. Measured against finite differences of full steps (1e-7 m moves, coarse
// scene, tests/unit/sim/local_model_test.cc): frictionless press within 0.12 % of |K| h,
// sticking press (mu = 10) within 1.2 % (laterally: the slope term), and during a mu = 0.3 slide
// the model misses the slope (sliding on a deformed surface) and contacts closing under a
// further press: it is not yet good enough there (issue 12).
#include <Eigen/Dense>

#include <optional>
#include <vector>

#include "sim/step_pipeline.h"
#include "sim/surface_ahead.h"

namespace hapco::sim {

struct LocalContactModel {
  Eigen::Vector3d device_translation_m = Eigen::Vector3d::Zero();  // d_k, the pose answered, m
  Eigen::Vector3d device_force_n = Eigen::Vector3d::Zero();        // F(d_k), N
  // dF/dd for the step's active set, N/m (world axes). Symmetric negative semi-definite
  // without sliding contacts (a spring pushing back); sliding makes it non-symmetric.
  Eigen::Matrix3d stiffness_n_per_m = Eigen::Matrix3d::Zero();
  // What a client needs to keep separation and friction right away from d_k (the linear
  // model knows neither): the unit direction of the resultant normal force on the device
  // (Σ_α r_α,n n_α times the gain, normalised; zero without contact force) and the scene's
  // Coulomb coefficient. A rendered force must not pull along -normal_device (contacts only
  // push) and its part across normal_device stays within friction_coefficient times its part
  // along it (the resultant of forces in their cones lies in that cone when the normals agree).
  Eigen::Vector3d normal_device = Eigen::Vector3d::Zero();
  double friction_coefficient = 0.0;
  int sticking = 0, sliding = 0;  // contacts in the active set
  // Without any contact at d_k: the obstacle surface ahead of the tool within the builder's
  // reach (surface_ahead.h), so a client renders the first contact when the device gets there
  // instead of a round trip later. Near d_k the gap is surface_gap_m + surface_normal·(d − d_k);
  // a contact there pushes the device along surface_normal (unit).
  bool surface_ahead = false;
  double surface_gap_m = 0.0;
  Eigen::Vector3d surface_normal = Eigen::Vector3d::Zero();

  // F(d) ≈ F(d_k) + K (d - d_k), N.
  Eigen::Vector3d ForceAt(const Eigen::Vector3d& pose_m) const {
    return device_force_n + stiffness_n_per_m * (pose_m - device_translation_m);
  }
};

// The local model of the session's last step (zero stiffness without active contacts).
// Reuses its buffers: allocation-free once it has seen the largest active set (for the
// server's 1 kHz path). Cost: the active set's n x n LU (n <= 3 x contacts): docs/network-haptics.md.
class LocalModelBuilder {
 public:
  // Without contact, look for the surface ahead within surface_reach_m (m; 0: never).
  static constexpr double kDefaultSurfaceReachM = 0.01;
  // The search for the surface ahead costs 50-150 us on the benchmarks (sim_pipeline_bench),
  // tens of contact-free steps' worth. Apart, the geometry only translates (nothing is
  // loaded), so a result found at pose d_p holds at d as gap_p + n·(d − d_p) while the nearest
  // pair stays the same: the search runs again once the device has moved this far since the
  // last one, or after this many steps (the client extrapolates the same way).
  static constexpr double kSurfaceResearchDistanceM = 0.0005;
  static constexpr int kSurfaceResearchSteps = 20;
  // How sliding contacts are linearized. kOnTheCone (the clients' model): r stays on the cone
  // along the solution's slip direction. kAsSticking: as if they stuck (u = 0, r free), the
  // trial state of a return mapping; multirate.h projects the resulting force back onto the
  // friction cone, which also turns the friction when the device changes direction.
  enum class Sliding { kOnTheCone, kAsSticking };
  explicit LocalModelBuilder(double surface_reach_m = kDefaultSurfaceReachM, Sliding sliding = Sliding::kOnTheCone);

  // Builds the surface-ahead search for `model` now (its trees and buffers), so that a
  // session's 1 kHz path never does; Linearize builds it on first need otherwise (offline).
  void Prepare(const TwoBodyModel& model);

  const LocalContactModel& Linearize(const TwoBodySession& session);
  const LocalContactModel& model() const { return model_; }
  // dr/dd of the last Linearize (3m x 3, N/m): how each contact's force (its local frame n, t1,
  // t2) moves with the device translation for that step's active set, r_α = Σ_j∈α direction_j
  // dz_j/dd (zero rows for separating contacts). m is that step's contact count. Multirate
  // answers predict their solve's start with it (multirate.h).
  void ContactForcePerDeviceTranslation(int num_contacts, Eigen::MatrixXd* dr_dd) const;

 private:
  void LinearizeContacts(const TwoBodySession& session);

  struct Unknown {
    int contact = 0;
    Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // r_α = z * direction (local frame)
  };
  LocalContactModel model_;
  double surface_reach_m_;
  Sliding sliding_;
  std::optional<SurfaceAheadProbe> surface_probe_;  // built for the first session's model
  const TwoBodyModel* probe_model_ = nullptr;
  SurfaceAhead last_surface_;                                     // of the last search
  Eigen::Vector3d last_surface_pose_m_ = Eigen::Vector3d::Zero();  // where it ran, m
  int steps_since_surface_search_ = -1;                            // -1: none to reuse
  std::vector<Unknown> unknowns_;
  std::vector<int> rows_;  // rows of u = W r + q held at zero
  Eigen::MatrixXd g_, w_basis_, system_, rhs_, dz_, dr_;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
};

// G = dũ/dd (3m x 3, m/m) of the session's last step: how each contact's free relative
// displacement (its local frame n, t1, t2) moves with the device translation, through its
// tool nodes' unit fields (the obstacle side does not move with d within a step). Resizes *g.
void FreeDisplacementPerDeviceTranslation(const TwoBodySession& session, Eigen::MatrixXd* g);

// One-off form of LocalModelBuilder::Linearize (tests, offline tools).
LocalContactModel LinearizeLastStep(const TwoBodySession& session);

}  // namespace hapco::sim
