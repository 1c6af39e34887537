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

// Eigen's wrapper, with read access to the CHOLMOD factor it holds (its permutation and its
// trailing supernodes, read by the compliance block below).
class SupernodalLlt : public Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> {
 public:
  const cholmod_factor* factor() const { return m_cholmodFactor; }
};

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

// CHOLMOD's fill-reducing order of K_ff (its default choice among AMD and METIS), from a
// symbolic analysis only.
std::vector<int> FillReducingOrder(const Eigen::SparseMatrix<double>& k_ff_lower) {
  cholmod_sparse a = Eigen::viewAsCholmod(k_ff_lower.selfadjointView<Eigen::Lower>());
  CholmodSession cholmod;
  cholmod.factor = cholmod_analyze(&a, &cholmod.common);
  HAPCO_ASSERT(cholmod.factor != nullptr, "CHOLMOD analysis of K_ff failed");
  const int* perm = static_cast<const int*>(cholmod.factor->Perm);
  return {perm, perm + a.nrow};
}

// `order` with the dofs listed in `trailing` (trailing_index[f] >= 0) moved to the end, in that list's order.
// The others keep their relative order: an elimination order restricted to a subgraph fills no
// more than it did in the whole graph.
std::vector<int> OrderWithTrailing(const std::vector<int>& order, const std::vector<int>& trailing,
                                   const std::vector<int>& trailing_index) {
  std::vector<int> result;
  result.reserve(order.size());
  for (int f : order)
    if (trailing_index[static_cast<std::size_t>(f)] < 0) result.push_back(f);
  result.insert(result.end(), trailing.begin(), trailing.end());
  return result;
}

// Copies the trailing m x m block L_TT of a supernodal factor whose last m columns are T into
// `out` (column-major, leading dimension ld; lower triangle only). Supernode t holds columns
// super[t] .. super[t+1]-1 as a dense column-major nrows x ncols array at px[t], rows listed at
// pi[t].
void CopyTrailingBlock(const cholmod_factor& f, int m, double* out, std::ptrdiff_t ld) {
  HAPCO_ASSERT(f.is_super, "expected a supernodal factor");
  const int n = static_cast<int>(f.n);
  const int offset = n - m;
  const auto* super = static_cast<const int*>(f.super);
  const auto* pi = static_cast<const int*>(f.pi);
  const auto* px = static_cast<const int*>(f.px);
  const auto* rows = static_cast<const int*>(f.s);
  const auto* values = static_cast<const double*>(f.x);
  for (std::size_t t = 0; t < f.nsuper; ++t) {
    const int first_col = super[t], end_col = super[t + 1];
    if (end_col <= offset) continue;
    const int nrows = pi[t + 1] - pi[t];
    for (int col = std::max(first_col, offset); col < end_col; ++col) {
      const double* column = values + px[t] + static_cast<std::ptrdiff_t>(col - first_col) * nrows;
      for (int r = col - first_col; r < nrows; ++r) {
        const int row = rows[pi[t] + r];
        if (row >= offset) out[(row - offset) + (col - offset) * ld] = column[r];
      }
    }
  }
}

// (L L^T)^-1 in place from the Cholesky factor L in the lower triangle of the m x m array `a`
// (leading dimension m), then mirrored into the upper triangle.
void InvertFromCholeskyFactor(double* a, int m) {
  int info = 0;
  dpotri_("L", &m, a, &m, &info);
  HAPCO_ASSERT(info == 0, "LAPACK dpotri failed on the contact nodes' Schur factor");
  for (std::ptrdiff_t c = 1; c < m; ++c)
    for (std::ptrdiff_t r = 0; r < c; ++r) a[r + c * m] = a[c + r * m];
}

}  // namespace

struct ElasticBody::Factor {
  SupernodalLlt llt;
  // Empty: llt applies CHOLMOD's own fill-reducing order. Otherwise llt factors K_ff permuted
  // so that position k holds free dof order[k] (natural order inside CHOLMOD), with the
  // `trailing` free dofs last, in that order; trailing_index[f] = position of f among them or -1.
  std::vector<int> order;
  std::vector<int> trailing;
  std::vector<int> trailing_index;
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
    CheckNodes(spec_.compliance_nodes, "compliance");
    factor_->trailing_index.assign(static_cast<std::size_t>(nf), -1);
    for (const int n : spec_.compliance_nodes)
      for (int a = 0; a < 3; ++a) {
        const int f = dof_to_free_[static_cast<std::size_t>(3 * n + a)];
        if (f < 0 || factor_->trailing_index[static_cast<std::size_t>(f)] >= 0) continue;
        factor_->trailing_index[static_cast<std::size_t>(f)] = static_cast<int>(factor_->trailing.size());
        factor_->trailing.push_back(f);
      }
    if (factor_->trailing.empty()) {
      factor_->llt.compute(k_ff);
    } else {
      // One factorization serves both the solves and the compliance block: the candidates'
      // dofs go last, so the trailing block of L is their Schur complement's factor.
      factor_->order = OrderWithTrailing(FillReducingOrder(k_ff), factor_->trailing, factor_->trailing_index);
      Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> to_position(nf);
      for (int k = 0; k < nf; ++k) to_position.indices()[factor_->order[static_cast<std::size_t>(k)]] = k;
      Eigen::SparseMatrix<double> permuted(nf, nf);
      permuted.selfadjointView<Eigen::Lower>() = k_ff.selfadjointView<Eigen::Lower>().twistedBy(to_position);
      cholmod_common& common = factor_->llt.cholmod();
      common.nmethods = 1;
      common.method[0].ordering = CHOLMOD_NATURAL;
      common.postorder = 0;  // a postorder could move the trailing dofs away from the end
      factor_->llt.compute(permuted);
      if (factor_->llt.info() == Eigen::Success) {
        const int* used = static_cast<const int*>(factor_->llt.factor()->Perm);
        for (int k = 0; k < nf; ++k) HAPCO_ASSERT(used == nullptr || used[k] == k, "CHOLMOD did not keep the given order");
      }
    }
    if (factor_->llt.info() != Eigen::Success) {
      throw InputError("stiffness is not positive definite after removing the clamped and "
                       "driven nodes: the Dirichlet nodes must stop every rigid motion (clamp "
                       "a face, not one or two nodes)");
    }
    stats_.factorization_seconds = watch.ElapsedSeconds();
    RecordFactorSize();
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

void ElasticBody::RecordFactorSize() {
  stats_.factor_nonzeros = static_cast<long>(factor_->llt.cholmod().lnz);
  const cholmod_factor& l = *factor_->llt.factor();
  stats_.factor_bytes = sizeof(double) * l.xsize + sizeof(int) * (l.is_super ? l.ssize : l.nzmax);
  const std::size_t m = factor_->trailing.size();
  stats_.schur_factor_bytes = sizeof(double) * m * m;
}

void ElasticBody::ReleaseComplianceOrder() {
  if (factor_ == nullptr || factor_->trailing.empty()) return;
  Stopwatch watch;
  const Eigen::SparseMatrix<double> k_ff = FreeStiffnessLower();
  factor_.reset();  // first, so the two factors never coexist
  factor_ = std::make_unique<Factor>();
  factor_->trailing_index.assign(static_cast<std::size_t>(num_free_dofs()), -1);
  factor_->llt.compute(k_ff);
  HAPCO_ASSERT(factor_->llt.info() == Eigen::Success, "CHOLMOD refactorization of K_ff failed (the first one succeeded)");
  stats_.factorization_seconds += watch.ElapsedSeconds();
  RecordFactorSize();
}

Eigen::MatrixXd ElasticBody::SolveFree(const Eigen::MatrixXd& rhs_free) const {
  HAPCO_ASSERT(factor_ != nullptr, "no free dofs to solve for");
  if (factor_->order.empty()) {
    Eigen::MatrixXd x = factor_->llt.solve(rhs_free);
    HAPCO_ASSERT(factor_->llt.info() == Eigen::Success, "CHOLMOD solve failed");
    return x;
  }
  const auto& order = factor_->order;
  const int nf = num_free_dofs();
  Eigen::MatrixXd permuted(nf, rhs_free.cols());
  for (int k = 0; k < nf; ++k) permuted.row(k) = rhs_free.row(order[static_cast<std::size_t>(k)]);
  const Eigen::MatrixXd y = factor_->llt.solve(permuted);
  HAPCO_ASSERT(factor_->llt.info() == Eigen::Success, "CHOLMOD solve failed");
  Eigen::MatrixXd x(nf, rhs_free.cols());
  for (int k = 0; k < nf; ++k) x.row(order[static_cast<std::size_t>(k)]) = y.row(k);
  return x;
}

std::vector<int> ElasticBody::FreeDofOrder() const {
  if (!factor_->order.empty()) return factor_->order;
  const cholmod_factor* f = factor_->llt.factor();
  HAPCO_ASSERT(f != nullptr && f->Perm != nullptr, "no CHOLMOD factor of K_ff");
  const int* perm = static_cast<const int*>(f->Perm);
  return {perm, perm + f->n};
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
  Eigen::MatrixXd c(n, n);
  ComplianceBlockInto(nodes, c.data());
  return c;
}

Eigen::MatrixXd ElasticBody::ComplianceBlockBySolves(std::span<const int> nodes) const {
  CheckNodes(nodes, "compliance");
  const int s = static_cast<int>(nodes.size());
  const int nf = num_free_dofs();
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(3 * s, 3 * s);
  if (nf == 0 || s == 0) return c;
  // Chunk width: two nf x 3·chunk dense arrays (rhs and solution) of at most ~32 MB each.
  const int chunk_nodes = std::clamp(4'000'000 / (3 * nf), 1, 170);
  ForEachComplianceColumnChunk(nodes, chunk_nodes, [&](int first, int count, const Eigen::MatrixXd& columns) {
    c.middleCols(3 * first, 3 * count) = columns;
  });
  return c;
}

void ElasticBody::ForEachComplianceColumnChunk(
    std::span<const int> nodes, int chunk_nodes,
    const std::function<void(int first, int count, const Eigen::MatrixXd& columns)>& sink) const {
  CheckNodes(nodes, "compliance");
  HAPCO_ASSERT(chunk_nodes >= 1, "chunk of at least one node");
  const int s = static_cast<int>(nodes.size());
  const int nf = num_free_dofs();
  for (int first = 0; first < s; first += chunk_nodes) {
    const int count = std::min(chunk_nodes, s - first);
    Eigen::MatrixXd columns = Eigen::MatrixXd::Zero(3 * s, 3 * count);
    if (nf > 0) {
      // Unit loads at the chunk's free dofs; a Dirichlet dof's column stays zero.
      Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(nf, 3 * count);
      for (int k = 0; k < count; ++k)
        for (int b = 0; b < 3; ++b) {
          const int f = dof_to_free_[static_cast<std::size_t>(3 * nodes[static_cast<std::size_t>(first + k)] + b)];
          if (f >= 0) rhs(f, 3 * k + b) = 1.0;
        }
      const Eigen::MatrixXd x = SolveFree(rhs);
      for (int i = 0; i < s; ++i)
        for (int a = 0; a < 3; ++a) {
          const int f = dof_to_free_[static_cast<std::size_t>(3 * nodes[static_cast<std::size_t>(i)] + a)];
          if (f >= 0) columns.row(3 * i + a) = x.row(f);
        }
    }
    sink(first, count, columns);
  }
}

void ElasticBody::ComplianceBlockInto(std::span<const int> nodes, double* block_m_per_n) const {
  CheckNodes(nodes, "compliance");
  const int s = static_cast<int>(nodes.size());
  const std::ptrdiff_t rows = 3 * static_cast<std::ptrdiff_t>(s);
  std::fill(block_m_per_n, block_m_per_n + rows * rows, 0.0);
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

  // C_SS = (K_ff^-1)_SS = (K_SS - K_SI K_II^-1 K_IS)^-1: with S ordered last in a Cholesky
  // factor of K_ff, its trailing m x m block L_SS is the Schur complement's own factor
  // (L_SS L_SS^T), so C_SS is that small dense SPD matrix inverted (dpotri): O(m^3), instead of
  // m full solves with the factor (each O(nnz(L))), which at ~100k dofs and m ~ 2600 took two
  // minutes. The body's factor has its compliance_nodes last; if S is among them, (K^-1)_SS is
  // a sub-block of their inverse. Otherwise factor K_ff once more with S last.
  const std::vector<int>& trailing_index = factor_->trailing_index;
  const bool in_body_factor = std::all_of(s_to_free.begin(), s_to_free.end(), [&](int f) {
    return trailing_index[static_cast<std::size_t>(f)] >= 0;
  });
  // Position of S's k-th dof in the inverted trailing block.
  std::vector<int> s_to_inverse(static_cast<std::size_t>(m));
  const int trailing = in_body_factor ? static_cast<int>(factor_->trailing.size()) : m;
  for (int k = 0; k < m; ++k) {
    s_to_inverse[static_cast<std::size_t>(k)] = in_body_factor ? trailing_index[static_cast<std::size_t>(s_to_free[static_cast<std::size_t>(k)])] : k;
  }
  // Where the block's free rows are exactly the trailing block in its order (the model's case:
  // S is the body's compliance_nodes, no node twice), the inverse is computed in the caller's
  // array and spread out in place: the peak memory is that array, not two m² arrays (the
  // precomputation's peak at ~100k dofs, docs/free-interaction.md "Precomputation cost").
  bool in_place = trailing == m;
  for (int r = 0, next = 0; in_place && r < 3 * s; ++r) {
    const int k = block_to_s[static_cast<std::size_t>(r)];
    if (k < 0) continue;
    in_place = s_to_inverse[static_cast<std::size_t>(k)] == next++;
  }
  Eigen::MatrixXd copy;  // the inverse otherwise
  double* inverse = block_m_per_n;
  if (!in_place) {
    copy = Eigen::MatrixXd::Zero(trailing, trailing);
    inverse = copy.data();
  }
  if (in_body_factor) {
    CopyTrailingBlock(*factor_->llt.factor(), trailing, inverse, trailing);
  } else {
    std::vector<int> perm = OrderWithTrailing(FreeDofOrder(), s_to_free, free_to_s);
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
    CopyTrailingBlock(*cholmod.factor, m, inverse, m);
  }  // the second factor is freed before the inversion
  InvertFromCholeskyFactor(inverse, trailing);

  if (in_place) {
    // Spread the m x m inverse (leading dimension m) to 3s x 3s with zero Dirichlet rows and
    // columns, from the last entry back: an entry's target index is never below its source
    // index (both orders are the same, with gaps), so nothing is overwritten before it is read.
    for (std::ptrdiff_t c = rows - 1; c >= 0; --c) {
      const int kc = block_to_s[static_cast<std::size_t>(c)];
      double* target = block_m_per_n + c * rows;
      if (kc < 0) {
        std::fill(target, target + rows, 0.0);
        continue;
      }
      const double* source = block_m_per_n + static_cast<std::ptrdiff_t>(kc) * m;
      for (std::ptrdiff_t r = rows - 1; r >= 0; --r) {
        const int kr = block_to_s[static_cast<std::size_t>(r)];
        target[r] = kr < 0 ? 0.0 : source[kr];
      }
    }
    return;
  }
  for (std::ptrdiff_t c = 0; c < rows; ++c) {
    const int sc = block_to_s[static_cast<std::size_t>(c)];
    if (sc < 0) continue;
    const std::ptrdiff_t ic = s_to_inverse[static_cast<std::size_t>(sc)];
    for (std::ptrdiff_t r = 0; r < rows; ++r) {
      const int sr = block_to_s[static_cast<std::size_t>(r)];
      block_m_per_n[r + c * rows] = sr < 0 ? 0.0 : copy(s_to_inverse[static_cast<std::size_t>(sr)], ic);
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
