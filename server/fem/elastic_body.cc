#include "fem/elastic_body.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <string>
#include <utility>

#include <Eigen/Geometry>

// GCC's -Wnull-dereference fires inside Eigen's CHOLMOD view of the sparse matrix (an inlined
// path for an empty matrix that cannot occur here: K_ff has nf > 0 columns).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <Eigen/CholmodSupport>
#pragma GCC diagnostic pop

#include "common/error.h"
#include "common/timer.h"
#include "fem/assembly.h"

namespace hapco::fem {

struct ElasticBody::Factor {
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> llt;
};

ElasticBody::~ElasticBody() = default;
ElasticBody::ElasticBody(ElasticBody&&) noexcept = default;
ElasticBody& ElasticBody::operator=(ElasticBody&&) noexcept = default;

void ElasticBody::CheckNodes(std::span<const int> nodes, const char* what) const {
  for (const int n : nodes) {
    if (n < 0 || n >= spec_.mesh.num_nodes()) {
      throw InputError(std::string(what) + " node " + std::to_string(n) + " is outside 0.." +
                       std::to_string(spec_.mesh.num_nodes() - 1));
    }
  }
}

void ElasticBody::CheckRigidMotionsStopped() const {
  // All three dofs of every Dirichlet node are fixed, so a rigid motion t + w x p survives only
  // if the nodes are collinear (then rotation about their line is free). Checking this here
  // gives a clear message; a numerically singular K_ff might otherwise factor "successfully".
  const auto& x = spec_.mesh.nodes_m;
  const double size_m = (x.colwise().maxCoeff() - x.colwise().minCoeff()).norm();
  std::vector<int> nodes = spec_.clamped_nodes;
  nodes.insert(nodes.end(), spec_.driven_nodes.begin(), spec_.driven_nodes.end());
  const Eigen::RowVector3d p0 = x.row(nodes.front());
  int far = nodes.front();
  for (const int n : nodes)
    if ((x.row(n) - p0).squaredNorm() > (x.row(far) - p0).squaredNorm()) far = n;
  const Eigen::Vector3d axis = (x.row(far) - p0).transpose();
  bool spans_plane = false;
  for (const int n : nodes) {
    const Eigen::Vector3d r = (x.row(n) - p0).transpose();
    if (axis.cross(r).norm() > 1e-8 * size_m * size_m) {
      spans_plane = true;
      break;
    }
  }
  if (!spans_plane) {
    throw InputError("singular stiffness: the " + std::to_string(nodes.size()) +
                     " clamped/driven nodes lie on one line, so the body can still rotate "
                     "about it; hold at least three non-collinear nodes (e.g. a whole face)");
  }
}

ElasticBody::ElasticBody(Spec spec) : spec_(std::move(spec)) {
  Stopwatch watch;
  // AssembleStiffness validates mesh and material; the node lists are checked here first so
  // the cheapest mistakes are reported before any assembly work.
  ValidateMesh(spec_.mesh);
  ValidateMaterial(spec_.material);
  CheckNodes(spec_.clamped_nodes, "clamped");
  CheckNodes(spec_.driven_nodes, "driven");
  for (auto* list : {&spec_.clamped_nodes, &spec_.driven_nodes}) {
    std::sort(list->begin(), list->end());
    list->erase(std::unique(list->begin(), list->end()), list->end());
  }
  if (spec_.clamped_nodes.empty() && spec_.driven_nodes.empty()) {
    throw InputError("singular stiffness: body has no clamped or driven nodes "
                     "(add Dirichlet nodes that stop every rigid motion)");
  }
  std::vector<int> both;
  std::set_intersection(spec_.clamped_nodes.begin(), spec_.clamped_nodes.end(),
                        spec_.driven_nodes.begin(), spec_.driven_nodes.end(),
                        std::back_inserter(both));
  if (!both.empty()) {
    throw InputError("node " + std::to_string(both.front()) +
                     " is both clamped and driven; a node can have one Dirichlet condition");
  }

  CheckRigidMotionsStopped();

  stiffness_ = AssembleStiffness(spec_.mesh, spec_.material);
  // Found with the scene fuzz harness: E = 1e308 Pa on a 100 m box overflows to inf entries, and
  // CHOLMOD factors such a matrix without complaint (every later solve is NaN).
  for (Eigen::Index k = 0; k < stiffness_.nonZeros(); ++k) {
    if (!std::isfinite(stiffness_.valuePtr()[k])) {
      throw InputError("stiffness has non-finite entries: Young's modulus times the element size "
                       "overflows (give the material and the box in SI units, within physical ranges)");
    }
  }
  const int dofs = num_dofs();
  dof_to_free_.assign(static_cast<std::size_t>(dofs), 0);
  for (const auto* list : {&spec_.clamped_nodes, &spec_.driven_nodes})
    for (const int n : *list)
      for (int a = 0; a < 3; ++a) dof_to_free_[static_cast<std::size_t>(3 * n + a)] = -1;
  for (int d = 0; d < dofs; ++d) {
    if (dof_to_free_[static_cast<std::size_t>(d)] < 0) continue;
    dof_to_free_[static_cast<std::size_t>(d)] = static_cast<int>(free_to_dof_.size());
    free_to_dof_.push_back(d);
  }
  stats_.assembly_seconds = watch.ElapsedSeconds();
  stats_.stiffness_nonzeros = static_cast<long>(stiffness_.nonZeros());
  stats_.free_dofs = num_free_dofs();

  // K_ff, lower triangle only (CHOLMOD reads one triangle of a symmetric matrix).
  const int nf = num_free_dofs();
  if (nf > 0) {
    watch.Restart();
    std::vector<Eigen::Triplet<double>> entries;
    entries.reserve(static_cast<std::size_t>(stiffness_.nonZeros() / 2 + dofs));
    for (int col = 0; col < dofs; ++col) {
      const int fc = dof_to_free_[static_cast<std::size_t>(col)];
      if (fc < 0) continue;
      for (Eigen::SparseMatrix<double>::InnerIterator it(stiffness_, col); it; ++it) {
        const int fr = dof_to_free_[static_cast<std::size_t>(it.row())];
        if (fr >= fc) entries.emplace_back(fr, fc, it.value());
      }
    }
    Eigen::SparseMatrix<double> k_ff(nf, nf);
    k_ff.setFromTriplets(entries.begin(), entries.end());
    entries = {};
    factor_ = std::make_unique<Factor>();
    factor_->llt.compute(k_ff);
    if (factor_->llt.info() != Eigen::Success) {
      throw InputError("stiffness is not positive definite after removing the clamped and "
                       "driven nodes: the Dirichlet nodes must stop every rigid motion (clamp "
                       "a face, not one or two nodes)");
    }
    stats_.factorization_seconds = watch.ElapsedSeconds();
    stats_.factor_nonzeros = static_cast<long>(factor_->llt.cholmod().lnz);
  }

  unit_fields_ = Eigen::MatrixXd::Zero(dofs, 3);
  if (!spec_.driven_nodes.empty()) {
    const Eigen::VectorXd no_load = Eigen::VectorXd::Zero(dofs);
    for (int a = 0; a < 3; ++a)
      unit_fields_.col(a) = SolveDisplacement(no_load, Eigen::Vector3d::Unit(a));
  }
}

Eigen::MatrixXd ElasticBody::SolveFree(const Eigen::MatrixXd& rhs_free) const {
  HAPCO_ASSERT(factor_ != nullptr, "no free dofs to solve for");
  Eigen::MatrixXd x = factor_->llt.solve(rhs_free);
  HAPCO_ASSERT(factor_->llt.info() == Eigen::Success, "CHOLMOD solve failed");
  return x;
}

Eigen::VectorXd ElasticBody::SolveDisplacement(const Eigen::VectorXd& nodal_force_n,
                                               const Eigen::Vector3d& driven_translation_m) const {
  const int dofs = num_dofs();
  if (nodal_force_n.size() != dofs) {
    throw InputError("nodal force vector has " + std::to_string(nodal_force_n.size()) +
                     " entries, the body has " + std::to_string(dofs) + " dofs (3 per node)");
  }
  Eigen::VectorXd u = Eigen::VectorXd::Zero(dofs);
  for (const int n : spec_.driven_nodes) u.segment<3>(3 * n) = driven_translation_m;
  const int nf = num_free_dofs();
  if (nf == 0) return u;
  // f_f - K_fd u_d; K u with u zero on free dofs gives exactly K_fd u_d on free rows.
  Eigen::VectorXd rhs(nf);
  if (spec_.driven_nodes.empty() || driven_translation_m.isZero(0.0)) {
    for (int i = 0; i < nf; ++i) rhs[i] = nodal_force_n[free_to_dof_[static_cast<std::size_t>(i)]];
  } else {
    const Eigen::VectorXd k_u = stiffness_ * u;
    for (int i = 0; i < nf; ++i) {
      const int d = free_to_dof_[static_cast<std::size_t>(i)];
      rhs[i] = nodal_force_n[d] - k_u[d];
    }
  }
  const Eigen::VectorXd x = SolveFree(rhs);
  for (int i = 0; i < nf; ++i) u[free_to_dof_[static_cast<std::size_t>(i)]] = x[i];
  return u;
}

Eigen::MatrixXd ElasticBody::ComplianceBlock(std::span<const int> nodes) const {
  CheckNodes(nodes, "compliance");
  const auto n = static_cast<Eigen::Index>(3 * nodes.size());
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(n, n);
  ComplianceColumns(nodes, [&c](int column, const Eigen::Ref<const Eigen::VectorXd>& values) { c.col(column) = values; });
  return c;
}

void ElasticBody::ComplianceColumns(
    std::span<const int> nodes, const std::function<void(int, const Eigen::Ref<const Eigen::VectorXd>&)>& sink) const {
  CheckNodes(nodes, "compliance");
  const int s = static_cast<int>(nodes.size());
  const int nf = num_free_dofs();
  if (nf == 0 || s == 0) return;
  // Free columns of the block: (position in the block, free dof index).
  std::vector<std::pair<int, int>> columns;
  for (int j = 0; j < s; ++j)
    for (int b = 0; b < 3; ++b) {
      const int f = dof_to_free_[static_cast<std::size_t>(3 * nodes[static_cast<std::size_t>(j)] + b)];
      if (f >= 0) columns.emplace_back(3 * j + b, f);
    }
  // Chunk width: two nf x chunk dense arrays (rhs and solution) of at most ~32 MB each.
  const int max_chunk = std::clamp(static_cast<int>(4'000'000 / nf), 1, 512);
  const int total = static_cast<int>(columns.size());
  Eigen::VectorXd column = Eigen::VectorXd::Zero(3 * s);
  for (int start = 0; start < total; start += max_chunk) {
    const int width = std::min(max_chunk, total - start);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(nf, width);
    for (int k = 0; k < width; ++k) rhs(columns[static_cast<std::size_t>(start + k)].second, k) = 1.0;
    const Eigen::MatrixXd x = SolveFree(rhs);
    for (int k = 0; k < width; ++k) {
      for (const auto& [block_row, f] : columns) column[block_row] = x(f, k);
      sink(columns[static_cast<std::size_t>(start + k)].first, column);
    }
  }
}

Eigen::Vector3d ElasticBody::ReactionForce(const Eigen::VectorXd& displacement_m,
                                           const Eigen::VectorXd& nodal_force_n,
                                           std::span<const int> nodes) const {
  const int dofs = num_dofs();
  if (displacement_m.size() != dofs || nodal_force_n.size() != dofs) {
    throw InputError("ReactionForce needs displacement and force vectors of " +
                     std::to_string(dofs) + " entries (3 per node)");
  }
  CheckNodes(nodes, "reaction");
  // K is symmetric with both triangles stored: row d of K U is column d dotted with U.
  Eigen::Vector3d total = Eigen::Vector3d::Zero();
  for (const int n : nodes)
    for (int a = 0; a < 3; ++a) {
      const int d = 3 * n + a;
      total[a] += stiffness_.col(d).dot(displacement_m) - nodal_force_n[d];
    }
  return total;
}

}  // namespace hapco::fem
