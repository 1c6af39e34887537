#include "contact/projection.h"

#include <cmath>

#include "common/error.h"

namespace hapco::contact {

std::string_view ContactStateName(ContactState state) {
  switch (state) {
    case ContactState::kSeparating: return "separating";
    case ContactState::kSticking: return "sticking";
    case ContactState::kSliding: return "sliding";
  }
  return "unknown";
}

Eigen::Vector3d ProjectOnCoulombCone(const Eigen::Vector3d& r, double mu) {
  const double rn = r(0);
  // ‖r_t‖ with sqrt, not hypot: forces are far from overflow, and hypot's care costs a tenth
  // of the global solvers' sweep.
  const double a = std::sqrt(r(1) * r(1) + r(2) * r(2));
  // Inside K_μ (sticking). r_n >= 0 matters for μ = 0, where a = 0 <= μ r_n = −0.
  if (rn >= 0.0 && a <= mu * rn) return r;
  if (mu * a <= -rn) return Eigen::Vector3d::Zero();     // in the polar cone (separating)
  // Boundary (sliding), algorithms.md §3: normal part (r_n + μa)/(1 + μ²), tangential μ times
  // it along r_t/a. With μ = 0 this is (r_n, 0, 0), r_n > 0.
  const double normal = (rn + mu * a) / (1.0 + mu * mu);
  Eigen::Vector3d p;
  p(0) = normal;
  const double scale = a > 0.0 ? mu * normal / a : 0.0;
  p(1) = scale * r(1);
  p(2) = scale * r(2);
  return p;
}

ContactState ClassifyContact(const Eigen::Vector3d& r_n, const Eigen::Vector3d& u_m,
                             double force_tolerance_n, double displacement_tolerance_m) {
  if (r_n(0) <= force_tolerance_n) return ContactState::kSeparating;
  if (std::hypot(u_m(1), u_m(2)) > displacement_tolerance_m) return ContactState::kSliding;
  return ContactState::kSticking;
}

std::array<int, 3> CountContactStates(const Eigen::VectorXd& force_n,
                                      const Eigen::VectorXd& displacement_m,
                                      double force_tolerance_n, double displacement_tolerance_m) {
  if (force_n.size() != displacement_m.size() || force_n.size() % 3 != 0) {
    throw InputError("CountContactStates: force and displacement must both have size 3m (got " +
                     std::to_string(force_n.size()) + " and " +
                     std::to_string(displacement_m.size()) + ")");
  }
  std::array<int, 3> counts{0, 0, 0};
  for (Eigen::Index i = 0; i < force_n.size(); i += 3) {
    const ContactState s = ClassifyContact(force_n.segment<3>(i), displacement_m.segment<3>(i),
                                           force_tolerance_n, displacement_tolerance_m);
    ++counts[static_cast<std::size_t>(s)];
  }
  return counts;
}

}  // namespace hapco::contact
