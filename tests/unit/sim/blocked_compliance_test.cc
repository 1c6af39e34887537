// BlockedCompliance: the step's layout of a surface compliance holds exactly the dense values,
// and the model's operator (filled column by column from the batched solves) equals the
// dense compliance block of the same nodes.
#include <algorithm>
#include <cstdlib>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "sim/blocked_compliance.h"
#include "sim/two_body_model.h"

namespace hapco::sim {
namespace {

TEST(BlockedComplianceTest, EveryBlockIsTheDenseBlockAndRoundTrips) {
  const int n = 7;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Eigen::MatrixXd dense(3 * n, 3 * n);
  for (Eigen::Index j = 0; j < dense.cols(); ++j)
    for (Eigen::Index i = 0; i < dense.rows(); ++i) dense(i, j) = uniform(rng);  // not symmetric: catches a transpose
  const BlockedCompliance blocked(dense);
  ASSERT_EQ(blocked.nodes(), n);
  EXPECT_EQ(blocked.bytes(), sizeof(double) * 9 * n * n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const Eigen::Matrix3d expected = dense.block<3, 3>(3 * i, 3 * j);
      EXPECT_TRUE(Eigen::Matrix3d(blocked.block(i, j)) == expected) << i << "," << j;
    }
  EXPECT_TRUE(blocked.ToDense() == dense);
}

// Banded: the stored blocks read back, the others read as zero, and only the pages of the
// stored blocks count (large n: a column spans many pages).
TEST(BlockedComplianceTest, BandedStoresItsBandAndReadsTheRestAsZero) {
  const int n = 3000, half_width = 100;
  std::vector<int> begin(n), end(n);
  for (int j = 0; j < n; ++j) {
    begin[static_cast<std::size_t>(j)] = std::max(0, j - half_width);
    end[static_cast<std::size_t>(j)] = std::min(n, j + half_width + 1);
  }
  BlockedCompliance c = BlockedCompliance::Banded(n, begin, end);
  ASSERT_TRUE(c.banded());
  for (int j = 0; j < n; ++j)
    for (int i = c.band_begin(j); i < c.band_end(j); ++i) {
      double* block = c.mutable_block(i, j);
      for (int k = 0; k < 9; ++k) block[k] = 1.0 + i + 0.001 * j + 1e-7 * k;
    }
  for (int j = 0; j < n; j += 97)
    for (int i = 0; i < n; i += 13) {
      const bool in_band = std::abs(i - j) <= half_width;
      EXPECT_EQ(c.stored(i, j), in_band);
      EXPECT_EQ(c.block(i, j)(2, 1), in_band ? 1.0 + i + 0.001 * j + 1e-7 * 5 : 0.0) << i << "," << j;
    }
  // 201 blocks of 72 bytes per column = 14 472 bytes: 4 or 5 pages of 4 KiB each.
  EXPECT_GE(c.bytes(), static_cast<std::size_t>(n) * 4 * 4096);
  EXPECT_LE(c.bytes(), static_cast<std::size_t>(n) * 5 * 4096);
  EXPECT_LT(c.bytes(), c.dense_bytes() / 10);
}

TEST(BlockedComplianceTest, ModelOperatorEqualsTheDenseComplianceOfItsSurfaceNodes) {
  SceneSpec scene;
  scene.name = "small";
  scene.obstacle.name = "red";
  scene.obstacle.box = {Eigen::Vector3d::Zero(), Eigen::Vector3d(0.10, 0.02, 0.02), Eigen::Vector3i(6, 2, 2),
                        fem::ElementOrder::kTet10};
  scene.obstacle.material = {3.0e6, 0.3};
  scene.obstacle.clamped_faces = {fem::BoxFace::kXMin};
  scene.tool.name = "green";
  scene.tool.box = {Eigen::Vector3d(0.04, 0.0, 0.02), Eigen::Vector3d(0.02, 0.02, 0.01), Eigen::Vector3i(2, 2, 1),
                    fem::ElementOrder::kTet4};
  scene.tool.material = {8.0e7, 0.3};
  scene.tool.driven_face = fem::BoxFace::kZMax;
  scene.trajectory = {{"press", {0, 0, -0.001}, 2}};
  const TwoBodyModel model(scene);
  const ContactSurface& surface = model.obstacle_surface();
  const Eigen::MatrixXd expected = model.obstacle().ComplianceBlock(surface.nodes);
  EXPECT_TRUE(surface.compliance_m_per_n.ToDense() == expected);
  EXPECT_GT(expected.norm(), 0.0);
  // Clamped nodes have zero rows and columns; free nodes a positive diagonal.
  int clamped = 0;
  for (int i = 0; i < surface.compliance_m_per_n.nodes(); ++i) {
    const double diagonal = surface.compliance_m_per_n.block(i, i).trace();
    if (diagonal == 0.0) ++clamped; else EXPECT_GT(diagonal, 0.0);
  }
  EXPECT_GT(clamped, 0);
}

}  // namespace
}  // namespace hapco::sim
