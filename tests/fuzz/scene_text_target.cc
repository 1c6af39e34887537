// Scene text -> validated scene -> (small) bodies. An accepted scene must be buildable within
// the memory limit, its trajectory queries must stay in range, and a small body must build
// or be refused with InputError (never an assertion, a crash or UB).
#include <cmath>
#include <string>

#include <Eigen/SparseCore>

#include "common/error.h"
#include "fem/box_mesh.h"
#include "fuzz_targets.h"
#include "io/scene_file.h"
#include "sim/scene.h"

namespace hapco::fuzz {
namespace {

// Bodies up to this size are meshed and factored in the harness (one or two cells: the
// element code is slow under coverage instrumentation); larger accepted ones are checked
// against the estimate only.
constexpr long long kMaxBuiltNodes = 30;
constexpr long long kMaxBuiltElements = 12;

void CheckBody(const sim::BodySpec& body) {
  const sim::BodyBuildEstimate estimate = sim::EstimateBodyBuild(body.box);
  HAPCO_FUZZ_CHECK(estimate.bytes <= sim::kMaxBodyBuildBytes, "accepted a body over the memory limit");
  if (estimate.nodes > kMaxBuiltNodes || estimate.elements > kMaxBuiltElements) return;
  const fem::Mesh mesh = fem::MakeBoxMesh(body.box);
  HAPCO_FUZZ_CHECK(mesh.num_nodes() == estimate.nodes, "estimate counts other nodes than the mesher");
  HAPCO_FUZZ_CHECK(mesh.num_elements() == estimate.elements, "estimate counts other elements");
  try {
    const fem::ElasticBody built = sim::BuildBody(body);
    HAPCO_FUZZ_CHECK(built.num_dofs() == 3 * mesh.num_nodes(), "built body has other dofs");
    // A body that builds must give finite answers: the server steps it for every pose.
    const Eigen::SparseMatrix<double>& k = built.stiffness();
    for (Eigen::Index i = 0; i < k.nonZeros(); ++i) {
      HAPCO_FUZZ_CHECK(std::isfinite(k.valuePtr()[i]), "built body has a non-finite stiffness");
    }
    HAPCO_FUZZ_CHECK(built.unit_driven_translation_fields().allFinite(), "non-finite driven fields");
    const Eigen::VectorXd load = Eigen::VectorXd::Constant(built.num_dofs(), 1e-3);
    const Eigen::VectorXd u = built.SolveDisplacement(load, Eigen::Vector3d(0, 0, -1e-4));
    HAPCO_FUZZ_CHECK(u.allFinite(), "built body gives a non-finite displacement");
  } catch (const InputError&) {
    // e.g. a material that makes K_ff indefinite: refused with a message, fine.
  }
}

}  // namespace

int SceneText(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  sim::SceneSpec scene;
  try {
    scene = io::ParseSceneText(text, "fuzz.txtpb");
  } catch (const InputError&) {
    return 0;
  }
  HAPCO_FUZZ_CHECK(!scene.trajectory.empty(), "accepted a scene without trajectory");
  const int total = scene.total_steps();
  HAPCO_FUZZ_CHECK(total >= 1 && total <= sim::kMaxTrajectorySteps, "trajectory step count out of range");
  HAPCO_FUZZ_CHECK(scene.DeviceTranslationAtStep(total).allFinite(), "non-finite device translation");
  const int phase = scene.PhaseOfStep(total);
  HAPCO_FUZZ_CHECK(phase >= 0 && phase < static_cast<int>(scene.trajectory.size()), "phase out of range");
  CheckBody(scene.obstacle);
  CheckBody(scene.tool);
  return 0;
}

}  // namespace hapco::fuzz
