// ElasticBody: consistency of its queries with each other and with an independent solve.
#include <algorithm>
#include <numeric>
#include <random>
#include <set>

#include <Eigen/SparseCholesky>
#include <gtest/gtest.h>

#include "common/error.h"
#include "fem/assembly.h"
#include "fem/box_mesh.h"
#include "fem/elastic_body.h"
#include "fem_test_util.h"

namespace hapco::fem {
namespace {

using testing::Box;

const Material kRed{3e6, 0.3};

// The red body of benchmark 1 at a coarse size, plus a driven patch on its top face (as if a
// device held those nodes), for the queries that need driven nodes.
struct Scene {
  BoxMeshSpec spec;
  ElasticBody body;
};

Scene MakeScene(ElementOrder order, bool with_driven) {
  const BoxMeshSpec spec = Box(0.10, 0.02, 0.02, 6, 2, 2, order);
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = kRed;
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  if (with_driven) {
    for (int n : NodesOnBoxFace(s.mesh, spec, BoxFace::kZMax))
      if (s.mesh.nodes_m(n, 0) > spec.min_corner_m.x() + 0.06) s.driven_nodes.push_back(n);
  }
  return {spec, ElasticBody(std::move(s))};
}

Eigen::VectorXd RandomLoads(int dofs, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 0.1);
  Eigen::VectorXd f(dofs);
  for (int i = 0; i < dofs; ++i) f[i] = normal(rng);
  return f;
}

class ElasticBodyTest : public ::testing::TestWithParam<ElementOrder> {};

TEST_P(ElasticBodyTest, SolveMatchesIndependentSolverAndBoundaryData) {
  const Scene scene = MakeScene(GetParam(), true);
  const ElasticBody& body = scene.body;
  const Eigen::VectorXd f = RandomLoads(body.num_dofs(), 1);
  const Eigen::Vector3d d(1e-4, -2e-4, -3e-4);
  const Eigen::VectorXd u = body.SolveDisplacement(f, d);
  for (int n : body.clamped_nodes()) EXPECT_EQ(u.segment<3>(3 * n).norm(), 0.0);
  for (int n : body.driven_nodes()) EXPECT_EQ((u.segment<3>(3 * n) - d).norm(), 0.0);
  // Free rows of K u equal f (equilibrium), checked through K itself.
  const Eigen::VectorXd residual = body.stiffness() * u - f;
  std::set<int> dirichlet(body.clamped_nodes().begin(), body.clamped_nodes().end());
  dirichlet.insert(body.driven_nodes().begin(), body.driven_nodes().end());
  double worst = 0.0;
  for (int dof = 0; dof < body.num_dofs(); ++dof)
    if (!dirichlet.count(dof / 3)) worst = std::max(worst, std::abs(residual[dof]));
  EXPECT_LT(worst, 1e-9 * f.cwiseAbs().maxCoeff());
  EXPECT_EQ(body.num_free_dofs(), body.num_dofs() - 3 * static_cast<int>(dirichlet.size()));
  EXPECT_EQ(body.stats().free_dofs, body.num_free_dofs());
  EXPECT_GT(body.stats().factor_nonzeros, 0);
}

TEST_P(ElasticBodyTest, DrivenTranslationIsLinearInTheUnitFields) {
  const Scene scene = MakeScene(GetParam(), true);
  const ElasticBody& body = scene.body;
  const Eigen::Vector3d d(2e-4, -1e-4, -5e-4);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(body.num_dofs());
  const Eigen::VectorXd direct = body.SolveDisplacement(zero, d);
  ASSERT_EQ(body.unit_driven_translation_fields().rows(), body.num_dofs());
  ASSERT_EQ(body.unit_driven_translation_fields().cols(), 3);
  const Eigen::VectorXd combined = body.unit_driven_translation_fields() * d;
  EXPECT_LE((direct - combined).norm(), 1e-12 * direct.norm());
  EXPECT_GT(direct.norm(), 0.0);
  // No driven nodes: zero fields.
  const Scene clamped_only = MakeScene(GetParam(), false);
  EXPECT_EQ(clamped_only.body.unit_driven_translation_fields().norm(), 0.0);
}

TEST_P(ElasticBodyTest, ComplianceBlockIsSymmetricAndMatchesUnitLoadSolves) {
  const Scene scene = MakeScene(GetParam(), true);
  const ElasticBody& body = scene.body;
  // Nodes on the top face: some free, some driven (their rows/columns must be zero), plus a
  // clamped one and a repeated one.
  std::vector<int> nodes = NodesOnBoxFace(body.mesh(), scene.spec, BoxFace::kZMax);
  nodes.push_back(body.clamped_nodes().front());
  nodes.push_back(nodes.front());
  const Eigen::MatrixXd c = body.ComplianceBlock(nodes);
  ASSERT_EQ(c.rows(), 3 * static_cast<int>(nodes.size()));
  EXPECT_LE((c - c.transpose()).norm(), 1e-12 * c.norm());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(body.num_dofs());
  for (std::size_t j = 0; j < nodes.size(); j += 3) {
    for (int b = 0; b < 3; ++b) {
      Eigen::VectorXd f = zero;
      f[3 * nodes[j] + b] = 1.0;
      const Eigen::VectorXd u = body.SolveDisplacement(f, Eigen::Vector3d::Zero());
      for (std::size_t i = 0; i < nodes.size(); ++i)
        for (int a = 0; a < 3; ++a)
          EXPECT_NEAR(c(3 * i + a, 3 * j + b), u[3 * nodes[i] + a], 1e-12 * c.cwiseAbs().maxCoeff());
    }
  }
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (body.is_dirichlet_node(nodes[i])) {
      EXPECT_EQ(c.row(3 * i).norm() + c.col(3 * i).norm(), 0.0);
    } else {
      EXPECT_GT(c(3 * i + 2, 3 * i + 2), 0.0);  // pushing a free node moves it that way
    }
  }
}

// The Schur-complement block (a factorization with the set ordered last, then dpotri) against
// 3|S| solves with the body's own factor: two independent computations of (K_ff^-1)_SS. Sets:
// shuffled boundary nodes with repeats and Dirichlet nodes, every node of the body (no
// interior left to eliminate), and Dirichlet nodes only (no free dof: all zero).
TEST_P(ElasticBodyTest, SchurComplementBlockMatchesBatchedSolves) {
  const Scene scene = MakeScene(GetParam(), true);
  const ElasticBody& body = scene.body;
  std::vector<int> boundary;
  for (const BoxFace face : {BoxFace::kZMax, BoxFace::kYMin, BoxFace::kXMax})
    for (int n : NodesOnBoxFace(body.mesh(), scene.spec, face)) boundary.push_back(n);
  std::mt19937 rng(3);
  std::shuffle(boundary.begin(), boundary.end(), rng);
  boundary.push_back(boundary[5]);
  std::vector<int> every(static_cast<std::size_t>(body.mesh().num_nodes()));
  std::iota(every.begin(), every.end(), 0);
  const std::vector<int> dirichlet_only = body.clamped_nodes();
  for (const std::vector<int>* set : std::initializer_list<const std::vector<int>*>{&boundary, &every, &dirichlet_only}) {
    const Eigen::MatrixXd schur = body.ComplianceBlock(*set);
    const Eigen::MatrixXd solves = body.ComplianceBlockBySolves(*set);
    ASSERT_EQ(schur.rows(), 3 * static_cast<Eigen::Index>(set->size()));
    ASSERT_EQ(solves.rows(), schur.rows());
    EXPECT_LE((schur - solves).cwiseAbs().maxCoeff(), 1e-10 * std::max(solves.cwiseAbs().maxCoeff(), 1e-300))
        << set->size() << " nodes";
    EXPECT_EQ(schur.transpose(), schur);
  }
  EXPECT_EQ(body.ComplianceBlock(dirichlet_only).norm(), 0.0);
  EXPECT_GT(body.ComplianceBlock(every).norm(), 0.0);
}

// The body of `plain` again, its factor with the dofs of `nodes` last.
ElasticBody WithComplianceNodes(const Scene& plain, const std::vector<int>& nodes) {
  ElasticBody::Spec s;
  s.mesh = plain.body.mesh();
  s.material = kRed;
  s.clamped_nodes = plain.body.clamped_nodes();
  s.driven_nodes = plain.body.driven_nodes();
  s.compliance_nodes = nodes;
  return ElasticBody(std::move(s));
}

// A body built with compliance nodes (its factor orders their dofs last) must solve and give
// compliance blocks exactly as one factored in CHOLMOD's own order: for the listed nodes, a
// subset of them (read off the same factor) and a set beyond them (a second factorization).
TEST_P(ElasticBodyTest, ComplianceNodesOrderedLastChangeNoResult) {
  const Scene plain = MakeScene(GetParam(), true);
  std::vector<int> top = NodesOnBoxFace(plain.body.mesh(), plain.spec, BoxFace::kZMax);
  std::mt19937 rng(5);
  std::shuffle(top.begin(), top.end(), rng);
  const ElasticBody ordered = WithComplianceNodes(plain, top);

  const Eigen::VectorXd f = RandomLoads(plain.body.num_dofs(), 11);
  const Eigen::Vector3d drive(1e-4, -2e-4, -3e-4);
  const Eigen::VectorXd u_plain = plain.body.SolveDisplacement(f, drive);
  const Eigen::VectorXd u_ordered = ordered.SolveDisplacement(f, drive);
  EXPECT_LE((u_ordered - u_plain).cwiseAbs().maxCoeff(), 1e-10 * u_plain.cwiseAbs().maxCoeff());
  EXPECT_LE((ordered.unit_driven_translation_fields() - plain.body.unit_driven_translation_fields()).cwiseAbs().maxCoeff(),
            1e-10);

  const std::vector<int> subset(top.begin() + 3, top.begin() + 3 + static_cast<long>(top.size()) / 2);
  std::vector<int> beyond = subset;
  for (int n : NodesOnBoxFace(plain.body.mesh(), plain.spec, BoxFace::kYMin)) beyond.push_back(n);
  for (const std::vector<int>* set : std::initializer_list<const std::vector<int>*>{&top, &subset, &beyond}) {
    const Eigen::MatrixXd fast = ordered.ComplianceBlock(*set);
    const Eigen::MatrixXd solves = plain.body.ComplianceBlockBySolves(*set);
    ASSERT_EQ(fast.rows(), 3 * static_cast<Eigen::Index>(set->size()));
    EXPECT_GT(solves.cwiseAbs().maxCoeff(), 0.0);
    EXPECT_LE((fast - solves).cwiseAbs().maxCoeff(), 1e-10 * solves.cwiseAbs().maxCoeff()) << set->size() << " nodes";
  }
}

// Releasing the compliance order frees the dense Schur factor and keeps every answer: solves
// (against the body factored without it from the start) and compliance blocks (against solves).
TEST_P(ElasticBodyTest, ReleasingTheComplianceOrderKeepsSolvesAndBlocks) {
  const Scene plain = MakeScene(GetParam(), true);
  const std::vector<int> top = NodesOnBoxFace(plain.body.mesh(), plain.spec, BoxFace::kZMax);
  ElasticBody body = WithComplianceNodes(plain, top);
  const Eigen::MatrixXd before = body.ComplianceBlock(top);
  const std::size_t free_top_dofs = static_cast<std::size_t>(before.diagonal().count());
  EXPECT_EQ(body.stats().schur_factor_bytes, sizeof(double) * free_top_dofs * free_top_dofs);
  const std::size_t bytes_with_schur = body.stats().factor_bytes;

  body.ReleaseComplianceOrder();
  EXPECT_EQ(body.stats().schur_factor_bytes, 0u);
  EXPECT_LT(body.stats().factor_bytes, bytes_with_schur);
  EXPECT_EQ(body.stats().factor_nonzeros, plain.body.stats().factor_nonzeros) << "CHOLMOD's own order, as without compliance nodes";
  const Eigen::VectorXd f = RandomLoads(plain.body.num_dofs(), 13);
  const Eigen::Vector3d drive(-2e-4, 1e-4, -1e-4);
  const Eigen::VectorXd u_plain = plain.body.SolveDisplacement(f, drive);
  EXPECT_LE((body.SolveDisplacement(f, drive) - u_plain).cwiseAbs().maxCoeff(), 1e-10 * u_plain.cwiseAbs().maxCoeff());
  const Eigen::MatrixXd after = body.ComplianceBlock(top);
  EXPECT_LE((after - before).cwiseAbs().maxCoeff(), 1e-10 * before.cwiseAbs().maxCoeff());
}

TEST_P(ElasticBodyTest, ReactionsBalanceTheAppliedLoads) {
  const Scene scene = MakeScene(GetParam(), true);
  const ElasticBody& body = scene.body;
  const Eigen::VectorXd f = RandomLoads(body.num_dofs(), 7);
  const Eigen::VectorXd u = body.SolveDisplacement(f, Eigen::Vector3d(0.0, 0.0, -1e-4));
  std::vector<int> dirichlet = body.clamped_nodes();
  dirichlet.insert(dirichlet.end(), body.driven_nodes().begin(), body.driven_nodes().end());
  // Loads applied to the body (entries at Dirichlet dofs are ignored by the solve).
  Eigen::Vector3d applied = Eigen::Vector3d::Zero();
  std::set<int> dset(dirichlet.begin(), dirichlet.end());
  for (int n = 0; n < body.mesh().num_nodes(); ++n)
    if (!dset.count(n)) applied += f.segment<3>(3 * n);
  Eigen::VectorXd f_free = f;
  for (int n : dirichlet) f_free.segment<3>(3 * n).setZero();
  const Eigen::Vector3d reactions = body.ReactionForce(u, f_free, dirichlet);
  EXPECT_LT((reactions + applied).norm(), 1e-10 * applied.norm());
  // Free nodes carry no reaction.
  std::vector<int> free_nodes;
  for (int n = 0; n < body.mesh().num_nodes(); ++n)
    if (!dset.count(n)) free_nodes.push_back(n);
  EXPECT_LT(body.ReactionForce(u, f, free_nodes).norm(), 1e-9 * applied.norm());
}

TEST_P(ElasticBodyTest, IsMovable) {
  Scene scene = MakeScene(GetParam(), true);
  const Eigen::VectorXd before = scene.body.unit_driven_translation_fields().col(2);
  ElasticBody moved = std::move(scene.body);
  const Eigen::VectorXd after =
      moved.SolveDisplacement(Eigen::VectorXd::Zero(moved.num_dofs()), Eigen::Vector3d::UnitZ());
  EXPECT_LE((before - after).norm(), 1e-12 * before.norm());
}

INSTANTIATE_TEST_SUITE_P(Orders, ElasticBodyTest,
                         ::testing::Values(ElementOrder::kTet4, ElementOrder::kTet10),
                         testing::OrderName);

std::string ErrorOf(ElasticBody::Spec spec) {
  try {
    ElasticBody body(std::move(spec));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(ElasticBodyInput, RejectsBadSpecsWithAClearMessage) {
  const BoxMeshSpec box = Box(0.10, 0.02, 0.02, 4, 1, 1, ElementOrder::kTet4);
  ElasticBody::Spec good;
  good.mesh = MakeBoxMesh(box);
  good.material = kRed;
  good.clamped_nodes = NodesOnBoxFace(good.mesh, box, BoxFace::kXMin);
  EXPECT_EQ(ErrorOf(good), "");

  ElasticBody::Spec s = good;
  s.clamped_nodes.clear();
  EXPECT_NE(ErrorOf(s).find("no clamped or driven nodes"), std::string::npos);
  s = good;
  s.material.youngs_modulus_pa = 0.0;
  EXPECT_NE(ErrorOf(s).find("youngs_modulus_pa"), std::string::npos);
  s = good;
  s.material.poisson_ratio = 0.5;
  EXPECT_NE(ErrorOf(s).find("poisson_ratio"), std::string::npos);
  s = good;
  s.mesh.nodes_m.row(s.mesh.elements(3, 1)) = s.mesh.nodes_m.row(s.mesh.elements(3, 0));  // coincident
  EXPECT_NE(ErrorOf(s).find("degenerate or inverted"), std::string::npos);
  s = good;
  s.driven_nodes = {s.clamped_nodes.front()};
  EXPECT_NE(ErrorOf(s).find("both clamped and driven"), std::string::npos);
  s = good;
  s.clamped_nodes.push_back(s.mesh.num_nodes());
  EXPECT_NE(ErrorOf(s).find("clamped node"), std::string::npos);
  s = good;
  s.clamped_nodes = {0};  // one node cannot stop rotations about itself
  EXPECT_NE(ErrorOf(s).find("singular stiffness"), std::string::npos);
  s.clamped_nodes = {0, 1, 2};  // three nodes on the y = z = min edge: collinear
  EXPECT_NE(ErrorOf(s).find("lie on one line"), std::string::npos);

  // Found with the scene fuzz harness: finite inputs whose stiffness overflows to inf used to
  // factor "successfully" (every solve NaN).
  const BoxMeshSpec huge_box = Box(100.0, 100.0, 100.0, 1, 1, 1, ElementOrder::kTet4);
  s = good;
  s.mesh = MakeBoxMesh(huge_box);
  s.clamped_nodes = NodesOnBoxFace(s.mesh, huge_box, BoxFace::kXMin);
  s.material.youngs_modulus_pa = 1e308;
  EXPECT_NE(ErrorOf(s).find("stiffness has non-finite entries"), std::string::npos) << ErrorOf(s);

  const ElasticBody body(good);
  EXPECT_THROW(body.SolveDisplacement(Eigen::VectorXd::Zero(5), Eigen::Vector3d::Zero()), InputError);
  const std::vector<int> bad = {-1};
  EXPECT_THROW(body.ComplianceBlock(bad), InputError);
}

}  // namespace
}  // namespace hapco::fem
