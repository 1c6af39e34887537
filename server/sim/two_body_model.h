#pragma once
// The per-scene precomputation of algorithms.md §6 ("model no more than the scene needs"):
// both bodies factored once, and the only operators a haptic step needs, restricted to the
// nodes that can ever touch:
//   - the compliance blocks K⁻¹ of the obstacle's candidate surface and of the tool's
//     candidate surface,
//   - the tool's free displacement at its candidate nodes per unit device translation,
//   - the collision detector's tree over the candidate obstacle faces.
// Immutable after construction; one model serves any number of sessions (design.md ex. 4).
#include <Eigen/Dense>
#include <vector>

#include "fem/elastic_body.h"
#include "sim/collision.h"
#include "sim/scene.h"

namespace hapco::sim {

struct TwoBodyModelStats {
  double build_seconds = 0.0;       // meshing, assembly, factorization of both bodies, s
  double compliance_seconds = 0.0;  // both compliance blocks, s
  double total_seconds = 0.0;
  std::size_t operator_bytes = 0;   // memory held by the precomputed dense operators, bytes
};

class TwoBodyModel {
 public:
  // Throws InputError when the scene cannot be built (see BuildBody) or the bodies do not face
  // each other.
  explicit TwoBodyModel(SceneSpec scene);

  const SceneSpec& scene() const { return scene_; }
  const fem::ElasticBody& obstacle() const { return obstacle_; }
  const fem::ElasticBody& tool() const { return tool_; }

  // Obstacle faces that can be touched: on the box face that looks at the tool, within the
  // footprint the tool sweeps along the whole trajectory plus a margin of one cell.
  const std::vector<fem::SurfaceTriangle>& obstacle_triangles() const { return obstacle_triangles_; }
  // Contact frame (rows n, t1, t2) of each of those faces in the reference configuration.
  // Small-displacement theory: the contact normal is the undeformed face normal, so W, ũ and
  // the force directions stay consistent with the linear model (a frictionless press gives
  // no side force); the deformed geometry only decides where a tool node sits.
  const std::vector<Eigen::Matrix3d>& obstacle_reference_frames() const { return obstacle_frames_; }
  // Sorted node ids carrying those faces, and node id -> position in that list (-1 if absent).
  const std::vector<int>& obstacle_candidates() const { return obstacle_candidates_; }
  const std::vector<int>& obstacle_candidate_index() const { return obstacle_candidate_index_; }
  // Tool nodes on its face opposite the driven face, and node id -> position (-1 if absent).
  const std::vector<int>& tool_candidates() const { return tool_candidates_; }
  const std::vector<int>& tool_candidate_index() const { return tool_candidate_index_; }
  const std::vector<Eigen::Vector3d>& tool_candidate_normals() const { return tool_normals_; }

  // Compliance among candidate nodes (3n x 3n, m/N), ordered as the candidate lists.
  const Eigen::MatrixXd& obstacle_compliance_m_per_n() const { return obstacle_compliance_; }
  const Eigen::MatrixXd& tool_compliance_m_per_n() const { return tool_compliance_; }
  // Tool candidate displacement per unit device translation (3n_t x 3, m/m).
  const Eigen::MatrixXd& tool_unit_fields() const { return tool_unit_fields_; }

  // Obstacle thickness along the normal of its facing face, m: deeper penetrations than about
  // half of it would be matched to the opposite face, so it bounds the detector's search.
  double obstacle_thickness_m() const { return obstacle_thickness_m_; }

  const TwoBodyModelStats& stats() const { return stats_; }

 private:
  SceneSpec scene_;
  fem::ElasticBody obstacle_;
  fem::ElasticBody tool_;
  std::vector<fem::SurfaceTriangle> obstacle_triangles_;
  std::vector<Eigen::Matrix3d> obstacle_frames_;
  std::vector<int> obstacle_candidates_, obstacle_candidate_index_;
  std::vector<int> tool_candidates_, tool_candidate_index_;
  std::vector<Eigen::Vector3d> tool_normals_;
  Eigen::MatrixXd obstacle_compliance_, tool_compliance_, tool_unit_fields_;
  double obstacle_thickness_m_ = 0.0;
  TwoBodyModelStats stats_;
};

}  // namespace hapco::sim
