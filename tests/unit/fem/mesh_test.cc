// Box meshing, boundary extraction, validation and the quadrature rule.
#include <cmath>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "common/error.h"
#include "fem/assembly.h"
#include "fem/box_mesh.h"
#include "fem/element_stiffness.h"
#include "fem/mesh.h"
#include "fem_test_util.h"

namespace hapco::fem {
namespace {

using testing::Box;

class BoxMeshTest : public ::testing::TestWithParam<ElementOrder> {};

TEST_P(BoxMeshTest, CountsAndVolumeMatchTheBox) {
  const BoxMeshSpec spec = Box(0.10, 0.02, 0.03, 5, 2, 3, GetParam());
  const Mesh mesh = MakeBoxMesh(spec);
  EXPECT_NO_THROW(ValidateMesh(mesh));
  EXPECT_EQ(mesh.num_elements(), 6 * 5 * 2 * 3);
  // Tet10 nodes = grid points of the half-size grid (every edge midpoint is a grid point of
  // the doubled grid, and the Kuhn split uses exactly the edges whose midpoints are those).
  const int expected_nodes = GetParam() == ElementOrder::kTet4 ? 6 * 3 * 4 : 11 * 5 * 7;
  EXPECT_EQ(mesh.num_nodes(), expected_nodes);
  double volume = 0.0;
  for (int e = 0; e < mesh.num_elements(); ++e) {
    const double v = ElementVolume(mesh, e);
    EXPECT_GT(v, 0.0) << "element " << e << " is not right-handed";
    volume += v;
  }
  EXPECT_NEAR(volume, 0.10 * 0.02 * 0.03, 1e-15);
}

TEST_P(BoxMeshTest, BoundaryTrianglesCoverTheSurfaceWithOutwardNormals) {
  const int nx = 4, ny = 3, nz = 2;
  const double sx = 0.1, sy = 0.02, sz = 0.03;
  const BoxMeshSpec spec = Box(sx, sy, sz, nx, ny, nz, GetParam());
  const Mesh mesh = MakeBoxMesh(spec);
  const auto faces = BoundaryTriangles(mesh);
  // A non-conforming split would leave interior faces counted once: the count catches it.
  ASSERT_EQ(static_cast<int>(faces.size()), 2 * (nx * ny + ny * nz + nx * nz) * 2);
  const Eigen::Vector3d centre = spec.min_corner_m + 0.5 * spec.size_m;
  double area = 0.0;
  for (const auto& f : faces) {
    const Eigen::Vector3d a = mesh.nodes_m.row(f.corners[0]).transpose();
    const Eigen::Vector3d b = mesh.nodes_m.row(f.corners[1]).transpose();
    const Eigen::Vector3d c = mesh.nodes_m.row(f.corners[2]).transpose();
    const Eigen::Vector3d normal = (b - a).cross(c - a);
    const Eigen::Vector3d face_centre = (a + b + c) / 3.0;
    EXPECT_GT(normal.dot(face_centre - centre), 0.0);
    area += 0.5 * normal.norm();
    EXPECT_NEAR(TriangleArea(mesh, f), 0.5 * normal.norm(), 1e-18);
    for (int k = 0; k < 3; ++k) {
      if (GetParam() == ElementOrder::kTet4) {
        EXPECT_EQ(f.midsides[k], -1);
      } else {
        const Eigen::Vector3d p = mesh.nodes_m.row(f.corners[k]).transpose();
        const Eigen::Vector3d q = mesh.nodes_m.row(f.corners[(k + 1) % 3]).transpose();
        ASSERT_GE(f.midsides[k], 0);
        EXPECT_LT((mesh.nodes_m.row(f.midsides[k]).transpose() - 0.5 * (p + q)).norm(), 1e-15);
      }
    }
  }
  EXPECT_NEAR(area, 2.0 * (sx * sy + sy * sz + sx * sz), 1e-14);
}

TEST_P(BoxMeshTest, FaceNodesLieOnTheFaceAndCountMatchesTheGrid) {
  const BoxMeshSpec spec = Box(0.1, 0.02, 0.03, 4, 3, 2, GetParam());
  const Mesh mesh = MakeBoxMesh(spec);
  const int m = GetParam() == ElementOrder::kTet4 ? 1 : 2;  // grid refinement of node lattice
  const std::map<BoxFace, int> expected = {
      {BoxFace::kXMin, (3 * m + 1) * (2 * m + 1)}, {BoxFace::kXMax, (3 * m + 1) * (2 * m + 1)},
      {BoxFace::kYMin, (4 * m + 1) * (2 * m + 1)}, {BoxFace::kYMax, (4 * m + 1) * (2 * m + 1)},
      {BoxFace::kZMin, (4 * m + 1) * (3 * m + 1)}, {BoxFace::kZMax, (4 * m + 1) * (3 * m + 1)}};
  for (const auto& [face, count] : expected) {
    const auto ids = NodesOnBoxFace(mesh, spec, face);
    EXPECT_EQ(static_cast<int>(ids.size()), count);
    EXPECT_TRUE(std::is_sorted(ids.begin(), ids.end()));
    const int axis = static_cast<int>(face) / 2;
    const double plane = spec.min_corner_m[axis] + (static_cast<int>(face) % 2 ? spec.size_m[axis] : 0.0);
    for (int n : ids) EXPECT_NEAR(mesh.nodes_m(n, axis), plane, 1e-12);
  }
}

TEST(BoxMesh, Tet10MidsidesAreSharedEdgeMidpoints) {
  const BoxMeshSpec spec = Box(1.0, 1.0, 1.0, 2, 2, 2, ElementOrder::kTet10);
  const Mesh mesh = MakeBoxMesh(spec);
  std::map<std::pair<int, int>, int> edge_to_mid;
  for (int e = 0; e < mesh.num_elements(); ++e) {
    for (int k = 0; k < 6; ++k) {
      const int a = mesh.elements(e, kTet10EdgeCorners[k][0]);
      const int b = mesh.elements(e, kTet10EdgeCorners[k][1]);
      const int mid = mesh.elements(e, 4 + k);
      const auto key = std::minmax(a, b);
      auto [it, inserted] = edge_to_mid.try_emplace({key.first, key.second}, mid);
      EXPECT_EQ(it->second, mid) << "edge shared by two elements has two midside nodes";
      EXPECT_LT((mesh.nodes_m.row(mid) - 0.5 * (mesh.nodes_m.row(a) + mesh.nodes_m.row(b))).norm(), 1e-15);
    }
  }
  EXPECT_EQ(static_cast<int>(edge_to_mid.size()) + 27, mesh.num_nodes());
}

INSTANTIATE_TEST_SUITE_P(Orders, BoxMeshTest,
                         ::testing::Values(ElementOrder::kTet4, ElementOrder::kTet10),
                         testing::OrderName);

TEST(BoxMesh, RejectsBadSpecs) {
  BoxMeshSpec spec = Box(0.1, 0.02, 0.02, 2, 2, 2, ElementOrder::kTet4);
  spec.size_m.y() = 0.0;
  try {
    MakeBoxMesh(spec);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("size along y"), std::string::npos) << e.what();
  }
  spec = Box(0.1, 0.02, 0.02, 2, 0, 2, ElementOrder::kTet4);
  try {
    MakeBoxMesh(spec);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("divisions along y"), std::string::npos) << e.what();
  }
}

// The 4-point rule must integrate every monomial of degree <= 2 exactly over the reference
// tetrahedron: integral of xi^a eta^b zeta^c = a! b! c! / (a+b+c+3)! (Dirichlet formula).
TEST(Quadrature, FourPointRuleIsExactForDegreeTwo) {
  const auto factorial = [](int n) { double f = 1; for (int i = 2; i <= n; ++i) f *= i; return f; };
  for (int a = 0; a <= 2; ++a)
    for (int b = 0; a + b <= 2; ++b)
      for (int c = 0; a + b + c <= 2; ++c) {
        double sum = 0.0;
        for (const auto& qp : Tet4PointRule()) {
          const double xi = qp.barycentric[1], eta = qp.barycentric[2], zeta = qp.barycentric[3];
          sum += qp.weight / 6.0 * std::pow(xi, a) * std::pow(eta, b) * std::pow(zeta, c);
        }
        const double exact = factorial(a) * factorial(b) * factorial(c) / factorial(a + b + c + 3);
        EXPECT_NEAR(sum, exact, 1e-15) << a << b << c;
      }
  // ...and not for degree 3 (the rule is the cheapest one for this integrand, not more).
  double xi3 = 0.0;
  for (const auto& qp : Tet4PointRule()) xi3 += qp.weight / 6.0 * std::pow(qp.barycentric[1], 3);
  EXPECT_GT(std::abs(xi3 - 6.0 / 720.0), 1e-6);
}

TEST(ValidateMesh, RejectsCoincidentNodesAndInvertedElements) {
  Mesh mesh;
  mesh.order = ElementOrder::kTet4;
  mesh.nodes_m.resize(5, 3);
  mesh.nodes_m << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 0, 0;  // node 4 coincides with node 1
  mesh.elements.resize(1, 4);
  mesh.elements << 0, 1, 2, 3;
  EXPECT_NO_THROW(ValidateMesh(mesh));
  mesh.elements << 0, 4, 2, 1;  // two coincident nodes: zero volume
  try {
    ValidateMesh(mesh);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("element 0 is degenerate or inverted"), std::string::npos) << e.what();
  }
  mesh.elements << 0, 2, 1, 3;  // left-handed
  EXPECT_THROW(ValidateMesh(mesh), InputError);
  mesh.elements << 0, 1, 1, 3;  // same node twice
  try {
    ValidateMesh(mesh);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("twice"), std::string::npos) << e.what();
  }
  mesh.elements << 0, 1, 2, 7;
  try {
    ValidateMesh(mesh);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("node 7"), std::string::npos) << e.what();
  }
  mesh.order = ElementOrder::kTet10;  // 4 columns for a Tet10 mesh
  EXPECT_THROW(ValidateMesh(mesh), InputError);
}

TEST(ValidateMesh, RejectsTet10WithAMidsideNodeFoldedOver) {
  BoxMeshSpec spec = Box(1.0, 1.0, 1.0, 1, 1, 1, ElementOrder::kTet10);
  Mesh mesh = MakeBoxMesh(spec);
  EXPECT_NO_THROW(ValidateMesh(mesh));
  // Pull one midside node far past the opposite corners: the Jacobian turns negative.
  const int mid = mesh.elements(0, 4);
  const int a = mesh.elements(0, 0), b = mesh.elements(0, 1);
  mesh.nodes_m.row(mid) = mesh.nodes_m.row(a) + 5.0 * (mesh.nodes_m.row(b) - mesh.nodes_m.row(a));
  EXPECT_THROW(ValidateMesh(mesh), InputError);
}

TEST(ValidateMaterial, NamesTheBadField) {
  const auto message = [](Material m) -> std::string {
    try {
      ValidateMaterial(m);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(message({3e6, 0.3}), "");
  EXPECT_NE(message({0.0, 0.3}).find("youngs_modulus_pa"), std::string::npos);
  EXPECT_NE(message({-1.0, 0.3}).find("youngs_modulus_pa"), std::string::npos);
  EXPECT_NE(message({std::nan(""), 0.3}).find("youngs_modulus_pa"), std::string::npos);
  EXPECT_NE(message({3e6, 0.5}).find("poisson_ratio"), std::string::npos);
  EXPECT_NE(message({3e6, -1.0}).find("poisson_ratio"), std::string::npos);
}

}  // namespace
}  // namespace hapco::fem
