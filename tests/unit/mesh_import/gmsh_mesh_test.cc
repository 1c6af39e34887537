// Gmsh import (server/mesh_import): geometry and node order checked against facts that do not
// come from the importer (a box's volume, straight edges' midpoints, beam theory), and every
// refusal of a bad file checked for its message.
#include "mesh_import/gmsh_mesh.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/error.h"
#include "fem/assembly.h"
#include "fem/elastic_body.h"
#include "sim/scene.h"

namespace hapco::mesh_import {
namespace {

namespace fs = std::filesystem;

class GmshMeshTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("hapco-gmsh-test-" + std::to_string(getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "cache");
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) const {
    const fs::path path = dir_ / name;
    std::ofstream(path) << text;
    return path.string();
  }
  MeshRequest Request(const std::string& path, fem::ElementOrder order, double size) const {
    MeshRequest request;
    request.path = path;
    request.order = order;
    request.mesh_size = size;
    request.length_unit_m = 0.001;  // the files are in mm
    request.cache_dir = (dir_ / "cache").string();
    return request;
  }
  // A 100 x 20 x 20 mm bar, groups "root" (x = 0), "tip" (x = 100) and "bar" (the volume).
  std::string BarGeo() const {
    return Write("bar.geo",
                 "SetFactory(\"OpenCASCADE\");\n"
                 "Box(1) = {0, 0, 0, 100, 20, 20};\n"
                 "Physical Volume(\"bar\") = {1};\n"
                 "Physical Surface(\"root\") = Surface In BoundingBox{-0.1, -0.1, -0.1, 0.1, 20.1, 20.1};\n"
                 "Physical Surface(\"tip\") = Surface In BoundingBox{99.9, -0.1, -0.1, 100.1, 20.1, 20.1};\n");
  }
  std::string ExpectRefused(const MeshRequest& request) const {
    try {
      ImportMesh(request);
    } catch (const InputError& error) {
      const std::string message = error.what();
      EXPECT_EQ(message.rfind(request.path + ": ", 0), 0u) << "the message names the file: " << message;
      return message;
    }
    ADD_FAILURE() << request.path << " was accepted";
    return {};
  }

  fs::path dir_;
};

double TotalVolume(const fem::Mesh& mesh) {
  double volume = 0.0;
  for (int e = 0; e < mesh.num_elements(); ++e) volume += fem::ElementVolume(mesh, e);
  return volume;
}

TEST_F(GmshMeshTest, GeoIsMeshedScaledAndItsGroupsLieWhereTheGeometrySays) {
  MeshRequest request = Request(BarGeo(), fem::ElementOrder::kTet4, 5.0);
  request.offset_m = Eigen::Vector3d(0.5, 0.0, -0.25);
  const ImportedMesh imported = ImportMesh(request);
  const fem::Mesh& mesh = imported.mesh;
  EXPECT_EQ(imported.gmsh_element_type, 4);
  EXPECT_GT(mesh.num_elements(), 100);
  // A box's tetrahedra fill it exactly: 0.1 x 0.02 x 0.02 m^3, whatever Gmsh's triangulation.
  EXPECT_NEAR(TotalVolume(mesh), 0.1 * 0.02 * 0.02, 1e-12);
  EXPECT_NEAR(mesh.nodes_m.col(0).minCoeff(), 0.5, 1e-12);
  EXPECT_NEAR(mesh.nodes_m.col(0).maxCoeff(), 0.6, 1e-12);
  EXPECT_NEAR(mesh.nodes_m.col(2).minCoeff(), -0.25, 1e-12);
  ASSERT_EQ(imported.group_nodes.count("root"), 1u);
  ASSERT_EQ(imported.group_nodes.count("tip"), 1u);
  ASSERT_EQ(imported.group_nodes.count("bar"), 1u);
  EXPECT_EQ(imported.group_nodes.at("bar").size(), static_cast<std::size_t>(mesh.num_nodes()));
  for (int node : imported.group_nodes.at("root")) EXPECT_NEAR(mesh.nodes_m(node, 0), 0.5, 1e-12);
  for (int node : imported.group_nodes.at("tip")) EXPECT_NEAR(mesh.nodes_m(node, 0), 0.6, 1e-12);
  // Every node on the x = 0 plane is in "root": a 5 mm mesh of a 20 x 20 mm face has >= 16.
  int on_root_plane = 0;
  for (int n = 0; n < mesh.num_nodes(); ++n) on_root_plane += std::abs(mesh.nodes_m(n, 0) - 0.5) < 1e-12;
  EXPECT_EQ(static_cast<std::size_t>(on_root_plane), imported.group_nodes.at("root").size());
  EXPECT_GE(on_root_plane, 16);
}

TEST_F(GmshMeshTest, Tet10MidsideNodesSitOnTheEdgesOfTheirVtkCornerPairs) {
  // Straight edges (a box): every midside node is the midpoint of the corner pair that
  // fem::kTet10EdgeCorners (VTK order) assigns to it. A wrong Gmsh -> VTK map fails here.
  const ImportedMesh imported = ImportMesh(Request(BarGeo(), fem::ElementOrder::kTet10, 5.0));
  const fem::Mesh& mesh = imported.mesh;
  ASSERT_EQ(mesh.elements.cols(), 10);
  EXPECT_EQ(imported.gmsh_element_type, 11);
  double worst_m = 0.0;
  for (int e = 0; e < mesh.num_elements(); ++e) {
    for (int k = 0; k < 6; ++k) {
      const auto& pair = fem::kTet10EdgeCorners[static_cast<std::size_t>(k)];
      const Eigen::Vector3d midpoint =
          0.5 * (mesh.nodes_m.row(mesh.elements(e, pair[0])) + mesh.nodes_m.row(mesh.elements(e, pair[1]))).transpose();
      worst_m = std::max(worst_m, (mesh.nodes_m.row(mesh.elements(e, 4 + k)).transpose() - midpoint).norm());
    }
  }
  EXPECT_LT(worst_m, 1e-12);
  EXPECT_NEAR(TotalVolume(mesh), 0.1 * 0.02 * 0.02, 1e-12);
}

TEST_F(GmshMeshTest, UnstructuredTet10CantileverMatchesTimoshenkoBeamTheory) {
  // The bar clamped at "root", a uniform shear traction P/A on "tip": the load-conjugate tip
  // deflection against Timoshenko (Cowper's kappa), as tests/unit/fem/cantilever_test.cc does
  // for the structured box mesh. Within 2 % on Gmsh's unstructured 5 mm Tet10 mesh.
  const ImportedMesh imported = ImportMesh(Request(BarGeo(), fem::ElementOrder::kTet10, 5.0));
  constexpr double kLength = 0.1, kSide = 0.02, kYoungs = 3e6, kPoisson = 0.3, kLoad = 0.1;
  fem::ElasticBody::Spec spec;
  spec.mesh = imported.mesh;
  spec.material = {kYoungs, kPoisson};
  spec.clamped_nodes = imported.group_nodes.at("root");
  const std::vector<int>& tip_nodes = imported.group_nodes.at("tip");
  std::vector<fem::SurfaceTriangle> tip;
  for (const fem::SurfaceTriangle& face : fem::BoundaryTriangles(spec.mesh)) {
    bool on_tip = true;
    for (int c : face.corners) on_tip = on_tip && std::binary_search(tip_nodes.begin(), tip_nodes.end(), c);
    if (on_tip) tip.push_back(face);
  }
  const Eigen::VectorXd f = fem::UniformTractionLoads(spec.mesh, tip, Eigen::Vector3d(0, 0, -kLoad / (kSide * kSide)));
  ASSERT_NEAR(f.sum(), -kLoad, 1e-12);
  const fem::ElasticBody body(std::move(spec));
  const Eigen::VectorXd u = body.SolveDisplacement(f, Eigen::Vector3d::Zero());
  const double inertia = kSide * kSide * kSide * kSide / 12.0;
  const double shear_modulus = kYoungs / (2.0 * (1.0 + kPoisson));
  const double kappa = 10.0 * (1.0 + kPoisson) / (12.0 + 11.0 * kPoisson);
  const double expected = kLoad * kLength * kLength * kLength / (3.0 * kYoungs * inertia) +
                          kLoad * kLength / (kappa * shear_modulus * kSide * kSide);
  const double delta = f.dot(u) / kLoad;
  EXPECT_NEAR(delta, expected, 0.02 * expected);
  RecordProperty("gmsh_tet10_5mm_relative_error", std::to_string((delta - expected) / expected));
}

TEST_F(GmshMeshTest, GeoMeshIsCachedByContentAndRemeshedWhenTheFileChanges) {
  const std::string path = BarGeo();
  const ImportedMesh first = ImportMesh(Request(path, fem::ElementOrder::kTet4, 5.0));
  EXPECT_FALSE(first.from_cache);
  EXPECT_EQ(fs::path(first.meshed_file).parent_path(), dir_ / "cache");
  const ImportedMesh second = ImportMesh(Request(path, fem::ElementOrder::kTet4, 5.0));
  EXPECT_TRUE(second.from_cache);
  EXPECT_EQ(second.meshed_file, first.meshed_file);
  // Gmsh writes 16 significant digits: the cached nodes agree to ~1e-17 m, the connectivity exactly.
  ASSERT_EQ(second.mesh.num_nodes(), first.mesh.num_nodes());
  EXPECT_LT((second.mesh.nodes_m - first.mesh.nodes_m).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(second.mesh.elements, first.mesh.elements);
  // Another size, another order or another file content: another cache entry.
  EXPECT_FALSE(ImportMesh(Request(path, fem::ElementOrder::kTet4, 4.0)).from_cache);
  EXPECT_FALSE(ImportMesh(Request(path, fem::ElementOrder::kTet10, 5.0)).from_cache);
  std::ofstream(path, std::ios::app) << "// edited\n";
  EXPECT_FALSE(ImportMesh(Request(path, fem::ElementOrder::kTet4, 5.0)).from_cache);
}

TEST_F(GmshMeshTest, MshFileIsReadAndItsElementOrderMustMatch) {
  const ImportedMesh meshed = ImportMesh(Request(BarGeo(), fem::ElementOrder::kTet4, 5.0));
  const MeshRequest msh = Request(meshed.meshed_file, fem::ElementOrder::kTet4, 0.0);
  const ImportedMesh read = ImportMesh(msh);
  ASSERT_EQ(read.mesh.num_nodes(), meshed.mesh.num_nodes());
  EXPECT_LT((read.mesh.nodes_m - meshed.mesh.nodes_m).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(read.mesh.elements, meshed.mesh.elements);
  EXPECT_EQ(read.group_nodes, meshed.group_nodes);
  const std::string message = ExpectRefused(Request(meshed.meshed_file, fem::ElementOrder::kTet10, 0.0));
  EXPECT_NE(message.find("holds no Tet10 tetrahedra"), std::string::npos) << message;
  EXPECT_NE(message.find("Tetrahedron 4 (type 4)"), std::string::npos) << message;
  EXPECT_NE(message.find("set element_order: TET4"), std::string::npos) << message;
  // And a second-order file read as Tet4 says which order it is (it did not: a helper session).
  const ImportedMesh quadratic = ImportMesh(Request(BarGeo(), fem::ElementOrder::kTet10, 5.0));
  const std::string reverse = ExpectRefused(Request(quadratic.meshed_file, fem::ElementOrder::kTet4, 0.0));
  EXPECT_NE(reverse.find("holds no Tet4 tetrahedra"), std::string::npos) << reverse;
  EXPECT_NE(reverse.find("set element_order: TET10"), std::string::npos) << reverse;
}

// A hand-written MSH 2.2 file with one tetrahedron, corners in the given order.
std::string OneTetrahedron(const char* corners) {
  return std::string("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"
                     "$Elements\n1\n7 4 2 0 1 ") +
         corners + "\n$EndElements\n";
}

TEST_F(GmshMeshTest, BadFilesAreRefusedWithOneLineNamingTheFileAndTheFault) {
  EXPECT_NE(ExpectRefused(Request((dir_ / "absent.msh").string(), fem::ElementOrder::kTet4, 0)).find("does not exist"),
            std::string::npos);
  EXPECT_NE(ExpectRefused(Request(Write("body.stl", "solid x\n"), fem::ElementOrder::kTet4, 0)).find("neither a Gmsh mesh"),
            std::string::npos);
  const std::string syntax = ExpectRefused(Request(Write("broken.geo", "Box(1) = {0, 0;\n"), fem::ElementOrder::kTet4, 1));
  EXPECT_NE(syntax.find("Gmsh could not read it"), std::string::npos) << syntax;
  EXPECT_NE(syntax.find("line 1: syntax error"), std::string::npos) << syntax;
  // A .msh cut short: Gmsh says only "Error loading"; the message says what to look at.
  std::string cut = OneTetrahedron("1 2 3 4");
  cut.resize(cut.find("$EndElements") - 4);  // inside the element's line
  const std::string truncated = ExpectRefused(Request(Write("cut.msh", cut), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(truncated.find("Gmsh could not read it"), std::string::npos) << truncated;
  EXPECT_NE(truncated.find("is the file complete"), std::string::npos) << truncated;
  const std::string flat = ExpectRefused(Request(Write("flat.geo",
                                                       "SetFactory(\"OpenCASCADE\");\nRectangle(1) = {0, 0, 0, 10, 10};\n"),
                                                 fem::ElementOrder::kTet4, 2));
  EXPECT_NE(flat.find("no volume elements"), std::string::npos) << flat;
  const std::string no_size = ExpectRefused(Request(BarGeo(), fem::ElementOrder::kTet4, 0.0));
  EXPECT_NE(no_size.find("needs a mesh_size > 0"), std::string::npos) << no_size;
  // Refused before meshing: 100 x 20 x 20 mm at 0.05 mm would be ~10^9 nodes.
  const std::string huge = ExpectRefused(Request(BarGeo(), fem::ElementOrder::kTet4, 0.05));
  EXPECT_NE(huge.find("would make about"), std::string::npos) << huge;
  const std::string pieces = ExpectRefused(Request(Write("two.geo",
                                                         "SetFactory(\"OpenCASCADE\");\n"
                                                         "Box(1) = {0, 0, 0, 10, 10, 10};\n"
                                                         "Box(2) = {20, 0, 0, 10, 10, 10};\n"),
                                                   fem::ElementOrder::kTet4, 5));
  EXPECT_NE(pieces.find("2 disconnected pieces"), std::string::npos) << pieces;
}

// Gmsh's Exit command ends the process (status 0) while Gmsh reads the file: a batch-style
// .geo made a tool vanish without a word. It is refused with its line, also in an Included
// file; the word in a comment or a string is not a command. (Were the scan to miss one, this
// test binary would end with status 0 mid-run and ctest would report it: the ExitGuard turns
// that into status 1.)
TEST_F(GmshMeshTest, ExitCommandIsRefusedWithItsLineInsteadOfEndingTheProgram) {
  const std::string box = "SetFactory(\"OpenCASCADE\");\nBox(1) = {0, 0, 0, 10, 10, 10};\n";
  const std::string batch = ExpectRefused(Request(Write("batch.geo", box + "Mesh 3;\nExit;\n"), fem::ElementOrder::kTet4, 5));
  EXPECT_NE(batch.find("line 4: `Exit` would end this program"), std::string::npos) << batch;
  Write("tail.geo", "// made by hand\nExit;\n");
  const std::string included =
      ExpectRefused(Request(Write("main.geo", box + "Include \"tail.geo\";\n"), fem::ElementOrder::kTet4, 5));
  EXPECT_NE(included.find("included file"), std::string::npos) << included;
  EXPECT_NE(included.find("tail.geo, line 2"), std::string::npos) << included;
  // Only words: a comment, a block comment over lines, a string, a longer name.
  const ImportedMesh fine = ImportMesh(Request(
      Write("fine.geo", box + "// Exit;\n/* Exit;\n Exit; */\nPrintf(\"Exit;\");\nExitCode = 1;\nPhysical Volume(\"v\") = {1};\n"),
      fem::ElementOrder::kTet4, 5));
  EXPECT_GT(fine.mesh.num_elements(), 0);
  // An Include whose name is computed is not followed by the scan: Gmsh then runs the Exit,
  // and the guard turns its status 0 into 1 with a message on stderr.
  const MeshRequest computed = Request(Write("computed.geo", box + "Include StrCat(\"ta\", \"il.geo\");\n"),
                                       fem::ElementOrder::kTet4, 5);
  EXPECT_EXIT(ImportMesh(computed), ::testing::ExitedWithCode(1), "Gmsh ended the program while reading it");
}

TEST_F(GmshMeshTest, InvertedAndDegenerateTetrahedraAreNamedByTheirTag) {
  MeshRequest good = Request(Write("good.msh", OneTetrahedron("1 2 3 4")), fem::ElementOrder::kTet4, 0);
  EXPECT_NEAR(TotalVolume(ImportMesh(good).mesh), 1e-9 / 6.0, 1e-18);  // 1 mm^3 / 6
  const std::string inverted =
      ExpectRefused(Request(Write("inverted.msh", OneTetrahedron("1 3 2 4")), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(inverted.find("tetrahedron 7 is inverted"), std::string::npos) << inverted;
  std::string flat_text = OneTetrahedron("1 2 3 4");
  flat_text.replace(flat_text.find("4 0 0 1"), 7, "4 1 1 0");  // node 4 in the plane of 1, 2, 3
  const std::string degenerate = ExpectRefused(Request(Write("flat.msh", flat_text), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(degenerate.find("tetrahedron 7 is degenerate"), std::string::npos) << degenerate;
  // Two tetrahedra (tags 7 and 8) sharing a face; the second one's fifth node is the one at
  // fault. Flat by round-off (a tiny negative volume) is degenerate, not inverted; a node at
  // 1e300 is named with its element, not blamed on the first one (both were, a helper session).
  auto two = [](const char* fifth) {
    return std::string("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 ") +
           fifth + "\n$EndNodes\n$Elements\n2\n7 4 2 0 1 1 2 3 4\n8 4 2 0 1 2 3 4 5\n$EndElements\n";
  };
  EXPECT_NEAR(TotalVolume(ImportMesh(Request(Write("two.msh", two("1 1 1")), fem::ElementOrder::kTet4, 0)).mesh),
              1e-9 / 6.0 + 2e-9 / 6.0, 1e-18);
  const std::string rounded = ExpectRefused(Request(
      Write("rounded.msh", two("0.33333333333333 0.33333333333333 0.33333333333333")), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(rounded.find("tetrahedron 8 is degenerate"), std::string::npos) << rounded;
  const std::string huge = ExpectRefused(Request(Write("huge.msh", two("1e300 1 1")), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(huge.find("tetrahedron 8 is degenerate"), std::string::npos) << huge;
  EXPECT_NE(huge.find("node 5 at (1e+297, 0.001, 0.001) m"), std::string::npos) << huge;
  std::string nan_text = OneTetrahedron("1 2 3 4");
  nan_text.replace(nan_text.find("4 0 0 1"), 7, "4 0 nan 1");
  const std::string nan = ExpectRefused(Request(Write("nan.msh", nan_text), fem::ElementOrder::kTet4, 0));
  EXPECT_NE(nan.find("node 4 has a non-finite coordinate"), std::string::npos) << nan;
}

TEST_F(GmshMeshTest, MemoryEstimateOfAMeshBodyIsNotBelowWhatCholmodFactors) {
  // The estimate that refuses a too-large mesh before the FEM allocates (sim::EstimateMeshBuild)
  // against the factor CHOLMOD actually builds, for a bar and a compact body, both orders.
  const std::string cube = Write("cube.geo",
                                 "SetFactory(\"OpenCASCADE\");\nBox(1) = {0, 0, 0, 30, 30, 30};\n"
                                 "Physical Surface(\"root\") = Surface In BoundingBox{-0.1, -0.1, -0.1, 30.1, 30.1, 0.1};\n");
  for (const auto& [path, size] : {std::pair{BarGeo(), 5.0}, std::pair{cube, 3.0}}) {
    for (fem::ElementOrder order : {fem::ElementOrder::kTet4, fem::ElementOrder::kTet10}) {
      const ImportedMesh imported = ImportMesh(Request(path, order, size));
      const sim::BodyBuildEstimate estimate = sim::EstimateMeshBuild(imported.mesh);
      fem::ElasticBody::Spec spec;
      spec.mesh = imported.mesh;
      spec.material = {1e6, 0.3};
      spec.clamped_nodes = imported.group_nodes.at("root");
      const fem::ElasticBody body(std::move(spec));
      const double actual = static_cast<double>(body.stats().factor_nonzeros);
      EXPECT_GE(estimate.factor_nonzeros, actual) << path << " " << fem::ToString(order) << " ratio " << estimate.factor_nonzeros / actual;
      EXPECT_LE(estimate.factor_nonzeros, 4.0 * actual) << path << " " << fem::ToString(order);
      RecordProperty(fs::path(path).stem().string() + "_" + fem::ToString(order) + "_estimate_over_actual",
                     std::to_string(estimate.factor_nonzeros / actual));
    }
  }
}

}  // namespace
}  // namespace hapco::mesh_import
