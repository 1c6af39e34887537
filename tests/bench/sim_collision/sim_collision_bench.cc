// Contact detection cost per haptic step (sim/collision.h): the AABB tree against the
// brute-force search over every obstacle triangle, on the paper scene (algorithms.md §1) and
// on obstacles of growing size with the same tool. Prints medians and counts of work; the
// ratio tree/brute is measured in the same run.
#include <algorithm>
#include <cstdio>
#include <vector>

#include <Eigen/Core>

#include "common/timer.h"
#include "fem/box_mesh.h"
#include "fem/mesh.h"
#include "sim/collision.h"

namespace {

using hapco::Stopwatch;
using namespace hapco;  // NOLINT: a short benchmark

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Row {
  int triangles = 0;
  int candidates = 0;
  int contacts = 0;
  double tree_us = 0.0;
  int top_triangles = 0;
  double top_tree_us = 0.0;  // detector given only the obstacle's top face (the candidates)
  double brute_us = 0.0;
  double tested_per_query = 0.0;
  double boxes_per_query = 0.0;
};

// Obstacle 0.10 x 0.02 x 0.02 m scaled in x/y by `scale` with `scale`x the divisions; tool
// 2 x 2 x 1 cm resting on its top face at mid-span, pressed by 0.1 mm.
Row Measure(int scale, fem::ElementOrder order, int repeats) {
  fem::BoxMeshSpec obstacle_spec;
  obstacle_spec.size_m = Eigen::Vector3d(0.10 * scale, 0.02 * scale, 0.02);
  obstacle_spec.divisions = Eigen::Vector3i(20 * scale, 4 * scale, 4);
  obstacle_spec.order = order;
  fem::BoxMeshSpec tool_spec;
  tool_spec.min_corner_m = Eigen::Vector3d(0.05 * scale - 0.01, 0.01 * scale - 0.01, 0.02);
  tool_spec.size_m = Eigen::Vector3d(0.02, 0.02, 0.01);
  tool_spec.divisions = Eigen::Vector3i(4, 4, 2);
  tool_spec.order = order;
  const fem::Mesh obstacle = fem::MakeBoxMesh(obstacle_spec);
  const fem::Mesh tool = fem::MakeBoxMesh(tool_spec);
  const auto candidates = fem::NodesOnBoxFace(tool, tool_spec, fem::BoxFace::kZMin);
  sim::ContactDetector detector(
      fem::BoundaryTriangles(obstacle), obstacle.nodes_m, candidates,
      sim::CandidateNodeNormals(tool, fem::BoundaryTriangles(tool), candidates));
  Eigen::Matrix<double, Eigen::Dynamic, 3> tool_x = tool.nodes_m;
  tool_x.col(2).array() -= 1e-4;
  const sim::CollisionParameters params;
  std::vector<sim::ContactPoint> contacts;
  contacts.reserve(candidates.size());

  Row row;
  row.triangles = static_cast<int>(detector.obstacle_triangles().size());
  row.candidates = static_cast<int>(candidates.size());
  std::vector<double> tree_s, brute_s;
  detector.Detect(obstacle.nodes_m, tool_x, params, &contacts);  // warm-up
  for (int r = 0; r < repeats; ++r) {
    Stopwatch watch;
    detector.Detect(obstacle.nodes_m, tool_x, params, &contacts);
    tree_s.push_back(watch.ElapsedSeconds());
  }
  const sim::DetectorStats stats = detector.last_stats();
  row.contacts = static_cast<int>(contacts.size());
  row.tested_per_query =
      static_cast<double>(stats.triangles_tested) / static_cast<double>(stats.queries);
  row.boxes_per_query =
      static_cast<double>(stats.bvh_nodes_visited) / static_cast<double>(stats.queries);
  const int brute_repeats = std::max(3, repeats / (scale * scale));
  for (int r = 0; r < brute_repeats; ++r) {
    Stopwatch watch;
    detector.DetectBruteForce(obstacle.nodes_m, tool_x, params, &contacts);
    brute_s.push_back(watch.ElapsedSeconds());
  }
  row.tree_us = 1e6 * Median(tree_s);

  // The scene's use: only the faces that can ever be touched (the top face), so the refit
  // (linear in the triangles given) stays small too.
  std::vector<fem::SurfaceTriangle> top;
  for (const auto& t : fem::BoundaryTriangles(obstacle)) {
    bool on_top = true;
    for (int c : t.corners) on_top = on_top && obstacle.nodes_m(c, 2) > 0.02 - 1e-9;
    if (on_top) top.push_back(t);
  }
  sim::ContactDetector top_detector(
      top, obstacle.nodes_m, candidates,
      sim::CandidateNodeNormals(tool, fem::BoundaryTriangles(tool), candidates));
  row.top_triangles = static_cast<int>(top.size());
  std::vector<double> top_s;
  top_detector.Detect(obstacle.nodes_m, tool_x, params, &contacts);
  for (int r = 0; r < repeats; ++r) {
    Stopwatch watch;
    top_detector.Detect(obstacle.nodes_m, tool_x, params, &contacts);
    top_s.push_back(watch.ElapsedSeconds());
  }
  row.top_tree_us = 1e6 * Median(top_s);
  row.brute_us = 1e6 * Median(brute_s);
  return row;
}

}  // namespace

int main() {
  std::printf("sim_collision_bench: Detect per step, tool 2x2x1 cm (4x4x2) pressed 0.1 mm\n");
  std::printf("%-6s %5s %9s %6s %8s %10s %10s %8s %12s %11s %7s %11s\n", "order", "scale",
              "triangles", "nodes", "contacts", "tree_us", "brute_us", "ratio", "tested/query",
              "boxes/query", "top_tri", "top_tree_us");
  for (auto order : {fem::ElementOrder::kTet4, fem::ElementOrder::kTet10}) {
    for (int scale : {1, 2, 4, 8}) {
      const Row r = Measure(scale, order, 201);
      std::printf("%-6s %5d %9d %6d %8d %10.2f %10.2f %8.1f %12.2f %11.2f %7d %11.2f\n",
                  fem::ToString(order), scale, r.triangles, r.candidates, r.contacts, r.tree_us,
                  r.brute_us, r.brute_us / r.tree_us, r.tested_per_query, r.boxes_per_query,
                  r.top_triangles, r.top_tree_us);
    }
  }
  return 0;
}
