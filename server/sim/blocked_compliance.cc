#include "sim/blocked_compliance.h"

#include <sys/mman.h>

#include <algorithm>
#include <new>
#include <vector>

#include "common/error.h"

namespace hapco::sim {

BlockedCompliance::BlockedCompliance(int nodes) : nodes_(nodes) {
  HAPCO_ASSERT(nodes >= 0, "BlockedCompliance: negative node count");
  const std::size_t count = 9 * static_cast<std::size_t>(nodes_) * static_cast<std::size_t>(nodes_);
  data_ = AllocateZeroed(count);
}

BlockedCompliance BlockedCompliance::Banded(int nodes, std::vector<int> band_begin, std::vector<int> band_end) {
  HAPCO_ASSERT(nodes >= 0 && band_begin.size() == static_cast<std::size_t>(nodes) &&
                   band_end.size() == static_cast<std::size_t>(nodes),
               "BlockedCompliance::Banded: one band per column");
  for (int j = 0; j < nodes; ++j) {
    const auto k = static_cast<std::size_t>(j);
    HAPCO_ASSERT(0 <= band_begin[k] && band_begin[k] <= j && j < band_end[k] && band_end[k] <= nodes,
                 "BlockedCompliance::Banded: a column's band must hold its own diagonal block");
  }
  BlockedCompliance c;
  c.nodes_ = nodes;
  c.data_ = AllocateZeroed(9 * static_cast<std::size_t>(nodes) * static_cast<std::size_t>(nodes), true);
  c.band_begin_ = std::move(band_begin);
  c.band_end_ = std::move(band_end);
  return c;
}

double* BlockedCompliance::mutable_block(int i, int j) {
  HAPCO_ASSERT(i >= 0 && j >= 0 && i < nodes_ && j < nodes_ && stored(i, j), "BlockedCompliance: block not stored");
  return data_.get() + Offset(i, j);
}

std::size_t BlockedCompliance::bytes() const {
  if (!banded()) return dense_bytes();
  // The pages the stored blocks span (each column's band is one run of blocks).
  constexpr std::size_t kPage = 4096;
  std::size_t total = 0;
  for (int j = 0; j < nodes_; ++j) {
    const std::size_t first = sizeof(double) * Offset(band_begin(j), j) / kPage;
    const std::size_t last = (sizeof(double) * Offset(band_end(j), j) - 1) / kPage;
    total += (last - first + 1) * kPage;
  }
  return total;
}

BlockedCompliance::Storage BlockedCompliance::AllocateZeroed(std::size_t count, bool reserve_only) {
  if (reserve_only) {
    // Address space only: pages are backed when first written. No huge pages, which would
    // back 2 MiB (several columns) for one written block.
    const std::size_t bytes = sizeof(double) * (count + kPaddingDoubles);
    void* memory = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (memory == MAP_FAILED) throw std::bad_alloc();
    madvise(memory, bytes, MADV_NOHUGEPAGE);
    return Storage(static_cast<double*>(memory), CompliancePagesUnmapper{bytes});
  }
  // Anonymous pages (zero) on 2 MiB huge pages where the kernel allows it (THP "madvise"
  // mode, the common default): a step reads ~10^4 blocks scattered over ~10^3 small pages of
  // a 100+ MiB C, and with 4 KiB pages their TLB misses were most of the broad phase's time.
  // kPaddingDoubles more: a 4-lane load of a block's last 3-vector (compliance_kernels.cc)
  // reads one double past it, also past the last block.
  const std::size_t bytes = sizeof(double) * (count + kPaddingDoubles);
  constexpr std::size_t kHuge = std::size_t{2} << 20;
  const std::size_t mapped = (bytes + kHuge - 1) / kHuge * kHuge;
  void* memory = mmap(nullptr, mapped, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (memory == MAP_FAILED) throw std::bad_alloc();
  madvise(memory, mapped, MADV_HUGEPAGE);  // advice only: 4 KiB pages if refused
  return Storage(static_cast<double*>(memory), CompliancePagesUnmapper{mapped});
}

void CompliancePagesUnmapper::operator()(double* memory) const {
  if (memory != nullptr) munmap(memory, bytes);
}

BlockedCompliance::BlockedCompliance(const Eigen::MatrixXd& compliance_m_per_n)
    : BlockedCompliance(FromDenseInPlace(static_cast<int>(compliance_m_per_n.cols() / 3), [&](double* dense) {
        HAPCO_ASSERT(compliance_m_per_n.rows() == compliance_m_per_n.cols() && compliance_m_per_n.rows() % 3 == 0,
                     "BlockedCompliance: C must be square with 3 rows per node");
        std::copy(compliance_m_per_n.data(), compliance_m_per_n.data() + compliance_m_per_n.size(), dense);
      })) {}

BlockedCompliance BlockedCompliance::FromDenseInPlace(int nodes,
                                                      const std::function<void(double* dense_m_per_n)>& write_dense) {
  BlockedCompliance c(nodes);
  write_dense(c.data_.get());
  // The columns 3j..3j+2 of the dense array and the blocks (·, j) occupy the same 9n doubles
  // (at 9jn): dense (3i + a, 3j + b) at 9jn + 3n·b + 3i + a, block (i, j) entry (a, b) at
  // 9jn + 9i + 3b + a. So each column triple is reordered on its own, through a 9n buffer.
  const auto n = static_cast<std::size_t>(nodes);
  std::vector<double> triple(9 * n);
  for (std::size_t j = 0; j < n; ++j) {
    double* column = c.data_.get() + 9 * j * n;
    std::copy(column, column + 9 * n, triple.begin());
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t b = 0; b < 3; ++b)
        for (std::size_t a = 0; a < 3; ++a) column[9 * i + 3 * b + a] = triple[3 * n * b + 3 * i + a];
  }
  return c;
}

Eigen::MatrixXd BlockedCompliance::ToDense() const {
  Eigen::MatrixXd dense(3 * nodes_, 3 * nodes_);
  for (int j = 0; j < nodes_; ++j) {
    for (int i = 0; i < nodes_; ++i) dense.block<3, 3>(3 * i, 3 * j) = block(i, j);
  }
  return dense;
}

}  // namespace hapco::sim
