// Element and global stiffness: symmetry, rigid-body modes, definiteness, patch tests.
#include <cmath>
#include <set>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <gtest/gtest.h>

#include "fem/assembly.h"
#include "fem/box_mesh.h"
#include "fem/element_stiffness.h"
#include "fem_test_util.h"

namespace hapco::fem {
namespace {

using testing::Box;
using testing::BoundaryNodes;
using testing::Distort;
using testing::Interpolate;

const Material kRubber{3e6, 0.3};  // the red body (algorithms.md section 1)

class StiffnessTest : public ::testing::TestWithParam<ElementOrder> {
 protected:
  // A distorted 3x3x3 mesh of a 2 x 3 x 4 cm box, so no test relies on a regular grid.
  void SetUp() override {
    spec_ = Box(0.02, 0.03, 0.04, 3, 3, 3, GetParam());
    mesh_ = MakeBoxMesh(spec_);
    Distort(mesh_, spec_, 0.25, 42);
    k_ = AssembleStiffness(mesh_, kRubber);
  }
  BoxMeshSpec spec_;
  Mesh mesh_;
  Eigen::SparseMatrix<double> k_;
};

TEST_P(StiffnessTest, IsSymmetric) {
  const Eigen::SparseMatrix<double> kt = k_.transpose();
  EXPECT_LE((k_ - kt).norm(), 1e-13 * k_.norm());
  EXPECT_EQ(k_.rows(), 3 * mesh_.num_nodes());
}

TEST_P(StiffnessTest, RigidMotionsCostNoForce) {
  const Eigen::Vector3d centre(0.02, 0.0, 0.05);
  for (int a = 0; a < 3; ++a) {
    const Eigen::VectorXd translation =
        Interpolate(mesh_, [&](const Eigen::Vector3d&) -> Eigen::Vector3d { return Eigen::Vector3d::Unit(a); });
    EXPECT_LE((k_ * translation).norm(), 1e-12 * k_.norm() * translation.norm()) << "axis " << a;
    // Infinitesimal rotation u = w x (x - c).
    const Eigen::VectorXd rotation = Interpolate(mesh_, [&](const Eigen::Vector3d& x) -> Eigen::Vector3d {
      return Eigen::Vector3d::Unit(a).cross(x - centre);
    });
    EXPECT_LE((k_ * rotation).norm(), 1e-12 * k_.norm() * rotation.norm()) << "axis " << a;
  }
  // ...while a stretch does cost force (the check above is not vacuous).
  const Eigen::VectorXd stretch = Interpolate(mesh_, [](const Eigen::Vector3d& x) -> Eigen::Vector3d {
    return Eigen::Vector3d(x.x(), 0.0, 0.0);
  });
  EXPECT_GT((k_ * stretch).norm(), 1e-3 * k_.norm() * stretch.norm());
}

TEST_P(StiffnessTest, ClampedStiffnessIsPositiveDefinite) {
  // Small mesh: remove the x-min face dofs and check every eigenvalue of K_ff is positive.
  const BoxMeshSpec spec = Box(0.02, 0.01, 0.01, 2, 1, 1, GetParam());
  const Mesh mesh = MakeBoxMesh(spec);
  const Eigen::MatrixXd k = Eigen::MatrixXd(AssembleStiffness(mesh, kRubber));
  const auto clamped = NodesOnBoxFace(mesh, spec, BoxFace::kXMin);
  const std::set<int> fixed(clamped.begin(), clamped.end());
  std::vector<int> free;
  for (int d = 0; d < k.rows(); ++d)
    if (!fixed.count(d / 3)) free.push_back(d);
  Eigen::MatrixXd kff(free.size(), free.size());
  for (std::size_t i = 0; i < free.size(); ++i)
    for (std::size_t j = 0; j < free.size(); ++j) kff(i, j) = k(free[i], free[j]);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(kff, Eigen::EigenvaluesOnly);
  EXPECT_GT(eig.eigenvalues().minCoeff(), 1e-8 * eig.eigenvalues().maxCoeff());
  // Without the clamp, exactly six zero eigenvalues (the rigid motions).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> all(k, Eigen::EigenvaluesOnly);
  const double scale = all.eigenvalues().maxCoeff();
  int zeros = 0;
  for (int i = 0; i < all.eigenvalues().size(); ++i) zeros += std::abs(all.eigenvalues()[i]) < 1e-10 * scale;
  EXPECT_EQ(zeros, 6);
}

// Prescribes u_exact on all boundary nodes, solves K_ii u_i = -K_ib u_b (zero body force) with
// an independent sparse LDL^T, and returns the largest interior error relative to max |u|.
template <typename Field>
double PatchError(const Mesh& mesh, const BoxMeshSpec& spec, const Eigen::SparseMatrix<double>& k, Field field) {
  const Eigen::VectorXd exact = Interpolate(mesh, field);
  const auto boundary = BoundaryNodes(mesh, spec);
  const std::set<int> fixed(boundary.begin(), boundary.end());
  std::vector<int> to_free(k.rows(), -1);
  int nf = 0;
  for (int d = 0; d < k.rows(); ++d)
    if (!fixed.count(d / 3)) to_free[d] = nf++;
  EXPECT_GT(nf, 0);
  Eigen::VectorXd ub = exact;
  for (int d = 0; d < k.rows(); ++d)
    if (to_free[d] >= 0) ub[d] = 0.0;
  const Eigen::VectorXd kub = k * ub;
  std::vector<Eigen::Triplet<double>> t;
  for (int c = 0; c < k.outerSize(); ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(k, c); it; ++it)
      if (to_free[it.row()] >= 0 && to_free[c] >= 0) t.emplace_back(to_free[it.row()], to_free[c], it.value());
  Eigen::SparseMatrix<double> kii(nf, nf);
  kii.setFromTriplets(t.begin(), t.end());
  Eigen::VectorXd rhs(nf);
  for (int d = 0; d < k.rows(); ++d)
    if (to_free[d] >= 0) rhs[to_free[d]] = -kub[d];
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(kii);
  EXPECT_EQ(ldlt.info(), Eigen::Success);
  const Eigen::VectorXd ui = ldlt.solve(rhs);
  double err = 0.0;
  for (int d = 0; d < k.rows(); ++d)
    if (to_free[d] >= 0) err = std::max(err, std::abs(ui[to_free[d]] - exact[d]));
  return err / exact.cwiseAbs().maxCoeff();
}

TEST_P(StiffnessTest, PatchTestReproducesConstantStrain) {
  // A general linear field (all six strains plus a rotation and a translation), 1e-4 strain.
  Eigen::Matrix3d grad;
  grad << 1.0, -0.4, 0.7, 0.3, -0.8, 0.2, -0.5, 0.6, 0.9;
  grad *= 1e-4;
  const Eigen::Vector3d offset(1e-6, -2e-6, 3e-6);
  const double err = PatchError(mesh_, spec_, k_, [&](const Eigen::Vector3d& x) -> Eigen::Vector3d {
    return offset + grad * x;
  });
  EXPECT_LT(err, 1e-10);
}

TEST_P(StiffnessTest, QuadraticEquilibriumFieldIsExactForTet10Only) {
  // u = (x^2 - y^2 + yz, -2xy + zx, xy) (scaled, centred): divergence-free and harmonic, so
  // it solves Navier's equation with no body force. It lies in the Tet10 space (straight
  // edges), so Tet10 must reproduce it; Tet4 cannot, which the second check confirms.
  const Eigen::Vector3d c = spec_.min_corner_m + 0.5 * spec_.size_m;
  const auto field = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    const Eigen::Vector3d x = p - c;
    return 0.05 * Eigen::Vector3d(x.x() * x.x() - x.y() * x.y() + x.y() * x.z(),
                                  -2.0 * x.x() * x.y() + x.z() * x.x(), x.x() * x.y());
  };
  const double err = PatchError(mesh_, spec_, k_, field);
  if (GetParam() == ElementOrder::kTet10) {
    EXPECT_LT(err, 1e-9);
  } else {
    EXPECT_GT(err, 1e-4);
  }
}

INSTANTIATE_TEST_SUITE_P(Orders, StiffnessTest,
                         ::testing::Values(ElementOrder::kTet4, ElementOrder::kTet10),
                         testing::OrderName);

TEST(ElementStiffness, Tet4MatchesTet10OnAffineFields) {
  // On a straight-edged element both interpolate a linear field exactly, so the strain
  // energies 1/2 u^T K u agree; the reference energy is V/2 eps^T D eps by hand.
  Eigen::Matrix<double, 4, 3> x4;
  x4 << 0.0, 0.0, 0.0, 0.02, 0.001, 0.0, 0.003, 0.015, 0.002, 0.001, 0.004, 0.018;
  Eigen::Matrix<double, 10, 3> x10;
  x10.topRows<4>() = x4;
  for (int k = 0; k < 6; ++k)
    x10.row(4 + k) = 0.5 * (x4.row(kTet10EdgeCorners[k][0]) + x4.row(kTet10EdgeCorners[k][1]));
  Eigen::Matrix3d grad;
  grad << 2e-3, 1e-3, 0.0, -3e-3, 1e-3, 4e-3, 0.0, 5e-4, -1e-3;
  Eigen::Matrix<double, 12, 1> u4;
  Eigen::Matrix<double, 30, 1> u10;
  for (int n = 0; n < 10; ++n) {
    const Eigen::Vector3d u = grad * x10.row(n).transpose();
    u10.segment<3>(3 * n) = u;
    if (n < 4) u4.segment<3>(3 * n) = u;
  }
  const Eigen::Matrix3d eps = 0.5 * (grad + grad.transpose());
  const double lambda = 3e6 * 0.3 / (1.3 * 0.4), mu = 3e6 / 2.6;
  const double volume = (x4.row(1) - x4.row(0)).cross(x4.row(2) - x4.row(0)).dot(x4.row(3) - x4.row(0)) / 6.0;
  const double energy = volume * (0.5 * lambda * eps.trace() * eps.trace() + mu * (eps.array() * eps.array()).sum());
  const Material m{3e6, 0.3};
  EXPECT_NEAR(0.5 * u4.dot(Tet4Stiffness(x4, m) * u4), energy, 1e-12 * energy);
  EXPECT_NEAR(0.5 * u10.dot(Tet10Stiffness(x10, m) * u10), energy, 1e-12 * energy);
}

}  // namespace
}  // namespace hapco::fem
