#include "sim/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>

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

std::string DescribeOverLimit(const fem::BoxMeshSpec& box, const BodyBuildEstimate& estimate) {
  char text[200];
  std::snprintf(text, sizeof(text),
                "%d x %d x %d %s cells (%lld nodes) would need about %.1f GiB to build, more "
                "than the %.0f GiB allowed; use fewer divisions",
                box.divisions.x(), box.divisions.y(), box.divisions.z(), fem::ToString(box.order),
                estimate.nodes, estimate.bytes / (1 << 30), kMaxBodyBuildBytes / (1 << 30));
  return text;
}

namespace {

// Factor and stiffness estimate from node counts per axis n[0] >= n[1] >= n[2] (sorted).
BodyBuildEstimate EstimateFromNodeGrid(std::array<double, 3> n, fem::ElementOrder order, BodyBuildEstimate estimate) {
  std::sort(n.begin(), n.end(), std::greater<>());
  const double dofs = 3.0 * static_cast<double>(estimate.nodes);
  // Factor entries per dof ~ k (n1 n2)^0.8, k from 3.4 (cube) to 6.9 (long bar); fitted on
  // Tet4 and Tet10 boxes from 21x5x5 to 121x25x25 nodes with 15 % margin.
  const double cross_section = n[1] * n[2];
  const double aspect = n[1] / n[0];
  const double k = 1.15 * (3.0 + 3.0 * (1.0 - aspect));
  estimate.factor_nonzeros = dofs * k * std::pow(cross_section, 0.8);
  // Stiffness entries per dof: measured 42 (Tet4), 82 (Tet10); 24 bytes each with assembly.
  const double stiffness_nonzeros = dofs * (order == fem::ElementOrder::kTet10 ? 85.0 : 45.0);
  // 14 bytes per factor entry (value, index, supernodal padding: measured 13.5), the
  // stiffness, and per node its position, unit fields and bookkeeping.
  estimate.bytes = 14.0 * estimate.factor_nonzeros + 24.0 * stiffness_nonzeros +
                   200.0 * static_cast<double>(estimate.nodes);
  return estimate;
}

}  // namespace

BodyBuildEstimate EstimateBodyBuild(const fem::BoxMeshSpec& box) {
  // Node counts per axis (corners, plus midsides for Tet10).
  const long long per_cell = box.order == fem::ElementOrder::kTet10 ? 2 : 1;
  std::array<double, 3> n{};
  for (int a = 0; a < 3; ++a) n[static_cast<std::size_t>(a)] = static_cast<double>(per_cell * std::max(box.divisions[a], 1) + 1);
  BodyBuildEstimate estimate;
  estimate.nodes = static_cast<long long>(n[0] * n[1] * n[2]);
  estimate.elements = 6LL * std::max(box.divisions.x(), 1) * std::max(box.divisions.y(), 1) *
                      std::max(box.divisions.z(), 1);
  return EstimateFromNodeGrid(n, box.order, estimate);
}

BodyBuildEstimate EstimateMeshBuild(const fem::Mesh& mesh) {
  BodyBuildEstimate estimate;
  estimate.nodes = mesh.num_nodes();
  estimate.elements = mesh.num_elements();
  if (mesh.num_nodes() == 0) return estimate;
  // The box of the same aspect ratios with as many nodes: n_a = extent_a * (N / volume)^(1/3).
  Eigen::Vector3d extent = (mesh.nodes_m.colwise().maxCoeff() - mesh.nodes_m.colwise().minCoeff()).transpose();
  extent = extent.cwiseMax(1e-9 * extent.maxCoeff()).cwiseMax(1e-300);
  const double scale = std::cbrt(static_cast<double>(mesh.num_nodes()) / (extent.x() * extent.y() * extent.z()));
  std::array<double, 3> n{};
  for (int a = 0; a < 3; ++a) n[static_cast<std::size_t>(a)] = std::max(1.0, extent[a] * scale);
  estimate = EstimateFromNodeGrid(n, mesh.order, estimate);
  // An unstructured (Gmsh) mesh fills more than the box of as many nodes: the box estimate was
  // 0.93-1.19 of CHOLMOD's factor on Gmsh bars and cubes, Tet4 and Tet10 (mesh_import_test).
  constexpr double kUnstructuredFill = 1.3;
  estimate.bytes += 14.0 * (kUnstructuredFill - 1.0) * estimate.factor_nonzeros;
  estimate.factor_nonzeros *= kUnstructuredFill;
  return estimate;
}

std::string DescribeOverLimit(const fem::Mesh& mesh, const BodyBuildEstimate& estimate) {
  char text[200];
  std::snprintf(text, sizeof(text),
                "%d nodes (%s) would need about %.1f GiB to build, more than the %.0f GiB allowed; "
                "use a coarser mesh",
                mesh.num_nodes(), fem::ToString(mesh.order), estimate.bytes / (1 << 30), kMaxBodyBuildBytes / (1 << 30));
  return text;
}

fem::Mesh BodyMesh(const BodySpec& body) {
  if (body.mesh != nullptr) {
    const BodyBuildEstimate estimate = EstimateMeshBuild(body.mesh->mesh);
    if (estimate.bytes > kMaxBodyBuildBytes) {
      throw InputError("body '" + body.name + "' (" + body.mesh->source + "): " + DescribeOverLimit(body.mesh->mesh, estimate));
    }
    return body.mesh->mesh;
  }
  const BodyBuildEstimate estimate = EstimateBodyBuild(body.box);
  if (estimate.bytes > kMaxBodyBuildBytes) {
    throw InputError("body '" + body.name + "': " + DescribeOverLimit(body.box, estimate));
  }
  return fem::MakeBoxMesh(body.box);
}

fem::ElasticBody BuildBody(const BodySpec& body, fem::Mesh mesh, std::vector<int> compliance_nodes) {
  fem::ElasticBody::Spec spec;
  spec.mesh = std::move(mesh);
  spec.material = body.material;
  spec.compliance_nodes = std::move(compliance_nodes);
  if (body.mesh != nullptr) {
    spec.clamped_nodes = body.mesh->clamped_nodes;
    for (int node : body.mesh->driven_nodes) {
      if (!std::binary_search(spec.clamped_nodes.begin(), spec.clamped_nodes.end(), node)) spec.driven_nodes.push_back(node);
    }
  } else {
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
  }
  try {
    return fem::ElasticBody(std::move(spec));
  } catch (const InputError& error) {
    const std::string where = body.mesh != nullptr ? " (" + body.mesh->source + ")" : "";
    throw InputError("body '" + body.name + "'" + where + ": " + error.what());
  }
}

fem::ElasticBody BuildBody(const BodySpec& body) { return BuildBody(body, BodyMesh(body), {}); }

}  // namespace hapco::sim
