#include "sim/collision.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <utility>

#include <Eigen/Geometry>

#include "common/error.h"

namespace hapco::sim {

// Ericson, Real-Time Collision Detection §5.1.5, by Voronoi region.
Eigen::Vector3d ClosestPointBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                        const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a;
  const Eigen::Vector3d ac = c - a;
  const Eigen::Vector3d ap = p - a;
  const double d1 = ab.dot(ap);
  const double d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return {1.0, 0.0, 0.0};  // vertex a
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp);
  const double d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return {0.0, 1.0, 0.0};  // vertex b
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {  // edge ab
    const double v = d1 / (d1 - d3);
    return {1.0 - v, v, 0.0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp);
  const double d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return {0.0, 0.0, 1.0};  // vertex c
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {  // edge ac
    const double w = d2 / (d2 - d6);
    return {1.0 - w, 0.0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {  // edge bc
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0.0, 1.0 - w, w};
  }
  const double denom = 1.0 / (va + vb + vc);  // interior
  const double v = vb * denom;
  const double w = vc * denom;
  return {1.0 - v - w, v, w};
}

namespace {

constexpr int kLeafSize = 4;
// Gaps closer than this fraction of the mean reference edge are ties (round-off between
// coplanar faces sharing an edge).
constexpr double kTieRelative = 1e-9;


Eigen::Vector3d Row(const PointsRef& points, int i) { return points.row(i).transpose(); }

void CheckParameters(const CollisionParameters& p) {
  if (!(std::isfinite(p.activation_gap_m) && p.activation_gap_m >= 0.0)) {
    throw InputError("collision activation_gap_m must be finite and >= 0, got " +
                     std::to_string(p.activation_gap_m));
  }
  if (!(std::isfinite(p.max_penetration_m) && p.max_penetration_m >= 0.0)) {
    throw InputError("collision max_penetration_m must be finite and >= 0, got " +
                     std::to_string(p.max_penetration_m));
  }
  if (!(p.edge_tolerance >= 0.0 && p.edge_tolerance <= 0.1)) {
    throw InputError("collision edge_tolerance must be in [0, 0.1] (barycentric slack), got " +
                     std::to_string(p.edge_tolerance));
  }
  if (!(p.persistence_min_cosine > 0.0 && p.persistence_min_cosine <= 1.0)) {
    throw InputError("collision persistence_min_cosine must be in (0, 1] (a cosine), got " +
                     std::to_string(p.persistence_min_cosine));
  }
  if (!(p.persistent_edge_tolerance >= 0.0 && p.persistent_edge_tolerance <= 0.5)) {
    throw InputError("collision persistent_edge_tolerance must be in [0, 0.5] (barycentric slack), got " +
                     std::to_string(p.persistent_edge_tolerance));
  }
  if (!(p.min_normal_opposition >= -1.0 && p.min_normal_opposition <= 1.0)) {
    throw InputError("collision min_normal_opposition must be in [-1, 1] (a cosine), got " +
                     std::to_string(p.min_normal_opposition));
  }
}

// A 6-node face's midsides, each as its offset from the midpoint of its edge (corner k,
// corner k+1), m. Its quadratic surface is the corner triangle plus Σ_k 4 l_k l_k+1 offset_k,
// and Σ_k 4 l_k l_k+1 <= 4/3 on the face: the surface lies within (4/3) max_k |offset_k| of
// the triangle.
std::array<Eigen::Vector3d, 3> MidsideOffsets(const PointsRef& positions_m, const fem::SurfaceTriangle& face,
                                              const std::array<Eigen::Vector3d, 3>& corners_m) {
  std::array<Eigen::Vector3d, 3> offsets;
  for (std::size_t k = 0; k < 3; ++k) {
    offsets[k] = Row(positions_m, face.midsides[k]) - 0.5 * (corners_m[k] + corners_m[(k + 1) % 3]);
  }
  return offsets;
}

// Barycentric coordinates of a point's projection into a triangle from the dot products of
// its edges ab, ac (d00 = ab·ab, d01 = ab·ac, d11 = ac·ac, denom = d00 d11 − d01²) and of the
// point's offset ap (d20 = ap·ab, d21 = ap·ac): the one formula of ProjectionBarycentric and
// of the detector's cached faces (FaceGeometry).
Eigen::Vector3d BarycentricFromDots(double d00, double d01, double d11, double denom, double d20, double d21) {
  const double v = (d11 * d20 - d01 * d21) / denom;
  const double w = (d00 * d21 - d01 * d20) / denom;
  return {1.0 - v - w, v, w};
}

}  // namespace

Eigen::Vector3d ProjectionBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                      const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d v0 = b - a;
  const Eigen::Vector3d v1 = c - a;
  const Eigen::Vector3d v2 = p - a;
  const double d00 = v0.dot(v0);
  const double d01 = v0.dot(v1);
  const double d11 = v1.dot(v1);
  const double d20 = v2.dot(v0);
  const double d21 = v2.dot(v1);
  return BarycentricFromDots(d00, d01, d11, d00 * d11 - d01 * d01, d20, d21);
}

Eigen::Matrix3d FrameFromNormal(const Eigen::Vector3d& n) {
  const Eigen::Vector3d axis =
      std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = (axis - axis.dot(n) * n).normalized();
  const Eigen::Vector3d t2 = n.cross(t1);
  Eigen::Matrix3d frame;
  frame.row(0) = n.transpose();
  frame.row(1) = t1.transpose();
  frame.row(2) = t2.transpose();
  return frame;
}


namespace {

// The sub-triangles' vertices as nodes of their 6-node face (0-2 corners, 3 + k the midside on
// edge (k, k+1)), in the order of SubtriangleOfFace::which, and each face node's parametric
// (barycentric) coordinates: one table for both the split and the map back.
constexpr int kSubtriangleNodes[4][3] = {{0, 3, 5}, {1, 4, 3}, {2, 5, 4}, {3, 4, 5}};
constexpr double kFaceNodeCoordinates[6][3] = {{1, 0, 0},     {0, 1, 0},     {0, 0, 1},
                                               {0.5, 0.5, 0}, {0, 0.5, 0.5}, {0.5, 0, 0.5}};

}  // namespace

std::array<fem::SurfaceTriangle, 4> FourSubtriangles(const fem::SurfaceTriangle& face) {
  const auto node = [&face](int k) {
    return k < 3 ? face.corners[static_cast<std::size_t>(k)] : face.midsides[static_cast<std::size_t>(k - 3)];
  };
  std::array<fem::SurfaceTriangle, 4> parts;
  for (int which = 0; which < 4; ++which) {
    for (int v = 0; v < 3; ++v) {
      parts[static_cast<std::size_t>(which)].corners[static_cast<std::size_t>(v)] = node(kSubtriangleNodes[which][v]);
    }
    parts[static_cast<std::size_t>(which)].midsides = {-1, -1, -1};
  }
  return parts;
}

SubtriangleSplit SplitIntoSubtriangles(const std::vector<fem::SurfaceTriangle>& faces) {
  SubtriangleSplit split;
  for (const fem::SurfaceTriangle& face : faces) {
    const auto parts = FourSubtriangles(face);
    for (int which = 0; which < 4; ++which) {
      split.triangles.push_back(parts[static_cast<std::size_t>(which)]);
      split.faces.push_back({face, which});
    }
  }
  return split;
}

Eigen::Vector3d FaceBarycentricOfSubtriangle(int which, const Eigen::Vector3d& sub_barycentric) {
  Eigen::Vector3d l = Eigen::Vector3d::Zero();
  for (int v = 0; v < 3; ++v) {
    for (int k = 0; k < 3; ++k) l[k] += sub_barycentric[v] * kFaceNodeCoordinates[kSubtriangleNodes[which][v]][k];
  }
  return l;
}

ContactDetector::ContactDetector(std::vector<fem::SurfaceTriangle> obstacle_triangles,
                                 const PointsRef& obstacle_reference_positions_m,
                                 std::vector<int> tool_nodes,
                                 std::vector<Eigen::Vector3d> tool_normals,
                                 std::vector<SubtriangleOfFace> subtriangle_faces)
    : triangles_(std::move(obstacle_triangles)),
      subtriangle_faces_(std::move(subtriangle_faces)),
      tool_nodes_(std::move(tool_nodes)),
      tool_normals_(std::move(tool_normals)),
      num_obstacle_nodes_(static_cast<int>(obstacle_reference_positions_m.rows())) {
  if (triangles_.empty()) throw InputError("contact detector: no obstacle triangles given");
  if (!subtriangle_faces_.empty()) {
    if (subtriangle_faces_.size() != triangles_.size()) {
      throw InputError("contact detector: " + std::to_string(subtriangle_faces_.size()) + " sub-triangle faces for " +
                       std::to_string(triangles_.size()) + " triangles");
    }
    for (std::size_t t = 0; t < triangles_.size(); ++t) {
      const SubtriangleOfFace& of = subtriangle_faces_[t];
      if (of.which < 0 || of.which > 3 || of.face.midsides[0] < 0 ||
          FourSubtriangles(of.face)[static_cast<std::size_t>(of.which)].corners != triangles_[t].corners) {
        throw InputError("contact detector: triangle " + std::to_string(t) +
                         " is not the sub-triangle of the 6-node face given for it");
      }
    }
  }
  if (!obstacle_reference_positions_m.allFinite()) {
    throw InputError("contact detector: non-finite obstacle reference position");
  }
  const int n_tri = static_cast<int>(triangles_.size());
  std::vector<Eigen::Vector3d> centroids(static_cast<std::size_t>(n_tri));
  double edge_sum_m = 0.0;
  for (int t = 0; t < n_tri; ++t) {
    const auto& tri = triangles_[static_cast<std::size_t>(t)];
    for (int id : tri.corners) {
      if (id < 0 || id >= num_obstacle_nodes_) {
        throw InputError("contact detector: obstacle triangle " + std::to_string(t) +
                         " has corner node " + std::to_string(id) + " outside [0, " +
                         std::to_string(num_obstacle_nodes_) + ")");
      }
    }
    const int midsides_given = static_cast<int>(
        std::count_if(tri.midsides.begin(), tri.midsides.end(), [](int m) { return m >= 0; }));
    if (midsides_given != 0 && midsides_given != 3) {
      throw InputError("contact detector: obstacle triangle " + std::to_string(t) +
                       " has some but not all midside nodes (give 3 for Tet10, none for Tet4)");
    }
    for (int id : tri.midsides) {
      if (id >= num_obstacle_nodes_) {
        throw InputError("contact detector: obstacle triangle " + std::to_string(t) +
                         " has midside node " + std::to_string(id) + " outside [0, " +
                         std::to_string(num_obstacle_nodes_) + ")");
      }
    }
    const Eigen::Vector3d a = Row(obstacle_reference_positions_m, tri.corners[0]);
    const Eigen::Vector3d b = Row(obstacle_reference_positions_m, tri.corners[1]);
    const Eigen::Vector3d c = Row(obstacle_reference_positions_m, tri.corners[2]);
    const double longest_m = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    if (!((b - a).cross(c - a).norm() > 1e-12 * longest_m * longest_m)) {
      throw InputError("contact detector: obstacle triangle " + std::to_string(t) +
                       " is degenerate (zero area) in the reference configuration");
    }
    centroids[static_cast<std::size_t>(t)] = (a + b + c) / 3.0;
    reference_normals_.push_back((b - a).cross(c - a).normalized());
    reference_corners_m_.push_back({a, b, c});
    edge_sum_m += (b - a).norm() + (c - b).norm() + (a - c).norm();
  }
  tie_tolerance_m_ = kTieRelative * edge_sum_m / (3.0 * n_tri);
  face_geometry_.resize(static_cast<std::size_t>(n_tri));
  face_geometry_call_.assign(static_cast<std::size_t>(n_tri), 0);  // detect_call_ starts at 1

  for (int id : tool_nodes_) {
    if (id < 0) throw InputError("contact detector: negative tool node id " + std::to_string(id));
    max_tool_node_ = std::max(max_tool_node_, id);
  }
  if (!tool_normals_.empty()) {
    if (tool_normals_.size() != tool_nodes_.size()) {
      throw InputError("contact detector: " + std::to_string(tool_normals_.size()) +
                       " tool normals for " + std::to_string(tool_nodes_.size()) +
                       " tool nodes (give one per node, or none)");
    }
    for (const auto& n : tool_normals_) {
      if (!(std::abs(n.norm() - 1.0) < 1e-6)) {
        throw InputError("contact detector: tool normals must be unit vectors");
      }
    }
  }

  // Topology once, from the reference configuration: median split of the centroids along
  // the longest axis of their bounds.
  order_.resize(static_cast<std::size_t>(n_tri));
  std::iota(order_.begin(), order_.end(), 0);
  nodes_.reserve(static_cast<std::size_t>(2 * n_tri / kLeafSize + 2));
  const int depth = BuildNode(centroids, 0, n_tri, 0);
  stack_.reserve(static_cast<std::size_t>(2 * depth + 4));
  triangle_boxes_.resize(static_cast<std::size_t>(n_tri));
  // The tree's inverse maps, for RefitEnabled.
  slot_of_triangle_.resize(static_cast<std::size_t>(n_tri));
  for (int slot = 0; slot < n_tri; ++slot) slot_of_triangle_[static_cast<std::size_t>(order_[static_cast<std::size_t>(slot)])] = slot;
  leaf_of_slot_.assign(static_cast<std::size_t>(n_tri), -1);
  parent_.assign(nodes_.size(), -1);
  node_depth_.assign(nodes_.size(), 0);
  std::vector<std::size_t> nodes_at_depth;
  for (std::size_t index = 0; index < nodes_.size(); ++index) {
    const BvhNode& node = nodes_[index];
    if (nodes_at_depth.size() <= static_cast<std::size_t>(node_depth_[index])) nodes_at_depth.resize(static_cast<std::size_t>(node_depth_[index]) + 1, 0);
    ++nodes_at_depth[static_cast<std::size_t>(node_depth_[index])];
    if (node.count > 0) {
      for (int slot = node.first; slot < node.first + node.count; ++slot) leaf_of_slot_[static_cast<std::size_t>(slot)] = static_cast<int>(index);
    } else {
      for (const auto child : {index + 1, static_cast<std::size_t>(node.right)}) {
        parent_[child] = static_cast<int>(index);
        node_depth_[child] = node_depth_[index] + 1;
      }
    }
  }
  nodes_by_depth_.resize(nodes_at_depth.size());
  for (std::size_t d = 0; d < nodes_at_depth.size(); ++d) nodes_by_depth_[d].reserve(nodes_at_depth[d]);
  refitted_slots_.reserve(static_cast<std::size_t>(n_tri));
  refitted_nodes_.reserve(nodes_.size());
  node_refitted_.assign(nodes_.size(), 0);
  candidates_.reserve(64);

  // Corner neighbours for persistent contacts (a node slides at most onto an adjacent face
  // per step at haptic increments).
  std::vector<std::vector<int>> faces_of_node(static_cast<std::size_t>(num_obstacle_nodes_));
  for (int t = 0; t < n_tri; ++t) {
    for (int id : triangles_[static_cast<std::size_t>(t)].corners) faces_of_node[static_cast<std::size_t>(id)].push_back(t);
  }
  neighbour_offsets_.assign(static_cast<std::size_t>(n_tri) + 1, 0);
  std::vector<int> around;
  for (int t = 0; t < n_tri; ++t) {
    around.clear();
    for (int id : triangles_[static_cast<std::size_t>(t)].corners) {
      const auto& f = faces_of_node[static_cast<std::size_t>(id)];
      around.insert(around.end(), f.begin(), f.end());
    }
    std::sort(around.begin(), around.end());
    around.erase(std::unique(around.begin(), around.end()), around.end());
    neighbours_.insert(neighbours_.end(), around.begin(), around.end());
    neighbour_offsets_[static_cast<std::size_t>(t) + 1] = static_cast<int>(neighbours_.size());
  }
  stats_.triangles_total = n_tri;
}

// Returns the depth of the subtree.
int ContactDetector::BuildNode(const std::vector<Eigen::Vector3d>& centroids, int begin,
                               int end, int depth) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  if (end - begin <= kLeafSize) {
    nodes_[static_cast<std::size_t>(index)].first = begin;
    nodes_[static_cast<std::size_t>(index)].count = end - begin;
    return depth;
  }
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  for (int i = begin; i < end; ++i) {
    const auto& c = centroids[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])];
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  const int mid = begin + (end - begin) / 2;
  // Ties broken by triangle id so the topology does not depend on the sort implementation.
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int l, int r) {
                     const double cl = centroids[static_cast<std::size_t>(l)][axis];
                     const double cr = centroids[static_cast<std::size_t>(r)][axis];
                     return cl < cr || (cl == cr && l < r);
                   });
  const int left_depth = BuildNode(centroids, begin, mid, depth + 1);
  const int right = static_cast<int>(nodes_.size());
  nodes_[static_cast<std::size_t>(index)].right = right;
  const int right_depth = BuildNode(centroids, mid, end, depth + 1);
  return std::max(left_depth, right_depth);
}

void ContactDetector::ValidateCall(const PointsRef& obstacle_positions_m,
                                   const PointsRef& tool_positions_m,
                                   const CollisionParameters& parameters) const {
  if (obstacle_positions_m.rows() != num_obstacle_nodes_) {
    throw InputError("contact detector: " + std::to_string(obstacle_positions_m.rows()) +
                     " obstacle positions, expected " + std::to_string(num_obstacle_nodes_) +
                     " (one per obstacle node)");
  }
  if (tool_positions_m.rows() <= max_tool_node_) {
    throw InputError("contact detector: " + std::to_string(tool_positions_m.rows()) +
                     " tool positions, but tool node " + std::to_string(max_tool_node_) +
                     " is a candidate");
  }
  CheckParameters(parameters);
}

ContactDetector::Box ContactDetector::InflatedBox(const PointsRef& obstacle_positions_m,
                                                  const CollisionParameters& parameters, int triangle) const {
  // A qualifying node lies within max(activation, penetration) of the face plane and its
  // projection is within edge_tolerance (barycentric) of the face, i.e. at most
  // 2·edge_tolerance·extent outside the face's box along any axis (two coordinates can be
  // negative). Inflating each triangle's box by that margin makes the query a point-in-box
  // test that can never miss a pair the exact test would accept.
  const double normal_margin_m = std::max(parameters.activation_gap_m, parameters.max_penetration_m);
  const auto& tri = triangles_[static_cast<std::size_t>(triangle)];
  const Eigen::Vector3d a = Row(obstacle_positions_m, tri.corners[0]);
  const Eigen::Vector3d b = Row(obstacle_positions_m, tri.corners[1]);
  const Eigen::Vector3d c = Row(obstacle_positions_m, tri.corners[2]);
  Box box;
  box.min = a.cwiseMin(b).cwiseMin(c);
  box.max = a.cwiseMax(b).cwiseMax(c);
  const double extent_m = (box.max - box.min).maxCoeff();
  // (TestTriangle accepts gaps to a 6-node face's quadratic surface: MidsideOffsets.)
  double bulge_m = 0.0;
  if (tri.midsides[0] >= 0) {
    for (const Eigen::Vector3d& offset : MidsideOffsets(obstacle_positions_m, tri, {a, b, c})) {
      bulge_m = std::max(bulge_m, (4.0 / 3.0) * offset.norm());
    }
  }
  const double margin_m = normal_margin_m + bulge_m + (2.0 * parameters.edge_tolerance + 1e-12) * extent_m;
  box.min.array() -= margin_m;
  box.max.array() += margin_m;
  return box;
}

namespace {
void MakeEmpty(Eigen::Vector3d* min, Eigen::Vector3d* max) {
  min->setConstant(std::numeric_limits<double>::infinity());  // empty: never entered
  max->setConstant(-std::numeric_limits<double>::infinity());
}
}  // namespace

void ContactDetector::Refit(const PointsRef& obstacle_positions_m,
                            const CollisionParameters& parameters,
                            const std::vector<char>* triangle_enabled) {
  refit_empty_elsewhere_ = false;
  for (std::size_t slot = 0; slot < order_.size(); ++slot) {
    Box& box = triangle_boxes_[slot];
    if (triangle_enabled != nullptr && !(*triangle_enabled)[static_cast<std::size_t>(order_[slot])]) {
      MakeEmpty(&box.min, &box.max);
      continue;
    }
    box = InflatedBox(obstacle_positions_m, parameters, order_[slot]);
  }
  // Children follow their parent, so a reverse sweep sees children first.
  for (int index = static_cast<int>(nodes_.size()) - 1; index >= 0; --index) FitNode(index);
}

void ContactDetector::FitNode(int index) {
  BvhNode& node = nodes_[static_cast<std::size_t>(index)];
  if (node.count > 0) {
    node.box = triangle_boxes_[static_cast<std::size_t>(node.first)];
    for (int i = 1; i < node.count; ++i) {
      const Box& b = triangle_boxes_[static_cast<std::size_t>(node.first + i)];
      node.box.min = node.box.min.cwiseMin(b.min);
      node.box.max = node.box.max.cwiseMax(b.max);
    }
  } else {
    const Box& l = nodes_[static_cast<std::size_t>(index) + 1].box;
    const Box& r = nodes_[static_cast<std::size_t>(node.right)].box;
    node.box.min = l.min.cwiseMin(r.min);
    node.box.max = l.max.cwiseMax(r.max);
  }
}

void ContactDetector::RefitEnabled(const PointsRef& obstacle_positions_m, const CollisionParameters& parameters,
                                   const std::vector<int>& enabled_triangles) {
  // Boxes a full Refit would make empty stay empty; only what the last call filled is cleared.
  if (refit_empty_elsewhere_) {
    for (int slot : refitted_slots_) MakeEmpty(&triangle_boxes_[static_cast<std::size_t>(slot)].min, &triangle_boxes_[static_cast<std::size_t>(slot)].max);
    for (int node : refitted_nodes_) MakeEmpty(&nodes_[static_cast<std::size_t>(node)].box.min, &nodes_[static_cast<std::size_t>(node)].box.max);
  } else {
    for (Box& box : triangle_boxes_) MakeEmpty(&box.min, &box.max);
    for (BvhNode& node : nodes_) MakeEmpty(&node.box.min, &node.box.max);
    refit_empty_elsewhere_ = true;
  }
  for (int node : refitted_nodes_) node_refitted_[static_cast<std::size_t>(node)] = 0;
  refitted_slots_.clear();
  refitted_nodes_.clear();
  for (int triangle : enabled_triangles) {
    const int slot = slot_of_triangle_[static_cast<std::size_t>(triangle)];
    triangle_boxes_[static_cast<std::size_t>(slot)] = InflatedBox(obstacle_positions_m, parameters, triangle);
    refitted_slots_.push_back(slot);
    for (int node = leaf_of_slot_[static_cast<std::size_t>(slot)]; node >= 0 && !node_refitted_[static_cast<std::size_t>(node)];
         node = parent_[static_cast<std::size_t>(node)]) {
      node_refitted_[static_cast<std::size_t>(node)] = 1;
      refitted_nodes_.push_back(node);
      nodes_by_depth_[static_cast<std::size_t>(node_depth_[static_cast<std::size_t>(node)])].push_back(node);
    }
  }
  // Deepest first: a node's children are refitted (or empty) before it. The same FitNode as
  // Refit, so the same bits.
  for (auto bucket = nodes_by_depth_.rbegin(); bucket != nodes_by_depth_.rend(); ++bucket) {
    for (int index : *bucket) FitNode(index);
    bucket->clear();
  }
}

void ContactDetector::UpdateFaceGeometry(const PointsRef& obstacle_positions_m, int triangle) {
  const auto& tri = triangles_[static_cast<std::size_t>(triangle)];
  FaceGeometry& g = face_geometry_[static_cast<std::size_t>(triangle)];
  g.a = Row(obstacle_positions_m, tri.corners[0]);
  g.ab = Row(obstacle_positions_m, tri.corners[1]) - g.a;
  g.ac = Row(obstacle_positions_m, tri.corners[2]) - g.a;
  const Eigen::Vector3d cross = g.ab.cross(g.ac);
  const double twice_area_m2 = cross.norm();
  g.valid = twice_area_m2 > 0.0;  // collapsed (or non-finite) face: no normal
  g.normal = cross / twice_area_m2;
  // The terms of ProjectionBarycentric that do not depend on the point (same expressions, so
  // the same bits).
  g.d00 = g.ab.dot(g.ab);
  g.d01 = g.ab.dot(g.ac);
  g.d11 = g.ac.dot(g.ac);
  g.denom = g.d00 * g.d11 - g.d01 * g.d01;
  g.quadratic = tri.midsides[0] >= 0;
  g.bulge_m = 0.0;
  if (g.quadratic) {
    g.midside_offset_m = MidsideOffsets(obstacle_positions_m, tri, {g.a, g.a + g.ab, g.a + g.ac});
    for (const Eigen::Vector3d& offset : g.midside_offset_m) {
      g.bulge_m = std::max(g.bulge_m, (4.0 / 3.0) * std::abs(offset.dot(g.normal)));
      if (!offset.allFinite()) g.valid = false;  // a non-finite midside: no surface to measure
    }
  }
}

void ContactDetector::TestTriangle(int triangle, const Eigen::Vector3d& x, int tool_index,
                                   const PointsRef& obstacle_positions_m,
                                   const CollisionParameters& parameters, double max_depth_m,
                                   double edge_tolerance, const Eigen::Vector3d& previous_normal) {
  ++stats_.triangles_tested;
  // Normal compatibility and persistence on the reference normals (small-displacement theory,
  // like the contact frames): a face folded by a large local indentation keeps its identity.
  // Judged first: it needs no current geometry.
  const Eigen::Vector3d& reference_n = reference_normals_[static_cast<std::size_t>(triangle)];
  if (!tool_normals_.empty() &&
      -reference_n.dot(tool_normals_[static_cast<std::size_t>(tool_index)]) <
          parameters.min_normal_opposition) {
    return;
  }
  if (face_geometry_call_[static_cast<std::size_t>(triangle)] != detect_call_) {
    UpdateFaceGeometry(obstacle_positions_m, triangle);
    face_geometry_call_[static_cast<std::size_t>(triangle)] = detect_call_;
  }
  const FaceGeometry& g = face_geometry_[static_cast<std::size_t>(triangle)];
  if (!g.valid) return;
  const double travel_depth_m = max_depth_m;  // the caller's bound, before the face's rise
  if (triangle_rise_m_ != nullptr) max_depth_m += 2.0 * (*triangle_rise_m_)[static_cast<std::size_t>(triangle)];
  const Eigen::Vector3d& n = g.normal;
  const Eigen::Vector3d ap = x - g.a;
  const double flat_gap_m = ap.dot(n);
  // (A 6-node face's surface lies within bulge_m of the flat triangle: the exact test is below.)
  if (!(flat_gap_m < parameters.activation_gap_m + g.bulge_m && flat_gap_m >= -max_depth_m - g.bulge_m)) return;
  // ProjectionBarycentric(x, a, b, c) from the face's cached terms.
  const Eigen::Vector3d projection = BarycentricFromDots(g.d00, g.d01, g.d11, g.denom, ap.dot(g.ab), ap.dot(g.ac));
  if (!(projection.minCoeff() >= -edge_tolerance)) return;
  const auto& tri = triangles_[static_cast<std::size_t>(triangle)];
  const Eigen::Vector3d& a = g.a;
  const Eigen::Vector3d b = Row(obstacle_positions_m, tri.corners[1]);
  const Eigen::Vector3d c = Row(obstacle_positions_m, tri.corners[2]);
  // Inside (or within the slack of) the face: the closest point is the projection itself, or
  // for a projection just outside an edge the nearest point of that edge.
  const Eigen::Vector3d bary =
      projection.minCoeff() >= 0.0 ? projection : ClosestPointBarycentric(x, a, b, c);
  Eigen::Vector3d point_m = bary[0] * a + bary[1] * b + bary[2] * c;
  double gap_m = flat_gap_m;
  if (g.quadratic) {
    // The quadratic surface's point at these coordinates: Σ N_i x_i = the flat point +
    // Σ_k 4 l_k l_k+1 (midside offset k) (the corner and midside shape functions of Select),
    // and its gap along the face normal.
    for (int k = 0; k < 3; ++k) {
      point_m += (4.0 * bary[k] * bary[(k + 1) % 3]) * g.midside_offset_m[static_cast<std::size_t>(k)];
    }
    gap_m = (x - point_m).dot(n);
    if (!(gap_m < parameters.activation_gap_m && gap_m >= -max_depth_m)) return;
  }
  if (gap_m < -travel_depth_m) {
    // Deeper than the travel bound, on the face's rise alone: only over the face as it was
    // undeformed. A face with a corner on a clamped edge and another pressed 3 mm down tilts
    // by 27°, and along that tilt a tool node beyond the clamped end (x < 0, in air) projected
    // into it 4.4 mm "deep" and took 448 N (docs/free-interaction.md, "Faces that spring back").
    const auto& corners = reference_corners_m_[static_cast<std::size_t>(triangle)];
    if (!(ProjectionBarycentric(x, corners[0], corners[1], corners[2]).minCoeff() >= -edge_tolerance)) return;
  }
  Candidate& candidate = candidates_.emplace_back();
  candidate.triangle = triangle;
  candidate.gap_m = gap_m;
  candidate.point_m = point_m;
  candidate.normal = n;
  candidate.barycentric = bary;
  candidate.persistent = previous_normal.dot(reference_n) >= parameters.persistence_min_cosine;
  candidate.outside = std::max(0.0, -projection.minCoeff());
  candidate.max_depth_m = max_depth_m;
}

void ContactDetector::Select(int tool_index, const CollisionParameters& parameters,
                             std::vector<ContactPoint>* contacts) const {
  if (candidates_.empty()) return;
  // Faces in the persistence cone of the node's previous face first, at any depth; without
  // one, only faces within the pair's depth allowance (a new contact).
  const bool any_persistent =
      std::any_of(candidates_.begin(), candidates_.end(), [](const Candidate& c) { return c.persistent; });
  auto qualifies = [&](const Candidate& c) {
    return any_persistent ? c.persistent : c.gap_m >= -c.max_depth_m;
  };
  // A face that holds the node's projection beats one reached only with the persistent slack
  // (a coplanar neighbour would otherwise tie on the gap and move the point to its edge).
  const bool any_inside = std::any_of(candidates_.begin(), candidates_.end(), [&](const Candidate& c) {
    return qualifies(c) && c.outside <= parameters.edge_tolerance;
  });
  auto eligible = [&](const Candidate& c) {
    return qualifies(c) && (!any_inside || c.outside <= parameters.edge_tolerance);
  };
  // Order-independent choice (the tree and the brute force visit faces in different
  // orders): smallest |gap|, then, among ties within round-off, the lowest triangle index.
  double best_abs_gap_m = std::numeric_limits<double>::infinity();
  for (const auto& c : candidates_) {
    if (eligible(c)) best_abs_gap_m = std::min(best_abs_gap_m, std::abs(c.gap_m));
  }
  const Candidate* best = nullptr;
  for (const auto& c : candidates_) {
    if (eligible(c) && std::abs(c.gap_m) <= best_abs_gap_m + tie_tolerance_m_ &&
        (best == nullptr || c.triangle < best->triangle)) {
      best = &c;
    }
  }
  if (best == nullptr) return;
  const auto& tri = triangles_[static_cast<std::size_t>(best->triangle)];
  ContactPoint& contact = contacts->emplace_back();
  contact.tool_node = tool_nodes_[static_cast<std::size_t>(tool_index)];
  contact.node_slot = tool_index;
  contact.obstacle_triangle = best->triangle;
  contact.barycentric = best->barycentric;
  contact.obstacle_nodes.fill(-1);
  contact.weights.fill(0.0);
  // The face whose shape functions carry the point: the triangle itself, or the 6-node face
  // of a sub-triangle, at the face's parametric coordinates of the point.
  const fem::SurfaceTriangle* face = &tri;
  Eigen::Vector3d l = best->barycentric;
  if (!subtriangle_faces_.empty()) {
    const SubtriangleOfFace& of = subtriangle_faces_[static_cast<std::size_t>(best->triangle)];
    face = &of.face;
    l = FaceBarycentricOfSubtriangle(of.which, l);
  }
  if (face->midsides[0] < 0) {
    contact.num_obstacle_nodes = 3;
    for (int k = 0; k < 3; ++k) {
      contact.obstacle_nodes[static_cast<std::size_t>(k)] = face->corners[static_cast<std::size_t>(k)];
      contact.weights[static_cast<std::size_t>(k)] = l[k];
    }
  } else {
    // Quadratic 6-node triangle: corner k: l_k (2 l_k − 1); midside on edge (k, k+1):
    // 4 l_k l_{k+1}. They sum to 1 for any barycentric l.
    contact.num_obstacle_nodes = 6;
    for (int k = 0; k < 3; ++k) {
      const auto corner = static_cast<std::size_t>(k);
      const auto mid = static_cast<std::size_t>(3 + k);
      contact.obstacle_nodes[corner] = face->corners[corner];
      contact.obstacle_nodes[mid] = face->midsides[corner];
      contact.weights[corner] = l[k] * (2.0 * l[k] - 1.0);
      contact.weights[mid] = 4.0 * l[k] * l[(k + 1) % 3];
    }
  }
  contact.frame = FrameFromNormal(best->normal);
  contact.obstacle_point_m = best->point_m;
  contact.gap_m = best->gap_m;
}

void ContactDetector::Detect(const PointsRef& obstacle_positions_m,
                             const PointsRef& tool_positions_m,
                             const CollisionParameters& parameters,
                             std::vector<ContactPoint>* contacts,
                             const DetectionContext& context) {
  HAPCO_ASSERT(contacts != nullptr, "Detect needs an output vector");
  ValidateCall(obstacle_positions_m, tool_positions_m, parameters);
  HAPCO_ASSERT(context.previous_triangle == nullptr || context.previous_triangle->size() == tool_nodes_.size(),
               "one previous triangle per tool node");
  HAPCO_ASSERT(context.node_enabled == nullptr || context.node_enabled->size() == tool_nodes_.size(),
               "one enabled flag per tool node");
  HAPCO_ASSERT(context.triangle_enabled == nullptr || context.triangle_enabled->size() == triangles_.size(),
               "one enabled flag per triangle");
  HAPCO_ASSERT(context.triangle_rise_m == nullptr || context.triangle_rise_m->size() == triangles_.size(),
               "one rise per triangle");
  CollisionParameters box_parameters = parameters;
  if (context.triangle_rise_m != nullptr) {
    double rise_m = 0.0;
    const auto face = [&](int t) { rise_m = std::max(rise_m, (*context.triangle_rise_m)[static_cast<std::size_t>(t)]); };
    if (context.triangle_enabled != nullptr && context.enabled_triangles != nullptr) {
      for (int t : *context.enabled_triangles) face(t);  // the faces near the tool only
    } else {
      for (int t = 0; t < static_cast<int>(triangles_.size()); ++t) {
        if (context.triangle_enabled == nullptr || (*context.triangle_enabled)[static_cast<std::size_t>(t)]) face(t);
      }
    }
    HAPCO_ASSERT(std::isfinite(rise_m) && rise_m >= 0.0, "triangle rises are finite and >= 0");
    box_parameters.max_penetration_m += 2.0 * rise_m;
  }
  triangle_rise_m_ = context.triangle_rise_m;
  if (context.triangle_enabled != nullptr && context.enabled_triangles != nullptr) {
    RefitEnabled(obstacle_positions_m, box_parameters, *context.enabled_triangles);
  } else {
    Refit(obstacle_positions_m, box_parameters, context.triangle_enabled);
  }
  ++detect_call_;  // every face's geometry is recomputed on its first test
  contacts->clear();
  stats_ = DetectorStats{};
  stats_.triangles_total = static_cast<std::int64_t>(triangles_.size());
  const Eigen::Vector3d no_history = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < tool_nodes_.size(); ++i) {
    if (context.node_enabled != nullptr && !(*context.node_enabled)[i]) continue;
    const int previous = context.previous_triangle != nullptr ? (*context.previous_triangle)[i] : -1;
    const Eigen::Vector3d& previous_normal =
        previous >= 0 ? reference_normals_[static_cast<std::size_t>(previous)] : no_history;
    const Eigen::Vector3d x = Row(tool_positions_m, tool_nodes_[i]);
    ++stats_.queries;
    candidates_.clear();
    stack_.clear();
    stack_.push_back(0);
    while (!stack_.empty()) {
      const BvhNode& node = nodes_[static_cast<std::size_t>(stack_.back())];
      const int self = stack_.back();
      stack_.pop_back();
      ++stats_.bvh_nodes_visited;
      if ((x.array() < node.box.min.array()).any() || (x.array() > node.box.max.array()).any()) {
        continue;
      }
      if (node.count > 0) {
        for (int s = node.first; s < node.first + node.count; ++s) {
          if ((x.array() < triangle_boxes_[static_cast<std::size_t>(s)].min.array()).any() ||
              (x.array() > triangle_boxes_[static_cast<std::size_t>(s)].max.array()).any()) {
            continue;
          }
          TestTriangle(order_[static_cast<std::size_t>(s)], x, static_cast<int>(i),
                       obstacle_positions_m, parameters, parameters.max_penetration_m,
                       parameters.edge_tolerance, previous_normal);
        }
      } else {
        stack_.push_back(node.right);
        stack_.push_back(self + 1);
      }
    }
    if (previous >= 0) {
      // The persistent faces, at any depth (a face found twice gives the same candidate).
      for (int k = neighbour_offsets_[static_cast<std::size_t>(previous)];
           k < neighbour_offsets_[static_cast<std::size_t>(previous) + 1]; ++k) {
        const int t = neighbours_[static_cast<std::size_t>(k)];
        if (context.triangle_enabled != nullptr && !(*context.triangle_enabled)[static_cast<std::size_t>(t)]) continue;
        TestTriangle(t, x, static_cast<int>(i), obstacle_positions_m, parameters,
                     std::numeric_limits<double>::infinity(), parameters.persistent_edge_tolerance,
                     previous_normal);
      }
    }
    Select(static_cast<int>(i), parameters, contacts);
  }
  triangle_rise_m_ = nullptr;
}

void ContactDetector::DetectBruteForce(const PointsRef& obstacle_positions_m,
                                       const PointsRef& tool_positions_m,
                                       const CollisionParameters& parameters,
                                       std::vector<ContactPoint>* contacts) {
  HAPCO_ASSERT(contacts != nullptr, "DetectBruteForce needs an output vector");
  ValidateCall(obstacle_positions_m, tool_positions_m, parameters);
  contacts->clear();
  ++detect_call_;  // every face's geometry is recomputed on its first test
  stats_ = DetectorStats{};
  stats_.triangles_total = static_cast<std::int64_t>(triangles_.size());
  for (std::size_t i = 0; i < tool_nodes_.size(); ++i) {
    const Eigen::Vector3d x = Row(tool_positions_m, tool_nodes_[i]);
    ++stats_.queries;
    candidates_.clear();
    for (int t = 0; t < static_cast<int>(triangles_.size()); ++t) {
      TestTriangle(t, x, static_cast<int>(i), obstacle_positions_m, parameters,
                   parameters.max_penetration_m, parameters.edge_tolerance, Eigen::Vector3d::Zero());
    }
    Select(static_cast<int>(i), parameters, contacts);
  }
}

std::vector<Eigen::Vector3d> CandidateNodeNormals(const fem::Mesh& mesh,
                                                  const std::vector<fem::SurfaceTriangle>& surface,
                                                  const std::vector<int>& nodes) {
  std::vector<int> slot(static_cast<std::size_t>(mesh.num_nodes()), -1);
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const int id = nodes[i];
    if (id < 0 || id >= mesh.num_nodes()) {
      throw InputError("candidate node " + std::to_string(id) + " is not a node of the mesh");
    }
    slot[static_cast<std::size_t>(id)] = static_cast<int>(i);
  }
  std::vector<Eigen::Vector3d> sums(nodes.size(), Eigen::Vector3d::Zero());
  for (const auto& tri : surface) {
    const bool on_patch = std::all_of(tri.corners.begin(), tri.corners.end(), [&](int id) {
      return id >= 0 && id < mesh.num_nodes() && slot[static_cast<std::size_t>(id)] >= 0;
    });
    if (!on_patch) continue;
    const Eigen::Vector3d a = mesh.nodes_m.row(tri.corners[0]).transpose();
    const Eigen::Vector3d b = mesh.nodes_m.row(tri.corners[1]).transpose();
    const Eigen::Vector3d c = mesh.nodes_m.row(tri.corners[2]).transpose();
    const Eigen::Vector3d area_normal = (b - a).cross(c - a);  // |.| = 2 area: area weighting
    for (int id : tri.corners) sums[static_cast<std::size_t>(slot[static_cast<std::size_t>(id)])] += area_normal;
    for (int id : tri.midsides) {
      if (id >= 0 && id < mesh.num_nodes() && slot[static_cast<std::size_t>(id)] >= 0) {
        sums[static_cast<std::size_t>(slot[static_cast<std::size_t>(id)])] += area_normal;
      }
    }
  }
  for (std::size_t i = 0; i < sums.size(); ++i) {
    if (!(sums[i].norm() > 0.0)) {
      throw InputError("candidate node " + std::to_string(nodes[i]) +
                       " touches no surface triangle whose corners are all candidates");
    }
    sums[i].normalize();
  }
  return sums;
}

}  // namespace hapco::sim
