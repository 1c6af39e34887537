#include "sim/two_body_model.h"

#include <algorithm>
#include <array>

#include "common/error.h"
#include "common/timer.h"

namespace hapco::sim {
namespace {

fem::BoxFace OppositeFace(fem::BoxFace face) {
  static constexpr std::array<fem::BoxFace, 6> kOpposite = {
      fem::BoxFace::kXMax, fem::BoxFace::kXMin, fem::BoxFace::kYMax,
      fem::BoxFace::kYMin, fem::BoxFace::kZMax, fem::BoxFace::kZMin};
  return kOpposite[static_cast<int>(face)];
}

// The obstacle face that looks at the tool: the axis direction along which the two boxes are
// separated the most (the separating axis; 0 gap when resting on each other).
fem::BoxFace FacingObstacleFace(const fem::BoxMeshSpec& obstacle, const fem::BoxMeshSpec& tool) {
  const Eigen::Vector3d obstacle_max = obstacle.min_corner_m + obstacle.size_m;
  const Eigen::Vector3d tool_max = tool.min_corner_m + tool.size_m;
  double best_gap_m = -std::numeric_limits<double>::infinity();
  fem::BoxFace best = fem::BoxFace::kZMax;
  for (int axis = 0; axis < 3; ++axis) {
    const double gap_above_m = tool.min_corner_m[axis] - obstacle_max[axis];
    const double gap_below_m = obstacle.min_corner_m[axis] - tool_max[axis];
    if (gap_above_m > best_gap_m) {
      best_gap_m = gap_above_m;
      best = static_cast<fem::BoxFace>(2 * axis + 1);
    }
    if (gap_below_m > best_gap_m) {
      best_gap_m = gap_below_m;
      best = static_cast<fem::BoxFace>(2 * axis);
    }
  }
  return best;
}

std::vector<int> IndexOf(const std::vector<int>& nodes, int num_nodes) {
  std::vector<int> index(static_cast<std::size_t>(num_nodes), -1);
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i) index[static_cast<std::size_t>(nodes[i])] = i;
  return index;
}

}  // namespace

TwoBodyModel::TwoBodyModel(SceneSpec scene)
    : scene_(std::move(scene)), obstacle_(BuildBody(scene_.obstacle)), tool_(BuildBody(scene_.tool)) {
  Stopwatch total;
  stats_.build_seconds = obstacle_.stats().assembly_seconds + obstacle_.stats().factorization_seconds +
                         tool_.stats().assembly_seconds + tool_.stats().factorization_seconds;
  const fem::BoxMeshSpec& obstacle_box = scene_.obstacle.box;
  const fem::BoxMeshSpec& tool_box = scene_.tool.box;

  // Tool candidates: the face opposite the driven one (the paper's green bottom face).
  HAPCO_ASSERT(scene_.tool.driven_face.has_value(), "scene checks guarantee a driven face");
  const fem::BoxFace tool_face = OppositeFace(*scene_.tool.driven_face);
  tool_candidates_ = fem::NodesOnBoxFace(tool_.mesh(), tool_box, tool_face);
  tool_candidate_index_ = IndexOf(tool_candidates_, tool_.mesh().num_nodes());
  tool_normals_ = CandidateNodeNormals(tool_.mesh(), fem::BoundaryTriangles(tool_.mesh()), tool_candidates_);

  // Obstacle candidates: faces on the facing side, within the swept footprint.
  const fem::BoxFace obstacle_face = FacingObstacleFace(obstacle_box, tool_box);
  const int normal_axis = static_cast<int>(obstacle_face) / 2;
  obstacle_thickness_m_ = obstacle_box.size_m[normal_axis];
  Eigen::Vector3d sweep_min = Eigen::Vector3d::Zero(), sweep_max = Eigen::Vector3d::Zero();
  for (int step = 1; step <= scene_.total_steps(); ++step) {
    const Eigen::Vector3d d = scene_.DeviceTranslationAtStep(step);
    sweep_min = sweep_min.cwiseMin(d);
    sweep_max = sweep_max.cwiseMax(d);
  }
  const Eigen::Vector3d cell_m = obstacle_box.size_m.cwiseQuotient(obstacle_box.divisions.cast<double>());
  const double margin_m = cell_m.maxCoeff() + scene_.activation_gap_m;
  const Eigen::Vector3d reach_min = tool_box.min_corner_m + sweep_min - Eigen::Vector3d::Constant(margin_m);
  const Eigen::Vector3d reach_max =
      tool_box.min_corner_m + tool_box.size_m + sweep_max + Eigen::Vector3d::Constant(margin_m);
  const std::vector<int> face_nodes = fem::NodesOnBoxFace(obstacle_.mesh(), obstacle_box, obstacle_face);
  const auto& nodes_m = obstacle_.mesh().nodes_m;
  auto within_reach = [&](int node) {
    for (int axis = 0; axis < 3; ++axis) {
      if (axis == normal_axis) continue;
      const double x = nodes_m(node, axis);
      if (x < reach_min[axis] || x > reach_max[axis]) return false;
    }
    return true;
  };
  for (const fem::SurfaceTriangle& triangle : fem::BoundaryTriangles(obstacle_.mesh())) {
    bool keep = true;
    for (int corner : triangle.corners) {
      keep = keep && std::binary_search(face_nodes.begin(), face_nodes.end(), corner);
    }
    if (!keep) continue;
    // Keep a face if any corner is within reach, so the kept patch covers the reach box.
    if (!(within_reach(triangle.corners[0]) || within_reach(triangle.corners[1]) ||
          within_reach(triangle.corners[2]))) {
      continue;
    }
    obstacle_triangles_.push_back(triangle);
    for (int node : triangle.corners) obstacle_candidates_.push_back(node);
    for (int node : triangle.midsides) {
      if (node >= 0) obstacle_candidates_.push_back(node);
    }
  }
  if (obstacle_triangles_.empty()) {
    throw InputError("the tool's path never reaches the obstacle's facing surface: no candidate contact faces");
  }
  for (const fem::SurfaceTriangle& triangle : obstacle_triangles_) {
    const Eigen::Vector3d p0 = nodes_m.row(triangle.corners[0]).transpose();
    const Eigen::Vector3d p1 = nodes_m.row(triangle.corners[1]).transpose();
    const Eigen::Vector3d p2 = nodes_m.row(triangle.corners[2]).transpose();
    obstacle_frames_.push_back(FrameFromNormal((p1 - p0).cross(p2 - p0).normalized()));
  }
  std::sort(obstacle_candidates_.begin(), obstacle_candidates_.end());
  obstacle_candidates_.erase(std::unique(obstacle_candidates_.begin(), obstacle_candidates_.end()),
                             obstacle_candidates_.end());
  obstacle_candidate_index_ = IndexOf(obstacle_candidates_, obstacle_.mesh().num_nodes());

  Stopwatch compliance;
  obstacle_compliance_ = obstacle_.ComplianceBlock(obstacle_candidates_);
  tool_compliance_ = tool_.ComplianceBlock(tool_candidates_);
  stats_.compliance_seconds = compliance.ElapsedSeconds();

  const Eigen::MatrixXd& fields = tool_.unit_driven_translation_fields();
  tool_unit_fields_.resize(3 * static_cast<Eigen::Index>(tool_candidates_.size()), 3);
  for (int i = 0; i < static_cast<int>(tool_candidates_.size()); ++i) {
    tool_unit_fields_.middleRows(3 * i, 3) = fields.middleRows(3 * tool_candidates_[i], 3);
  }
  stats_.operator_bytes = sizeof(double) * static_cast<std::size_t>(obstacle_compliance_.size() +
                                                                    tool_compliance_.size() +
                                                                    tool_unit_fields_.size());
  stats_.total_seconds = stats_.build_seconds + total.ElapsedSeconds();
}

}  // namespace hapco::sim
