#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <vector>

#include <Eigen/Dense>

namespace hapco::sim {

// A surface compliance C (3n x 3n, m/N) stored for the 1 kHz step: the 3x3 block C(i, j) of
// each node pair as 9 consecutive doubles (column-major), blocks of one column j consecutive
// in i: block (i, j) at 9·(j·n + i).
//
// Why not a dense column-major matrix: a step reads C among the ~100 surface nodes near the
// tool (the broad phase's U = C f and the W gather of algorithms.md §5), scattered over a
// matrix far larger than the L2 cache. There a 3x3 block spans three columns 24n bytes apart,
// i.e. three or more cache lines, and the step's cost was those misses, not the arithmetic
// (docs/performance.md). Here a block is 72 contiguous bytes (at most two lines) and a run of
// consecutive nodes is one stream. Same values, same bytes, same precision as the dense C.
// Releases BlockedCompliance's pages (mmap'ed: see AllocateZeroed).
struct CompliancePagesUnmapper {
  std::size_t bytes = 0;
  void operator()(double* memory) const;
};

class BlockedCompliance {
 public:
  BlockedCompliance() = default;
  // n x n zero blocks (n nodes).
  explicit BlockedCompliance(int nodes);
  // From a dense 3n x 3n compliance (tests, small bodies).
  explicit BlockedCompliance(const Eigen::MatrixXd& compliance_m_per_n);
  // n nodes; write_dense(p) writes C as a dense 3n x 3n column-major array at p (9n² doubles:
  // this object's own storage), which is then reordered into blocks in place. For a large C
  // this is the only 72 n²-byte array: no dense copy beside the blocks.
  static BlockedCompliance FromDenseInPlace(int nodes, const std::function<void(double* dense_m_per_n)>& write_dense);

  // Banded (issue 11 item 4, docs/free-interaction.md "Beyond memory"): only the blocks (i, j)
  // with band_begin[j] <= i < band_end[j] are stored, the others read as zero (node pairs
  // farther apart than the scene's compliance range). The addresses stay those of the full
  // layout, so the step's kernels are unchanged: one anonymous mapping of 72 n² bytes reserved
  // without backing (MAP_NORESERVE, no huge pages), of which only the pages holding stored
  // blocks are written. An unwritten page reads as zero and takes no memory, so with the nodes
  // ordered along an axis (each column's band one run of slots) the memory is about 72 bytes
  // per stored block. Fill with mutable_block().
  static BlockedCompliance Banded(int nodes, std::vector<int> band_begin, std::vector<int> band_end);
  bool banded() const { return !band_begin_.empty(); }
  // Rows [band_begin(j), band_end(j)) of column j are stored (all rows when not banded).
  int band_begin(int j) const { return banded() ? band_begin_[static_cast<std::size_t>(j)] : 0; }
  int band_end(int j) const { return banded() ? band_end_[static_cast<std::size_t>(j)] : nodes_; }
  bool stored(int i, int j) const { return i >= band_begin(j) && i < band_end(j); }
  // Block (i, j) for writing; (i, j) must be stored.
  double* mutable_block(int i, int j);

  int nodes() const { return nodes_; }
  // Memory the blocks take, bytes: 72 n² when dense; banded, the pages of the stored blocks.
  std::size_t bytes() const;
  // What the same compliance takes dense: 72 n² bytes.
  std::size_t dense_bytes() const { return DenseBytes(nodes_); }
  static std::size_t DenseBytes(std::size_t nodes) { return sizeof(double) * 9 * nodes * nodes; }
  // C(i, j), m/N: displacement of node i per unit force at node j.
  Eigen::Map<const Eigen::Matrix3d> block(int i, int j) const {
    return Eigen::Map<const Eigen::Matrix3d>(data_.get() + Offset(i, j));
  }
  // The blocks (0..n-1, j): 9 n consecutive doubles.
  const double* column_data(int j) const { return data_.get() + Offset(0, j); }
  // The dense matrix again (tests and small bodies only: allocates 72 n² bytes).
  Eigen::MatrixXd ToDense() const;

 private:
  std::size_t Offset(int i, int j) const {
    return 9 * (static_cast<std::size_t>(j) * static_cast<std::size_t>(nodes_) + static_cast<std::size_t>(i));
  }
  using Storage = std::unique_ptr<double[], CompliancePagesUnmapper>;
  static constexpr std::size_t kPaddingDoubles = 4;  // zero doubles after the last block
  static Storage AllocateZeroed(std::size_t count, bool reserve_only = false);

  int nodes_ = 0;
  Storage data_;
  std::vector<int> band_begin_, band_end_;  // empty when dense
};

}  // namespace hapco::sim
