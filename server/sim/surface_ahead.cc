#include "sim/surface_ahead.h"

#include <cmath>

#include "common/error.h"

namespace hapco::sim {

SurfaceAheadProbe::SurfaceAheadProbe(const TwoBodyModel& model, double reach_m)
    : model_(model),
      reach_m_(reach_m),
      tool_pass_(model.obstacle_surface().triangles, model.obstacle().mesh().nodes_m, model.tool_surface().nodes,
                 model.tool_surface().node_normals, model.obstacle_surface().subtriangle_faces),
      edge_pass_(model.tool_surface().triangles, model.tool().mesh().nodes_m, model.obstacle_reverse_slaves(),
                 model.obstacle_reverse_slave_normals(), model.tool_surface().subtriangle_faces),
      tool_positions_m_(model.tool().mesh().nodes_m) {
  if (!(std::isfinite(reach_m) && reach_m > 0.0)) {
    throw InputError("surface-ahead reach must be finite and > 0 m, got " + std::to_string(reach_m));
  }
  // Separated pairs only (0 <= gap < reach): a probe runs when the step found no contact.
  parameters_.activation_gap_m = reach_m;
  parameters_.max_penetration_m = 0.0;
  points_.reserve(model.tool_surface().nodes.size() + model.obstacle_reverse_slaves().size());
}

const SurfaceAhead& SurfaceAheadProbe::Probe(const Eigen::Vector3d& device_translation_m) {
  result_ = SurfaceAhead{};
  if (!device_translation_m.allFinite()) return result_;
  // The tool's surface translated by its free displacement for d (no contact load).
  const auto& tool_nodes = model_.tool_surface().nodes;
  const auto& tool_reference = model_.tool().mesh().nodes_m;
  const Eigen::MatrixXd& unit_fields = model_.tool_unit_fields();
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    const int node = tool_nodes[static_cast<std::size_t>(i)];
    tool_positions_m_.row(node) =
        tool_reference.row(node) + (unit_fields.middleRows<3>(3 * i) * device_translation_m).transpose();
  }
  const auto& obstacle_reference = model_.obstacle().mesh().nodes_m;
  double best = reach_m_;
  // The nearest pair of a pass: `sign` turns its face normal into the direction the contact
  // pushes the device, `obstacle_point` gives the obstacle's point of the pair.
  const auto nearest = [&](double sign, const auto& obstacle_point) {
    for (const ContactPoint& p : points_) {
      if (!(p.gap_m < best)) continue;
      best = p.gap_m;
      result_.found = true;
      result_.gap_m = std::max(0.0, p.gap_m);
      result_.normal_device = sign * p.frame.row(0).transpose();
      result_.point_m = obstacle_point(p);
    }
  };
  // Pass 1: a tool node over an obstacle face; the contact pushes the tool along the face
  // normal (towards the tool).
  tool_pass_.Detect(obstacle_reference, tool_positions_m_, parameters_, &points_);
  nearest(1.0, [](const ContactPoint& p) -> Eigen::Vector3d { return p.obstacle_point_m; });
  // Pass 2: an obstacle edge node over a tool face; the contact pushes the tool against that
  // face's normal.
  edge_pass_.Detect(tool_positions_m_, obstacle_reference, parameters_, &points_);
  nearest(-1.0, [&](const ContactPoint& p) -> Eigen::Vector3d { return obstacle_reference.row(p.tool_node).transpose(); });
  return result_;
}

}  // namespace hapco::sim
