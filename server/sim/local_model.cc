#include "sim/local_model.h"

#include <vector>

#include "contact/projection.h"

namespace hapco::sim {

LocalContactModel LinearizeLastStep(const TwoBodySession& session) {
  LocalContactModel model;
  const StepOutput& out = session.last_output();
  model.device_translation_m = out.device_translation_m;
  model.device_force_n = out.device_force_n;
  const std::vector<StepContact>& contacts = session.contacts();
  const contact::ContactProblem& problem = session.last_problem();
  const contact::SolverResult& result = session.last_result();
  const int m = static_cast<int>(contacts.size());
  if (m == 0 || result.force_n.size() < 3 * m) return model;

  // Active set: the equations E and the basis B of the unknowns (local frame per contact).
  struct Unknown {
    int contact;
    Eigen::Vector3d direction;  // r_α = z * direction (local frame)
  };
  std::vector<Unknown> unknowns;
  std::vector<int> rows;  // rows of u = W r + q that are held at zero
  for (int alpha = 0; alpha < m; ++alpha) {
    const ContactSample sample = session.SampleContact(alpha);
    if (sample.state == contact::ContactState::kSticking) {
      ++model.sticking;
      for (int k = 0; k < 3; ++k) {
        unknowns.push_back({alpha, Eigen::Vector3d::Unit(k)});
        rows.push_back(3 * alpha + k);
      }
    } else if (sample.state == contact::ContactState::kSliding) {
      ++model.sliding;
      const Eigen::Vector3d r = result.force_n.segment<3>(3 * alpha);
      Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
      if (r[0] > 0) direction.tail<2>() = r.tail<2>() / r[0];  // r_t = μ r_n ŝ on the cone
      unknowns.push_back({alpha, direction});
      rows.push_back(3 * alpha);
    }
  }
  if (unknowns.empty()) return model;

  // G = dq/dd (3m x 3) and the contact-to-device map D = dF/dr (3 x 3m), world axes.
  const Eigen::MatrixXd& unit_fields = session.model().tool_unit_fields();
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(3 * m, 3);
  Eigen::MatrixXd to_device = Eigen::MatrixXd::Zero(3, 3 * m);
  const double gain = session.model().scene().force_gain;
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& c = contacts[static_cast<std::size_t>(alpha)];
    Eigen::Matrix3d moved = Eigen::Matrix3d::Zero();
    double weight = 0.0;
    for (int k = 0; k < c.num_tool; ++k) {
      const double coefficient = c.tool_coefficients[static_cast<std::size_t>(k)];
      moved += coefficient * unit_fields.block<3, 3>(3 * c.tool_slots[static_cast<std::size_t>(k)], 0);
      weight += coefficient;
    }
    g.block<3, 3>(3 * alpha, 0) = c.frame * moved;
    to_device.block<3, 3>(0, 3 * alpha) = gain * weight * c.frame.transpose();
  }

  // (E W B) z' = -E G, with B the unknowns' directions.
  const int n = static_cast<int>(unknowns.size());
  Eigen::MatrixXd basis = Eigen::MatrixXd::Zero(3 * m, n);
  for (int j = 0; j < n; ++j) basis.block<3, 1>(3 * unknowns[static_cast<std::size_t>(j)].contact, j) = unknowns[static_cast<std::size_t>(j)].direction;
  const Eigen::MatrixXd w_basis = problem.flexibility_m_per_n * basis;
  Eigen::MatrixXd system(n, n), rhs(n, 3);
  for (int i = 0; i < n; ++i) {
    system.row(i) = w_basis.row(rows[static_cast<std::size_t>(i)]);
    rhs.row(i) = -g.row(rows[static_cast<std::size_t>(i)]);
  }
  const Eigen::MatrixXd dz = system.fullPivLu().solve(rhs);  // sliding makes it non-symmetric
  model.stiffness_n_per_m = to_device * (basis * dz);
  return model;
}

}  // namespace hapco::sim
