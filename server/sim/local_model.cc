#include "sim/local_model.h"

#include <cmath>
#include <vector>

#include "common/error.h"

#include "contact/projection.h"

namespace hapco::sim {

LocalModelBuilder::LocalModelBuilder(double surface_reach_m, Sliding sliding)
    : surface_reach_m_(surface_reach_m), sliding_(sliding) {
  HAPCO_ASSERT(std::isfinite(surface_reach_m) && surface_reach_m >= 0.0, "surface reach must be finite and >= 0");
}

void LocalModelBuilder::Prepare(const TwoBodyModel& model) {
  if (surface_reach_m_ <= 0.0 || probe_model_ == &model) return;
  surface_probe_.emplace(model, surface_reach_m_);
  probe_model_ = &model;
  steps_since_surface_search_ = -1;
}

const LocalContactModel& LocalModelBuilder::Linearize(const TwoBodySession& session) {
  LinearizeContacts(session);
  LocalContactModel& model = model_;
  if (model.normal_device.isZero() && surface_reach_m_ > 0.0 && session.last_output().step > 0) {
    // No contact pushes: nothing is loaded, so the configuration is the probe's
    // (surface_ahead.h).
    if (probe_model_ != &session.model()) Prepare(session.model());
    const Eigen::Vector3d& d = model.device_translation_m;
    const bool reuse = steps_since_surface_search_ >= 0 && steps_since_surface_search_ < kSurfaceResearchSteps &&
                       (d - last_surface_pose_m_).norm() <= kSurfaceResearchDistanceM;
    if (reuse) {
      ++steps_since_surface_search_;
    } else {
      last_surface_ = surface_probe_->Probe(d);
      last_surface_pose_m_ = d;
      steps_since_surface_search_ = 0;
    }
    if (last_surface_.found) {
      const double gap_m = last_surface_.gap_m + last_surface_.normal_device.dot(d - last_surface_pose_m_);
      model.surface_ahead = gap_m >= 0.0;  // (a pose through it is answered by the next search)
      model.surface_gap_m = std::max(0.0, gap_m);
      model.surface_normal = last_surface_.normal_device;
    }
  } else {
    steps_since_surface_search_ = -1;  // a contact loads the bodies: search afresh after it
  }
  return model;
}

void LocalModelBuilder::LinearizeContacts(const TwoBodySession& session) {
  LocalContactModel& model = model_;
  model = LocalContactModel{};
  const StepOutput& out = session.last_output();
  model.device_translation_m = out.device_translation_m;
  model.device_force_n = out.device_force_n;
  model.friction_coefficient = session.model().scene().friction_coefficient;
  const std::vector<StepContact>& contacts = session.contacts();
  const contact::ContactProblem& problem = session.last_problem();
  const contact::SolverResult& result = session.last_result();
  const int m = static_cast<int>(contacts.size());
  unknowns_.clear();
  rows_.clear();
  if (m == 0 || result.force_n.size() < 3 * m) return;
  const double gain = session.model().scene().force_gain;

  // Active set: the equations E and the basis B of the unknowns (local frame per contact).
  // The normal of the resultant: r_α,n n_α on the tool, n_α = the frame's normal signed
  // towards the tool (SampleContact), summed and normalised.
  Eigen::Vector3d normal_force_n = Eigen::Vector3d::Zero();
  for (int alpha = 0; alpha < m; ++alpha) {
    const ContactSample sample = session.SampleContact(alpha);
    const Eigen::Vector3d r = result.force_n.segment<3>(3 * alpha);
    // The normal comes from the active set only: a separating contact's force is round-off
    // (a tool exactly on the surface leaves ~1e-11 N on every contact), and a normal without
    // the stiffness of an active contact is a model that pushes back without any stiffness.
    if (sample.state != contact::ContactState::kSeparating) normal_force_n += r[0] * sample.normal;
    const bool stick_like = sample.state == contact::ContactState::kSticking ||
                            (sample.state == contact::ContactState::kSliding && sliding_ == Sliding::kAsSticking);
    if (stick_like) {
      if (sample.state == contact::ContactState::kSticking) {
        ++model.sticking;
      } else {
        ++model.sliding;
      }
      for (int k = 0; k < 3; ++k) {
        unknowns_.push_back({alpha, Eigen::Vector3d::Unit(k)});
        rows_.push_back(3 * alpha + k);
      }
    } else if (sample.state == contact::ContactState::kSliding) {
      ++model.sliding;
      Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
      if (r[0] > 0) direction.tail<2>() = r.tail<2>() / r[0];  // r_t = μ r_n ŝ on the cone
      unknowns_.push_back({alpha, direction});
      rows_.push_back(3 * alpha);
    }
  }
  const double normal_norm = (gain * normal_force_n).norm();
  if (normal_norm > 0.0) model.normal_device = gain * normal_force_n / normal_norm;
  if (unknowns_.empty()) return;

  // G = dq/dd (3m x 3), world axes: contact α's relative displacement moves with its tool
  // nodes' unit fields.
  FreeDisplacementPerDeviceTranslation(session, &g_);

  // (E W B) dz/dd = -E G. B has one 3-vector per unknown, so W B is read from W's columns of
  // that contact (no dense product with B).
  const int n = static_cast<int>(unknowns_.size());
  const Eigen::MatrixXd& w = problem.flexibility_m_per_n;
  w_basis_.resize(3 * m, n);
  for (int j = 0; j < n; ++j) {
    const Unknown& u = unknowns_[static_cast<std::size_t>(j)];
    w_basis_.col(j).noalias() = w.middleCols<3>(3 * u.contact) * u.direction;  // noalias: no temporary
  }
  system_.resize(n, n);
  rhs_.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    system_.row(i) = w_basis_.row(rows_[static_cast<std::size_t>(i)]);
    rhs_.row(i) = -g_.row(rows_[static_cast<std::size_t>(i)]);
  }
  lu_.compute(system_);  // sliding makes it non-symmetric
  dz_ = lu_.solve(rhs_);

  // dF/dd = gain Σ_α (Σ_p c_αp) R_αᵀ dr_α/dd, dr_α/dd = Σ_j∈α direction_j dz_j/dd.
  for (int j = 0; j < n; ++j) {
    const Unknown& u = unknowns_[static_cast<std::size_t>(j)];
    const StepContact& c = contacts[static_cast<std::size_t>(u.contact)];
    double weight = 0.0;
    for (int k = 0; k < c.num_tool; ++k) weight += c.tool_coefficients[static_cast<std::size_t>(k)];
    const Eigen::RowVector3d dz_j = dz_.row(j);  // fixed size: no temporary on the heap
    model.stiffness_n_per_m.noalias() += (gain * weight) * (c.frame.transpose() * u.direction) * dz_j;
  }
}

void LocalModelBuilder::ContactForcePerDeviceTranslation(int num_contacts, Eigen::MatrixXd* dr_dd) const {
  dr_dd->setZero(3 * num_contacts, 3);
  // dz_ is stale when the last Linearize had no unknowns (it returns before solving).
  if (unknowns_.empty() || dz_.rows() != static_cast<Eigen::Index>(unknowns_.size())) return;
  for (std::size_t j = 0; j < unknowns_.size(); ++j) {
    const Unknown& u = unknowns_[j];
    if (u.contact >= num_contacts) continue;
    const Eigen::RowVector3d dz_j = dz_.row(static_cast<Eigen::Index>(j));
    dr_dd->middleRows<3>(3 * u.contact).noalias() += u.direction * dz_j;
  }
}

void FreeDisplacementPerDeviceTranslation(const TwoBodySession& session, Eigen::MatrixXd* g) {
  const std::vector<StepContact>& contacts = session.contacts();
  const int m = static_cast<int>(contacts.size());
  const Eigen::MatrixXd& unit_fields = session.model().tool_unit_fields();
  g->setZero(3 * m, 3);
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& c = contacts[static_cast<std::size_t>(alpha)];
    Eigen::Matrix3d moved = Eigen::Matrix3d::Zero();
    for (int k = 0; k < c.num_tool; ++k) {
      moved += c.tool_coefficients[static_cast<std::size_t>(k)] *
               unit_fields.block<3, 3>(3 * c.tool_slots[static_cast<std::size_t>(k)], 0);
    }
    g->block<3, 3>(3 * alpha, 0) = c.frame * moved;
  }
}

LocalContactModel LinearizeLastStep(const TwoBodySession& session) {
  LocalModelBuilder builder;
  return builder.Linearize(session);
}

}  // namespace hapco::sim
