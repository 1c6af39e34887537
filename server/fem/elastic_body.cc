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

// LAPACK (Debian's liblapack, OpenBLAS when installed): inverse of an SPD matrix from its
// Cholesky factor, in place in the given triangle.
extern "C" void dpotri_(const char* uplo, const int* n, double* a, const int* lda, int* info);

namespace {

// Eigen's wrapper, with read access to the CHOLMOD factor it holds (for its fill-reducing
// permutation, reused by the compliance block below).
class SupernodalLlt : public Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> {
 public:
  const cholmod_factor* factor() const { return m_cholmodFactor; }
};

}  // namespace

struct ElasticBody::Factor {
  SupernodalLlt llt;
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

  const int nf = num_free_dofs();
  if (nf > 0) {
    watch.Restart();
    const Eigen::SparseMatrix<double> k_ff = FreeStiffnessLower();
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

Eigen::SparseMatrix<double> ElasticBody::FreeStiffnessLower() const {
  // K_ff, lower triangle only (CHOLMOD reads one triangle of a symmetric matrix).
  const int dofs = num_dofs();
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
  Eigen::SparseMatrix<double> k_ff(num_free_dofs(), num_free_dofs());
  k_ff.setFromTriplets(entries.begin(), entries.end());
  return k_ff;
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

Eigen::MatrixXd ElasticBody::ComplianceBlockBySolves(std::span<const int> nodes) const {
  CheckNodes(nodes, "compliance");
  const int s = static_cast<int>(nodes.size());
  const int nf = num_free_dofs();
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(3 * s, 3 * s);
  if (nf == 0 || s == 0) return c;
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
  for (int start = 0; start < total; start += max_chunk) {
    const int width = std::min(max_chunk, total - start);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(nf, width);
    for (int k = 0; k < width; ++k) rhs(columns[static_cast<std::size_t>(start + k)].second, k) = 1.0;
    const Eigen::MatrixXd x = SolveFree(rhs);
    for (int k = 0; k < width; ++k)
      for (const auto& [block_row, f] : columns) c(block_row, columns[static_cast<std::size_t>(start + k)].first) = x(f, k);
  }
  return c;
}

namespace {

// A CHOLMOD workspace that is freed on every path out.
struct CholmodSession {
  cholmod_common common{};
  cholmod_factor* factor = nullptr;
  CholmodSession() { cholmod_start(&common); }
  ~CholmodSession() {
    if (factor != nullptr) cholmod_free_factor(&factor, &common);
    cholmod_finish(&common);
  }
  CholmodSession(const CholmodSession&) = delete;
  CholmodSession& operator=(const CholmodSession&) = delete;
};

}  // namespace

void ElasticBody::ComplianceColumns(
    std::span<const int> nodes, const std::function<void(int, const Eigen::Ref<const Eigen::VectorXd>&)>& sink) const {
  CheckNodes(nodes, "compliance");
  const int s = static_cast<int>(nodes.size());
  const int nf = num_free_dofs();
  if (nf == 0 || s == 0) return;
  // Free dofs of the block, once each: S. A node listed twice gives the same columns twice.
  std::vector<int> block_to_s(static_cast<std::size_t>(3 * s), -1);
  std::vector<int> s_to_free;
  std::vector<int> free_to_s(static_cast<std::size_t>(nf), -1);
  for (int j = 0; j < s; ++j)
    for (int b = 0; b < 3; ++b) {
      const int f = dof_to_free_[static_cast<std::size_t>(3 * nodes[static_cast<std::size_t>(j)] + b)];
      if (f < 0) continue;
      if (free_to_s[static_cast<std::size_t>(f)] < 0) {
        free_to_s[static_cast<std::size_t>(f)] = static_cast<int>(s_to_free.size());
        s_to_free.push_back(f);
      }
      block_to_s[static_cast<std::size_t>(3 * j + b)] = free_to_s[static_cast<std::size_t>(f)];
    }
  const int m = static_cast<int>(s_to_free.size());
  if (m == 0) return;

  // C_SS = (K_ff^-1)_SS = (K_SS - K_SI K_II^-1 K_IS)^-1: factor K_ff once more with S ordered
  // last, so the trailing m x m block L_SS of the Cholesky factor is the Schur complement's own
  // factor (L_SS L_SS^T), and invert that small dense SPD matrix with LAPACK (dpotri). This
  // costs one sparse factorization plus O(m^3) dense work, instead of m full solves with the
  // factor (each O(nnz(L))): at ~100k dofs and m ~ 2600 that was two minutes.
  // The interior keeps the body factor's fill-reducing order (an elimination order restricted
  // to a subgraph fills no more than it did in the whole graph).
  const cholmod_factor* body_factor = factor_->llt.factor();
  HAPCO_ASSERT(body_factor != nullptr && static_cast<int>(body_factor->n) == nf, "no CHOLMOD factor of K_ff");
  const int* body_perm = static_cast<const int*>(body_factor->Perm);
  std::vector<int> perm;
  perm.reserve(static_cast<std::size_t>(nf));
  for (int k = 0; k < nf; ++k)
    if (free_to_s[static_cast<std::size_t>(body_perm[k])] < 0) perm.push_back(body_perm[k]);
  perm.insert(perm.end(), s_to_free.begin(), s_to_free.end());

  const Eigen::SparseMatrix<double> k_ff = FreeStiffnessLower();
  cholmod_sparse a = Eigen::viewAsCholmod(k_ff.selfadjointView<Eigen::Lower>());
  CholmodSession cholmod;
  cholmod.common.nmethods = 1;
  cholmod.common.method[0].ordering = CHOLMOD_GIVEN;
  cholmod.common.postorder = 0;  // a postorder could move S away from the end
  cholmod.common.supernodal = CHOLMOD_SUPERNODAL;
  cholmod.factor = cholmod_analyze_p(&a, perm.data(), nullptr, 0, &cholmod.common);
  HAPCO_ASSERT(cholmod.factor != nullptr, "CHOLMOD analysis with S last failed");
  const int* used_perm = static_cast<const int*>(cholmod.factor->Perm);
  for (int k = 0; k < nf; ++k) HAPCO_ASSERT(used_perm[k] == perm[static_cast<std::size_t>(k)], "CHOLMOD did not keep the given order");
  cholmod_factorize(&a, cholmod.factor, &cholmod.common);
  HAPCO_ASSERT(cholmod.common.status == CHOLMOD_OK && static_cast<int>(cholmod.factor->minor) == nf,
               "CHOLMOD factorization with S last failed (the body factor succeeded)");
  HAPCO_ASSERT(cholmod.factor->is_super, "expected a supernodal factor");

  // Copy the trailing block out of the supernodes: supernode t holds columns super[t] ..
  // super[t+1]-1 as a dense column-major nrows x ncols array at px[t], rows listed at pi[t].
  const int offset = nf - m;
  Eigen::MatrixXd inverse = Eigen::MatrixXd::Zero(m, m);
  const auto* super = static_cast<const int*>(cholmod.factor->super);
  const auto* pi = static_cast<const int*>(cholmod.factor->pi);
  const auto* px = static_cast<const int*>(cholmod.factor->px);
  const auto* rows = static_cast<const int*>(cholmod.factor->s);
  const auto* values = static_cast<const double*>(cholmod.factor->x);
  for (std::size_t t = 0; t < cholmod.factor->nsuper; ++t) {
    const int first_col = super[t], end_col = super[t + 1];
    if (end_col <= offset) continue;
    const int nrows = pi[t + 1] - pi[t];
    for (int col = std::max(first_col, offset); col < end_col; ++col) {
      const double* column = values + px[t] + static_cast<std::ptrdiff_t>(col - first_col) * nrows;
      for (int r = col - first_col; r < nrows; ++r) {
        const int row = rows[pi[t] + r];
        if (row >= offset) inverse(row - offset, col - offset) = column[r];
      }
    }
  }
  cholmod_free_factor(&cholmod.factor, &cholmod.common);
  int info = 0;
  dpotri_("L", &m, inverse.data(), &m, &info);
  HAPCO_ASSERT(info == 0, "LAPACK dpotri failed on the contact nodes' Schur factor");
  for (int c = 1; c < m; ++c)
    for (int r = 0; r < c; ++r) inverse(r, c) = inverse(c, r);

  Eigen::VectorXd column = Eigen::VectorXd::Zero(3 * s);
  for (int c = 0; c < 3 * s; ++c) {
    const int sc = block_to_s[static_cast<std::size_t>(c)];
    if (sc < 0) continue;
    for (int r = 0; r < 3 * s; ++r) {
      const int sr = block_to_s[static_cast<std::size_t>(r)];
      column[r] = sr < 0 ? 0.0 : inverse(sr, sc);
    }
    sink(c, column);
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
