// Scene files: the shipped benchmarks load as algorithms.md §1 describes them, and every kind
// of bad input is rejected with one message that names the field (and line).
#include "io/scene_file.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "common/error.h"

namespace hapco::io {
namespace {

std::string ReadFile(const std::string& path) {
  std::ifstream file(path);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

const std::string kBenchmark1 = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark1.txtpb";
const std::string kBenchmark2 = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark2.txtpb";

// Returns the InputError message produced by parsing `text`, or "" if it parsed.
std::string ErrorOf(const std::string& text) {
  try {
    ParseSceneText(text, "scene.txtpb");
  } catch (const InputError& error) {
    return error.what();
  }
  return "";
}

// The benchmark 1 text with one substring replaced (must be present exactly once).
std::string Benchmark1With(const std::string& from, const std::string& to) {
  std::string text = ReadFile(kBenchmark1);
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  EXPECT_EQ(text.find(from, at + 1), std::string::npos) << from << " is not unique";
  return text.replace(at, from.size(), to);
}

// 1-based line of the first occurrence of `needle` in the benchmark 1 file.
int LineOf(const std::string& needle) {
  const std::string text = ReadFile(kBenchmark1);
  const auto at = text.find(needle);
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(at), '\n'));
}

TEST(SceneFileTest, Benchmark1MatchesThePaperScene) {
  const sim::SceneSpec scene = LoadSceneFile(kBenchmark1);
  // Red bar 10 x 2 x 2 cm, E = 3000 kPa, nu = 0.3, clamped at both ends (algorithms.md §1).
  EXPECT_EQ(scene.obstacle.box.size_m, Eigen::Vector3d(0.10, 0.02, 0.02));
  EXPECT_DOUBLE_EQ(scene.obstacle.material.youngs_modulus_pa, 3.0e6);
  EXPECT_DOUBLE_EQ(scene.obstacle.material.poisson_ratio, 0.3);
  ASSERT_EQ(scene.obstacle.clamped_faces.size(), 2u);
  EXPECT_FALSE(scene.obstacle.driven_face.has_value());
  // Green block E = 80000 kPa, driven by its top face, resting on the red top face.
  EXPECT_DOUBLE_EQ(scene.tool.material.youngs_modulus_pa, 8.0e7);
  ASSERT_TRUE(scene.tool.driven_face.has_value());
  EXPECT_EQ(*scene.tool.driven_face, fem::BoxFace::kZMax);
  EXPECT_DOUBLE_EQ(scene.tool.box.min_corner_m.z(),
                   scene.obstacle.box.min_corner_m.z() + scene.obstacle.box.size_m.z());
  // Centred at mid-span.
  EXPECT_NEAR(scene.tool.box.min_corner_m.x() + scene.tool.box.size_m.x() / 2, 0.05, 1e-12);
  // Five phases, P = 1 mm: press 3P, +x 10P, +y 5P, -x 10P, lift 3P; 310 steps in all.
  ASSERT_EQ(scene.trajectory.size(), 5u);
  EXPECT_EQ(scene.total_steps(), 30 + 100 + 50 + 100 + 30);
  EXPECT_TRUE(scene.DeviceTranslationAtStep(30).isApprox(Eigen::Vector3d(0, 0, -0.003)));
  EXPECT_TRUE(scene.DeviceTranslationAtStep(130).isApprox(Eigen::Vector3d(0.010, 0, -0.003)));
  // After the last phase the device is back at x = 0, lifted to z = 0, shifted by +y 5P.
  EXPECT_LT((scene.DeviceTranslationAtStep(310) - Eigen::Vector3d(0, 0.005, 0)).norm(), 1e-15);
  EXPECT_EQ(scene.PhaseOfStep(1), 0);
  EXPECT_EQ(scene.PhaseOfStep(30), 0);
  EXPECT_EQ(scene.PhaseOfStep(31), 1);
  EXPECT_EQ(scene.PhaseOfStep(310), 4);
  EXPECT_DOUBLE_EQ(scene.friction_coefficient, 0.3);
}

TEST(SceneFileTest, Benchmark2ClampsOnlyTheLeftEnd) {
  const sim::SceneSpec scene = LoadSceneFile(kBenchmark2);
  ASSERT_EQ(scene.obstacle.clamped_faces.size(), 1u);
  EXPECT_EQ(scene.obstacle.clamped_faces[0], fem::BoxFace::kXMin);
}

TEST(SceneFileTest, SyntaxErrorNamesLineAndColumn) {
  // "divisions_y = 4" instead of "divisions_y: 4" on the obstacle's box.
  const std::string message = ErrorOf(Benchmark1With("divisions_y: 4\n    divisions_z: 4",
                                                     "divisions_y = 4\n    divisions_z: 4"));
  const std::string text = ReadFile(kBenchmark1);
  const auto at = text.find("divisions_y: 4");
  const auto line_start = text.rfind('\n', at) + 1;
  const int column = static_cast<int>(at - line_start) + static_cast<int>(std::string("divisions_y ").size()) + 1;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("divisions_y: 4")) + ":" +
                         std::to_string(column) + ":"),
            std::string::npos) << message;
  EXPECT_NE(message.find("\"=\""), std::string::npos) << message;
}

// Given a recording, an FCLIB file or another binary file, the tools answered
// "...:1:13: Interpreting non ascii codepoint 249." (a helper session).
TEST(SceneFileTest, AFileThatIsNoSceneTextSaysWhatItIs) {
  EXPECT_EQ(ErrorOf(std::string("HAPCOREC\x01\x02\xf9", 11)),
            "scene.txtpb: a HapCo recording, not a scene file (hapco-report reads recordings; the scene a recording "
            "was made with is in its header)");
  EXPECT_NE(ErrorOf(std::string("\x89HDF\r\n\x1a\n\0\0", 10)).find("an HDF5 file (an FCLIB problem?"),
            std::string::npos);
  EXPECT_NE(ErrorOf("$MeshFormat\n4.1 0 8\n").find("a Gmsh mesh"), std::string::npos);
  EXPECT_NE(ErrorOf(std::string("name: \"x\"\x01\x02", 11)).find("a binary file"), std::string::npos);
  // Text with a syntax error is still a syntax error with its line.
  EXPECT_NE(ErrorOf("format_version: 1\nbogus_field: 2\n").find("scene.txtpb:2:"), std::string::npos);
}

TEST(SceneFileTest, UnknownFieldIsASyntaxErrorWithItsLine) {
  const std::string message =
      ErrorOf(Benchmark1With("force_gain: 0.25", "force_gain: 0.25\nforce_gian: 2"));
  EXPECT_NE(message.find("force_gian"), std::string::npos) << message;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("force_gain: 0.25") + 1) + ":"),
            std::string::npos) << message;
}

TEST(SceneFileTest, NonPositiveYoungsModulusNamesFieldAndLine) {
  const std::string message =
      ErrorOf(Benchmark1With("youngs_modulus_pa: 3.0e6", "youngs_modulus_pa: -3.0e6"));
  EXPECT_NE(message.find("obstacle.material.youngs_modulus_pa"), std::string::npos) << message;
  EXPECT_NE(message.find("must be between 1 Pa"), std::string::npos) << message;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("youngs_modulus_pa: 3.0e6")) + ":"),
            std::string::npos) << message;
}

TEST(SceneFileTest, IncompressiblePoissonRatioIsRejected) {
  const std::string message = ErrorOf(Benchmark1With(
      "youngs_modulus_pa: 8.0e7 poisson_ratio: 0.3", "youngs_modulus_pa: 8.0e7 poisson_ratio: 0.5"));
  EXPECT_NE(message.find("tool.material.poisson_ratio"), std::string::npos) << message;
  EXPECT_NE(message.find("(-1, 0.5)"), std::string::npos) << message;
}

TEST(SceneFileTest, AndersonAccelerationIsReadAndItsRangeChecked) {
  const sim::SceneSpec scene = LoadSceneFile(kBenchmark1);
  EXPECT_EQ(scene.solver_parameters.anderson_depth, 5);
  EXPECT_EQ(scene.solver_parameters.anderson_start, contact::SolverParameters{}.anderson_start);
  const sim::SceneSpec later = ParseSceneText(
      Benchmark1With("anderson_depth: 5", "anderson_depth: 3 anderson_start: 40"), "scene.txtpb");
  EXPECT_EQ(later.solver_parameters.anderson_depth, 3);
  EXPECT_EQ(later.solver_parameters.anderson_start, 40);
  const sim::SceneSpec off = ParseSceneText(Benchmark1With("anderson_depth: 5", ""), "scene.txtpb");
  EXPECT_EQ(off.solver_parameters.anderson_depth, 0) << "absent: the paper's iteration";

  std::string message = ErrorOf(Benchmark1With("anderson_depth: 5", "anderson_depth: 9"));
  EXPECT_NE(message.find("solver.anderson_depth"), std::string::npos) << message;
  EXPECT_NE(message.find("between 0 (off) and 8"), std::string::npos) << message;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("anderson_depth: 5")) + ":"), std::string::npos)
      << message;
  message = ErrorOf(Benchmark1With("anderson_depth: 5", "anderson_depth: 5 anderson_start: 0"));
  EXPECT_NE(message.find("solver.anderson_start"), std::string::npos) << message;
}

// A contact enum: false by default (benchmark 1 does not set it), true with `value`, and an
// unknown number is refused naming the field and the choices.
template <typename Flag>
void ExpectContactChoiceReadAndUnknownNamed(const std::string& field, const std::string& value,
                                            const std::string& choices, Flag flag) {
  EXPECT_FALSE(flag(LoadSceneFile(kBenchmark1))) << field << ": default";
  const std::string from = "activation_gap_m: 0.0005";
  EXPECT_TRUE(flag(ParseSceneText(Benchmark1With(from, from + " " + field + ": " + value), "scene.txtpb"))) << field;
  const std::string message = ErrorOf(Benchmark1With(from, from + " " + field + ": 7"));
  EXPECT_NE(message.find("contact." + field), std::string::npos) << message;
  EXPECT_NE(message.find(choices), std::string::npos) << message;
}

TEST(SceneFileTest, QuadraticFaceSearchIsReadAndAnUnknownValueNamed) {
  ExpectContactChoiceReadAndUnknownNamed("quadratic_face_search", "FOUR_SUBTRIANGLES",
                                         "CORNER_TRIANGLE or FOUR_SUBTRIANGLES",
                                         [](const sim::SceneSpec& spec) { return spec.quadratic_face_subtriangles; });
}

TEST(SceneFileTest, ReversePassSlavesAreReadAndAnUnknownValueNamed) {
  ExpectContactChoiceReadAndUnknownNamed("reverse_pass_slaves", "ALL_SURFACE_NODES",
                                         "SHARP_EDGE_NODES or ALL_SURFACE_NODES",
                                         [](const sim::SceneSpec& spec) { return spec.reverse_pass_all_nodes; });
}

TEST(SceneFileTest, ComplianceRangeIsReadAndANegativeOrNonFiniteOneNamed) {
  EXPECT_EQ(LoadSceneFile(kBenchmark1).compliance_range_m, 0.0) << "default: every pair";
  const std::string from = "activation_gap_m: 0.0005";
  EXPECT_EQ(ParseSceneText(Benchmark1With(from, from + " compliance_range_m: 0.04"), "scene.txtpb").compliance_range_m,
            0.04);
  for (const std::string bad : {"-0.01", "nan", "inf"}) {
    const std::string message = ErrorOf(Benchmark1With(from, from + " compliance_range_m: " + bad));
    EXPECT_NE(message.find("contact.compliance_range_m"), std::string::npos) << bad << ": " << message;
    EXPECT_NE(message.find(">= 0 m"), std::string::npos) << bad << ": " << message;
  }
}

TEST(SceneFileTest, BodyWithoutDirichletConditionIsRejectedAsSingular) {
  std::string text = Benchmark1With("  clamped_faces: X_MIN\n  clamped_faces: X_MAX\n", "");
  const std::string message = ErrorOf(text);
  EXPECT_NE(message.find("obstacle.clamped_faces"), std::string::npos) << message;
  EXPECT_NE(message.find("singular"), std::string::npos) << message;
}

TEST(SceneFileTest, ZeroSizedBoxWouldGiveDegenerateElementsAndIsRejected) {
  const std::string message =
      ErrorOf(Benchmark1With("size_m { x: 0.02 y: 0.02 z: 0.01 }", "size_m { x: 0.02 y: 0.02 z: 0 }"));
  EXPECT_NE(message.find("tool.box.size_m"), std::string::npos) << message;
}

TEST(SceneFileTest, ZeroDivisionsAreRejected) {
  const std::string message = ErrorOf(Benchmark1With("divisions_x: 20", "divisions_x: 0"));
  EXPECT_NE(message.find("obstacle.box.divisions_x"), std::string::npos) << message;
}

TEST(SceneFileTest, WrongFormatVersionIsRejected) {
  const std::string message = ErrorOf(Benchmark1With("format_version: 1", "format_version: 7"));
  EXPECT_NE(message.find("format_version"), std::string::npos) << message;
  EXPECT_NE(message.find("version 1"), std::string::npos) << message;
}

TEST(SceneFileTest, ToolWithoutDrivenFaceIsRejected) {
  const std::string message = ErrorOf(Benchmark1With("driven_face: Z_MAX", "clamped_faces: Z_MAX"));
  EXPECT_NE(message.find("tool.driven_face"), std::string::npos) << message;
}

// With no driven face and no clamped face the tool used to be reported as "tool.clamped_faces:
// ... singular" without a line: the missing driven_face is named, at the tool block's line.
TEST(SceneFileTest, ToolWithNeitherDrivenNorClampedFaceIsToldItNeedsADrivenFaceAtItsLine) {
  const std::string message = ErrorOf(Benchmark1With("driven_face: Z_MAX", ""));
  EXPECT_NE(message.find("tool.driven_face: is missing"), std::string::npos) << message;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("tool {")) + ":"), std::string::npos) << message;
  EXPECT_EQ(message.find("clamped_faces"), std::string::npos) << message;
}

// Only the tool follows the device: a driven face on the obstacle was taken as one more clamp
// (a press on it met a rigid wall: 45 N where 1.4 N was right). Refused at its line.
TEST(SceneFileTest, DrivenFaceOnTheObstacleIsRefused) {
  const std::string message = ErrorOf(Benchmark1With("  clamped_faces: X_MAX\n", "  clamped_faces: X_MAX\n  driven_face: Z_MAX\n"));
  EXPECT_NE(message.find("obstacle.driven_face: only the tool follows the haptic device"), std::string::npos) << message;
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("  clamped_faces: X_MAX") + 1) + ":"), std::string::npos)
      << message;
}

// A missing `}` makes the next field land in the block left open; the parser's "Material has
// no field named driven_face" now says that a `}` is probably missing.
TEST(SceneFileTest, MissingClosingBraceIsNamedAsSuch) {
  const std::string message = ErrorOf(Benchmark1With("youngs_modulus_pa: 8.0e7 poisson_ratio: 0.3 }",
                                                     "youngs_modulus_pa: 8.0e7 poisson_ratio: 0.3"));
  EXPECT_NE(message.find("is a `}` missing before this line? `driven_face` is a field of Body, not of Material"),
            std::string::npos)
      << message;
  // A genuinely unknown field gets no such hint.
  EXPECT_EQ(ErrorOf(Benchmark1With("force_gain: 0.25", "force_gain: 0.25\nforce_gian: 2")).find("missing"),
            std::string::npos);
}

TEST(SceneFileTest, TrajectoryPhaseWithoutStepsIsRejected) {
  const std::string message = ErrorOf(Benchmark1With("steps: 50", "steps: 0"));
  EXPECT_NE(message.find("trajectory.phases[2].steps"), std::string::npos) << message;
}

// The example: 400 x 80 x 80 cells used to be accepted and grew to ~12 GB while
// building the body. Refused at load time, at the line of the divisions, naming the estimate.
TEST(SceneFileTest, BodyThatWouldNeedManyGigabytesIsRefusedBeforeBuilding) {
  const std::string message = ErrorOf(Benchmark1With(
      "divisions_x: 20\n    divisions_y: 4\n    divisions_z: 4",
      "divisions_x: 400\n    divisions_y: 80\n    divisions_z: 80"));
  EXPECT_NE(message.find("scene.txtpb:" + std::to_string(LineOf("divisions_x: 20")) +
                         ": obstacle.box.divisions_x: 400 x 80 x 80 Tet10 cells"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("GiB to build, more than the 4 GiB allowed"), std::string::npos) << message;
}

// The reference model of the free-interaction study (40 x 8 x 8 Tet10, ~0.7 GB measured)
// stays accepted.
TEST(SceneFileTest, RefinedReferenceBodyIsWithinTheMemoryLimit) {
  EXPECT_EQ(ErrorOf(Benchmark1With("divisions_x: 20\n    divisions_y: 4\n    divisions_z: 4",
                                   "divisions_x: 40\n    divisions_y: 8\n    divisions_z: 8")),
            "");
}

// Found while writing the fuzz harness (tests/data/fuzz/scene_text): enough phases of 1e7 steps overflowed the
// int step count (UB) and asked DeviceTrajectory() for billions of points.
TEST(SceneFileTest, TrajectoryWithTooManyStepsInTotalIsRefused) {
  std::string phases;
  for (int k = 0; k < 11; ++k) phases += "  phases { displacement_m { z: -0.001 } steps: 10000000 }\n";
  const std::string message =
      ErrorOf(Benchmark1With("  phases { name: \"press\"   displacement_m { z: -0.003 } steps: 30 }\n", phases));
  EXPECT_NE(message.find("trajectory.phases[10].steps: brings the trajectory to 110000000 steps; at most 100000000"),
            std::string::npos)
      << message;
}

// Found with the scene fuzz harness (tests/data/fuzz/scene_text): a finite but unphysical
// Young's modulus or box overflowed the stiffness to inf (E = 1e308 Pa, 100 m) or underflowed
// it to a "not positive definite" error that blamed the Dirichlet nodes (E = 1e-320 Pa).
TEST(SceneFileTest, UnphysicalMaterialAndBoxSizesAreRefused) {
  std::string message = ErrorOf(Benchmark1With("youngs_modulus_pa: 3.0e6", "youngs_modulus_pa: 1e308"));
  EXPECT_NE(message.find("obstacle.material.youngs_modulus_pa: must be between 1 Pa"), std::string::npos)
      << message;
  message = ErrorOf(Benchmark1With("youngs_modulus_pa: 3.0e6", "youngs_modulus_pa: 1e-320"));
  EXPECT_NE(message.find("obstacle.material.youngs_modulus_pa"), std::string::npos) << message;
  message = ErrorOf(Benchmark1With("size_m { x: 0.02 y: 0.02 z: 0.01 }", "size_m { x: 100 y: 0.02 z: 0.01 }"));
  EXPECT_NE(message.find("tool.box.size_m: every edge length must be between 1e-06 and 10 m"),
            std::string::npos)
      << message;
  message = ErrorOf(Benchmark1With("min_corner_m { x: 0.0 y: 0.0 z: 0.0 }", "min_corner_m { x: 1e308 y: 0.0 z: 0.0 }"));
  EXPECT_NE(message.find("obstacle.box.min_corner_m"), std::string::npos) << message;
}

TEST(SceneFileTest, MissingFileIsAClearError) {
  try {
    LoadSceneFile("/nonexistent/scene.txtpb");
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("cannot open"), std::string::npos);
  }
}


// ---- Mesh bodies (Gmsh .geo/.msh; docs/mesh-scenes.md) ---------------------------------------

const std::string kOrganTip = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/organ_tip.txtpb";
const std::string kOrganPair = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/organ_pair.txtpb";

// Meshed .geo files go to a cache of this test's own, not the user's ~/.cache.
class MeshSceneTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cache_ = std::string(::testing::TempDir()) + "hapco-scene-file-test-cache";
    setenv("XDG_CACHE_HOME", cache_.c_str(), 1);
  }
  // Parses the organ_tip text with one unique substring replaced, as if it were the shipped
  // file (relative mesh paths resolve from proto/scenes/); "" when it loads.
  static std::string OrganTipErrorWith(const std::string& from, const std::string& to) {
    std::string text = ReadFile(kOrganTip);
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    EXPECT_EQ(text.find(from, at + 1), std::string::npos) << from << " is not unique";
    try {
      ParseSceneText(text.replace(at, from.size(), to), kOrganTip);
    } catch (const InputError& error) {
      return error.what();
    }
    return "";
  }
  static std::string cache_;
};
std::string MeshSceneTest::cache_;

TEST_F(MeshSceneTest, ShippedOrganScenesLoadWithTheNodeSetsTheirGeometryDefines) {
  for (const std::string& path : {kOrganTip, kOrganPair}) {
    const sim::SceneSpec scene = LoadSceneFile(path);
    ASSERT_NE(scene.obstacle.mesh, nullptr) << path;
    ASSERT_NE(scene.tool.mesh, nullptr) << path;
    const fem::Mesh& organ = scene.obstacle.mesh->mesh;
    // organ.geo: lengths in mm, the clamped base is the plane z = 0, the dome reaches 15 mm.
    EXPECT_NEAR(organ.nodes_m.col(2).maxCoeff(), 0.015, 1e-9) << path;
    EXPECT_NEAR(organ.nodes_m.col(0).maxCoeff() - organ.nodes_m.col(0).minCoeff(), 0.080, 1e-9) << path;
    ASSERT_FALSE(scene.obstacle.mesh->clamped_nodes.empty());
    for (int node : scene.obstacle.mesh->clamped_nodes) EXPECT_NEAR(organ.nodes_m(node, 2), 0.0, 1e-12);
    // The contact group (the skin) has every boundary node but those only on the base.
    EXPECT_GT(scene.obstacle.mesh->contact_nodes.size(), scene.obstacle.mesh->clamped_nodes.size());
    // The tool's driven group is its flat top (instrument_tip.geo z = 39.2 mm, small_organ.geo
    // z = 24.2 mm): one plane, the highest of the tool.
    const fem::Mesh& tool = scene.tool.mesh->mesh;
    ASSERT_FALSE(scene.tool.mesh->driven_nodes.empty());
    for (int node : scene.tool.mesh->driven_nodes) {
      EXPECT_NEAR(tool.nodes_m(node, 2), tool.nodes_m.col(2).maxCoeff(), 1e-12) << path;
    }
  }
}

TEST_F(MeshSceneTest, MissingPhysicalGroupIsNamedWithTheGroupsTheFileHas) {
  const std::string message = OrganTipErrorWith("clamped_groups: \"base\"", "clamped_groups: \"bottom\"");
  const std::string text = ReadFile(kOrganTip);
  const int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(text.find("clamped_groups")), '\n'));
  EXPECT_NE(message.find("organ_tip.txtpb:" + std::to_string(line) +
                         ": obstacle.mesh.clamped_groups: physical group 'bottom' is not in"),
            std::string::npos)
      << message;
  EXPECT_NE(message.find("(it has: base, organ, skin)"), std::string::npos) << message;
}

// A group the .geo defines but whose selection catches nothing is left out of the mesh by
// Gmsh; "not in the file" sent a helper session looking for a typo that was not there.
TEST_F(MeshSceneTest, APhysicalGroupThatSelectsNothingIsCalledEmptyNotMissing) {
  std::string geo = ReadFile(std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/meshes/organ.geo");
  const std::string base_box = "BoundingBox{-41, -26, -0.01, 41, 26, 0.01}";
  const auto at = geo.find(base_box);
  ASSERT_NE(at, std::string::npos) << "organ.geo's base selection changed";
  geo.replace(at, base_box.size(), "BoundingBox{-41, -26, -5.01, 41, 26, -4.99}");  // 5 mm below the base
  const std::string path = std::string(::testing::TempDir()) + "hapco-empty-group-organ.geo";
  std::ofstream(path) << geo;
  const std::string message = OrganTipErrorWith("\"meshes/organ.geo\"", "\"" + path + "\"");
  EXPECT_NE(message.find("obstacle.mesh.clamped_groups: physical group 'base' is defined in"), std::string::npos)
      << message;
  EXPECT_NE(message.find("but holds nothing"), std::string::npos) << message;
  EXPECT_NE(message.find("(the mesh has: organ, skin)"), std::string::npos) << message;
}

TEST_F(MeshSceneTest, MeshFileIsResolvedFromTheSceneFolderAndAMissingOneIsNamed) {
  const std::string message = OrganTipErrorWith("meshes/organ.geo", "meshes/liver.geo");
  EXPECT_NE(message.find("obstacle.mesh.file: "), std::string::npos) << message;
  EXPECT_NE(message.find("proto/scenes/meshes/liver.geo: does not exist"), std::string::npos) << message;
}

TEST_F(MeshSceneTest, BoxFacesOnAMeshBodyAndAToolWithoutDrivenGroupAreRefused) {
  std::string message = OrganTipErrorWith("  element_order: TET10\n", "  element_order: TET10\n  clamped_faces: Z_MIN\n");
  EXPECT_NE(message.find("obstacle.clamped_faces: is for box bodies"), std::string::npos) << message;
  message = OrganTipErrorWith("    driven_group: \"handle\"\n", "");
  EXPECT_NE(message.find("tool.mesh.driven_group: is missing"), std::string::npos) << message;
  message = OrganTipErrorWith("    clamped_groups: \"base\"\n", "");
  EXPECT_NE(message.find("obstacle.mesh.clamped_groups: the body has no clamped and no driven group"), std::string::npos)
      << message;
  message = OrganTipErrorWith("    clamped_groups: \"base\"\n", "    clamped_groups: \"base\"\n    driven_group: \"base\"\n");
  EXPECT_NE(message.find("obstacle.mesh.driven_group: only the tool follows the haptic device"), std::string::npos)
      << message;
  message = OrganTipErrorWith("file: \"meshes/organ.geo\"\n    length_unit_m: 0.001", "file: \"meshes/organ.geo\"");
  EXPECT_NE(message.find("obstacle.mesh.length_unit_m: must be the metres per length unit"), std::string::npos) << message;
}

TEST_F(MeshSceneTest, TheFirstWavesMeshFileFieldPointsToTheMeshBlock) {
  const std::string message = ErrorOf("format_version: 1\nobstacle { mesh_file: \"bar.msh\" }\ntool { }\n");
  EXPECT_NE(message.find("is not read; give a mesh as `mesh { file: \"bar.msh\""), std::string::npos) << message;
}

}  // namespace
}  // namespace hapco::io
