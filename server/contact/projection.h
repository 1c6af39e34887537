#pragma once
// Coulomb cone projection and contact-state classification (algorithms.md §2-3).
// Local coordinates are ordered [normal, t1, t2] everywhere in this library.
#include <Eigen/Dense>

#include <array>
#include <string_view>

namespace hapco::contact {

// The three states of the contact law (algorithms.md §2).
enum class ContactState { kSeparating = 0, kSticking = 1, kSliding = 2 };

// "separating", "sticking", "sliding".
std::string_view ContactStateName(ContactState state);

// Euclidean projection of r onto K_mu = { r : ||r_t|| <= mu r_n } (algorithms.md §3), mu >= 0.
// With a = ||r_t||:
//   a <= mu r_n          -> r                                  (inside: sticking)
//   mu a <= -r_n         -> 0                                  (polar cone: separating)
//   otherwise            -> normal part (r_n + mu a)/(1 + mu^2), tangential length mu times it,
//                           along r_t / a                      (boundary: sliding)
// mu = 0 gives the half-line projection (max(r_n, 0), 0, 0). Units follow r (N for forces).
Eigen::Vector3d ProjectOnCoulombCone(const Eigen::Vector3d& r, double mu);

// State of one contact from its force r (N) and relative displacement u (m), local coords:
//   separating  if r_n <= force_tolerance_n,
//   sliding     else if ||u_t|| > displacement_tolerance_m,
//   sticking    otherwise.
// Deciding "sliding" from the slip rather than from ||r_t|| = mu r_n avoids calling every
// frictionless (mu = 0) contact sliding and every stuck contact at the cone edge sliding.
ContactState ClassifyContact(const Eigen::Vector3d& r_n, const Eigen::Vector3d& u_m,
                             double force_tolerance_n, double displacement_tolerance_m);

// Counts per state for 3m-vectors r (N) and u (m) of the same size (multiple of 3), indexed
// by static_cast<int>(ContactState): {separating, sticking, sliding}.
std::array<int, 3> CountContactStates(const Eigen::VectorXd& force_n,
                                      const Eigen::VectorXd& displacement_m,
                                      double force_tolerance_n, double displacement_tolerance_m);

}  // namespace hapco::contact
