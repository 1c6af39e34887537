#pragma once
// A linear elastic body with Dirichlet nodes, factored once (algorithms.md sections 1 and 6).
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "fem/mesh.h"

namespace hapco::fem {

struct ElasticBodyStats {
  double assembly_seconds = 0.0;       // validation + stiffness assembly, s
  double factorization_seconds = 0.0;  // CHOLMOD analyse + numeric factorization of K_ff, s
  long stiffness_nonzeros = 0;         // stored entries of the full 3N x 3N K
  long factor_nonzeros = 0;            // nonzeros of the Cholesky factor L (CHOLMOD lnz)
  // Memory of L's values and row indices, bytes. Supernodes are stored as dense rectangles, so
  // with compliance_nodes last this includes their full m x m Schur factor (8 m² bytes).
  std::size_t factor_bytes = 0;
  // Of which the dense Schur factor of the compliance_nodes' m free dofs: 8 m² bytes.
  std::size_t schur_factor_bytes = 0;
  int free_dofs = 0;                   // size of K_ff
};

// Immutable after construction (design.md, example 4): every query reuses the one factor, so a
// haptic step never re-assembles or re-factors. Not thread-safe, even through const methods:
// CHOLMOD keeps its workspace inside the solver, so solve from one thread at a time.
class ElasticBody {
 public:
  struct Spec {
    Mesh mesh;
    Material material;
    std::vector<int> clamped_nodes;  // displacement fixed to zero
    std::vector<int> driven_nodes;   // translated rigidly with the device (Dirichlet data)
    // Nodes whose compliance block will be asked for (a scene's contact candidates). Their
    // free dofs are ordered last in the body's one factor, so ComplianceBlock on them, or on
    // any subset, reads their Schur factor off it instead of factoring again. Empty: CHOLMOD
    // orders all dofs freely (and ComplianceBlock factors a second time).
    std::vector<int> compliance_nodes;
  };

  // Validates the spec (InputError), assembles K, removes all dofs of clamped and driven nodes,
  // factors K_ff once with CHOLMOD (supernodal LL^T; compliance_nodes' dofs last, the rest in
  // CHOLMOD's fill-reducing order) and computes the unit driven fields.
  // Throws InputError if there is no Dirichlet node, the Dirichlet nodes are collinear (a
  // rigid rotation is left free), a node id is out of range, a node is both clamped and
  // driven, or the CHOLMOD factorization finds K_ff not positive definite.
  explicit ElasticBody(Spec spec);
  ~ElasticBody();
  ElasticBody(ElasticBody&&) noexcept;
  ElasticBody& operator=(ElasticBody&&) noexcept;
  ElasticBody(const ElasticBody&) = delete;
  ElasticBody& operator=(const ElasticBody&) = delete;

  const Mesh& mesh() const { return spec_.mesh; }
  const Material& material() const { return spec_.material; }
  const std::vector<int>& clamped_nodes() const { return spec_.clamped_nodes; }
  const std::vector<int>& driven_nodes() const { return spec_.driven_nodes; }
  int num_dofs() const { return 3 * spec_.mesh.num_nodes(); }
  int num_free_dofs() const { return static_cast<int>(free_to_dof_.size()); }
  // Full assembled stiffness (3N x 3N, N/m, both triangles).
  const Eigen::SparseMatrix<double>& stiffness() const { return stiffness_; }
  // True for clamped and driven nodes. node must be in 0..num_nodes-1.
  bool is_dirichlet_node(int node) const {
    return dof_to_free_[3 * static_cast<std::size_t>(node)] < 0;
  }

  // Static solve with the stored factor: full displacement field (3N, m) under nodal loads
  // (3N, N; entries at Dirichlet dofs are ignored), clamped nodes fixed, driven nodes translated
  // rigidly by driven_translation_m. Solves K_ff u_f = f_f - K_fd u_d.
  Eigen::VectorXd SolveDisplacement(const Eigen::VectorXd& nodal_force_n,
                                    const Eigen::Vector3d& driven_translation_m) const;

  // algorithms.md section 6: displacement field (3N x 3, m per m of device travel) for a unit
  // rigid translation of the driven nodes along x, y, z with no load; column a is the field for
  // axis a, so U_free(d) = fields * d. Zero if there are no driven nodes.
  const Eigen::MatrixXd& unit_driven_translation_fields() const { return unit_fields_; }

  // Compliance block of a node set S (3|S| x 3|S|, m/N): C(3i+a, 3j+b) = displacement of node
  // S[i] along axis a for a unit force at node S[j] along axis b, all Dirichlet dofs held at
  // zero. Rows/columns of Dirichlet nodes are zero. Computed as the inverse of the Schur
  // complement of the free dofs of S (the trailing block of a Cholesky factor with S ordered
  // last, inverted with LAPACK dpotri): O(m^3) for m free dofs in S when S is within
  // Spec::compliance_nodes (the body's factor already has them last), else one more CHOLMOD
  // factorization first.
  Eigen::MatrixXd ComplianceBlock(std::span<const int> nodes) const;
  // The same block by 3|S| batched solves with the body's factor (the method before the Schur
  // complement one): O(|S| nnz(L)). Kept as the baseline of fem_bench and a second, independent
  // computation for the tests; the simulation uses ComplianceBlock.
  Eigen::MatrixXd ComplianceBlockBySolves(std::span<const int> nodes) const;
  // The columns of the same block, a chunk of nodes at a time, by batched solves with the
  // body's factor (no dense |S| x |S| array): sink(first, count, columns) gets the 3|S| x
  // 3·count columns of the nodes S[first .. first+count-1]. For compliances too large to hold
  // whole (sim/blocked_compliance.h, banded storage): peak memory is the factor and one chunk.
  void ForEachComplianceColumnChunk(std::span<const int> nodes, int chunk_nodes,
                                    const std::function<void(int first, int count, const Eigen::MatrixXd& columns)>& sink) const;
  // The same block written into the caller's array (column-major, 3|S| x 3|S|, 9|S|² doubles),
  // which also holds the inversion's work when S is the body's compliance_nodes in that order:
  // then the precomputation's peak is that array and the factor, with no second dense copy.
  void ComplianceBlockInto(std::span<const int> nodes, double* block_m_per_n) const;

  // Factors K_ff again in CHOLMOD's own fill-reducing order, without compliance_nodes last, and
  // frees the factor that had them: their dense Schur factor (stats().schur_factor_bytes) is
  // needed only to compute their compliance block, and on a large contact surface it is as
  // large as that block. Solves afterwards differ by round-off; ComplianceBlock still works
  // (it factors with its nodes last once more). Costs one factorization without the dense block.
  void ReleaseComplianceOrder();

  // Sum over `nodes` of (K U - f): the force (N) the supports exert on those nodes. For free
  // nodes of an equilibrium solution this is zero to round-off.
  Eigen::Vector3d ReactionForce(const Eigen::VectorXd& displacement_m,
                                const Eigen::VectorXd& nodal_force_n,
                                std::span<const int> nodes) const;

  const ElasticBodyStats& stats() const { return stats_; }

 private:
  struct Factor;  // CHOLMOD solver, hidden so users need not include CHOLMOD headers

  void CheckNodes(std::span<const int> nodes, const char* what) const;
  void RecordFactorSize();  // stats_ from factor_
  void CheckRigidMotionsStopped() const;
  // K_ff (free dofs only, lower triangle stored), N/m.
  Eigen::SparseMatrix<double> FreeStiffnessLower() const;
  // Solves K_ff X = B for free-dof right-hand sides (columns).
  Eigen::MatrixXd SolveFree(const Eigen::MatrixXd& rhs_free) const;
  // The factor's elimination order: position k eliminates free dof FreeDofOrder()[k].
  std::vector<int> FreeDofOrder() const;

  Spec spec_;
  Eigen::SparseMatrix<double> stiffness_;
  std::vector<int> dof_to_free_;   // 3N entries: free index, or -1 for a Dirichlet dof
  std::vector<int> free_to_dof_;
  std::unique_ptr<Factor> factor_;
  Eigen::MatrixXd unit_fields_;
  ElasticBodyStats stats_;
};

}  // namespace hapco::fem
