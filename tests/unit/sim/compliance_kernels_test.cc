// The step's compliance sums (sim/compliance_kernels.h), both builds, against the same sums
// written with the dense matrix: U = C f over a region, and the W gather Σ c_k d_l C(p_k, q_l).
// The slot sets include the first and the last slot (the four-lane loads read past a block's
// end there) and runs of one slot.
#include <random>

#include <gtest/gtest.h>

#include "sim/compliance_kernels.h"

namespace hapco::sim {
namespace {

constexpr int kNodes = 23;

// A symmetric positive definite 3n x 3n "compliance" with entries of a surface compliance's
// scale (1e-6 m/N) and no structure a transpose or a lane mix-up could hide behind.
Eigen::MatrixXd RandomCompliance(std::mt19937* rng) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::MatrixXd a(3 * kNodes, 3 * kNodes);
  for (Eigen::Index j = 0; j < a.cols(); ++j)
    for (Eigen::Index i = 0; i < a.rows(); ++i) a(i, j) = uniform(*rng);
  Eigen::MatrixXd c = 1e-6 * (a * a.transpose() / (3.0 * kNodes) + Eigen::MatrixXd::Identity(3 * kNodes, 3 * kNodes));
  return c;
}

std::vector<ComplianceKernel> KernelsOfThisCpu() {
  std::vector<ComplianceKernel> kernels = {ComplianceKernel::kPortable};
  if (FastestComplianceKernel() == ComplianceKernel::kAvx2Fma) kernels.push_back(ComplianceKernel::kAvx2Fma);
  return kernels;
}

SlotRunList Runs(const std::vector<int>& ascending) {
  SlotRunList runs;
  for (std::size_t k = 0; k < ascending.size(); ++k) {
    if (k == 0 || ascending[k] != ascending[k - 1] + 1) runs.push_back({ascending[k], ascending[k] + 1});
    else runs.back().second = ascending[k] + 1;
  }
  return runs;
}

TEST(ComplianceKernelsTest, RegionDisplacementIsCTimesFOnEveryRegionSlot) {
  std::mt19937 rng(11);
  const Eigen::MatrixXd dense = RandomCompliance(&rng);
  const BlockedCompliance blocked(dense);
  // Loaded: first and last slot, a run of three, singles. Free: the rest of a region.
  const std::vector<int> loaded = {0, 4, 5, 6, 9, 15, kNodes - 1};
  const std::vector<int> free_slots = {1, 2, 7, 10, 11, 12, 13, 20, 21};
  std::uniform_real_distribution<double> newtons(-2.0, 2.0);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * kNodes);
  for (int j : loaded)
    for (int a = 0; a < 3; ++a) f[3 * j + a] = newtons(rng);
  const Eigen::VectorXd expected = dense * f;  // f is zero off the loaded slots

  for (ComplianceKernel kernel : KernelsOfThisCpu()) {
    SCOPED_TRACE(ComplianceKernelName(kernel));
    // Slots outside the region must not be touched: they start at a sentinel.
    Eigen::VectorXd u = Eigen::VectorXd::Constant(3 * kNodes, 7.0);
    for (int i : loaded) u.segment<3>(3 * i).setZero();
    for (int i : free_slots) u.segment<3>(3 * i).setZero();
    AddComplianceTimesForces(kernel, blocked, Runs(free_slots), loaded, Runs(loaded), f.data(), u.data());
    const double scale = expected.cwiseAbs().maxCoeff();
    for (int i = 0; i < kNodes; ++i) {
      const bool in_region = std::count(loaded.begin(), loaded.end(), i) + std::count(free_slots.begin(), free_slots.end(), i) > 0;
      for (int a = 0; a < 3; ++a) {
        if (in_region) {
          EXPECT_NEAR(u[3 * i + a], expected[3 * i + a], 1e-14 * scale) << "slot " << i << " axis " << a;
        } else {
          EXPECT_EQ(u[3 * i + a], 7.0) << "slot " << i << " is outside the region";
        }
      }
    }
  }
}

TEST(ComplianceKernelsTest, BothKernelsAgreeToRounding) {
  if (FastestComplianceKernel() != ComplianceKernel::kAvx2Fma) GTEST_SKIP() << "this CPU has no AVX2/FMA";
  std::mt19937 rng(5);
  const Eigen::MatrixXd dense = RandomCompliance(&rng);
  const BlockedCompliance blocked(dense);
  std::vector<int> loaded, free_slots;
  std::bernoulli_distribution pick(0.5);
  for (int i = 0; i < kNodes; ++i) (pick(rng) ? loaded : free_slots).push_back(i);
  std::normal_distribution<double> newtons(0.0, 1.0);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * kNodes);
  for (int j : loaded)
    for (int a = 0; a < 3; ++a) f[3 * j + a] = newtons(rng);
  Eigen::VectorXd portable = Eigen::VectorXd::Zero(3 * kNodes), avx = portable;
  AddComplianceTimesForces(ComplianceKernel::kPortable, blocked, Runs(free_slots), loaded, Runs(loaded), f.data(),
                           portable.data());
  AddComplianceTimesForces(ComplianceKernel::kAvx2Fma, blocked, Runs(free_slots), loaded, Runs(loaded), f.data(),
                           avx.data());
  EXPECT_LE((portable - avx).cwiseAbs().maxCoeff(), 1e-14 * portable.cwiseAbs().maxCoeff());
  EXPECT_GT(portable.cwiseAbs().maxCoeff(), 0.0);
}

TEST(ComplianceKernelsTest, WeightedBlockSumIsTheDenseWeightedSum) {
  std::mt19937 rng(7);
  const Eigen::MatrixXd dense = RandomCompliance(&rng);
  const BlockedCompliance blocked(dense);
  // A 6-node face against a 3-node face, including the last slot; then one node against one.
  const std::array<int, 6> p = {kNodes - 1, 3, 8, 0, 14, 19};
  const std::array<double, 6> c = {0.31, -0.12, 0.05, 0.44, 0.2, 0.12};
  const std::array<int, 6> q = {2, kNodes - 1, 17, 0, 0, 0};
  const std::array<double, 6> d = {-0.5, 0.25, 0.25, 0.0, 0.0, 0.0};
  Eigen::Matrix3d expected = Eigen::Matrix3d::Zero();
  for (int k = 0; k < 6; ++k)
    for (int l = 0; l < 3; ++l) expected += c[k] * d[l] * dense.block<3, 3>(3 * p[k], 3 * q[l]);
  const std::array<int, 6> one = {kNodes - 1, 0, 0, 0, 0, 0};
  const std::array<double, 6> unit = {1.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  for (ComplianceKernel kernel : KernelsOfThisCpu()) {
    SCOPED_TRACE(ComplianceKernelName(kernel));
    const Eigen::Matrix3d sum = WeightedBlockSum(kernel, blocked, p, c, 6, q, d, 3);
    EXPECT_LE((sum - expected).cwiseAbs().maxCoeff(), 1e-14 * expected.cwiseAbs().maxCoeff()) << sum << "\n\n" << expected;
    const Eigen::Matrix3d last = WeightedBlockSum(kernel, blocked, one, unit, 1, one, unit, 1);
    const Eigen::Matrix3d last_expected = dense.block<3, 3>(3 * (kNodes - 1), 3 * (kNodes - 1));
    EXPECT_TRUE(last == last_expected) << last;
  }
}

}  // namespace
}  // namespace hapco::sim
