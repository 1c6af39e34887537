#pragma once
// The contact problem of a simulation step written as a global problem (contact/
// global_problem.h, FCLIB /fclib_global), so other tools' solvers can be run on HapCo scenes
// and the flexibility method can be checked against the precomputed path (paper §3):
//     M = blockdiag(K_ff tool, K_ff obstacle)           (free dofs, N/m)
//     H: column 3α+k = Σ_p c_αp e_k(α) at the free dofs of slave/master node p, the
//        contact weights c (tool > 0, obstacle < 0) times local axis k of contact α
//     f = [−K_fd u_d ; 0]                               (the driven translation d, N)
//     w = ũ − Hᵀ [U_free(d) ; 0]                        (m)
// so that Hᵀ M⁻¹ H = W and Hᵀ M⁻¹ f + w = ũ of the step, and v = M⁻¹(H r + f) is the
// displacement of both bodies' free dofs (m) under the contact forces r (N).
#include <vector>

#include "contact/global_problem.h"
#include "sim/step_pipeline.h"

namespace hapco::sim {

struct StepGlobalProblem {
  contact::GlobalContactProblem problem;
  // Global dof i < tool_dofs.size() is tool dof tool_dofs[i] (3·node + axis); the rest are
  // obstacle dofs obstacle_dofs[i − tool_dofs.size()].
  std::vector<int> tool_dofs, obstacle_dofs;
};

// The last step of `session` (its contacts, device translation and problem) as a global
// problem. Throws InputError when the step has no contact, or when a contact was given the
// rigid-against-rigid compliance (TwoBodyModel::rigid_contact_compliance_m_per_n), which no
// M and H reproduce.
StepGlobalProblem GlobalProblemOfStep(const TwoBodySession& session);

}  // namespace hapco::sim
