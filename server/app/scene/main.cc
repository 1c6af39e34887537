// hapco-scene: load a scene file, mesh and factor its bodies once, and print what a user
// wants to check before running it (sizes, costs, sanity checks). Thin: the work is in the
// libraries (design.md, example 14).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/memory.h"
#include "common/timer.h"
#include "fem/box_mesh.h"
#include "io/scene_file.h"
#include "io/scene_model.h"
#include "sim/compliance_kernels.h"
#include "sim/pose_limits.h"
#include "sim/scene.h"
#include "sim/two_body_model.h"

namespace {

constexpr const char* kDescription =
    R"(Loads a HapCo scene file (proto/scene.proto), meshes both bodies, assembles and factors their stiffness once (CHOLMOD), builds exactly what hapco-sim and hapco-server precompute (the contact surfaces within contact.reach_m of the tool, the dense compliance among their nodes, the tool's unit fields) and prints sizes, costs, memory and sanity checks.)";

constexpr const char* kFooter =
    "Exit code: 0 on success, 1 on a bad scene (one line on stderr names file, line and field).";

struct Options {
  std::string scene_path;
  bool no_compliance = false;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("hapco-scene", "SCENE.txtpb [options]", kDescription, kFooter);
  command.AddScene(&options->scene_path);
  command.AddFlag("--no-compliance", &options->no_compliance,
                  "stop after the factorisations: no contact surfaces, compliance or unit fields (faster on very "
                  "fine meshes)",
                  "Precomputation");
  if (!command.Parse(argc, argv)) return false;
  return true;
}

const char* FaceName(hapco::fem::BoxFace face) {
  static const char* names[] = {"X_MIN", "X_MAX", "Y_MIN", "Y_MAX", "Z_MIN", "Z_MAX"};
  return names[static_cast<int>(face)];
}

std::string Faces(const hapco::sim::BodySpec& body) {
  std::string text;
  for (hapco::fem::BoxFace face : body.clamped_faces) text += std::string(" ") + FaceName(face);
  return text.empty() ? " none" : text;
}

void PrintBody(const char* role, const hapco::sim::BodySpec& spec,
               const hapco::fem::ElasticBody& body) {
  const auto& box = spec.box;
  const auto& stats = body.stats();
  if (spec.mesh != nullptr) {
    const auto& nodes = body.mesh().nodes_m;
    const Eigen::Vector3d extent = (nodes.colwise().maxCoeff() - nodes.colwise().minCoeff()).transpose();
    std::printf("%-9s %s: mesh %s, bounding box %.4g x %.4g x %.4g m\n", role, spec.name.c_str(),
                hapco::fem::ToString(body.mesh().order), extent.x(), extent.y(), extent.z());
    std::printf("          %s\n", spec.mesh->summary.c_str());
  } else {
    std::printf("%-9s %s: box %.4g x %.4g x %.4g m, %s, %d x %d x %d cells\n", role,
                spec.name.c_str(), box.size_m.x(), box.size_m.y(), box.size_m.z(),
                hapco::fem::ToString(box.order), box.divisions.x(), box.divisions.y(),
                box.divisions.z());
  }
  std::printf("          %d nodes, %d elements, %d dofs (%d free); E = %.4g MPa, nu = %.6g\n",
              body.mesh().num_nodes(), body.mesh().num_elements(), body.num_dofs(),
              body.num_free_dofs(), spec.material.youngs_modulus_pa * 1e-6,
              spec.material.poisson_ratio);
  if (spec.mesh != nullptr) {
    std::printf("          %zu clamped, %zu driven nodes\n", body.clamped_nodes().size(), body.driven_nodes().size());
  } else {
    std::printf("          clamped faces:%s; driven face: %s (%zu clamped, %zu driven nodes)\n",
                Faces(spec).c_str(), spec.driven_face ? FaceName(*spec.driven_face) : "none",
                body.clamped_nodes().size(), body.driven_nodes().size());
  }
  std::printf("          K nonzeros %ld, Cholesky factor nonzeros %ld; assembly %.3f s, "
              "factorization %.3f s\n",
              stats.stiffness_nonzeros, stats.factor_nonzeros, stats.assembly_seconds,
              stats.factorization_seconds);
}

int Run(const Options& options) {
  const std::string& scene_path = options.scene_path;
  const bool compliance = !options.no_compliance;
  hapco::Stopwatch total;
  const hapco::sim::SceneSpec scene = hapco::io::LoadSceneFile(scene_path);
  std::printf("scene     %s: %s\n", scene.name.c_str(), scene.description.c_str());
  const hapco::fem::ElasticBody obstacle = hapco::sim::BuildBody(scene.obstacle);
  const hapco::fem::ElasticBody tool = hapco::sim::BuildBody(scene.tool);
  PrintBody("obstacle", scene.obstacle, obstacle);
  PrintBody("tool", scene.tool, tool);

  // Sanity check: a rigid translation of the tool (no contact) must cost no force.
  const Eigen::Vector3d translation_m(1e-3, -2e-3, 3e-3);
  const Eigen::VectorXd no_load = Eigen::VectorXd::Zero(tool.num_dofs());
  const Eigen::VectorXd rigid = tool.SolveDisplacement(no_load, translation_m);
  const double rigid_force_n = tool.ReactionForce(rigid, no_load, tool.driven_nodes()).norm();
  std::printf("check     rigid 3.7 mm translation of the free tool: reaction %.2e N "
              "(0 expected)\n", rigid_force_n);

  if (compliance) {
    hapco::Stopwatch watch;
    const std::unique_ptr<hapco::sim::TwoBodyModel> model_owner = hapco::io::MakeSceneModel(scene, scene_path);
    const hapco::sim::TwoBodyModel& model = *model_owner;
    const auto& o = model.obstacle_surface();
    const auto& t = model.tool_surface();
    const auto mib = [](std::size_t bytes) { return static_cast<double>(bytes) / (1 << 20); };
    const auto dense_bytes = [](const Eigen::MatrixXd& m) { return sizeof(double) * static_cast<std::size_t>(m.size()); };
    std::printf("contact   candidate surfaces (every boundary face within reach_m = %.3g m of the tool):\n",
                scene.reach_m);
    // With FOUR_SUBTRIANGLES the surfaces hold four searched sub-triangles per 6-node face.
    const auto faces = [](const hapco::sim::ContactSurface& s) {
      return s.subtriangle_faces.empty() ? s.triangles.size() : s.triangles.size() / 4;
    };
    std::printf("          obstacle %zu faces, %zu nodes (%zu %s: reverse-pass slaves); "
                "tool %zu faces, %zu nodes\n",
                faces(o), o.nodes.size(), model.obstacle_reverse_slaves().size(),
                scene.reverse_pass_all_nodes ? "all candidates (contact.reverse_pass_slaves)" : "on sharp edges",
                faces(t), t.nodes.size());
    std::printf("          quadratic faces searched on %s (contact.quadratic_face_search)\n",
                scene.quadratic_face_subtriangles ? "their four sub-triangles through the midside nodes"
                                                  : "the flat triangle of their corners");
    std::printf("precomputed, %.2f s (compliance %.2f s: %s):\n", watch.ElapsedSeconds(),
                model.stats().compliance_seconds,
                o.range_axis >= 0 ? "the obstacle's by batched solves, the tool's Schur complement inverted"
                                  : "each surface's Schur complement, inverted");
    const auto largest_diagonal = [](const hapco::sim::BlockedCompliance& c) {
      double largest = 0.0;
      for (int i = 0; i < c.nodes(); ++i) largest = std::max(largest, c.block(i, i).diagonal().maxCoeff());
      return largest;
    };
    if (o.range_axis >= 0) {
      std::printf("          obstacle compliance %dx%d, banded: node pairs within %.3g m along %c%s, %.1f MiB "
                  "(dense: %.1f MiB; steps that need a pair beyond the range are counted)\n",
                  3 * o.compliance_m_per_n.nodes(), 3 * o.compliance_m_per_n.nodes(), o.range_m, "xyz"[o.range_axis],
                  model.stats().range_chosen_automatically ? " (chosen: the dense blocks do not fit in memory)"
                                                           : " (contact.compliance_range_m)",
                  mib(o.compliance_m_per_n.bytes()), mib(o.compliance_m_per_n.dense_bytes()));
    } else {
      std::printf("          obstacle compliance %dx%d (3x3 blocks per node pair), %.1f MiB\n",
                  3 * o.compliance_m_per_n.nodes(), 3 * o.compliance_m_per_n.nodes(), mib(o.compliance_m_per_n.bytes()));
    }
    std::printf("          tool compliance %dx%d, %.2f MiB; tool unit fields %ldx3, %.3f MiB\n",
                3 * t.compliance_m_per_n.nodes(), 3 * t.compliance_m_per_n.nodes(), mib(t.compliance_m_per_n.bytes()),
                model.tool_unit_fields().rows(), mib(dense_bytes(model.tool_unit_fields())));
    std::printf("          total operators %.1f MiB; largest obstacle compliance %.3g m/N; rigid-contact "
                "compliance %.3g m/N\n",
                mib(model.stats().operator_bytes), largest_diagonal(o.compliance_m_per_n),
                model.rigid_contact_compliance_m_per_n());
    const auto& obstacle_factor = model.obstacle().stats();
    std::printf("          the bodies' factors (kept for full solves and field export) hold %.1f MiB more: obstacle "
                "%.1f MiB, %s\n",
                mib(obstacle_factor.factor_bytes + model.tool().stats().factor_bytes), mib(obstacle_factor.factor_bytes),
                o.range_axis >= 0                        ? "in CHOLMOD's own order (its banded compliance came from solves)"
                : obstacle_factor.schur_factor_bytes > 0 ? "with its surface's dense Schur factor last"
                                                         : "refactored without its surface's dense Schur factor");
    std::printf("          the step reads them with the %s compliance kernels (this CPU's fastest; "
                "sim/compliance_kernels.h)\n",
                hapco::sim::ComplianceKernelName(hapco::sim::FastestComplianceKernel()));
    double farthest_m = 0.0;
    for (const Eigen::Vector3d& d : scene.DeviceTrajectory()) farthest_m = std::max(farthest_m, d.norm());
    for (const std::string& note : {hapco::sim::StartingPositionNote(model), hapco::sim::ContactGroupsNote(model), hapco::sim::LockingNote(model),
                                    hapco::sim::RigidBodyNote(model),
                                    hapco::sim::ReachNote(model, farthest_m, "the scene's trajectory"),
                                    hapco::sim::ReachNote(model, hapco::sim::PoseLimits{}.workspace_m,
                                                          "hapco-server's default --workspace-m")}) {
      if (!note.empty()) std::printf("note      %s\n", note.c_str());
    }
  }
  std::printf("contact   mu = %.3g, activation gap %.3g mm; solver %s, tolerance %.3g m\n",
              scene.friction_coefficient, scene.activation_gap_m * 1e3,
              std::string(hapco::contact::SolverName(scene.solver)).c_str(),
              scene.solver_parameters.global_tolerance_m);
  std::printf("trajectory %d steps:", scene.total_steps());
  for (const auto& phase : scene.trajectory) {
    std::printf(" %s (%d, %+.1f/%+.1f/%+.1f mm)", phase.name.c_str(), phase.steps,
                phase.displacement_m.x() * 1e3, phase.displacement_m.y() * 1e3,
                phase.displacement_m.z() * 1e3);
  }
  std::printf("\nmemory    peak resident %.1f MiB; total %.2f s\n",
              static_cast<double>(hapco::PeakResidentBytes()) / (1 << 20), total.ElapsedSeconds());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-scene", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
