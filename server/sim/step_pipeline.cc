#include "sim/step_pipeline.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "common/error.h"
#include "common/timer.h"

namespace hapco::sim {
namespace {

// Barycentric distance below which a reverse-pass point counts as lying on a face edge or a
// node (dimensionless): there the tool's own nodes already carry the contact (pass 1). It is
// judged in the rigid configuration (reference geometry, tool translated by d), so elastic
// deformation never switches it: round-off only.
constexpr double kOnEdge = 1e-6;

Eigen::Vector3d Block(const Eigen::VectorXd& vector, int index) { return vector.segment<3>(3 * index); }

// The node of a face (corner, or midside of a 6-node face) at barycentric point l, or -1 where
// l is at none. Midside k lies halfway between corners k and k + 1 (fem::SurfaceTriangle).
int FaceNodeAt(const fem::SurfaceTriangle& face, const Eigen::Vector3d& l) {
  int corner = 0;
  if (l.maxCoeff(&corner) > 1.0 - kOnEdge) return face.corners[static_cast<std::size_t>(corner)];
  for (int k = 0; k < 3 && face.midsides[0] >= 0; ++k) {
    if (std::abs(l[k] - 0.5) < kOnEdge && std::abs(l[(k + 1) % 3] - 0.5) < kOnEdge) {
      return face.midsides[static_cast<std::size_t>(k)];
    }
  }
  return -1;
}

// Σ_k Σ_l c_k d_l C(p_k, q_l) over one body's 3x3 compliance blocks (rows maps a surface slot
// to its block row in C), world axes, m/N.
Eigen::Matrix3d WeightedBlockSum(const Eigen::MatrixXd& compliance, const std::vector<int>& rows,
                                 const std::array<int, 6>& p, const std::array<double, 6>& c, int np,
                                 const std::array<int, 6>& q, const std::array<double, 6>& d, int nq) {
  Eigen::Matrix3d total = Eigen::Matrix3d::Zero();
  for (int k = 0; k < np; ++k) {
    const int row = 3 * rows[static_cast<std::size_t>(p[static_cast<std::size_t>(k)])];
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (int l = 0; l < nq; ++l) {
      sum.noalias() += d[static_cast<std::size_t>(l)] *
                       compliance.block<3, 3>(row, 3 * rows[static_cast<std::size_t>(q[static_cast<std::size_t>(l)])]);
    }
    total.noalias() += c[static_cast<std::size_t>(k)] * sum;
  }
  return total;
}

}  // namespace

TwoBodySession::TwoBodySession(const TwoBodyModel& model, SolveMode mode)
    : model_(model),
      mode_(mode),
      tool_surface_(model.tool_surface()),
      obstacle_surface_(model.obstacle_surface()),
      tool_pass_(model.obstacle_surface().triangles, model.obstacle().mesh().nodes_m,
                 model.tool_surface().nodes, model.tool_surface().node_normals, model.obstacle_surface().subtriangle_faces),
      edge_pass_(model.tool_surface().triangles, model.tool().mesh().nodes_m, model.obstacle_reverse_slaves(),
                 model.obstacle_reverse_slave_normals(), model.tool_surface().subtriangle_faces) {
  solver = model.scene().solver;
  parameters = model.scene().solver_parameters;
  // A *new* contact deeper than about half a body's thickness would face that body's far
  // side; persistent contacts keep their face at any depth (ContactDetector), so a deep press
  // or a failed step never lets the tool pass through.
  tool_pass_parameters_.activation_gap_m = model.scene().activation_gap_m;
  max_new_depth_obstacle_m_ = 0.45 * model.obstacle_thickness_m();
  max_new_depth_tool_m_ = 0.45 * model.tool_thickness_m();
  tool_pass_parameters_.max_penetration_m = max_new_depth_obstacle_m_;
  edge_pass_parameters_.activation_gap_m = model.scene().activation_gap_m;
  edge_pass_parameters_.max_penetration_m = max_new_depth_tool_m_;

  const std::size_t n_tool = tool_surface_.nodes.size();
  const std::size_t n_obstacle = obstacle_surface_.nodes.size();
  const std::size_t n_edge = model.obstacle_reverse_slaves().size();
  // Every workspace of the haptic path is sized here for the most contacts the scene can have
  // (one per tool surface node and per obstacle edge node), so Step allocates only when the
  // contact count changes (W, ũ, μ).
  max_contacts_ = static_cast<int>(n_tool + n_edge);
  contacts_.reserve(static_cast<std::size_t>(max_contacts_));
  tool_pass_points_.reserve(n_tool);
  obstacle_detected_m_.assign(n_obstacle, Eigen::Vector3d::Zero());
  obstacle_detected_stamp_.assign(n_obstacle, 0);
  face_rise_m_.assign(obstacle_surface_.triangles.size(), 0.0);
  edge_pass_points_.reserve(n_edge);
  workspace_.Reserve(max_contacts_, parameters.max_iterations);
  result_.Reserve(max_contacts_, parameters.max_iterations);
  region_.reserve(n_obstacle);
  enabled_triangles_.reserve(obstacle_surface_.triangles.size());
  near_triangles_.reserve(obstacle_surface_.triangles.size());
  tree_stack_.reserve(static_cast<std::size_t>(obstacle_surface_.triangle_tree.depth()) + 1);
  region_free_.reserve(n_obstacle);
  region_runs_.reserve(n_obstacle);
  loaded_runs_.reserve(n_obstacle);
  cell_moved_m_ = Eigen::VectorXd::Zero(3 * obstacle_surface_.num_cells);
  tool_loaded_.reserve(n_tool);
  tool_free_.reserve(n_tool);
  tool_free_runs_.reserve(n_tool);
  tool_loaded_runs_.reserve(n_tool);
  previous_ids_.reserve(static_cast<std::size_t>(max_contacts_));
  obstacle_loaded_.reserve(n_obstacle);
  // Normal groups (see step_pipeline.h): the nearest of the 26 directions (±1, 0 per axis).
  constexpr int kGroups = 26;
  std::vector<Eigen::Vector3d> directions;
  for (int x = -1; x <= 1; ++x)
    for (int y = -1; y <= 1; ++y)
      for (int z = -1; z <= 1; ++z)
        if (x != 0 || y != 0 || z != 0) directions.push_back(Eigen::Vector3d(x, y, z).normalized());
  const auto& tool_normals = tool_surface_.node_normals;
  tool_normal_group_.resize(n_tool);
  for (std::size_t i = 0; i < n_tool; ++i) {
    int best = 0;
    for (int k = 1; k < kGroups; ++k) {
      if (directions[static_cast<std::size_t>(k)].dot(tool_normals[i]) >
          directions[static_cast<std::size_t>(best)].dot(tool_normals[i])) {
        best = k;
      }
    }
    tool_normal_group_[i] = best;
  }
  // The same reference normals and threshold as the detector's test, so a face is left out only
  // where that test would reject every node of every group near it.
  const std::vector<Eigen::Vector3d>& face_normals = tool_pass_.reference_normals();
  face_reachable_groups_.assign(face_normals.size(), 0);
  for (std::size_t t = 0; t < face_normals.size(); ++t) {
    for (std::size_t i = 0; i < n_tool; ++i) {
      if (!(-face_normals[t].dot(tool_normals[i]) < tool_pass_parameters_.min_normal_opposition)) {
        face_reachable_groups_[t] |= std::uint32_t{1} << tool_normal_group_[i];
      }
    }
  }
  group_lo_m_.resize(kGroups);
  group_hi_m_.resize(kGroups);
  edge_node_slot_.resize(n_edge);
  for (std::size_t e = 0; e < n_edge; ++e) {
    edge_node_slot_[e] = obstacle_surface_.node_index[static_cast<std::size_t>(model.obstacle_reverse_slaves()[e])];
  }
  Reset();
}

void TwoBodySession::Reset() {
  approach_ = Approach{};
  const auto n_tool = tool_surface_.nodes.size();
  const auto n_obstacle = obstacle_surface_.nodes.size();
  device_translation_m_.setZero();
  tool_displacement_m_ = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(n_tool));
  tool_free_m_ = tool_displacement_m_;
  obstacle_displacement_m_ = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(n_obstacle));
  tool_slot_force_n_ = tool_displacement_m_;
  obstacle_slot_force_n_ = obstacle_displacement_m_;
  tool_slot_loaded_.assign(n_tool, 0);
  obstacle_slot_loaded_.assign(n_obstacle, 0);
  tool_is_slave_.assign(n_tool, 0);
  previous_ids_.clear();
  tool_loaded_.clear();
  obstacle_loaded_.clear();
  obstacle_positions_m_ = model_.obstacle().mesh().nodes_m;
  tool_positions_m_ = model_.tool().mesh().nodes_m;
  region_.clear();
  in_region_.assign(n_obstacle, mode_ == SolveMode::kFullSolve ? 1 : 0);
  // Full solves keep every face enabled; the precomputed mode's broad phase enables the faces
  // near the tool (enabled_triangles_) each step.
  obstacle_triangle_enabled_.assign(obstacle_surface_.triangles.size(), mode_ == SolveMode::kFullSolve ? 1 : 0);
  enabled_triangles_.clear();
  edge_node_enabled_.assign(edge_node_slot_.size(), 1);
  tool_previous_triangle_.assign(n_tool, -1);
  edge_previous_triangle_.assign(edge_node_slot_.size(), -1);
  last_residual_penetration_m_ = 0.0;
  detection_count_ += 2;  // no face's last positions count (DetectContacts)
  contacts_.clear();
  force_by_id_n_ = Eigen::VectorXd::Zero(3 * (model_.tool().mesh().num_nodes() + model_.obstacle().mesh().num_nodes()));
  output_ = StepOutput{};
  active_tool_rows_.assign(n_tool, -1);
  active_obstacle_rows_.assign(n_obstacle, -1);
  active_tool_.clear();
  active_obstacle_.clear();
}

void TwoBodySession::Release() {
  tool_displacement_m_.noalias() = model_.tool_unit_fields() * device_translation_m_;
  obstacle_displacement_m_.setZero();
  for (int slot : tool_loaded_) {
    tool_slot_loaded_[static_cast<std::size_t>(slot)] = 0;
    tool_slot_force_n_.segment<3>(3 * slot).setZero();
  }
  for (int slot : obstacle_loaded_) {
    obstacle_slot_loaded_[static_cast<std::size_t>(slot)] = 0;
    obstacle_slot_force_n_.segment<3>(3 * slot).setZero();
  }
  tool_loaded_.clear();
  obstacle_loaded_.clear();
  for (int id : previous_ids_) force_by_id_n_.segment<3>(3 * id).setZero();
  previous_ids_.clear();
  std::fill(tool_previous_triangle_.begin(), tool_previous_triangle_.end(), -1);
  std::fill(edge_previous_triangle_.begin(), edge_previous_triangle_.end(), -1);
  last_residual_penetration_m_ = 0.0;
  detection_count_ += 2;  // no face's last positions count (DetectContacts)
  for (int node : obstacle_surface_.nodes) {
    obstacle_positions_m_.row(node) = model_.obstacle().mesh().nodes_m.row(node);
  }
}

void TwoBodySession::BroadPhase(const Eigen::Vector3d& increment_m) {
  // Predicted tool surface: last displacement plus the rigid increment of the device.
  const auto& tool_nodes = tool_surface_.nodes;
  const auto& tool_reference = model_.tool().mesh().nodes_m;
  const Eigen::MatrixXd& unit_fields = model_.tool_unit_fields();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  std::fill(group_lo_m_.begin(), group_lo_m_.end(), lo);
  std::fill(group_hi_m_.begin(), group_hi_m_.end(), hi);
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    const int node = tool_nodes[static_cast<std::size_t>(i)];
    const Eigen::Vector3d x = tool_reference.row(node).transpose() + Block(tool_displacement_m_, i) +
                              unit_fields.middleRows<3>(3 * i) * increment_m;
    tool_positions_m_.row(node) = x.transpose();
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
    const auto group = static_cast<std::size_t>(tool_normal_group_[static_cast<std::size_t>(i)]);
    group_lo_m_[group] = group_lo_m_[group].cwiseMin(x);
    group_hi_m_[group] = group_hi_m_[group].cwiseMax(x);
  }

  const auto& obstacle_nodes = obstacle_surface_.nodes;
  const auto& obstacle_reference = model_.obstacle().mesh().nodes_m;
  if (mode_ == SolveMode::kFullSolve) {
    // The full fields are known everywhere: every face and edge node stays enabled.
    for (int i = 0; i < static_cast<int>(obstacle_nodes.size()); ++i) {
      const int node = obstacle_nodes[static_cast<std::size_t>(i)];
      obstacle_positions_m_.row(node) = obstacle_reference.row(node) + Block(obstacle_displacement_m_, i).transpose();
    }
    output_.region_nodes = static_cast<int>(obstacle_nodes.size());
    return;
  }

  // Region (rigorous): a face can hold a tool node only within the activation gap, the
  // step's travel or the last solve's residual penetration, and no node of a cell moved along
  // axis a by more than Σ_j bound(3c + a, j)·|f_j| under the last forces (ContactSurface).
  // (plus the detector's lateral slack for persistent faces).
  const double near_m = tool_pass_parameters_.activation_gap_m + increment_m.norm() + last_residual_penetration_m_ +
                        2.0 * tool_pass_parameters_.persistent_edge_tolerance * obstacle_surface_.longest_edge_m;
  const Eigen::MatrixXd& bound = obstacle_surface_.cell_axis_bound_m_per_n;
  cell_moved_m_.setZero();
  for (int slot : obstacle_loaded_) {
    const double f = Block(obstacle_slot_force_n_, slot).norm();
    cell_moved_m_.noalias() += f * bound.col(slot);
  }
  if (!obstacle_surface_.far_bound_m_per_n.empty()) {
    // Banded compliance: the pairs beyond its range are not stored, so every cell may also
    // have moved by their bound (TwoBodyModel: far_bound_m_per_n).
    double far_m = 0.0;
    for (int slot : obstacle_loaded_) {
      far_m += obstacle_surface_.far_bound_m_per_n[static_cast<std::size_t>(slot)] * Block(obstacle_slot_force_n_, slot).norm();
    }
    cell_moved_m_.array() += far_m;
  }
  for (int slot : region_) in_region_[static_cast<std::size_t>(slot)] = 0;
  region_.clear();
  const auto& triangles = obstacle_surface_.triangles;
  const auto& node_index = obstacle_surface_.node_index;
  const auto& node_cell = obstacle_surface_.node_cell;
  // Most faces are far from the tool: the largest bound of any cell rules them out with one
  // box test, before their own nodes' bounds are looked up.
  Eigen::Vector3d moved_anywhere = Eigen::Vector3d::Zero();
  for (int cell = 0; cell < obstacle_surface_.num_cells; ++cell) {
    moved_anywhere = moved_anywhere.cwiseMax(cell_moved_m_.segment<3>(3 * cell));
  }
  const Eigen::Vector3d far_lo = lo.array() - (moved_anywhere.array() + near_m);
  const Eigen::Vector3d far_hi = hi.array() + (moved_anywhere.array() + near_m);
  // Only the faces whose reference box meets that far box are looked at (a tree query, not a
  // pass over the whole surface); the others stay disabled.
  for (int t : enabled_triangles_) obstacle_triangle_enabled_[static_cast<std::size_t>(t)] = 0;
  enabled_triangles_.clear();
  near_triangles_.clear();
  obstacle_surface_.triangle_tree.Overlapping(far_lo, far_hi, &near_triangles_, &tree_stack_);
  for (int t : near_triangles_) {
    Eigen::Vector3d moved = Eigen::Vector3d::Zero();
    const auto& tri = triangles[static_cast<std::size_t>(t)];
    for (int k = 0; k < 3; ++k) {
      for (int node : {tri.corners[static_cast<std::size_t>(k)], tri.midsides[static_cast<std::size_t>(k)]}) {
        if (node < 0) continue;
        const int cell = node_cell[static_cast<std::size_t>(node_index[static_cast<std::size_t>(node)])];
        moved = moved.cwiseMax(cell_moved_m_.segment<3>(3 * cell));
      }
    }
    const Eigen::Vector3d grow = moved.array() + near_m;
    const Eigen::Vector3d face_lo = obstacle_surface_.triangle_min_m[static_cast<std::size_t>(t)] - grow;
    const Eigen::Vector3d face_hi = obstacle_surface_.triangle_max_m[static_cast<std::size_t>(t)] + grow;
    // Near a group of tool nodes whose normals can face it (the groups' boxes lie inside lo, hi).
    bool enabled = false;
    for (std::uint32_t groups = face_reachable_groups_[static_cast<std::size_t>(t)]; groups != 0 && !enabled;
         groups &= groups - 1) {
      const auto group = static_cast<std::size_t>(__builtin_ctz(groups));
      enabled = (face_lo.array() <= group_hi_m_[group].array()).all() && (face_hi.array() >= group_lo_m_[group].array()).all();
    }
    if (!enabled) continue;
    obstacle_triangle_enabled_[static_cast<std::size_t>(t)] = 1;
    enabled_triangles_.push_back(t);
    // The detector reads the searched triangles' nodes: the corners, and a 6-node face's
    // midsides for its quadratic surface point (ContactDetector); with the FOUR_SUBTRIANGLES
    // search the sub-triangles' corners are the faces' corners and midsides.
    for (int k = 0; k < 6; ++k) {
      const int node = k < 3 ? tri.corners[static_cast<std::size_t>(k)] : tri.midsides[static_cast<std::size_t>(k - 3)];
      if (node < 0) continue;
      const int slot = node_index[static_cast<std::size_t>(node)];
      if (!in_region_[static_cast<std::size_t>(slot)]) {
        in_region_[static_cast<std::size_t>(slot)] = 1;
        region_.push_back(slot);
      }
    }
  }
  // The last step's contact nodes (midsides included): contacts mostly stay on their faces,
  // and here their U comes in the same vectorised runs as the rest.
  for (int slot : obstacle_loaded_) {
    if (!in_region_[static_cast<std::size_t>(slot)]) {
      in_region_[static_cast<std::size_t>(slot)] = 1;
      region_.push_back(slot);
    }
  }
  // Edge nodes (reverse pass) near the tool's faces, by the same bound.
  for (std::size_t e = 0; e < edge_node_slot_.size(); ++e) {
    const int slot = edge_node_slot_[e];
    const Eigen::Vector3d x = obstacle_reference.row(obstacle_nodes[static_cast<std::size_t>(slot)]).transpose();
    const Eigen::Vector3d grow = cell_moved_m_.segment<3>(3 * node_cell[static_cast<std::size_t>(slot)]).array() + near_m;
    const bool near = ((x + grow).array() >= lo.array()).all() && ((x - grow).array() <= hi.array()).all();
    edge_node_enabled_[e] = near ? 1 : 0;
    if (near && !in_region_[static_cast<std::size_t>(slot)]) {
      in_region_[static_cast<std::size_t>(slot)] = 1;
      region_.push_back(slot);
    }
  }
  // U = C f on the region only (algorithms.md §5), from the last step's loaded slots.
  ObstacleDisplacementOnRegion();
  for (int i : region_) {
    const int node = obstacle_nodes[static_cast<std::size_t>(i)];
    obstacle_positions_m_.row(node) = obstacle_reference.row(node) + Block(obstacle_displacement_m_, i).transpose();
  }
  output_.region_nodes = static_cast<int>(region_.size());
}

// Runs [begin, end) of consecutive entries of an ascending slot list.
void TwoBodySession::SlotRuns(const std::vector<int>& slots, std::vector<std::pair<int, int>>* runs) {
  runs->clear();
  for (std::size_t k = 0; k < slots.size(); ++k) {
    if (k == 0 || slots[k] != slots[k - 1] + 1) {
      runs->push_back({slots[k], slots[k] + 1});
    } else {
      runs->back().second = slots[k] + 1;
    }
  }
}

void TwoBodySession::ObstacleDisplacementOnRegion() {
  // U_i = Σ_j C(i, j) f_j for the region slots i, over the loaded slots j. The cost is the
  // ~10^4 block reads and their arithmetic (docs/free-interaction.md, docs/performance.md):
  // see AddComplianceTimesForces for how the blocks are read.
  std::sort(obstacle_loaded_.begin(), obstacle_loaded_.end());
  region_free_.clear();
  for (int slot : region_) {
    if (!obstacle_slot_loaded_[static_cast<std::size_t>(slot)]) region_free_.push_back(slot);
  }
  std::sort(region_free_.begin(), region_free_.end());
  SlotRuns(region_free_, &region_runs_);
  SlotRuns(obstacle_loaded_, &loaded_runs_);
  for (int i : region_) obstacle_displacement_m_.segment<3>(3 * i).setZero();
  AddComplianceTimesForces(compliance_kernel, obstacle_surface_.compliance_m_per_n, region_runs_, obstacle_loaded_,
                           loaded_runs_, obstacle_slot_force_n_.data(), obstacle_displacement_m_.data());
}

bool TwoBodySession::WithinComplianceRange() const {
  // Rows read this step: the region (which holds the loaded and contact slots by now); columns:
  // the loaded slots (U = C f) and the contacts' slots (the W gather). Each column's stored
  // rows are one run (BlockedCompliance::Banded), so the rows' span must lie inside it.
  const BlockedCompliance& c = obstacle_surface_.compliance_m_per_n;
  if (!c.banded() || mode_ == SolveMode::kFullSolve) return true;
  int lo = std::numeric_limits<int>::max(), hi = -1;
  for (int slot : region_) {
    lo = std::min(lo, slot);
    hi = std::max(hi, slot);
  }
  if (hi < 0) return true;
  const auto covers = [&](int j) { return c.band_begin(j) <= lo && hi < c.band_end(j); };
  for (int j : obstacle_loaded_) {
    if (!covers(j)) return false;
  }
  for (const StepContact& contact : contacts_) {
    for (int k = 0; k < contact.num_obstacle; ++k) {
      if (!covers(contact.obstacle_slots[static_cast<std::size_t>(k)])) return false;
    }
  }
  return true;
}

void TwoBodySession::CompleteContactDisplacements() {
  // U = C f of the last forces at the contact nodes the broad phase left out (midsides of
  // contact faces): the slip increment of algorithms.md §2 needs them.
  if (mode_ == SolveMode::kFullSolve) return;
  const BlockedCompliance& compliance = obstacle_surface_.compliance_m_per_n;
  for (const StepContact& c : contacts_) {
    for (int k = 0; k < c.num_obstacle; ++k) {
      const int slot = c.obstacle_slots[static_cast<std::size_t>(k)];
      if (in_region_[static_cast<std::size_t>(slot)]) continue;
      in_region_[static_cast<std::size_t>(slot)] = 1;
      region_.push_back(slot);
      Eigen::Vector3d u = Eigen::Vector3d::Zero();
      for (int j : obstacle_loaded_) u.noalias() += compliance.block(slot, j) * Block(obstacle_slot_force_n_, j);
      obstacle_displacement_m_.segment<3>(3 * slot) = u;
    }
  }
}

void TwoBodySession::DetectContacts(const Eigen::Vector3d& device_translation_m) {
  // A new contact is at most as deep as this step's travel plus what the last solve left
  // (twice that, for safety), and never deeper than half a body (see the constructor): the
  // tree's boxes are grown by that, not by the half body, so a query tests only nearby faces.
  const double travel_m = (device_translation_m - device_translation_m_).norm();
  const double new_depth_m = 2.0 * (tool_pass_parameters_.activation_gap_m + travel_m + last_residual_penetration_m_);
  tool_pass_parameters_.max_penetration_m = std::min(max_new_depth_obstacle_m_, new_depth_m);
  edge_pass_parameters_.max_penetration_m = std::min(max_new_depth_tool_m_, new_depth_m);
  // A face that springs back towards the tool: the travel bound misses what the face's own
  // deformation moved it. Frictionless, the 3 mm top sweep pushes the tool flush against a
  // clamped end (2.8 kN, the rim held up ~3 mm by the clamped edge); moving on, the rim
  // springs back, the faces next to the clamp dimpled by the rim's last loads spring back up
  // under it, and three rim nodes sat in the bar without contact until the tool was 11.7 mm
  // from the clamp: 30 % below the way out's force 2 mm from the clamp, 15-18 % from one step
  // to the next where they came back. A face that rose by δ since the last detection may hold
  // a new contact up to δ deeper than the travel allows (twice, as that bound), the total never
  // past half the obstacle, and only for a node over the face's undeformed triangle
  // (ContactDetector::TestTriangle, DetectionContext::triangle_rise_m). Per face: the most
  // any of its nodes moved outwards along its reference normal (a face no node of which was
  // placed at the last detection gets none: it was far from the tool). Only the faces the
  // broad phase kept are measured and searched: one that sprang back under the tool's nodes
  // is among them (BroadPhase grows each face by how far it can have moved). Measured on
  // paths nobody wrote: docs/free-interaction.md, "Faces that spring back".
  const double rise_cap_m = 0.5 * std::max(0.0, max_new_depth_obstacle_m_ - tool_pass_parameters_.max_penetration_m);
  const auto& obstacle_nodes = obstacle_surface_.nodes;
  const auto& triangles = obstacle_surface_.triangles;
  const auto& face_normals = tool_pass_.reference_normals();
  const auto face_rise = [&](int t) {
    double rise_m = 0.0;
    const fem::SurfaceTriangle& tri = triangles[static_cast<std::size_t>(t)];
    for (int k = 0; k < 6; ++k) {
      const int node = k < 3 ? tri.corners[static_cast<std::size_t>(k)] : tri.midsides[static_cast<std::size_t>(k - 3)];
      if (node < 0) continue;
      const auto slot = static_cast<std::size_t>(obstacle_surface_.node_index[static_cast<std::size_t>(node)]);
      if (obstacle_detected_stamp_[slot] != detection_count_) continue;  // not placed at the last one
      rise_m = std::max(rise_m, face_normals[static_cast<std::size_t>(t)].dot(
                                    obstacle_positions_m_.row(node).transpose() - obstacle_detected_m_[slot]));
    }
    face_rise_m_[static_cast<std::size_t>(t)] = std::min(rise_m, rise_cap_m);
  };
  const auto remember = [&](int slot) {
    obstacle_detected_m_[static_cast<std::size_t>(slot)] =
        obstacle_positions_m_.row(obstacle_nodes[static_cast<std::size_t>(slot)]).transpose();
    obstacle_detected_stamp_[static_cast<std::size_t>(slot)] = detection_count_;
  };
  if (mode_ == SolveMode::kPrecomputed) {
    for (int t : enabled_triangles_) face_rise(t);
    ++detection_count_;
    for (int slot : region_) remember(slot);
  } else {
    for (int t = 0; t < static_cast<int>(triangles.size()); ++t) face_rise(t);
    ++detection_count_;
    for (int slot = 0; slot < static_cast<int>(obstacle_nodes.size()); ++slot) remember(slot);
  }
  tool_pass_.Detect(obstacle_positions_m_, tool_positions_m_, tool_pass_parameters_, &tool_pass_points_,
                    {&tool_previous_triangle_, &obstacle_triangle_enabled_, nullptr,
                     mode_ == SolveMode::kPrecomputed ? &enabled_triangles_ : nullptr, &face_rise_m_});
  edge_pass_.Detect(tool_positions_m_, obstacle_positions_m_, edge_pass_parameters_, &edge_pass_points_,
                    {&edge_previous_triangle_, nullptr, &edge_node_enabled_});
  std::fill(tool_previous_triangle_.begin(), tool_previous_triangle_.end(), -1);
  std::fill(edge_previous_triangle_.begin(), edge_previous_triangle_.end(), -1);
  contacts_.clear();
  const auto& obstacle_index = obstacle_surface_.node_index;
  const auto& tool_index = tool_surface_.node_index;
  for (const ContactPoint& p : tool_pass_points_) {
    tool_previous_triangle_[static_cast<std::size_t>(p.node_slot)] = p.obstacle_triangle;
    StepContact& c = contacts_.emplace_back();
    c.pass = ContactPass::kToolNode;
    c.id = p.tool_node;
    c.slave_node = p.tool_node;
    c.master_triangle = p.obstacle_triangle;
    c.frame = obstacle_surface_.triangle_frames[static_cast<std::size_t>(p.obstacle_triangle)];
    c.num_tool = 1;
    c.tool_slots[0] = p.node_slot;
    c.tool_coefficients[0] = 1.0;
    c.num_obstacle = p.num_obstacle_nodes;
    for (int k = 0; k < p.num_obstacle_nodes; ++k) {
      c.obstacle_slots[static_cast<std::size_t>(k)] = obstacle_index[static_cast<std::size_t>(p.obstacle_nodes[static_cast<std::size_t>(k)])];
      c.obstacle_coefficients[static_cast<std::size_t>(k)] = -p.weights[static_cast<std::size_t>(k)];
    }
    c.obstacle_point_m = p.obstacle_point_m;
    c.predicted_gap_m = p.gap_m;
    tool_is_slave_[static_cast<std::size_t>(p.node_slot)] = 1;
  }
  const int tool_node_count = model_.tool().mesh().num_nodes();
  const auto& tool_reference = model_.tool().mesh().nodes_m;
  const bool all_obstacle_nodes_are_slaves = model_.scene().reverse_pass_all_nodes;
  for (const ContactPoint& p : edge_pass_points_) {
    edge_previous_triangle_[static_cast<std::size_t>(p.node_slot)] = p.obstacle_triangle;
    const auto triangle = static_cast<std::size_t>(p.obstacle_triangle);
    const fem::SurfaceTriangle& face = tool_surface_.triangles[triangle];
    // On a tool node in contact: pass 1 already has it. With the sharp-edge slaves only, also
    // on a sharp edge of the tool, where the tool's rim nodes are taken to hold it (the
    // benchmarks' tool is exactly as wide as the bar, so the bar's long edges lie on the
    // tool's rim); a full second pass keeps those, since the obstacle's nodes there may lie
    // between the tool's. Judged rigidly: reference positions, the tool translated by d.
    // Only where pass 1 holds that edge (both its corners in contact): a rim that lies exactly
    // on the obstacle's own edge (a tool flush with a clamped end) has its nodes on the edge of
    // the obstacle's faces, where pass 1 may miss them, and the obstacle's edge node is then
    // all that holds the tool there. (Covered unconditionally, that node's contact came and
    // went with which of the tool's faces at the rim corner the detector picked: a held pose
    // cycled 608 -> 679 -> 82 N for ever; docs/free-interaction.md.)
    auto slave = [&](int node) {
      const int slot = tool_index[static_cast<std::size_t>(node)];
      return slot >= 0 && tool_is_slave_[static_cast<std::size_t>(slot)] != 0;
    };
    const Eigen::Vector3d rigid = ProjectionBarycentric(
        model_.obstacle().mesh().nodes_m.row(p.tool_node).transpose(),
        tool_reference.row(face.corners[0]).transpose() + device_translation_m,
        tool_reference.row(face.corners[1]).transpose() + device_translation_m,
        tool_reference.row(face.corners[2]).transpose() + device_translation_m);
    bool covered = false;
    if (!all_obstacle_nodes_are_slaves) {
      for (int k = 0; k < 3; ++k) {
        covered = covered || (tool_surface_.sharp_edges[triangle][static_cast<std::size_t>(k)] &&
                              rigid[(k + 2) % 3] < kOnEdge && slave(face.corners[static_cast<std::size_t>(k)]) &&
                              slave(face.corners[static_cast<std::size_t>((k + 1) % 3)]));
      }
    }
    // On a tool node (corner or midside) that pass 1 holds, the same two material points would
    // be constrained twice, and the solver cannot split a force between two identical
    // constraints (W singular there).
    const int tool_node = FaceNodeAt(face, rigid);
    covered = covered || (tool_node >= 0 && tool_is_slave_[static_cast<std::size_t>(tool_index[static_cast<std::size_t>(tool_node)])]);
    if (covered) continue;
    StepContact& c = contacts_.emplace_back();
    c.pass = ContactPass::kObstacleNode;
    c.id = tool_node_count + p.tool_node;
    c.slave_node = p.tool_node;
    c.master_triangle = p.obstacle_triangle;
    c.frame = tool_surface_.triangle_frames[triangle];
    c.num_obstacle = 1;
    c.obstacle_slots[0] = edge_node_slot_[static_cast<std::size_t>(p.node_slot)];
    c.obstacle_coefficients[0] = 1.0;
    c.num_tool = p.num_obstacle_nodes;
    for (int k = 0; k < p.num_obstacle_nodes; ++k) {
      c.tool_slots[static_cast<std::size_t>(k)] = tool_index[static_cast<std::size_t>(p.obstacle_nodes[static_cast<std::size_t>(k)])];
      c.tool_coefficients[static_cast<std::size_t>(k)] = -p.weights[static_cast<std::size_t>(k)];
    }
    c.obstacle_point_m = obstacle_positions_m_.row(p.tool_node).transpose();
    c.predicted_gap_m = p.gap_m;
    ++output_.num_edge_contacts;
  }
  for (const ContactPoint& p : tool_pass_points_) tool_is_slave_[static_cast<std::size_t>(p.node_slot)] = 0;
}

const StepOutput& TwoBodySession::Step(const Eigen::Vector3d& device_translation_m) {
  if (!device_translation_m.allFinite()) {
    throw InputError("device translation must be finite");
  }
  if (!approaching()) {
    if (output_.step > 0 || device_translation_m.norm() <= kDirectFirstStepM ||
        !model_.ToolInsideObstacle(device_translation_m)) {
      const bool had_contacts = output_.num_contacts > 0;
      StepOnce(device_translation_m);
      // Its last contacts lost with the tool inside the obstacle: passed into it. Driven far
      // outside small strain (in from the side below the top and on into the bar, bending it
      // sideways by 15-20 mm; along a clamped end 5 mm deep), the deformed configuration the
      // detection works on no longer meets the tool, and the tool then sat 4 mm inside
      // benchmark 1's bar with 0 N for hundreds of steps (random paths, 2026-12-07). It
      // re-enters as a session opened there does: an approach from above (StartApproach).
      // (ToolInsideObstacle, at most a few us, only on the step that lost the last contact.)
      if (!(had_contacts && output_.num_contacts == 0) || model_.approach_normal().isZero() ||
          !model_.ToolInsideObstacle(device_translation_m)) {
        return output_;
      }
      output_.step -= 1;  // ContinueApproach counts this call's step
      StartApproach(device_translation_m, /*from_above=*/true);
      ContinueApproach(device_translation_m);
      output_.reentered = true;
      return output_;
    }
    StartApproach(device_translation_m);
  }
  return ContinueApproach(device_translation_m);
}

void TwoBodySession::StartApproach(const Eigen::Vector3d& device_translation_m, bool from_above) {
  // Where the device came from is unknown. The approach presses in along the start's contact
  // normal n, as a user meets a surface: lift 1 mm off it, move across above it, press to the
  // pose (with friction; a straight line from home dragged the tool sideways into the bar and
  // gave side forces of the wrong sign, and a frictionless one lost the sticking contacts'
  // share of the normal force: 2-3 % mid-span, 46 % next to a clamp; a helper session).
  constexpr double kLiftM = 1e-3;
  const Eigen::Vector3d& n = model_.approach_normal();
  approach_ = Approach{};
  if (from_above) {
    // The tool taken out, undeformed, to 1 mm above the pose along n, then pressed in.
    device_translation_m_ = device_translation_m - n * n.dot(device_translation_m) + kLiftM * n;
    Release();
    approach_.at_m = device_translation_m_;
    approach_.waypoints[static_cast<std::size_t>(approach_.num_waypoints++)] = device_translation_m;
    return;
  }
  approach_.at_m = device_translation_m_;
  if (n.norm() > 0) {
    const Eigen::Vector3d across = device_translation_m - n * n.dot(device_translation_m);
    approach_.waypoints[static_cast<std::size_t>(approach_.num_waypoints++)] = kLiftM * n;
    approach_.waypoints[static_cast<std::size_t>(approach_.num_waypoints++)] = across + kLiftM * n;
  }
  approach_.waypoints[static_cast<std::size_t>(approach_.num_waypoints++)] = device_translation_m;
}

const StepOutput& TwoBodySession::ContinueApproach(const Eigen::Vector3d& device_translation_m) {
  // 0.25 mm in contact: 0.4 % from a gradual 0.1 mm press 12 mm deep on the test bar and 0.09 %
  // 10 mm deep on benchmark 1 (0.1 mm: 0.25 % and 0.04 %, 2.4 times the poses; 0.5 mm: 1.1 %).
  constexpr double kApartStepM = 1e-3, kContactStepM = 2.5e-4;
  const int step = output_.step + 1;
  int approach_steps = 0;
  bool arrived = false;
  for (double budget = kApproachBudget; budget > 0.0;) {
    // Past the waypoints (the last is the first pose), the approach follows the device, which
    // may have moved meanwhile, in the same small steps: as a user would press in, then move.
    const bool following = approach_.next >= approach_.num_waypoints;
    const Eigen::Vector3d& to =
        following ? device_translation_m : approach_.waypoints[static_cast<std::size_t>(approach_.next)];
    const double step_m = output_.num_contacts > 0 ? kContactStepM : kApartStepM;
    if (approach_.next + 1 >= approach_.num_waypoints && (device_translation_m - approach_.at_m).norm() <= step_m) {
      arrived = true;  // the device's pose is a step away: the step below
      break;
    }
    const Eigen::Vector3d left = to - approach_.at_m;
    const bool reached = left.norm() <= step_m;
    approach_.at_m = reached ? to : Eigen::Vector3d(approach_.at_m + left * (step_m / left.norm()));
    StepOnce(approach_.at_m);
    ++approach_steps;
    budget -= output_.num_contacts > 0 ? 1.0 : kApproachApartCost;
    if (reached && !following) ++approach_.next;
  }
  if (arrived) {
    approach_ = Approach{};
    StepOnce(device_translation_m);
  }
  output_.step = step;  // the approach's own steps are not the session's
  output_.approach_steps = approach_steps;
  output_.approaching = !arrived;
  return output_;
}

const StepOutput& TwoBodySession::StepOnce(const Eigen::Vector3d& device_translation_m) {
  Stopwatch total;
  const int step = output_.step + 1;
  const double previous_force_n = output_.contact_force_n.norm();
  output_ = StepOutput{};
  output_.step = step;
  output_.device_translation_m = device_translation_m;

  // 1. Broad phase and both detection passes on the predicted configuration. The predicted
  //    obstacle still carries the last forces' deformation, so a tool that lifts by more than
  //    the activation gap in one step (a fast hand, a burst of lost poses) would find every pair
  //    beyond it, drop every contact, and sit inside the sprung-back bar with no contact left
  //    to persist and new ones that deep refused: after a step with contacts, the gap activates
  //    pairs within twice the step's travel too, and the solve (W holds the springback) decides
  //    which still push. (Without contacts nothing is loaded and nothing springs back.)
  Stopwatch watch;
  // 0. A tool lifted clear of the obstacle lets go. The staggered detection (step 1 below)
  //    finds contacts on the configuration the last forces predict; after a push far past what
  //    small strain describes (a device driven millimetres into a clamped end face, kN on a few
  //    nodes) that configuration is so bent that it still reaches the obstacle with the rigid
  //    tool millimetres clear of it, and the bent state is an equilibrium of the linear model:
  //    5 424 N at a pose that gives 0 N when reached through air (docs/free-interaction.md, "A
  //    tool driven into the clamped end face"). With every rigid gap open the only solution is
  //    zero force (TwoBodyModel::RigidToolClearOfObstacle), so the state is dropped.
  //    (Only a loaded state: contacts kept within the activation gap carry zero force.)
  const bool was_loaded = std::any_of(previous_ids_.begin(), previous_ids_.end(),
                                      [&](int id) { return !force_by_id_n_.segment<3>(3 * id).isZero(0.0); });
  if (was_loaded && model_.RigidToolClearOfObstacle(device_translation_m)) {
    Release();
    output_.released = true;
    output_.released_force_n = previous_force_n;
  }
  const double travel_m = (device_translation_m - device_translation_m_).norm();
  const double activation_gap_m =
      previous_ids_.empty() ? model_.scene().activation_gap_m : std::max(model_.scene().activation_gap_m, 2.0 * travel_m);
  tool_pass_parameters_.activation_gap_m = activation_gap_m;
  edge_pass_parameters_.activation_gap_m = activation_gap_m;
  BroadPhase(device_translation_m - device_translation_m_);
  DetectContacts(device_translation_m);
  CompleteContactDisplacements();
  output_.compliance_out_of_range = !WithinComplianceRange();
  device_translation_m_ = device_translation_m;
  output_.num_contacts = static_cast<int>(contacts_.size());
  output_.detect_seconds = watch.ElapsedSeconds();

  // 2. ũ and W for the active contacts. The tool's free displacement is linear in d
  //    (algorithms.md §6); the full-solve mode solves for it instead.
  watch.Restart();
  if (mode_ == SolveMode::kPrecomputed) {
    tool_free_m_.noalias() = model_.tool_unit_fields() * device_translation_m_;
    AssembleBlocked(tool_surface_.compliance_m_per_n, obstacle_surface_.compliance_m_per_n);
  } else {
    // The paper's way: compliance columns of the active nodes solved with the factors now.
    for (int slot : active_tool_) active_tool_rows_[static_cast<std::size_t>(slot)] = -1;
    for (int slot : active_obstacle_) active_obstacle_rows_[static_cast<std::size_t>(slot)] = -1;
    active_tool_.clear();
    active_obstacle_.clear();
    for (const StepContact& c : contacts_) {
      for (int k = 0; k < c.num_tool; ++k) active_tool_.push_back(c.tool_slots[static_cast<std::size_t>(k)]);
      for (int k = 0; k < c.num_obstacle; ++k) active_obstacle_.push_back(c.obstacle_slots[static_cast<std::size_t>(k)]);
    }
    for (auto* slots : {&active_tool_, &active_obstacle_}) {
      std::sort(slots->begin(), slots->end());
      slots->erase(std::unique(slots->begin(), slots->end()), slots->end());
    }
    std::vector<int> tool_nodes, obstacle_nodes;
    for (int i = 0; i < static_cast<int>(active_tool_.size()); ++i) {
      active_tool_rows_[static_cast<std::size_t>(active_tool_[static_cast<std::size_t>(i)])] = i;
      tool_nodes.push_back(tool_surface_.nodes[static_cast<std::size_t>(active_tool_[static_cast<std::size_t>(i)])]);
    }
    for (int i = 0; i < static_cast<int>(active_obstacle_.size()); ++i) {
      active_obstacle_rows_[static_cast<std::size_t>(active_obstacle_[static_cast<std::size_t>(i)])] = i;
      obstacle_nodes.push_back(obstacle_surface_.nodes[static_cast<std::size_t>(active_obstacle_[static_cast<std::size_t>(i)])]);
    }
    const Eigen::VectorXd free_m = model_.tool().SolveDisplacement(
        Eigen::VectorXd::Zero(model_.tool().num_dofs()), device_translation_m_);
    for (int i = 0; i < static_cast<int>(tool_surface_.nodes.size()); ++i) {
      tool_free_m_.segment<3>(3 * i) = free_m.segment<3>(3 * tool_surface_.nodes[static_cast<std::size_t>(i)]);
    }
    const Eigen::MatrixXd tool_block = model_.tool().ComplianceBlock(tool_nodes);
    const Eigen::MatrixXd obstacle_block = model_.obstacle().ComplianceBlock(obstacle_nodes);
    AssembleDense(tool_block, active_tool_rows_, obstacle_block, active_obstacle_rows_);
  }
  output_.assemble_seconds = watch.ElapsedSeconds();

  // 3. Solve, warm-started from the last forces of the same contacts.
  watch.Restart();
  const int m = static_cast<int>(contacts_.size());
  if (m > 0) {
    result_.force_n.resize(3 * m);
    for (int alpha = 0; alpha < m; ++alpha) {
      const StepContact& c = contacts_[static_cast<std::size_t>(alpha)];
      result_.force_n.segment<3>(3 * alpha) = c.frame * Block(force_by_id_n_, c.id);
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

  // 4. Forces back to the bodies (algorithms.md §5): node p carries c_p Rᵀ r.
  watch.Restart();
  for (int slot : tool_loaded_) tool_slot_loaded_[static_cast<std::size_t>(slot)] = 0;
  for (int slot : obstacle_loaded_) obstacle_slot_loaded_[static_cast<std::size_t>(slot)] = 0;
  tool_loaded_.clear();
  obstacle_loaded_.clear();
  last_residual_penetration_m_ = 0.0;
  for (int id : previous_ids_) force_by_id_n_.segment<3>(3 * id).setZero();
  previous_ids_.clear();
  auto load = [](int slot, const Eigen::Vector3d& f, std::vector<char>* loaded, std::vector<int>* list,
                 Eigen::VectorXd* forces) {
    if (!(*loaded)[static_cast<std::size_t>(slot)]) {
      (*loaded)[static_cast<std::size_t>(slot)] = 1;
      list->push_back(slot);
      forces->segment<3>(3 * slot).setZero();
    }
    forces->segment<3>(3 * slot) += f;
  };
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& c = contacts_[static_cast<std::size_t>(alpha)];
    const Eigen::Vector3d world_n = c.frame.transpose() * result_.force_n.segment<3>(3 * alpha);
    force_by_id_n_.segment<3>(3 * c.id) = world_n;
    previous_ids_.push_back(c.id);
    for (int k = 0; k < c.num_tool; ++k) {
      const Eigen::Vector3d f = c.tool_coefficients[static_cast<std::size_t>(k)] * world_n;
      load(c.tool_slots[static_cast<std::size_t>(k)], f, &tool_slot_loaded_, &tool_loaded_, &tool_slot_force_n_);
      output_.contact_force_n += f;
    }
    for (int k = 0; k < c.num_obstacle; ++k) {
      load(c.obstacle_slots[static_cast<std::size_t>(k)], c.obstacle_coefficients[static_cast<std::size_t>(k)] * world_n,
           &obstacle_slot_loaded_, &obstacle_loaded_, &obstacle_slot_force_n_);
    }
    last_residual_penetration_m_ = std::max(last_residual_penetration_m_, -result_.displacement_m[3 * alpha]);
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

template <typename PairBlocks>
void TwoBodySession::AssembleProblem(const PairBlocks& pair_blocks) {
  const int m = static_cast<int>(contacts_.size());
  // Same-size resizes are free in Eigen: the 1 kHz path allocates only when m changes.
  problem_.flexibility_m_per_n.resize(3 * m, 3 * m);
  problem_.free_displacement_m.resize(3 * m);
  problem_.friction_coefficient.setConstant(m, model_.scene().friction_coefficient);
  const auto& tool_reference = model_.tool().mesh().nodes_m;
  const auto& obstacle_reference = model_.obstacle().mesh().nodes_m;
  for (int alpha = 0; alpha < m; ++alpha) {
    const StepContact& a = contacts_[static_cast<std::size_t>(alpha)];
    // Signorini on the total gap, Coulomb on the slip increment (algorithms.md §2).
    Eigen::Vector3d total_m = Eigen::Vector3d::Zero(), increment_m = Eigen::Vector3d::Zero();
    for (int k = 0; k < a.num_tool; ++k) {
      const int slot = a.tool_slots[static_cast<std::size_t>(k)];
      const double c = a.tool_coefficients[static_cast<std::size_t>(k)];
      const Eigen::Vector3d free_m = Block(tool_free_m_, slot);
      total_m += c * (tool_reference.row(tool_surface_.nodes[static_cast<std::size_t>(slot)]).transpose() + free_m);
      increment_m += c * (free_m - Block(tool_displacement_m_, slot));
    }
    for (int k = 0; k < a.num_obstacle; ++k) {
      const int slot = a.obstacle_slots[static_cast<std::size_t>(k)];
      const double c = a.obstacle_coefficients[static_cast<std::size_t>(k)];
      total_m += c * obstacle_reference.row(obstacle_surface_.nodes[static_cast<std::size_t>(slot)]).transpose();
      increment_m -= c * Block(obstacle_displacement_m_, slot);
    }
    problem_.free_displacement_m[3 * alpha] = a.frame.row(0).dot(total_m);
    problem_.free_displacement_m.segment<2>(3 * alpha + 1) = a.frame.bottomRows<2>() * increment_m;
  }
  // W_αβ = R_α [Σ_pq c_αp c_βq C(p, q)] R_βᵀ over both bodies; W is symmetric, so α ≤ β. β
  // outermost: the pair sums read C(p, q) in the columns q of β's nodes (BlockedCompliance),
  // so one β's few columns serve every α in a row.
  for (int beta = 0; beta < m; ++beta) {
    const StepContact& b = contacts_[static_cast<std::size_t>(beta)];
    for (int alpha = 0; alpha <= beta; ++alpha) {
      const StepContact& a = contacts_[static_cast<std::size_t>(alpha)];
      const Eigen::Matrix3d world = pair_blocks(a, b);
      Eigen::Matrix3d local = a.frame * world * b.frame.transpose();
      if (beta == alpha && local(0, 0) < model_.rigid_contact_compliance_m_per_n()) {
        // Rigid against rigid (both sides Dirichlet): see TwoBodyModel.
        local.diagonal().array() += model_.rigid_contact_compliance_m_per_n();
      }
      problem_.flexibility_m_per_n.block<3, 3>(3 * alpha, 3 * beta) = local;
      if (beta != alpha) problem_.flexibility_m_per_n.block<3, 3>(3 * beta, 3 * alpha) = local.transpose();
    }
  }
}

void TwoBodySession::AssembleBlocked(const BlockedCompliance& tool, const BlockedCompliance& obstacle) {
  AssembleProblem([&](const StepContact& a, const StepContact& b) -> Eigen::Matrix3d {
    return WeightedBlockSum(compliance_kernel, tool, a.tool_slots, a.tool_coefficients, a.num_tool, b.tool_slots,
                            b.tool_coefficients, b.num_tool) +
           WeightedBlockSum(compliance_kernel, obstacle, a.obstacle_slots, a.obstacle_coefficients, a.num_obstacle,
                            b.obstacle_slots, b.obstacle_coefficients, b.num_obstacle);
  });
}

void TwoBodySession::AssembleDense(const Eigen::MatrixXd& tool, const std::vector<int>& tool_rows,
                                   const Eigen::MatrixXd& obstacle, const std::vector<int>& obstacle_rows) {
  AssembleProblem([&](const StepContact& a, const StepContact& b) -> Eigen::Matrix3d {
    return WeightedBlockSum(tool, tool_rows, a.tool_slots, a.tool_coefficients, a.num_tool, b.tool_slots,
                            b.tool_coefficients, b.num_tool) +
           WeightedBlockSum(obstacle, obstacle_rows, a.obstacle_slots, a.obstacle_coefficients, a.num_obstacle,
                            b.obstacle_slots, b.obstacle_coefficients, b.num_obstacle);
  });
}

void TwoBodySession::UpdatePrecomputed() {
  // U_tool = U_free(d) + C f over the tool surface (algorithms.md §5, §6), from the compliance
  // columns of the loaded slots only. The obstacle's U is evaluated by the next broad phase on
  // the region it needs, from the loaded slots kept here.
  // The same kernel as the obstacle's region (AddComplianceTimesForces), on every tool slot.
  tool_displacement_m_ = tool_free_m_;
  std::sort(tool_loaded_.begin(), tool_loaded_.end());
  tool_free_.clear();
  const int n_tool = tool_surface_.compliance_m_per_n.nodes();
  for (int i = 0; i < n_tool; ++i) {
    if (!tool_slot_loaded_[static_cast<std::size_t>(i)]) tool_free_.push_back(i);
  }
  SlotRuns(tool_free_, &tool_free_runs_);
  SlotRuns(tool_loaded_, &tool_loaded_runs_);
  AddComplianceTimesForces(compliance_kernel, tool_surface_.compliance_m_per_n, tool_free_runs_, tool_loaded_,
                           tool_loaded_runs_, tool_slot_force_n_.data(), tool_displacement_m_.data());
}

ContactSample TwoBodySession::SampleContact(int alpha) const {
  HAPCO_ASSERT(alpha >= 0 && alpha < static_cast<int>(contacts_.size()) && 3 * alpha + 3 <= result_.force_n.size(),
               "contact index out of range");
  const StepContact& contact = contacts_[static_cast<std::size_t>(alpha)];
  const Eigen::Vector3d r = result_.force_n.segment<3>(3 * alpha);
  const Eigen::Vector3d u = result_.displacement_m.segment<3>(3 * alpha);
  // r acts on the slave: the tool in pass 1, the obstacle in pass 2.
  const double tool_sign = contact.pass == ContactPass::kToolNode ? 1.0 : -1.0;
  ContactSample sample;
  sample.tool_node = contact.id;
  sample.pass = contact.pass;
  sample.position_m = contact.obstacle_point_m;
  sample.normal = tool_sign * contact.frame.row(0).transpose();
  sample.force_n = tool_sign * (contact.frame.transpose() * r);
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
    const StepContact& c = contacts_[static_cast<std::size_t>(alpha)];
    const Eigen::Vector3d world_n = c.frame.transpose() * result_.force_n.segment<3>(3 * alpha);
    for (int k = 0; k < c.num_tool; ++k) {
      tool_n->segment<3>(3 * tool_surface_.nodes[static_cast<std::size_t>(c.tool_slots[static_cast<std::size_t>(k)])]) +=
          c.tool_coefficients[static_cast<std::size_t>(k)] * world_n;
    }
    for (int k = 0; k < c.num_obstacle; ++k) {
      obstacle_n->segment<3>(3 * obstacle_surface_.nodes[static_cast<std::size_t>(c.obstacle_slots[static_cast<std::size_t>(k)])]) +=
          c.obstacle_coefficients[static_cast<std::size_t>(k)] * world_n;
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
  // The paper's per-step solves: full fields from the factors, then read the surfaces.
  Eigen::VectorXd obstacle_m, tool_m;
  FullDisplacements(&obstacle_m, &tool_m);
  const auto& obstacle_nodes = obstacle_surface_.nodes;
  const auto& tool_nodes = tool_surface_.nodes;
  for (int i = 0; i < static_cast<int>(obstacle_nodes.size()); ++i) {
    obstacle_displacement_m_.segment<3>(3 * i) = obstacle_m.segment<3>(3 * obstacle_nodes[static_cast<std::size_t>(i)]);
  }
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    tool_displacement_m_.segment<3>(3 * i) = tool_m.segment<3>(3 * tool_nodes[static_cast<std::size_t>(i)]);
  }
}

}  // namespace hapco::sim
