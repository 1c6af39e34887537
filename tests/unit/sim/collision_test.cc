// Collision detection (sim/collision.h): flat and deformed box obstacles, shared edges, the
// tree against brute force, and the paper's two-body scene (algorithms.md §1-2).
#include "sim/collision.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <new>
#include <numbers>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "common/error.h"
#include "fem/box_mesh.h"
#include "fem/mesh.h"
#include "sim/box_tree.h"

// Counts heap allocations while g_count_allocations is set (allocation-free Detect test).
namespace {
std::atomic<bool> g_count_allocations{false};
std::atomic<long> g_allocations{0};
}  // namespace

// GCC flags free() on memory from a replaced operator new even though that new uses malloc.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t size) {
  if (g_count_allocations.load(std::memory_order_relaxed)) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
  }
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace hapco::sim {
namespace {

using Points = Eigen::Matrix<double, Eigen::Dynamic, 3>;

constexpr double kTight = 1e-12;

fem::BoxMeshSpec ObstacleSpec(fem::ElementOrder order, Eigen::Vector3i divisions = {10, 2, 2}) {
  fem::BoxMeshSpec spec;
  spec.min_corner_m = Eigen::Vector3d::Zero();
  spec.size_m = Eigen::Vector3d(0.10, 0.02, 0.02);
  spec.divisions = divisions;
  spec.order = order;
  return spec;
}

std::vector<int> Iota(int n) {
  std::vector<int> ids(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) ids[static_cast<std::size_t>(i)] = i;
  return ids;
}

Points ToPoints(const std::vector<Eigen::Vector3d>& v) {
  Points p(static_cast<Eigen::Index>(v.size()), 3);
  for (std::size_t i = 0; i < v.size(); ++i) p.row(static_cast<Eigen::Index>(i)) = v[i].transpose();
  return p;
}

// Checks the invariants every contact must satisfy, against the obstacle positions.
void ExpectWellFormed(const ContactPoint& c, const Points& obstacle, const Points& tool) {
  const Eigen::Matrix3d& f = c.frame;
  EXPECT_LT((f * f.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(f.determinant(), 1.0, 1e-12);
  const Eigen::Vector3d n = f.row(0).transpose();
  const Eigen::Vector3d t1 = f.row(1).transpose();
  const Eigen::Vector3d t2 = f.row(2).transpose();
  EXPECT_LT((t1.cross(t2) - n).norm(), 1e-12);
  double sum = 0.0;
  for (int k = 0; k < c.num_obstacle_nodes; ++k) {
    sum += c.weights[static_cast<std::size_t>(k)];
    const int node = c.obstacle_nodes[static_cast<std::size_t>(k)];
    EXPECT_TRUE(node >= 0 && node < obstacle.rows());
  }
  for (int k = c.num_obstacle_nodes; k < 6; ++k) {
    EXPECT_EQ(c.obstacle_nodes[static_cast<std::size_t>(k)], -1);
    EXPECT_EQ(c.weights[static_cast<std::size_t>(k)], 0.0);
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  // Signed normal gap by definition.
  const Eigen::Vector3d x = tool.row(c.tool_node).transpose();
  EXPECT_NEAR(c.gap_m, (x - c.obstacle_point_m).dot(n), 1e-12);
}

// Σ w_i x_i = obstacle point: the point is the face's surface point (quadratic on a 6-node
// face), the one the weights carry into the solver.
void ExpectWeightsReproducePoint(const ContactPoint& c, const Points& obstacle) {
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  for (int k = 0; k < c.num_obstacle_nodes; ++k) {
    weighted += c.weights[static_cast<std::size_t>(k)] *
                obstacle.row(c.obstacle_nodes[static_cast<std::size_t>(k)]).transpose();
  }
  EXPECT_LT((weighted - c.obstacle_point_m).norm(), 1e-14);
}

class FlatBoxTest : public ::testing::TestWithParam<fem::ElementOrder> {};

TEST_P(FlatBoxTest, PointsAboveTopFaceGiveHeightAsGap) {
  const auto spec = ObstacleSpec(GetParam());
  const fem::Mesh mesh = fem::MakeBoxMesh(spec);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(0.0, 0.10), uy(0.0, 0.02), uh(0.0, 4.9e-4);
  std::vector<Eigen::Vector3d> q;
  std::vector<double> heights;
  for (int i = 0; i < 200; ++i) {
    heights.push_back(i < 5 ? 0.0 : uh(rng));
    q.emplace_back(ux(rng), uy(rng), 0.02 + heights.back());
  }
  const Points tool = ToPoints(q);
  ContactDetector detector(fem::BoundaryTriangles(mesh), mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> contacts;
  detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &contacts);
  ASSERT_EQ(contacts.size(), q.size());
  const int expected_nodes = GetParam() == fem::ElementOrder::kTet4 ? 3 : 6;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const ContactPoint& c = contacts[i];
    EXPECT_EQ(c.tool_node, static_cast<int>(i));
    EXPECT_NEAR(c.gap_m, heights[i], kTight);
    EXPECT_LT((c.frame.row(0).transpose() - Eigen::Vector3d::UnitZ()).norm(), kTight);
    EXPECT_LT((c.obstacle_point_m - Eigen::Vector3d(q[i].x(), q[i].y(), 0.02)).norm(), kTight);
    EXPECT_EQ(c.num_obstacle_nodes, expected_nodes);
    ExpectWellFormed(c, mesh.nodes_m, tool);
    ExpectWeightsReproducePoint(c, mesh.nodes_m);
  }
}

TEST_P(FlatBoxTest, NoContactBeyondFootprintOrAboveActivationGap) {
  const auto spec = ObstacleSpec(GetParam());
  const fem::Mesh mesh = fem::MakeBoxMesh(spec);
  CollisionParameters params;
  params.activation_gap_m = 5e-4;
  params.max_penetration_m = 1e-3;
  const std::vector<Eigen::Vector3d> q = {
      {0.05, 0.01, 0.02 + 6e-4},     // above the activation gap
      {0.05, 0.01, 0.02 + 5e-4},     // exactly at it: active means gap < activation
      {0.102, 0.01, 0.0201},         // beyond the x-max end, beside the top face
      {0.05, -0.003, 0.0201},        // beyond the y-min side
      {-0.01, -0.01, 0.0201},        // beyond a corner
      {0.05, 0.01, 0.02 - 2e-3},     // deeper than max_penetration (and far from sides)
      {0.05, 0.01, 0.02 - 2e-4},     // penetrating within max_penetration -> contact
  };
  const Points tool = ToPoints(q);
  ContactDetector detector(fem::BoundaryTriangles(mesh), mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> contacts;
  detector.Detect(mesh.nodes_m, tool, params, &contacts);
  ASSERT_EQ(contacts.size(), 1u);
  EXPECT_EQ(contacts[0].tool_node, 6);
  EXPECT_NEAR(contacts[0].gap_m, -2e-4, kTight);
  EXPECT_LT((contacts[0].frame.row(0).transpose() - Eigen::Vector3d::UnitZ()).norm(), kTight);
}

TEST_P(FlatBoxTest, SlidingNodeHasOneContactPerStepAcrossEdges) {
  const auto spec = ObstacleSpec(GetParam(), {20, 4, 4});
  const fem::Mesh mesh = fem::MakeBoxMesh(spec);
  const double h = 1e-4;
  // y = 0.005 is a grid line and the steps hit every grid vertex: the node runs along shared
  // edges and through shared vertices. y = 0.0123 crosses edges and diagonals in between.
  for (double y : {0.005, 0.0123}) {
    std::vector<Eigen::Vector3d> q;
    for (int k = 0; k <= 400; ++k) q.emplace_back(0.00025 * k, y, 0.02 + h);
    const Points tool = ToPoints(q);
    ContactDetector detector(fem::BoundaryTriangles(mesh), mesh.nodes_m, Iota(tool.rows()));
    std::vector<ContactPoint> contacts;
    detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &contacts);
    // One contact per node (no duplicates, none lost on edges, vertices or the box ends).
    ASSERT_EQ(contacts.size(), q.size()) << "y = " << y;
    std::set<int> triangles;
    int changes = 0;
    for (std::size_t k = 0; k < contacts.size(); ++k) {
      EXPECT_EQ(contacts[k].tool_node, static_cast<int>(k));
      EXPECT_NEAR(contacts[k].gap_m, h, kTight);
      EXPECT_LT((contacts[k].obstacle_point_m - Eigen::Vector3d(q[k].x(), y, 0.02)).norm(), kTight);
      ExpectWellFormed(contacts[k], mesh.nodes_m, tool);
      triangles.insert(contacts[k].obstacle_triangle);
      if (k > 0) {
        EXPECT_NEAR(contacts[k].gap_m, contacts[k - 1].gap_m, kTight);  // continuous
        if (contacts[k].obstacle_triangle != contacts[k - 1].obstacle_triangle) ++changes;
      }
    }
    // 20 cells along x, each top cell is two triangles: at least 20 faces visited.
    EXPECT_GE(static_cast<int>(triangles.size()), 20) << "y = " << y;
    EXPECT_GE(changes, 19) << "y = " << y;
    // The same query again gives the same faces (deterministic tie-break).
    std::vector<ContactPoint> again;
    detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &again);
    ASSERT_EQ(again.size(), contacts.size());
    for (std::size_t k = 0; k < again.size(); ++k) {
      EXPECT_EQ(again[k].obstacle_triangle, contacts[k].obstacle_triangle);
    }
  }
}

std::string OrderName(const ::testing::TestParamInfo<fem::ElementOrder>& param_info) {
  return fem::ToString(param_info.param);
}

TEST_P(FlatBoxTest, NodesOnSharedEdgesAndVerticesGoToTheLowestTriangle) {
  const auto spec = ObstacleSpec(GetParam(), {6, 3, 2});
  const fem::Mesh mesh = fem::MakeBoxMesh(spec);
  const auto tris = fem::BoundaryTriangles(mesh);
  // Every top-face node (shared vertices, and for Tet10 the midsides of shared edges),
  // lifted by h. The faces holding a node are exactly the top faces that reference it.
  const std::vector<int> top = fem::NodesOnBoxFace(mesh, spec, fem::BoxFace::kZMax);
  const double h = 1e-4;
  Points tool(static_cast<Eigen::Index>(top.size()), 3);
  std::vector<int> expected;
  for (std::size_t i = 0; i < top.size(); ++i) {
    tool.row(static_cast<Eigen::Index>(i)) = mesh.nodes_m.row(top[i]);
    tool(static_cast<Eigen::Index>(i), 2) += h;
    int lowest = -1;
    for (int t = static_cast<int>(tris.size()) - 1; t >= 0; --t) {
      const auto& tri = tris[static_cast<std::size_t>(t)];
      bool on_top = true;
      for (int c : tri.corners) on_top = on_top && std::abs(mesh.nodes_m(c, 2) - 0.02) < 1e-12;
      const bool references =
          std::count(tri.corners.begin(), tri.corners.end(), top[i]) > 0 ||
          std::count(tri.midsides.begin(), tri.midsides.end(), top[i]) > 0;
      if (on_top && references) lowest = t;
    }
    ASSERT_GE(lowest, 0);
    expected.push_back(lowest);
  }
  ContactDetector detector(tris, mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> tree, brute;
  detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &tree);
  detector.DetectBruteForce(mesh.nodes_m, tool, CollisionParameters{}, &brute);
  ASSERT_EQ(tree.size(), top.size());
  ASSERT_EQ(brute.size(), top.size());
  for (std::size_t i = 0; i < top.size(); ++i) {
    EXPECT_EQ(tree[i].obstacle_triangle, expected[i]) << "node " << top[i];
    EXPECT_EQ(brute[i].obstacle_triangle, expected[i]) << "node " << top[i];
    EXPECT_NEAR(tree[i].gap_m, h, kTight);
  }
}

INSTANTIATE_TEST_SUITE_P(Orders, FlatBoxTest,
                         ::testing::Values(fem::ElementOrder::kTet4, fem::ElementOrder::kTet10),
                         OrderName);

// Independent brute force: plane projection by least squares onto the corner triangle, the
// gap to the face's surface there (quadratic for 6-node faces), nearest |gap|.
struct Reference {
  bool found = false;
  double gap_m = 0.0;
  Eigen::Vector3d point_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  bool unique = true;  // the runner-up |gap| is clearly larger
};

Reference ReferenceSearch(const std::vector<fem::SurfaceTriangle>& tris, const Points& obstacle,
                          const Eigen::Vector3d& x, const CollisionParameters& p) {
  Reference best;
  double runner_up = std::numeric_limits<double>::infinity();
  for (const auto& t : tris) {
    const Eigen::Vector3d a = obstacle.row(t.corners[0]).transpose();
    const Eigen::Vector3d b = obstacle.row(t.corners[1]).transpose();
    const Eigen::Vector3d c = obstacle.row(t.corners[2]).transpose();
    Eigen::Matrix<double, 3, 2> m;
    m << b - a, c - a;
    const Eigen::Vector2d st = m.colPivHouseholderQr().solve(x - a);
    const double u = 1.0 - st.sum();
    if (std::min({u, st[0], st[1]}) < -p.edge_tolerance) continue;
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    // The surface point: the flat one, or on a 6-node face the quadratic surface at the same
    // face coordinates (P2 triangle: corners l_k (2 l_k - 1), midside of edge (k, k+1) 4 l_k l_k+1).
    Eigen::Vector3d point = a + m * st;
    if (t.midsides[0] >= 0) {
      const std::array<double, 3> l{u, st[0], st[1]};
      point.setZero();
      for (int k = 0; k < 3; ++k) {
        point += l[k] * (2.0 * l[k] - 1.0) * obstacle.row(t.corners[k]).transpose() +
                 4.0 * l[k] * l[(k + 1) % 3] * obstacle.row(t.midsides[k]).transpose();
      }
    }
    const double g = (x - point).dot(n);
    if (!(g < p.activation_gap_m && g >= -p.max_penetration_m)) continue;
    if (!best.found || std::abs(g) < std::abs(best.gap_m)) {
      if (best.found) runner_up = std::abs(best.gap_m);
      best.found = true;
      best.gap_m = g;
      best.point_m = point;
      best.normal = n;
    } else {
      runner_up = std::min(runner_up, std::abs(g));
    }
  }
  best.unique = runner_up > std::abs(best.gap_m) + 1e-9;
  return best;
}

// Smooth field that keeps the mesh valid: the top sags by up to `amplitude_m`, the bottom
// stays put.
Points Sagged(const fem::Mesh& mesh, double amplitude_m) {
  Points x = mesh.nodes_m;
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    const double s = std::sin(std::numbers::pi * x(i, 0) / 0.10);
    x(i, 2) -= amplitude_m * s * (x(i, 2) / 0.02);
  }
  return x;
}

// Points all around the 100 x 20 x 20 mm bar, within a few mm of its surface.
std::vector<Eigen::Vector3d> PointsAroundTheBar(std::mt19937* rng, int count) {
  std::uniform_real_distribution<double> ux(-0.003, 0.103), uy(-0.003, 0.023), uz(-0.003, 0.023);
  std::vector<Eigen::Vector3d> q;
  for (int i = 0; i < count; ++i) q.emplace_back(ux(*rng), uy(*rng), uz(*rng));
  return q;
}

CollisionParameters TwoMillimetreSearch() {
  CollisionParameters params;
  params.activation_gap_m = 2e-3;
  params.max_penetration_m = 2e-3;
  return params;
}

TEST(ContactDetectorTest, TreeMatchesBruteForceOnRandomPoints) {
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet10, {20, 4, 4}));
  const auto tris = fem::BoundaryTriangles(mesh);
  std::mt19937 rng(12345);
  const std::vector<Eigen::Vector3d> q = PointsAroundTheBar(&rng, 3000);
  const Points tool = ToPoints(q);
  const CollisionParameters params = TwoMillimetreSearch();
  ContactDetector detector(tris, mesh.nodes_m, Iota(tool.rows()));
  for (double sag_m : {0.0, 1e-3}) {
    const Points obstacle = Sagged(mesh, sag_m);
    std::vector<ContactPoint> tree, brute;
    detector.Detect(obstacle, tool, params, &tree);
    const DetectorStats tree_stats = detector.last_stats();
    detector.DetectBruteForce(obstacle, tool, params, &brute);
    ASSERT_EQ(tree.size(), brute.size());
    EXPECT_GT(tree.size(), 500u);  // the comparison covers many contacts
    for (std::size_t i = 0; i < tree.size(); ++i) {
      EXPECT_EQ(tree[i].tool_node, brute[i].tool_node);
      EXPECT_EQ(tree[i].obstacle_triangle, brute[i].obstacle_triangle);
      EXPECT_EQ(tree[i].gap_m, brute[i].gap_m);
    }
    EXPECT_LT(tree_stats.triangles_tested, detector.last_stats().triangles_tested / 20);

    // Against the independent search.
    std::size_t next = 0;
    int unique = 0;
    for (int i = 0; i < tool.rows(); ++i) {
      const Reference ref = ReferenceSearch(tris, obstacle, q[static_cast<std::size_t>(i)], params);
      const bool found = next < tree.size() && tree[next].tool_node == i;
      ASSERT_EQ(found, ref.found) << "point " << i;
      if (!found) continue;
      const ContactPoint& c = tree[next++];
      EXPECT_NEAR(c.gap_m, ref.gap_m, 1e-12) << "point " << i;
      if (ref.unique) {
        ++unique;
        EXPECT_LT((c.obstacle_point_m - ref.point_m).norm(), 1e-10) << "point " << i;
        EXPECT_LT((c.frame.row(0).transpose() - ref.normal).norm(), 1e-12) << "point " << i;
      }
      ExpectWellFormed(c, obstacle, tool);
      ExpectWeightsReproducePoint(c, obstacle);  // also on the sagged (curved) faces
    }
    EXPECT_GT(unique, 400);
  }
}

TEST(ContactDetectorTest, TiltedObstacleGivesExactPlaneGap) {
  // A linear field keeps the faces flat: the top becomes the plane z = 0.02 + α x exactly.
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet10));
  const double alpha = 0.05;
  Points obstacle = mesh.nodes_m;
  for (Eigen::Index i = 0; i < obstacle.rows(); ++i) {
    obstacle(i, 2) += alpha * obstacle(i, 0) * obstacle(i, 2) / 0.02;
  }
  std::vector<Eigen::Vector3d> q;
  const double h = 3e-4;  // vertical offset above the tilted top
  for (int i = 1; i < 40; ++i) q.emplace_back(0.0025 * i, 0.0071, 0.02 + alpha * 0.0025 * i + h);
  const Points tool = ToPoints(q);
  ContactDetector detector(fem::BoundaryTriangles(mesh), mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> contacts;
  detector.Detect(obstacle, tool, CollisionParameters{}, &contacts);
  ASSERT_EQ(contacts.size(), q.size());
  const Eigen::Vector3d n = Eigen::Vector3d(-alpha, 0.0, 1.0).normalized();
  for (const auto& c : contacts) {
    EXPECT_NEAR(c.gap_m, h / std::sqrt(1.0 + alpha * alpha), kTight);
    EXPECT_LT((c.frame.row(0).transpose() - n).norm(), kTight);
    ExpectWellFormed(c, obstacle, tool);
    ExpectWeightsReproducePoint(c, obstacle);  // midsides moved linearly: still midpoints
  }
}

TEST(ContactDetectorTest, GapsFollowSaggedSurface) {
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet10, {20, 4, 4}));
  const double amplitude_m = 1e-3;
  const Points obstacle = Sagged(mesh, amplitude_m);
  // Points h above the sagged surface z(x) = 0.02 − A sin(π x / L): the gap is h cos(slope)
  // up to the flat-facet error A (π/L)² Δx² / 8 ≈ 3e-6 m (Δx = 5 mm).
  const double h = 2e-4;
  std::vector<Eigen::Vector3d> q;
  std::vector<double> expected;
  for (int i = 1; i < 100; ++i) {
    const double x = 0.001 * i + 0.0003;
    const double k = std::numbers::pi / 0.10;
    const double slope = -amplitude_m * k * std::cos(k * x);
    q.emplace_back(x, 0.0093, 0.02 - amplitude_m * std::sin(k * x) + h);
    expected.push_back(h / std::sqrt(1.0 + slope * slope));
  }
  const Points tool = ToPoints(q);
  ContactDetector detector(fem::BoundaryTriangles(mesh), mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> contacts;
  detector.Detect(obstacle, tool, CollisionParameters{}, &contacts);
  ASSERT_EQ(contacts.size(), q.size());
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    EXPECT_NEAR(contacts[i].gap_m, expected[i], 5e-6) << "x = " << q[i].x();
    EXPECT_GT(contacts[i].frame(0, 2), 0.999);
    ExpectWellFormed(contacts[i], obstacle, tool);
  }
  // Against the undeformed (flat) obstacle the same points sit h − A sin(π x / L) above the
  // top: the detector really used the deformed positions above.
  std::vector<ContactPoint> flat;
  detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &flat);
  ASSERT_EQ(flat.size(), q.size());
  for (std::size_t i = 0; i < flat.size(); ++i) {
    EXPECT_NEAR(flat[i].gap_m, q[i].z() - 0.02, kTight);
  }
}

struct PaperScene {
  fem::BoxMeshSpec obstacle_spec;
  fem::BoxMeshSpec tool_spec;
  fem::Mesh obstacle;
  fem::Mesh tool;
  std::vector<int> candidates;
};

PaperScene MakePaperScene() {
  PaperScene s;
  s.obstacle_spec.size_m = Eigen::Vector3d(0.10, 0.02, 0.02);
  s.obstacle_spec.divisions = Eigen::Vector3i(20, 4, 4);
  s.obstacle_spec.order = fem::ElementOrder::kTet10;
  s.tool_spec.min_corner_m = Eigen::Vector3d(0.04, 0.0, 0.02);
  s.tool_spec.size_m = Eigen::Vector3d(0.02, 0.02, 0.01);
  s.tool_spec.divisions = Eigen::Vector3i(4, 4, 2);
  s.tool_spec.order = fem::ElementOrder::kTet10;
  s.obstacle = fem::MakeBoxMesh(s.obstacle_spec);
  s.tool = fem::MakeBoxMesh(s.tool_spec);
  s.candidates = fem::NodesOnBoxFace(s.tool, s.tool_spec, fem::BoxFace::kZMin);
  return s;
}

TEST(ContactDetectorTest, PaperSceneRestPressAndSlideOff) {
  const PaperScene s = MakePaperScene();
  ASSERT_EQ(s.candidates.size(), 81u);  // 9 x 9 corner and midside nodes on a 4 x 4 face
  const auto normals =
      CandidateNodeNormals(s.tool, fem::BoundaryTriangles(s.tool), s.candidates);
  ContactDetector detector(fem::BoundaryTriangles(s.obstacle), s.obstacle.nodes_m,
                           s.candidates, normals);
  const CollisionParameters params;  // activation 0.5 mm as in the paper scene
  std::vector<ContactPoint> contacts;
  contacts.reserve(s.candidates.size());

  const auto moved = [&](const Eigen::Vector3d& d) {
    Points x = s.tool.nodes_m;
    x.rowwise() += d.transpose();
    return x;
  };
  // At rest: every candidate touches with zero gap, n = +z, also the rim nodes lying on the
  // obstacle's top edges at y = 0 and y = 0.02 (the normal check keeps them off the sides).
  {
    const Points tool = moved(Eigen::Vector3d::Zero());
    detector.Detect(s.obstacle.nodes_m, tool, params, &contacts);
    ASSERT_EQ(contacts.size(), s.candidates.size());
    for (std::size_t i = 0; i < contacts.size(); ++i) {
      EXPECT_EQ(contacts[i].tool_node, s.candidates[i]);
      EXPECT_NEAR(contacts[i].gap_m, 0.0, kTight);
      EXPECT_LT((contacts[i].frame.row(0).transpose() - Eigen::Vector3d::UnitZ()).norm(), kTight);
      ExpectWellFormed(contacts[i], s.obstacle.nodes_m, tool);
      ExpectWeightsReproducePoint(contacts[i], s.obstacle.nodes_m);
    }
  }
  // Pressed 0.1 mm: all penetrate by 0.1 mm, still on the top face.
  {
    const Points tool = moved(Eigen::Vector3d(0.0, 0.0, -1e-4));
    detector.Detect(s.obstacle.nodes_m, tool, params, &contacts);
    ASSERT_EQ(contacts.size(), s.candidates.size());
    for (const auto& c : contacts) {
      EXPECT_NEAR(c.gap_m, -1e-4, kTight);
      EXPECT_LT((c.frame.row(0).transpose() - Eigen::Vector3d::UnitZ()).norm(), kTight);
    }
  }
  // Slid 5 mm along +y: nodes past the obstacle's y-max edge lose contact; the row that
  // lands exactly on the edge keeps it.
  {
    const Points tool = moved(Eigen::Vector3d(0.0, 0.005, 0.0));
    detector.Detect(s.obstacle.nodes_m, tool, params, &contacts);
    std::set<int> in_contact;
    for (const auto& c : contacts) {
      EXPECT_TRUE(in_contact.insert(c.tool_node).second) << "duplicate contact";
      EXPECT_NEAR(c.gap_m, 0.0, kTight);
    }
    int off = 0;
    for (int id : s.candidates) {
      const double y = tool(id, 1);
      if (y > 0.02 + 1e-9) {
        ++off;
        EXPECT_EQ(in_contact.count(id), 0u) << "node " << id << " at y = " << y;
      } else {
        EXPECT_EQ(in_contact.count(id), 1u) << "node " << id << " at y = " << y;
      }
    }
    EXPECT_EQ(off, 18);  // two rows of 9 nodes at y = 0.0225 and 0.025
  }
}

TEST(ContactDetectorTest, CandidateNodeNormalsOfBottomFaceAreMinusZ) {
  const PaperScene s = MakePaperScene();
  const auto normals =
      CandidateNodeNormals(s.tool, fem::BoundaryTriangles(s.tool), s.candidates);
  ASSERT_EQ(normals.size(), s.candidates.size());
  for (const auto& n : normals) EXPECT_LT((n + Eigen::Vector3d::UnitZ()).norm(), kTight);
}

TEST(ContactDetectorTest, TrianglesTestedPerQueryStaySmallOnBigMesh) {
  fem::BoxMeshSpec spec;
  spec.size_m = Eigen::Vector3d(1.0, 1.0, 0.02);
  spec.divisions = Eigen::Vector3i(100, 100, 2);
  spec.order = fem::ElementOrder::kTet4;
  const fem::Mesh mesh = fem::MakeBoxMesh(spec);
  const auto tris = fem::BoundaryTriangles(mesh);
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> u(0.0, 1.0), uh(-2e-4, 4e-4);
  std::vector<Eigen::Vector3d> q;
  for (int i = 0; i < 2000; ++i) q.emplace_back(u(rng), u(rng), 0.02 + uh(rng));
  const Points tool = ToPoints(q);
  ContactDetector detector(tris, mesh.nodes_m, Iota(tool.rows()));
  std::vector<ContactPoint> contacts;
  detector.Detect(mesh.nodes_m, tool, CollisionParameters{}, &contacts);
  EXPECT_EQ(contacts.size(), q.size());
  const DetectorStats& st = detector.last_stats();
  const double tested = static_cast<double>(st.triangles_tested) / static_cast<double>(st.queries);
  const double visited = static_cast<double>(st.bvh_nodes_visited) / static_cast<double>(st.queries);
  std::cout << "big mesh: " << st.triangles_total << " triangles, " << detector.bvh_node_count()
            << " boxes; per query: " << tested << " triangles tested, " << visited
            << " boxes visited (brute force: " << st.triangles_total << " triangles)\n";
  EXPECT_LT(tested, 0.01 * static_cast<double>(st.triangles_total));
  EXPECT_LT(visited, 0.01 * static_cast<double>(detector.bvh_node_count()));
}

// The step passes the list of enabled faces too (DetectionContext::enabled_triangles), and then
// only those boxes and the tree nodes above them are refitted. Over changing subsets (each call
// must clear what the last one filled), in both orders of calls, it finds exactly what the
// flags alone find, and with no faces enabled it finds nothing.
TEST(ContactDetectorTest, RefitOfTheEnabledFacesOnlyFindsWhatTheFlagsFind) {
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet10, {20, 4, 4}));
  const auto tris = fem::BoundaryTriangles(mesh);
  std::mt19937 rng(99);
  const Points tool = ToPoints(PointsAroundTheBar(&rng, 2000));
  const CollisionParameters params = TwoMillimetreSearch();
  ContactDetector with_list(tris, mesh.nodes_m, Iota(tool.rows()));
  ContactDetector flags_only(tris, mesh.nodes_m, Iota(tool.rows()));
  const Points obstacle = Sagged(mesh, 1e-3);
  std::size_t compared = 0;
  for (int round = 0; round < 8; ++round) {
    // A box of the surface (as the broad phase enables), a random scatter, nothing, everything.
    std::vector<char> enabled(tris.size(), 0);
    std::vector<int> list;
    const double x0 = 0.012 * round;
    for (std::size_t t = 0; t < tris.size(); ++t) {
      const double x = mesh.nodes_m(tris[t].corners[0], 0);
      const bool on = round == 6 ? false : round == 7 ? true : round % 2 == 0 ? (x >= x0 && x <= x0 + 0.03) : (rng() % 3 == 0);
      if (on) {
        enabled[t] = 1;
        list.push_back(static_cast<int>(t));
      }
    }
    std::shuffle(list.begin(), list.end(), rng);  // any order
    std::vector<ContactPoint> a, b;
    DetectionContext listed;
    listed.triangle_enabled = &enabled;
    listed.enabled_triangles = &list;
    DetectionContext flagged;
    flagged.triangle_enabled = &enabled;
    with_list.Detect(obstacle, tool, params, &a, listed);
    flags_only.Detect(obstacle, tool, params, &b, flagged);
    ASSERT_EQ(a.size(), b.size()) << "round " << round;
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].tool_node, b[i].tool_node);
      EXPECT_EQ(a[i].obstacle_triangle, b[i].obstacle_triangle);
      EXPECT_EQ(a[i].gap_m, b[i].gap_m);
      EXPECT_TRUE(enabled[static_cast<std::size_t>(a[i].obstacle_triangle)]);
    }
    compared += a.size();
    if (round == 6) {
      EXPECT_TRUE(a.empty());
    }
    if (round == 7) {
      EXPECT_GT(a.size(), 300u);
    }
    // A full refit in between (no list) must not leave stale boxes for the next listed call.
    if (round == 3) with_list.Detect(obstacle, tool, params, &a);
  }
  EXPECT_GT(compared, 800u);
}

// A face that rose since the last detection may hold a new contact up to twice the rise deeper
// than max_penetration_m (a bar face springing back up under a tool node once the load that
// pressed it goes), but only over its undeformed triangle: a face tilted by the deformation
// reaches under points beyond the body's end, which are in air.
TEST(ContactDetectorTest, ARisenFaceHoldsDeeperNewContactsOnlyOverItsUndeformedTriangle) {
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet4));
  const std::vector<fem::SurfaceTriangle> faces = fem::BoundaryTriangles(mesh);
  // The top tilted by -27° along x (z -= x/2 on the top): the end x = 0 stays, the rest dips.
  Points obstacle = mesh.nodes_m;
  for (Eigen::Index i = 0; i < obstacle.rows(); ++i) obstacle(i, 2) -= 0.5 * obstacle(i, 0) * obstacle(i, 2) / 0.02;
  // Over the undeformed top at x = 3 mm, 2 mm under the dipped top (gap -2/sqrt(1.25) mm), and
  // beyond the end x = 0 at x = -1 mm, 5 mm below the top: the tilted plane's normal projects it
  // onto the top's first cell 4.9 mm "deep".
  const Points tool = ToPoints({{0.003, 0.0071, 0.02 - 0.0015 - 0.002}, {-0.001, 0.0071, 0.015}});
  ContactDetector detector(faces, mesh.nodes_m, Iota(tool.rows()));
  CollisionParameters parameters;
  parameters.max_penetration_m = 1e-3;
  std::vector<ContactPoint> contacts;
  detector.Detect(obstacle, tool, parameters, &contacts);
  EXPECT_TRUE(contacts.empty()) << "both are deeper than max_penetration_m";
  const std::vector<double> risen(faces.size(), 2.5e-3);  // allows 1 + 5 mm
  DetectionContext context;
  context.triangle_rise_m = &risen;
  detector.Detect(obstacle, tool, parameters, &contacts, context);
  ASSERT_EQ(contacts.size(), 1u);
  EXPECT_EQ(contacts[0].tool_node, 0);
  EXPECT_NEAR(contacts[0].gap_m, -2e-3 / std::sqrt(1.25), 1e-9);
  ExpectWellFormed(contacts[0], obstacle, tool);
  // With a smaller rise the node under the top is too deep again.
  const std::vector<double> little(faces.size(), 0.2e-3);  // allows 1.4 mm
  context.triangle_rise_m = &little;
  detector.Detect(obstacle, tool, parameters, &contacts, context);
  EXPECT_TRUE(contacts.empty());
}

TEST(StaticBoxTreeTest, OverlapQueriesMatchATestOfEveryBox) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> corner(0.0, 1.0), size(0.0, 0.05);
  std::vector<Eigen::Vector3d> lo, hi;
  for (int i = 0; i < 1500; ++i) {
    const Eigen::Vector3d a(corner(rng), corner(rng), corner(rng));
    const Eigen::Vector3d d = i % 10 == 0 ? Eigen::Vector3d::Zero() : Eigen::Vector3d(size(rng), size(rng), size(rng));
    lo.push_back(a);
    hi.push_back(a + d);  // every tenth box is a point
  }
  const StaticBoxTree tree(lo, hi);
  ASSERT_EQ(tree.size(), 1500);
  std::vector<int> hits, stack;
  stack.reserve(static_cast<std::size_t>(tree.depth()) + 1);
  std::size_t total = 0;
  for (int query = 0; query < 200; ++query) {
    const Eigen::Vector3d a(corner(rng), corner(rng), corner(rng));
    const Eigen::Vector3d b = a + Eigen::Vector3d::Constant(query % 2 == 0 ? 0.1 : 0.0);
    hits.clear();
    tree.Overlapping(a, b, &hits, &stack);
    std::vector<int> expected;
    for (int i = 0; i < 1500; ++i) {
      if ((lo[i].array() <= b.array()).all() && (hi[i].array() >= a.array()).all()) expected.push_back(i);
    }
    std::sort(hits.begin(), hits.end());
    EXPECT_EQ(hits, expected) << "query " << query;
    total += expected.size();
    EXPECT_LE(stack.capacity(), static_cast<std::size_t>(tree.depth()) + 1);  // never grew
    // AnyOverlapping and, for a point, AnyContaining (visiting every box that holds it) say
    // the same as the full query.
    EXPECT_EQ(tree.AnyOverlapping(a, b), !expected.empty()) << "query " << query;
    if (query % 2 == 1) {
      std::vector<int> visited;
      EXPECT_FALSE(tree.AnyContaining(a, [&](int id) {
        visited.push_back(id);
        return false;
      }));
      std::sort(visited.begin(), visited.end());
      EXPECT_EQ(visited, expected) << "query " << query;
      if (!expected.empty()) {
        EXPECT_TRUE(tree.AnyContaining(a, [&](int id) { return id == expected.back(); }));
      }
    }
  }
  EXPECT_GT(total, 200u);
  // Touching counts (closed boxes): the query [hi, hi] of a box finds it.
  hits.clear();
  tree.Overlapping(hi[7], hi[7], &hits, &stack);
  EXPECT_NE(std::find(hits.begin(), hits.end(), 7), hits.end());
  hits.clear();
  StaticBoxTree().Overlapping(lo[0], hi[0], &hits, &stack);
  EXPECT_TRUE(hits.empty());
}

TEST(ContactDetectorTest, DetectIsAllocationFreeOnceWarmedUp) {
  const PaperScene s = MakePaperScene();
  ContactDetector detector(
      fem::BoundaryTriangles(s.obstacle), s.obstacle.nodes_m, s.candidates,
      CandidateNodeNormals(s.tool, fem::BoundaryTriangles(s.tool), s.candidates));
  std::vector<ContactPoint> contacts;
  detector.Detect(s.obstacle.nodes_m, s.tool.nodes_m, CollisionParameters{}, &contacts);
  ASSERT_FALSE(contacts.empty());
  Points tool = s.tool.nodes_m;
  tool.col(2).array() -= 1e-4;
  g_allocations = 0;
  g_count_allocations = true;
  detector.Detect(s.obstacle.nodes_m, tool, CollisionParameters{}, &contacts);
  g_count_allocations = false;
  EXPECT_EQ(g_allocations.load(), 0);
  EXPECT_EQ(contacts.size(), s.candidates.size());
}

// One 6-node face, corners 0-2 and midsides 3 (edge 0-1), 4 (1-2), 5 (2-0), in the plane z = 0
// with the midsides at their edge midpoints.
Points SixNodeFace() {
  const Eigen::Vector3d c0(0.0, 0.0, 0.0), c1(0.012, 0.001, 0.0), c2(0.002, 0.009, 0.0);
  return ToPoints({c0, c1, c2, (c0 + c1) / 2, (c1 + c2) / 2, (c2 + c0) / 2});
}
const fem::SurfaceTriangle kSixNodeFace{{0, 1, 2}, {3, 4, 5}};

TEST(QuadraticFaceSubtriangles, TileTheFaceAndMapToItsParametricCoordinates) {
  const Points x = SixNodeFace();
  const auto parts = FourSubtriangles(kSixNodeFace);
  const auto row = [&](int node) -> Eigen::Vector3d { return x.row(node).transpose(); };
  const Eigen::Vector3d face_area = (row(1) - row(0)).cross(row(2) - row(0)) / 2;
  Eigen::Vector3d area_sum = Eigen::Vector3d::Zero();
  // The face's parametric coordinates of a point in its plane, solved here directly:
  // p = l0 c0 + l1 c1 + l2 c2 with l0 = 1 - l1 - l2.
  Eigen::Matrix<double, 3, 2> edges;
  edges << row(1) - row(0), row(2) - row(0);
  const auto parametric = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    const Eigen::Vector2d l12 = edges.colPivHouseholderQr().solve(p - row(0));
    return {1.0 - l12.sum(), l12[0], l12[1]};
  };
  for (int which = 0; which < 4; ++which) {
    const auto& tri = parts[static_cast<std::size_t>(which)];
    EXPECT_EQ(tri.midsides, (std::array<int, 3>{-1, -1, -1}));
    const Eigen::Vector3d area = (row(tri.corners[1]) - row(tri.corners[0])).cross(row(tri.corners[2]) - row(tri.corners[0])) / 2;
    EXPECT_NEAR(area.dot(face_area) / face_area.squaredNorm(), 0.25, 1e-12) << "sub-triangle " << which;  // same side, a quarter
    area_sum += area;
    for (int v = 0; v < 3; ++v) {
      const Eigen::Vector3d expected = parametric(row(tri.corners[static_cast<std::size_t>(v)]));
      EXPECT_LT((FaceBarycentricOfSubtriangle(which, Eigen::Vector3d::Unit(v)) - expected).norm(), 1e-12)
          << "sub-triangle " << which << " vertex " << v;
    }
    // Inside points: the map is affine, so a sub-triangle point maps to its own face coordinates.
    const Eigen::Vector3d s(0.2, 0.5, 0.3);
    const Eigen::Vector3d p = s[0] * row(tri.corners[0]) + s[1] * row(tri.corners[1]) + s[2] * row(tri.corners[2]);
    EXPECT_LT((FaceBarycentricOfSubtriangle(which, s) - parametric(p)).norm(), 1e-12);
  }
  EXPECT_LT((area_sum - face_area).norm(), 1e-12 * face_area.norm());
}

TEST(QuadraticFaceSubtriangles, FlatFaceGivesTheCornerTriangleContact) {
  // Midsides at their edge midpoints: the sub-triangles lie in the corner triangle, so both
  // searches find the same point, gap and six weights.
  const Points x = SixNodeFace();
  const std::vector<Eigen::Vector3d> q = {{0.004, 0.003, 2e-4}, {0.009, 0.002, -1e-4}, {0.002, 0.007, 1e-4},
                                          {0.005, 0.004, 3e-5}};
  const Points tool = ToPoints(q);
  ContactDetector corners({kSixNodeFace}, x, Iota(tool.rows()));
  const SubtriangleSplit split = SplitIntoSubtriangles({kSixNodeFace});
  ContactDetector subtriangles(split.triangles, x, Iota(tool.rows()), {}, split.faces);
  std::vector<ContactPoint> a, b;
  corners.Detect(x, tool, CollisionParameters{}, &a);
  subtriangles.Detect(x, tool, CollisionParameters{}, &b);
  ASSERT_EQ(a.size(), q.size());
  ASSERT_EQ(b.size(), q.size());
  for (std::size_t i = 0; i < q.size(); ++i) {
    EXPECT_NEAR(a[i].gap_m, b[i].gap_m, 1e-15);
    EXPECT_LT((a[i].obstacle_point_m - b[i].obstacle_point_m).norm(), 1e-15);
    ASSERT_EQ(b[i].num_obstacle_nodes, 6);
    for (int k = 0; k < 6; ++k) {
      EXPECT_EQ(a[i].obstacle_nodes[static_cast<std::size_t>(k)], b[i].obstacle_nodes[static_cast<std::size_t>(k)]);
      EXPECT_NEAR(a[i].weights[static_cast<std::size_t>(k)], b[i].weights[static_cast<std::size_t>(k)], 1e-12);
    }
    ExpectWellFormed(b[i], x, tool);
    ExpectWeightsReproducePoint(b[i], x);
  }
}

TEST(QuadraticFaceSubtriangles, SeeADimplePressedIntoTheFace) {
  // The midsides pressed 0.5 mm into the face (a small tool's dimple): the middle sub-triangle
  // is the plane z = -h. A node 0.1 mm above it is 0.1 mm from the face's surface there, not
  // 0.4 mm inside the flat triangle of the corners. The corner-triangle search projects on
  // that flat triangle and measures the gap to the quadratic surface at the projection (the
  // point its weights give): the P2 surface at l, z = -h (4 Σ_k l_k l_k+1).
  Points x = SixNodeFace();
  const double h = 5e-4, g = 1e-4;
  for (int m = 3; m < 6; ++m) x(m, 2) = -h;
  const Eigen::Vector3d l(0.4, 0.35, 0.25);  // face coordinates of the node's foot point
  const Eigen::Vector3d foot = l[0] * x.row(0).transpose() + l[1] * x.row(1).transpose() + l[2] * x.row(2).transpose();
  const Points tool = ToPoints({Eigen::Vector3d(foot.x(), foot.y(), -h + g)});
  CollisionParameters parameters;
  parameters.activation_gap_m = 1e-3;
  ContactDetector corners({kSixNodeFace}, SixNodeFace(), {0});
  const SubtriangleSplit split = SplitIntoSubtriangles({kSixNodeFace});
  ContactDetector subtriangles(split.triangles, SixNodeFace(), {0}, {}, split.faces);
  std::vector<ContactPoint> a, b;
  corners.Detect(x, tool, parameters, &a);
  subtriangles.Detect(x, tool, parameters, &b);
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  const double quadratic_z_m = -h * 4.0 * (l[0] * l[1] + l[1] * l[2] + l[2] * l[0]);
  EXPECT_NEAR(a[0].gap_m, (-h + g) - quadratic_z_m, 1e-15);  // the quadratic surface under the node
  EXPECT_LT((a[0].obstacle_point_m - Eigen::Vector3d(foot.x(), foot.y(), quadratic_z_m)).norm(), 1e-15);
  ExpectWeightsReproducePoint(a[0], x);
  EXPECT_NEAR(b[0].gap_m, g, 1e-15);      // the dimple
  EXPECT_LT((b[0].obstacle_point_m - Eigen::Vector3d(foot.x(), foot.y(), -h)).norm(), 1e-15);
  ExpectWellFormed(b[0], x, tool);
  // Quadratic weights at the face coordinates l: they reproduce linear fields, so the weighted
  // face coordinates of the six nodes give l back.
  const Eigen::Matrix<double, 6, 3> node_coordinates =
      (Eigen::Matrix<double, 6, 3>() << 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.5, 0.5, 0, 0, 0.5, 0.5, 0.5, 0, 0.5).finished();
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  for (int k = 0; k < 6; ++k) {
    const int node = b[0].obstacle_nodes[static_cast<std::size_t>(k)];
    weighted += b[0].weights[static_cast<std::size_t>(k)] * node_coordinates.row(node).transpose();
  }
  EXPECT_LT((weighted - l).norm(), 1e-12);
}

TEST(QuadraticFaceSubtriangles, DetectorRejectsFacesThatDoNotMatch) {
  const Points x = SixNodeFace();
  const SubtriangleSplit split = SplitIntoSubtriangles({kSixNodeFace});
  const auto& triangles = split.triangles;
  const auto& of = split.faces;
  EXPECT_THROW(ContactDetector(triangles, x, {0}, {}, {of.begin(), of.begin() + 3}), InputError);
  auto swapped = of;
  std::swap(swapped[0].which, swapped[1].which);
  EXPECT_THROW(ContactDetector(triangles, x, {0}, {}, swapped), InputError);
  auto linear = of;
  linear[2].face.midsides = {-1, -1, -1};
  EXPECT_THROW(ContactDetector(triangles, x, {0}, {}, linear), InputError);
}

TEST(ContactDetectorTest, RejectsBadInput) {
  const fem::Mesh mesh = fem::MakeBoxMesh(ObstacleSpec(fem::ElementOrder::kTet4));
  const auto tris = fem::BoundaryTriangles(mesh);
  EXPECT_THROW(ContactDetector({}, mesh.nodes_m, {0}), InputError);
  auto bad = tris;
  bad[0].corners[1] = mesh.num_nodes();
  EXPECT_THROW(ContactDetector(bad, mesh.nodes_m, {0}), InputError);
  bad = tris;
  bad[0].corners[1] = bad[0].corners[0];
  EXPECT_THROW(ContactDetector(bad, mesh.nodes_m, {0}), InputError);
  bad = tris;
  bad[0].midsides[0] = 0;
  EXPECT_THROW(ContactDetector(bad, mesh.nodes_m, {0}), InputError);
  EXPECT_THROW(ContactDetector(tris, mesh.nodes_m, {-1}), InputError);
  EXPECT_THROW(ContactDetector(tris, mesh.nodes_m, {0, 1}, {Eigen::Vector3d::UnitZ()}),
               InputError);

  ContactDetector detector(tris, mesh.nodes_m, {0, 5});
  std::vector<ContactPoint> contacts;
  const Points tool = Points::Zero(6, 3);
  EXPECT_THROW(detector.Detect(mesh.nodes_m.topRows(3), tool, {}, &contacts), InputError);
  EXPECT_THROW(detector.Detect(mesh.nodes_m, tool.topRows(5), {}, &contacts), InputError);
  CollisionParameters p;
  p.activation_gap_m = -1.0;
  EXPECT_THROW(detector.Detect(mesh.nodes_m, tool, p, &contacts), InputError);
  p = {};
  p.max_penetration_m = std::nan("");
  EXPECT_THROW(detector.Detect(mesh.nodes_m, tool, p, &contacts), InputError);
  p = {};
  p.edge_tolerance = 0.5;
  EXPECT_THROW(detector.Detect(mesh.nodes_m, tool, p, &contacts), InputError);
}

}  // namespace
}  // namespace hapco::sim
