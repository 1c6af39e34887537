#include "sim/global_export.h"

#include <string>

#include "common/error.h"

namespace hapco::sim {
namespace {

// Free dofs of a body in increasing dof order, and the inverse map (−1 for Dirichlet dofs).
std::vector<int> FreeDofs(const fem::ElasticBody& body, std::vector<int>* index_of_dof) {
  std::vector<int> free;
  index_of_dof->assign(static_cast<std::size_t>(body.num_dofs()), -1);
  for (int node = 0; node < body.mesh().num_nodes(); ++node) {
    if (body.is_dirichlet_node(node)) continue;
    for (int a = 0; a < 3; ++a) {
      (*index_of_dof)[static_cast<std::size_t>(3 * node + a)] = static_cast<int>(free.size());
      free.push_back(3 * node + a);
    }
  }
  return free;
}

}  // namespace

StepGlobalProblem GlobalProblemOfStep(const TwoBodySession& session) {
  const TwoBodyModel& model = session.model();
  const std::vector<StepContact>& contacts = session.contacts();
  const contact::ContactProblem& local = session.last_problem();
  const int m = static_cast<int>(contacts.size());
  if (m == 0) throw InputError("the step has no contact: there is no contact problem to export");

  StepGlobalProblem out;
  std::vector<int> tool_index, obstacle_index;
  out.tool_dofs = FreeDofs(model.tool(), &tool_index);
  out.obstacle_dofs = FreeDofs(model.obstacle(), &obstacle_index);
  const int n_tool = static_cast<int>(out.tool_dofs.size());
  const int n = n_tool + static_cast<int>(out.obstacle_dofs.size());

  // M: the free-free blocks of both stiffness matrices.
  std::vector<Eigen::Triplet<double>> m_entries;
  auto add_stiffness = [&](const fem::ElasticBody& body, const std::vector<int>& index, int offset) {
    const Eigen::SparseMatrix<double>& k = body.stiffness();
    for (int j = 0; j < k.outerSize(); ++j) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(k, j); it; ++it) {
        const int row = index[static_cast<std::size_t>(it.row())], col = index[static_cast<std::size_t>(it.col())];
        if (row >= 0 && col >= 0) m_entries.emplace_back(offset + row, offset + col, it.value());
      }
    }
  };
  add_stiffness(model.tool(), tool_index, 0);
  add_stiffness(model.obstacle(), obstacle_index, n_tool);
  out.problem.m.resize(n, n);
  out.problem.m.setFromTriplets(m_entries.begin(), m_entries.end());

  // H: contact weights times the local axes, at the free dofs of the nodes involved.
  const auto& tool_nodes = model.tool_surface().nodes;
  const auto& obstacle_nodes = model.obstacle_surface().nodes;
  std::vector<Eigen::Triplet<double>> h_entries;
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& c = contacts[static_cast<std::size_t>(alpha)];
    auto add_node = [&](int node, double weight, const std::vector<int>& index, int offset) {
      for (int k = 0; k < 3; ++k) {
        for (int a = 0; a < 3; ++a) {
          const int dof = index[static_cast<std::size_t>(3 * node + a)];
          const double value = weight * c.frame(k, a);
          if (dof >= 0 && value != 0.0) h_entries.emplace_back(offset + dof, 3 * alpha + k, value);
        }
      }
    };
    for (int p = 0; p < c.num_tool; ++p) {
      add_node(tool_nodes[static_cast<std::size_t>(c.tool_slots[static_cast<std::size_t>(p)])],
               c.tool_coefficients[static_cast<std::size_t>(p)], tool_index, 0);
    }
    for (int p = 0; p < c.num_obstacle; ++p) {
      add_node(obstacle_nodes[static_cast<std::size_t>(c.obstacle_slots[static_cast<std::size_t>(p)])],
               c.obstacle_coefficients[static_cast<std::size_t>(p)], obstacle_index, n_tool);
    }
  }
  out.problem.h.resize(n, 3 * m);
  out.problem.h.setFromTriplets(h_entries.begin(), h_entries.end());

  // f: the equivalent loads of the driven translation, −K_fd u_d, on the tool's free dofs.
  const Eigen::Vector3d d = session.last_output().device_translation_m;
  const fem::ElasticBody& tool = model.tool();
  Eigen::VectorXd u_driven = Eigen::VectorXd::Zero(tool.num_dofs());
  for (int node : tool.driven_nodes()) u_driven.segment<3>(3 * node) = d;
  const Eigen::VectorXd k_u = tool.stiffness() * u_driven;
  out.problem.f = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd tool_free_m = Eigen::VectorXd::Zero(n);  // [U_free(d) ; 0]
  const Eigen::VectorXd field = tool.unit_driven_translation_fields() * d;
  for (int i = 0; i < n_tool; ++i) {
    out.problem.f(i) = -k_u(out.tool_dofs[static_cast<std::size_t>(i)]);
    tool_free_m(i) = field(out.tool_dofs[static_cast<std::size_t>(i)]);
  }
  out.problem.w = local.free_displacement_m - out.problem.h.transpose() * tool_free_m;
  out.problem.mu = local.friction_coefficient;

  // A rigid-against-rigid contact got an extra compliance that M and H cannot reproduce.
  for (int i = 0; i < 3 * m; ++i) {
    if (out.problem.h.col(i).squaredNorm() == 0.0) {  // column-major: one column's entries
      throw InputError("contact " + std::to_string(i / 3) +
                       " joins two Dirichlet nodes (rigid against rigid): no global problem reproduces it");
    }
  }
  contact::ValidateGlobalProblem(out.problem);
  return out;
}

}  // namespace hapco::sim
