#include "sim/scene.h"

#include <algorithm>

#include "common/error.h"

namespace hapco::sim {

int SceneSpec::total_steps() const {
  int total = 0;
  for (const TrajectoryPhase& phase : trajectory) total += phase.steps;
  return total;
}

std::vector<Eigen::Vector3d> SceneSpec::DeviceTrajectory() const {
  std::vector<Eigen::Vector3d> points;
  points.reserve(static_cast<std::size_t>(total_steps()) + 1);
  for (int k = 0; k <= total_steps(); ++k) points.push_back(DeviceTranslationAtStep(k));
  return points;
}

Eigen::Vector3d SceneSpec::DeviceTranslationAtStep(int step) const {
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  int remaining = step;
  for (const TrajectoryPhase& phase : trajectory) {
    const int taken = std::min(remaining, phase.steps);
    translation_m += phase.displacement_m * (static_cast<double>(taken) / phase.steps);
    remaining -= taken;
    if (remaining == 0) break;
  }
  return translation_m;
}

int SceneSpec::PhaseOfStep(int step) const {
  int end = 0;
  for (int index = 0; index < static_cast<int>(trajectory.size()); ++index) {
    end += trajectory[index].steps;
    if (step <= end) return index;
  }
  return static_cast<int>(trajectory.size()) - 1;
}

fem::ElasticBody BuildBody(const BodySpec& body) {
  fem::ElasticBody::Spec spec;
  spec.mesh = fem::MakeBoxMesh(body.box);
  spec.material = body.material;
  for (fem::BoxFace face : body.clamped_faces) {
    const std::vector<int> nodes = fem::NodesOnBoxFace(spec.mesh, body.box, face);
    spec.clamped_nodes.insert(spec.clamped_nodes.end(), nodes.begin(), nodes.end());
  }
  std::sort(spec.clamped_nodes.begin(), spec.clamped_nodes.end());
  spec.clamped_nodes.erase(std::unique(spec.clamped_nodes.begin(), spec.clamped_nodes.end()),
                           spec.clamped_nodes.end());
  if (body.driven_face) {
    for (int node : fem::NodesOnBoxFace(spec.mesh, body.box, *body.driven_face)) {
      // A node both clamped and driven stays clamped (an edge shared by two such faces).
      if (!std::binary_search(spec.clamped_nodes.begin(), spec.clamped_nodes.end(), node)) {
        spec.driven_nodes.push_back(node);
      }
    }
  }
  try {
    return fem::ElasticBody(std::move(spec));
  } catch (const InputError& error) {
    throw InputError("body '" + body.name + "': " + error.what());
  }
}

}  // namespace hapco::sim
