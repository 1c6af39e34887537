#include "sim/blocked_compliance.h"

#include <sys/mman.h>

#include <algorithm>
#include <new>

#include "common/error.h"

namespace hapco::sim {

BlockedCompliance::BlockedCompliance(int nodes) : nodes_(nodes) {
  HAPCO_ASSERT(nodes >= 0, "BlockedCompliance: negative node count");
  const std::size_t count = 9 * static_cast<std::size_t>(nodes_) * static_cast<std::size_t>(nodes_);
  data_ = AllocateZeroed(count);
}

BlockedCompliance::Storage BlockedCompliance::AllocateZeroed(std::size_t count) {
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
    : BlockedCompliance(static_cast<int>(compliance_m_per_n.cols() / 3)) {
  HAPCO_ASSERT(compliance_m_per_n.rows() == compliance_m_per_n.cols() && compliance_m_per_n.rows() % 3 == 0,
               "BlockedCompliance: C must be square with 3 rows per node");
  for (Eigen::Index c = 0; c < compliance_m_per_n.cols(); ++c) SetColumn(static_cast<int>(c), compliance_m_per_n.col(c));
}

void BlockedCompliance::SetColumn(int column, const Eigen::Ref<const Eigen::VectorXd>& values_m_per_n) {
  HAPCO_ASSERT(column >= 0 && column < 3 * nodes_ && values_m_per_n.size() == 3 * nodes_,
               "BlockedCompliance::SetColumn: column or length out of range");
  const int j = column / 3, b = column % 3;
  for (int i = 0; i < nodes_; ++i) {
    double* block = data_.get() + Offset(i, j);
    for (int a = 0; a < 3; ++a) block[3 * b + a] = values_m_per_n[3 * i + a];
  }
}

Eigen::MatrixXd BlockedCompliance::ToDense() const {
  Eigen::MatrixXd dense(3 * nodes_, 3 * nodes_);
  for (int j = 0; j < nodes_; ++j) {
    for (int i = 0; i < nodes_; ++i) dense.block<3, 3>(3 * i, 3 * j) = block(i, j);
  }
  return dense;
}

}  // namespace hapco::sim
