// BlockedCompliance: the step's layout of a surface compliance holds exactly the dense values,
// and the model's operator (filled column by column from the batched solves) equals the
// dense compliance block of the same nodes.
#include <random>

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
