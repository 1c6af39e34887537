#include "sim/step_pipeline.h"

#include <algorithm>

#include "common/error.h"
#include "common/timer.h"

namespace hapco::sim {
namespace {

Eigen::Vector3d Block(const Eigen::VectorXd& vector, int index) {
  return vector.segment<3>(3 * index);
}

}  // namespace

TwoBodySession::TwoBodySession(const TwoBodyModel& model, SolveMode mode)
    : model_(model),
      mode_(mode),
      detector_(model.obstacle_triangles(), model.obstacle().mesh().nodes_m,
                model.tool_candidates(), model.tool_candidate_normals()) {
  solver = model.scene().solver;
  parameters = model.scene().solver_parameters;
  collision_.activation_gap_m = model.scene().activation_gap_m;
  // A tool node predicted deep inside the obstacle (a large device increment, or a step whose
  // solve failed) must still find the face it went through, or the tool would pass through
  // for good; beyond half the thickness it would face the opposite side instead.
  collision_.max_penetration_m = 0.45 * model.obstacle_thickness_m();
  // Every workspace of the haptic path is sized here for the most contacts the scene can have
  // (one per tool candidate node), so Step allocates only when m changes (W, ũ, μ).
  max_contacts_ = static_cast<int>(model.tool_candidates().size());
  contacts_.reserve(static_cast<std::size_t>(max_contacts_));
  workspace_.Reserve(max_contacts_, parameters.max_iterations);
  result_.Reserve(max_contacts_, parameters.max_iterations);
  obstacle_slots_.resize(static_cast<std::size_t>(max_contacts_));
  world_forces_n_.resize(3 * max_contacts_);
  if (mode_ == SolveMode::kPrecomputed) {
    const auto num_candidates = static_cast<Eigen::Index>(model.obstacle_candidates().size());
    spread_.resize(3 * num_candidates, 3 * max_contacts_);
    obstacle_force_n_.resize(3 * num_candidates);
    slot_loaded_.assign(static_cast<std::size_t>(num_candidates), 0);
    active_slots_.reserve(static_cast<std::size_t>(num_candidates));
  }
  Reset();
}

void TwoBodySession::Reset() {
  device_translation_m_.setZero();
  obstacle_candidate_displacement_m_ =
      Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(model_.obstacle_candidates().size()));
  tool_candidate_displacement_m_ =
      Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(model_.tool_candidates().size()));
  tool_candidate_force_n_ = Eigen::VectorXd::Zero(tool_candidate_displacement_m_.size());
  tool_free_candidate_m_ = Eigen::VectorXd::Zero(tool_candidate_displacement_m_.size());
  obstacle_positions_m_ = model_.obstacle().mesh().nodes_m;
  tool_positions_m_ = model_.tool().mesh().nodes_m;
  contacts_.clear();
  output_ = StepOutput{};
  active_obstacle_map_.assign(static_cast<std::size_t>(model_.obstacle().mesh().num_nodes()), -1);
  active_tool_map_.assign(static_cast<std::size_t>(model_.tool().mesh().num_nodes()), -1);
}

const StepOutput& TwoBodySession::Step(const Eigen::Vector3d& device_translation_m) {
  if (!device_translation_m.allFinite()) {
    throw InputError("device translation must be finite");
  }
  Stopwatch total;
  const int step = output_.step + 1;
  output_ = StepOutput{};
  output_.step = step;
  output_.device_translation_m = device_translation_m;

  // 1. Collision detection on the predicted configuration: last displacement plus the rigid
  //    increment of the device for the tool.
  Stopwatch watch;
  const Eigen::Vector3d increment_m = device_translation_m - device_translation_m_;
  const auto& tool_nodes = model_.tool_candidates();
  const auto& obstacle_nodes = model_.obstacle_candidates();
  const Eigen::MatrixXd& unit_fields = model_.tool_unit_fields();
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    tool_positions_m_.row(tool_nodes[i]) =
        (model_.tool().mesh().nodes_m.row(tool_nodes[i]).transpose() +
         Block(tool_candidate_displacement_m_, i) + unit_fields.middleRows<3>(3 * i) * increment_m)
            .transpose();
  }
  for (int i = 0; i < static_cast<int>(obstacle_nodes.size()); ++i) {
    obstacle_positions_m_.row(obstacle_nodes[i]) =
        (model_.obstacle().mesh().nodes_m.row(obstacle_nodes[i]).transpose() +
         Block(obstacle_candidate_displacement_m_, i))
            .transpose();
  }
  detector_.Detect(obstacle_positions_m_, tool_positions_m_, collision_, &contacts_);
  for (ContactPoint& contact : contacts_) {
    contact.frame = model_.obstacle_reference_frames()[static_cast<std::size_t>(contact.obstacle_triangle)];
  }
  device_translation_m_ = device_translation_m;
  output_.num_contacts = static_cast<int>(contacts_.size());
  output_.detect_seconds = watch.ElapsedSeconds();

  // 2. ũ and W for the active contacts. The tool's free displacement is linear in d
  //    (algorithms.md §6); the full-solve mode solves for it instead.
  watch.Restart();
  if (mode_ == SolveMode::kPrecomputed) {
    tool_free_candidate_m_.noalias() = unit_fields * device_translation_m_;
    AssembleProblem(model_.tool_compliance_m_per_n(), model_.tool_candidate_index(),
                    model_.obstacle_compliance_m_per_n(), model_.obstacle_candidate_index());
  } else {
    // The paper's way: compliance columns of the active nodes solved with the factors now.
    for (int node : active_obstacle_nodes_) active_obstacle_map_[static_cast<std::size_t>(node)] = -1;
    for (int node : active_tool_nodes_) active_tool_map_[static_cast<std::size_t>(node)] = -1;
    active_obstacle_nodes_.clear();
    active_tool_nodes_.clear();
    for (const ContactPoint& contact : contacts_) {
      active_tool_nodes_.push_back(contact.tool_node);
      for (int k = 0; k < contact.num_obstacle_nodes; ++k) {
        active_obstacle_nodes_.push_back(contact.obstacle_nodes[static_cast<std::size_t>(k)]);
      }
    }
    for (auto* nodes : {&active_obstacle_nodes_, &active_tool_nodes_}) {
      std::sort(nodes->begin(), nodes->end());
      nodes->erase(std::unique(nodes->begin(), nodes->end()), nodes->end());
    }
    for (int i = 0; i < static_cast<int>(active_obstacle_nodes_.size()); ++i) {
      active_obstacle_map_[static_cast<std::size_t>(active_obstacle_nodes_[i])] = i;
    }
    for (int i = 0; i < static_cast<int>(active_tool_nodes_.size()); ++i) {
      active_tool_map_[static_cast<std::size_t>(active_tool_nodes_[i])] = i;
    }
    const Eigen::VectorXd free_m = model_.tool().SolveDisplacement(
        Eigen::VectorXd::Zero(model_.tool().num_dofs()), device_translation_m_);
    for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
      tool_free_candidate_m_.segment<3>(3 * i) = free_m.segment<3>(3 * tool_nodes[i]);
    }
    const Eigen::MatrixXd tool_block = model_.tool().ComplianceBlock(active_tool_nodes_);
    const Eigen::MatrixXd obstacle_block = model_.obstacle().ComplianceBlock(active_obstacle_nodes_);
    AssembleProblem(tool_block, active_tool_map_, obstacle_block, active_obstacle_map_);
  }
  output_.assemble_seconds = watch.ElapsedSeconds();

  // 3. Solve, warm-started from the last forces of the same tool nodes.
  watch.Restart();
  const int m = static_cast<int>(contacts_.size());
  if (m > 0) {
    result_.force_n.resize(3 * m);
    for (int alpha = 0; alpha < m; ++alpha) {
      const int index = model_.tool_candidate_index()[static_cast<std::size_t>(contacts_[alpha].tool_node)];
      result_.force_n.segment<3>(3 * alpha) = contacts_[alpha].frame * Block(tool_candidate_force_n_, index);
    }
    contact::Solve(solver, problem_, parameters, &workspace_, &result_);
    const contact::SolverStats& stats = result_.stats;
    output_.status = stats.status;
    output_.iterations = stats.iterations;
    output_.inner_iterations = stats.inner_iterations;
    output_.paper_error_m = stats.paper_error_m;
    output_.fc3d_error = stats.fc3d_error;
    output_.state_counts = stats.state_counts;
  } else {
    result_.force_n.resize(0);
    result_.displacement_m.resize(0);
  }
  output_.solve_seconds = watch.ElapsedSeconds();

  // 4. Forces back to the bodies (algorithms.md §5).
  watch.Restart();
  tool_candidate_force_n_.setZero();
  for (int alpha = 0; alpha < m; ++alpha) {
    const Eigen::Vector3d world_n = contacts_[alpha].frame.transpose() * result_.force_n.segment<3>(3 * alpha);
    const int index = model_.tool_candidate_index()[static_cast<std::size_t>(contacts_[alpha].tool_node)];
    tool_candidate_force_n_.segment<3>(3 * index) = world_n;
    output_.contact_force_n += world_n;
  }
  output_.device_force_n = model_.scene().force_gain * output_.contact_force_n;
  if (mode_ == SolveMode::kPrecomputed) {
    UpdatePrecomputed();
  } else {
    UpdateFullSolve();
  }
  output_.update_seconds = watch.ElapsedSeconds();
  output_.total_seconds = total.ElapsedSeconds();
  return output_;
}

void TwoBodySession::AssembleProblem(const Eigen::MatrixXd& tool_compliance,
                                     const std::vector<int>& tool_map,
                                     const Eigen::MatrixXd& obstacle_compliance,
                                     const std::vector<int>& obstacle_map) {
  const int m = static_cast<int>(contacts_.size());
  // Same-size resizes are free in Eigen: the 1 kHz path allocates only when m changes.
  problem_.flexibility_m_per_n.resize(3 * m, 3 * m);
  problem_.free_displacement_m.resize(3 * m);
  problem_.friction_coefficient.setConstant(m, model_.scene().friction_coefficient);
  const auto& tool_reference = model_.tool().mesh().nodes_m;
  const auto& obstacle_reference = model_.obstacle().mesh().nodes_m;
  const auto& tool_index = model_.tool_candidate_index();
  const auto& obstacle_index = model_.obstacle_candidate_index();
  // Two exact ways to gather the obstacle part of W (same sums, different order), chosen per
  // step by their multiply-add counts (n = obstacle nodes per contact, R = rows of C):
  //   spread: S_β = Σ_l w_βl C_obstacle(:, j_l) for every contact (n·R·3 per contact; three
  //           adjacent columns of a column-major matrix are one contiguous run, so these are
  //           vectorised axpys), then W_obs(α, β) = Σ_k w_αk S_β(i_k, :): n blocks per pair.
  //           S is reused by the update (U_obstacle = −Σ_β S_β f_β, 3m·R).
  //   pairs:  W_obs(α, β) = Σ_k Σ_l w_αk w_βl C(i_k, j_l): n² blocks per pair, and the update
  //           from the compliance columns of the loaded nodes only (3·R per active node).
  // The spread wins for many contacts (81 on a Tet10 tool: 1.4x), the pairs for few (25).
  for (int alpha = 0; alpha < m; ++alpha) {
    const ContactPoint& a = contacts_[alpha];
    std::array<int, 6>& slots = obstacle_slots_[static_cast<std::size_t>(alpha)];
    for (int k = 0; k < a.num_obstacle_nodes; ++k) {
      slots[static_cast<std::size_t>(k)] =
          obstacle_map[static_cast<std::size_t>(a.obstacle_nodes[static_cast<std::size_t>(k)])];
    }
  }
  const double rows = static_cast<double>(obstacle_compliance.rows());
  const double n = m > 0 ? static_cast<double>(contacts_[0].num_obstacle_nodes) : 0.0;
  const double md = static_cast<double>(m);
  const double spread_cost = md * n * rows * 3 + md * n * 9 * (md + 1) / 2 + 3 * md * rows;
  const double pairs_cost = n * n * 9 * md * (md + 1) / 2 + std::min(md * n, rows / 3) * 3 * rows;
  use_spread_ = spread_cost < pairs_cost;
  if (use_spread_) {
    const Eigen::Index spread_rows = obstacle_compliance.rows();
    if (spread_.rows() != spread_rows || spread_.cols() < 3 * m) {
      spread_.resize(spread_rows, std::max<Eigen::Index>(3 * m, 3 * max_contacts_));
    }
    for (int alpha = 0; alpha < m; ++alpha) {
      const ContactPoint& a = contacts_[alpha];
      const std::array<int, 6>& slots = obstacle_slots_[static_cast<std::size_t>(alpha)];
      auto spread = spread_.middleCols<3>(3 * alpha);
      spread.noalias() = a.weights[0] * obstacle_compliance.middleCols<3>(3 * slots[0]);
      for (int k = 1; k < a.num_obstacle_nodes; ++k) {
        spread.noalias() += a.weights[static_cast<std::size_t>(k)] *
                            obstacle_compliance.middleCols<3>(3 * slots[static_cast<std::size_t>(k)]);
      }
    }
  }

  for (int alpha = 0; alpha < m; ++alpha) {
    const ContactPoint& a = contacts_[alpha];
    const int ia = tool_index[static_cast<std::size_t>(a.tool_node)];
    const Eigen::Vector3d free_m = Block(tool_free_candidate_m_, ia);
    Eigen::Vector3d obstacle_point_m = Eigen::Vector3d::Zero();
    Eigen::Vector3d obstacle_previous_m = Eigen::Vector3d::Zero();
    for (int k = 0; k < a.num_obstacle_nodes; ++k) {
      const int node = a.obstacle_nodes[static_cast<std::size_t>(k)];
      const double w = a.weights[static_cast<std::size_t>(k)];
      obstacle_point_m += w * obstacle_reference.row(node).transpose();
      obstacle_previous_m += w * Block(obstacle_candidate_displacement_m_, obstacle_index[static_cast<std::size_t>(node)]);
    }
    // Signorini on the total gap, Coulomb on the slip increment (algorithms.md §2).
    const Eigen::Vector3d total_m = tool_reference.row(a.tool_node).transpose() + free_m - obstacle_point_m;
    const Eigen::Vector3d increment_m = free_m - Block(tool_candidate_displacement_m_, ia) + obstacle_previous_m;
    problem_.free_displacement_m[3 * alpha] = a.frame.row(0).dot(total_m);
    problem_.free_displacement_m.segment<2>(3 * alpha + 1) = a.frame.bottomRows<2>() * increment_m;

    // W_αβ = R_α [C_tool(a, b) + Σ_k w_αk S_β(i_k, :)] R_βᵀ; W is symmetric, so β ≥ α only.
    const std::array<int, 6>& slots = obstacle_slots_[static_cast<std::size_t>(alpha)];
    const int ta = tool_map[static_cast<std::size_t>(a.tool_node)];
    for (int beta = alpha; beta < m; ++beta) {
      const ContactPoint& b = contacts_[beta];
      const int tb = tool_map[static_cast<std::size_t>(b.tool_node)];
      Eigen::Matrix3d world = tool_compliance.block<3, 3>(3 * ta, 3 * tb);
      if (use_spread_) {
        for (int k = 0; k < a.num_obstacle_nodes; ++k) {
          world.noalias() += a.weights[static_cast<std::size_t>(k)] *
                             spread_.block<3, 3>(3 * slots[static_cast<std::size_t>(k)], 3 * beta);
        }
      } else {
        const std::array<int, 6>& other = obstacle_slots_[static_cast<std::size_t>(beta)];
        for (int k = 0; k < a.num_obstacle_nodes; ++k) {
          Eigen::Matrix3d row_sum = b.weights[0] * obstacle_compliance.block<3, 3>(3 * slots[static_cast<std::size_t>(k)], 3 * other[0]);
          for (int l = 1; l < b.num_obstacle_nodes; ++l) {
            row_sum.noalias() += b.weights[static_cast<std::size_t>(l)] *
                                 obstacle_compliance.block<3, 3>(3 * slots[static_cast<std::size_t>(k)],
                                                                 3 * other[static_cast<std::size_t>(l)]);
          }
          world.noalias() += a.weights[static_cast<std::size_t>(k)] * row_sum;
        }
      }
      const Eigen::Matrix3d local = a.frame * world * b.frame.transpose();
      problem_.flexibility_m_per_n.block<3, 3>(3 * alpha, 3 * beta) = local;
      if (beta != alpha) problem_.flexibility_m_per_n.block<3, 3>(3 * beta, 3 * alpha) = local.transpose();
    }
  }
}

void TwoBodySession::UpdatePrecomputed() {
  // U = U_free(d) + C f over the candidate nodes (algorithms.md §5, §6). The obstacle carries
  // −w_βl f_β at the nodes of contact β: with the spread, U_obstacle = −Σ_β S_β f_β (one
  // matrix-vector product); otherwise the compliance columns of the loaded nodes only. The
  // tool carries f_β at its node, so only its active compliance columns are touched. No
  // allocation either way.
  const int m = static_cast<int>(contacts_.size());
  const auto& tool_index = model_.tool_candidate_index();
  const Eigen::MatrixXd& tool_compliance = model_.tool_compliance_m_per_n();
  tool_candidate_displacement_m_ = tool_free_candidate_m_;
  if (m == 0) {
    obstacle_candidate_displacement_m_.setZero();
    return;
  }
  for (int alpha = 0; alpha < m; ++alpha) {
    const int ia = tool_index[static_cast<std::size_t>(contacts_[alpha].tool_node)];
    const Eigen::Vector3d world_n = Block(tool_candidate_force_n_, ia);
    world_forces_n_.segment<3>(3 * alpha) = -world_n;
    tool_candidate_displacement_m_.noalias() += tool_compliance.middleCols<3>(3 * ia) * world_n;
  }
  if (use_spread_) {
    obstacle_candidate_displacement_m_.noalias() = spread_.leftCols(3 * m) * world_forces_n_.head(3 * m);
    return;
  }
  // Nodal obstacle forces on the loaded nodes, then their compliance columns only.
  const Eigen::MatrixXd& obstacle_compliance = model_.obstacle_compliance_m_per_n();
  active_slots_.clear();
  for (int alpha = 0; alpha < m; ++alpha) {
    const ContactPoint& a = contacts_[alpha];
    for (int k = 0; k < a.num_obstacle_nodes; ++k) {
      const int slot = obstacle_slots_[static_cast<std::size_t>(alpha)][static_cast<std::size_t>(k)];
      if (!slot_loaded_[static_cast<std::size_t>(slot)]) {
        slot_loaded_[static_cast<std::size_t>(slot)] = 1;
        active_slots_.push_back(slot);
        obstacle_force_n_.segment<3>(3 * slot).setZero();
      }
      obstacle_force_n_.segment<3>(3 * slot) +=
          a.weights[static_cast<std::size_t>(k)] * world_forces_n_.segment<3>(3 * alpha);
    }
  }
  obstacle_candidate_displacement_m_.setZero();
  for (int slot : active_slots_) {
    obstacle_candidate_displacement_m_.noalias() +=
        obstacle_compliance.middleCols<3>(3 * slot) * obstacle_force_n_.segment<3>(3 * slot);
    slot_loaded_[static_cast<std::size_t>(slot)] = 0;
  }
}

ContactSample TwoBodySession::SampleContact(int alpha) const {
  HAPCO_ASSERT(alpha >= 0 && alpha < static_cast<int>(contacts_.size()) && 3 * alpha + 3 <= result_.force_n.size(),
               "contact index out of range");
  const ContactPoint& contact = contacts_[static_cast<std::size_t>(alpha)];
  const Eigen::Vector3d r = result_.force_n.segment<3>(3 * alpha);
  const Eigen::Vector3d u = result_.displacement_m.segment<3>(3 * alpha);
  ContactSample sample;
  sample.tool_node = contact.tool_node;
  sample.position_m = contact.obstacle_point_m;
  sample.normal = contact.frame.row(0).transpose();
  sample.force_n = contact.frame.transpose() * r;
  sample.gap_m = u[0];
  sample.slip_m = u.tail<2>().norm();
  const double tolerance_m = parameters.global_tolerance_m;
  sample.state = contact::ClassifyContact(r, u, result_.stats.rho * tolerance_m, tolerance_m);
  return sample;
}

void TwoBodySession::NodalContactForces(Eigen::VectorXd* obstacle_n, Eigen::VectorXd* tool_n) const {
  *obstacle_n = Eigen::VectorXd::Zero(model_.obstacle().num_dofs());
  *tool_n = Eigen::VectorXd::Zero(model_.tool().num_dofs());
  for (int alpha = 0; alpha < static_cast<int>(contacts_.size()) && 3 * alpha < result_.force_n.size(); ++alpha) {
    const ContactPoint& a = contacts_[alpha];
    const Eigen::Vector3d world_n = a.frame.transpose() * result_.force_n.segment<3>(3 * alpha);
    tool_n->segment<3>(3 * a.tool_node) += world_n;
    for (int k = 0; k < a.num_obstacle_nodes; ++k) {
      obstacle_n->segment<3>(3 * a.obstacle_nodes[static_cast<std::size_t>(k)]) -=
          a.weights[static_cast<std::size_t>(k)] * world_n;
    }
  }
}

void TwoBodySession::FullDisplacements(Eigen::VectorXd* obstacle_m, Eigen::VectorXd* tool_m) const {
  Eigen::VectorXd obstacle_force_n, tool_force_n;
  NodalContactForces(&obstacle_force_n, &tool_force_n);
  *obstacle_m = model_.obstacle().SolveDisplacement(obstacle_force_n, Eigen::Vector3d::Zero());
  *tool_m = model_.tool().SolveDisplacement(tool_force_n, device_translation_m_);
}

void TwoBodySession::UpdateFullSolve() {
  // The paper's per-step solves: full fields from the factors, then read the candidates.
  Eigen::VectorXd obstacle_m, tool_m;
  FullDisplacements(&obstacle_m, &tool_m);
  const auto& obstacle_nodes = model_.obstacle_candidates();
  const auto& tool_nodes = model_.tool_candidates();
  for (int i = 0; i < static_cast<int>(obstacle_nodes.size()); ++i) {
    obstacle_candidate_displacement_m_.segment<3>(3 * i) = obstacle_m.segment<3>(3 * obstacle_nodes[i]);
  }
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    tool_candidate_displacement_m_.segment<3>(3 * i) = tool_m.segment<3>(3 * tool_nodes[i]);
  }
}

}  // namespace hapco::sim
