#include "io/scene_file.h"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "common/error.h"
#include "scene.pb.h"
#ifdef HAPCO_WITH_GMSH
#include "mesh_import/gmsh_mesh.h"
#endif

namespace hapco::io {
namespace {

namespace pb = ::hapco::scene;

// Physical ranges of a body (SI). Outside them the element integrals overflow or underflow
// (found with the scene fuzz harness: E = 1e308 Pa on a 100 m box built a body with infinite
// stiffness, E = 1e-320 Pa was blamed on the Dirichlet nodes).
constexpr double kMinEdgeM = 1e-6;
constexpr double kMaxExtentM = 10.0;
constexpr double kMinYoungsModulusPa = 1.0;
constexpr double kMaxYoungsModulusPa = 1e13;
using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using google::protobuf::TextFormat;

// Whether a .geo file names a physical group `name` (a line with `Physical` and "name"). Gmsh
// drops a group whose selection holds no entity (a BoundingBox that misses), so the mesh lacks
// a group the user did define: the message must say so instead of "not in the file".
bool GeoNamesPhysicalGroup(const std::string& geo_path, const std::string& name) {
  std::ifstream in(geo_path);
  const std::string quoted = "\"" + name + "\"";
  std::string line;
  while (std::getline(in, line)) {
    const auto comment = line.find("//");
    if (comment != std::string::npos) line.resize(comment);
    if (line.find("Physical") != std::string::npos && line.find(quoted) != std::string::npos) return true;
  }
  return false;
}

// Collects the first syntax error with its 1-based line and column.
class FirstErrorCollector : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    if (!has_error_) {
      has_error_ = true;
      message_ = std::to_string(line + 1) + ":" + std::to_string(column + 1) + ": " + message;
    }
  }
  bool has_error() const { return has_error_; }
  const std::string& message() const { return message_; }

 private:
  bool has_error_ = false;
  std::string message_;
};

// Walks the parsed message and its location tree together so that each check can name the
// field path and, when the field was written in the file, its line.
class SceneChecker {
 public:
  SceneChecker(std::string source, const TextFormat::ParseInfoTree* tree)
      : source_(std::move(source)), tree_(tree) {}

  [[noreturn]] void Fail(const std::string& path, const Message& parent,
                         const TextFormat::ParseInfoTree* tree, const char* field_name,
                         const std::string& problem, int index = -1) const {
    std::string where = source_;
    const FieldDescriptor* field = parent.GetDescriptor()->FindFieldByName(field_name);
    // A repeated field is located by element; an unset field has no location to report.
    const bool locatable = field != nullptr && (field->is_repeated() ? index >= 0 : index < 0);
    if (tree != nullptr && locatable) {
      const auto location = tree->GetLocation(field, index);
      if (location.line >= 0) where += ":" + std::to_string(location.line + 1);
    }
    const std::string full = path.empty() ? field_name : path + "." + field_name;
    throw InputError(where + ": " + full + ": " + problem);
  }

  const TextFormat::ParseInfoTree* Nested(const TextFormat::ParseInfoTree* tree,
                                          const Message& parent, const char* field_name) const {
    if (tree == nullptr) return nullptr;
    const FieldDescriptor* field = parent.GetDescriptor()->FindFieldByName(field_name);
    return field == nullptr ? nullptr : tree->GetTreeForNested(field, -1);
  }

  sim::SceneSpec Check(const pb::Scene& scene) const {
    if (scene.format_version() != static_cast<unsigned>(kSceneFormatVersion)) {
      Fail("", scene, tree_, "format_version",
           "is " + std::to_string(scene.format_version()) + ", this HapCo reads version " +
               std::to_string(kSceneFormatVersion));
    }
    sim::SceneSpec spec;
    spec.name = scene.name().empty() ? "unnamed" : scene.name();
    spec.description = scene.description();
    if (!scene.has_obstacle()) Fail("", scene, tree_, "obstacle", "is missing");
    if (!scene.has_tool()) Fail("", scene, tree_, "tool", "is missing");
    // Only the tool follows the device: a driven face or group on the obstacle was taken as one
    // more clamp (the device's translation is never applied to it), so a press on that face met
    // a rigid wall (45 N where 1.4 N was right, a helper session's scene).
    if (scene.obstacle().driven_face() != pb::BOX_FACE_UNSPECIFIED) {
      Fail("obstacle", scene.obstacle(), Nested(tree_, scene, "obstacle"), "driven_face",
           "only the tool follows the haptic device; fix the obstacle's faces with `clamped_faces`");
    }
    if (scene.obstacle().has_mesh() && !scene.obstacle().mesh().driven_group().empty()) {
      Fail("obstacle.mesh", scene.obstacle().mesh(),
           Nested(Nested(tree_, scene, "obstacle"), scene.obstacle(), "mesh"), "driven_group",
           "only the tool follows the haptic device; fix the obstacle's nodes with `clamped_groups`");
    }
    spec.obstacle = CheckBody("obstacle", scene.obstacle(), Nested(tree_, scene, "obstacle"));
    // Before the body checks: without a driven face the tool would be reported as an
    // unsupported body ("no clamped and no driven face"), which hides the actual mistake.
    if (scene.tool().has_mesh() && scene.tool().mesh().driven_group().empty()) {
      Fail("tool.mesh", scene.tool().mesh(), Nested(Nested(tree_, scene, "tool"), scene.tool(), "mesh"), "driven_group",
           "is missing: the tool must have a physical group whose nodes follow the haptic device");
    }
    if (scene.tool().driven_face() == pb::BOX_FACE_UNSPECIFIED && !scene.tool().has_mesh()) {
      std::string where = source_;
      const FieldDescriptor* tool_field = scene.GetDescriptor()->FindFieldByName("tool");
      if (tree_ != nullptr && tool_field != nullptr) {
        const auto location = tree_->GetLocation(tool_field, -1);
        if (location.line >= 0) where += ":" + std::to_string(location.line + 1);
      }
      throw InputError(where + ": tool.driven_face: is missing: the tool must have a face that follows the "
                               "haptic device (e.g. `driven_face: Z_MAX` in the tool block)");
    }
    spec.tool = CheckBody("tool", scene.tool(), Nested(tree_, scene, "tool"));
    CheckContact(scene, &spec);
    CheckSolver(scene, &spec);
    CheckTrajectory(scene, &spec);
    if (!(scene.force_gain() > 0.0) || !std::isfinite(scene.force_gain())) {
      Fail("", scene, tree_, "force_gain",
           "must be a finite number > 0 (device force = gain x reaction), got " +
               Number(scene.force_gain()));
    }
    spec.force_gain = scene.force_gain();
    return spec;
  }

 private:
  static std::string Number(double value) {
    std::ostringstream out;
    out << value;
    return out.str();
  }

  static fem::BoxFace ToFace(pb::BoxFace face) {
    switch (face) {
      case pb::X_MIN: return fem::BoxFace::kXMin;
      case pb::X_MAX: return fem::BoxFace::kXMax;
      case pb::Y_MIN: return fem::BoxFace::kYMin;
      case pb::Y_MAX: return fem::BoxFace::kYMax;
      case pb::Z_MIN: return fem::BoxFace::kZMin;
      case pb::Z_MAX: return fem::BoxFace::kZMax;
      default: break;
    }
    HAPCO_ASSERT(false, "unspecified face passed the checks");
  }

  sim::BodySpec CheckBody(const std::string& path, const pb::Body& body,
                          const TextFormat::ParseInfoTree* tree) const {
    sim::BodySpec spec;
    spec.name = body.name().empty() ? path : body.name();
    if (body.geometry_case() == pb::Body::kMeshFile) {
      Fail(path, body, tree, "mesh_file",
           "is not read; give a mesh as `mesh { file: \"" + body.mesh_file() +
               "\" length_unit_m: 1 clamped_groups: \"...\" }` (docs/mesh-scenes.md)");
    }
    if (body.has_mesh()) {
      CheckElementOrder(path, body, tree, &spec);
      CheckMaterial(path, body, tree, &spec);
      CheckMeshBody(path, body, tree, &spec);
      return spec;
    }
    if (!body.has_box()) Fail(path, body, tree, "box", "is missing (the body's geometry: `box { ... }` or `mesh { ... }`)");
    const pb::BoxGeometry& box = body.box();
    const auto* box_tree = Nested(tree, body, "box");
    const std::string box_path = path + ".box";
    const Eigen::Vector3d size(box.size_m().x(), box.size_m().y(), box.size_m().z());
    // Physical ranges, not just finite: a 1e300 m box (or 1e-300 m) overflows or underflows
    // the element integrals, and a haptic scene spans centimetres.
    if (!box.has_size_m() || !(size.minCoeff() >= kMinEdgeM) || !(size.maxCoeff() <= kMaxExtentM)) {
      Fail(box_path, box, box_tree, "size_m",
           "every edge length must be between " + Number(kMinEdgeM) + " and " +
               Number(kMaxExtentM) + " m, got (" + Number(size.x()) + ", " + Number(size.y()) +
               ", " + Number(size.z()) + ")");
    }
    const Eigen::Vector3d corner(box.min_corner_m().x(), box.min_corner_m().y(),
                                 box.min_corner_m().z());
    if (!corner.allFinite() || corner.cwiseAbs().maxCoeff() > kMaxExtentM) {
      Fail(box_path, box, box_tree, "min_corner_m",
           "every coordinate must be finite and within " + Number(kMaxExtentM) + " m of the origin");
    }
    const char* division_fields[3] = {"divisions_x", "divisions_y", "divisions_z"};
    const unsigned divisions[3] = {box.divisions_x(), box.divisions_y(), box.divisions_z()};
    for (int axis = 0; axis < 3; ++axis) {
      if (divisions[axis] < 1 || divisions[axis] > 400) {
        Fail(box_path, box, box_tree, division_fields[axis],
             "must be between 1 and 400 cells, got " + std::to_string(divisions[axis]));
      }
    }
    spec.box.min_corner_m = corner;
    spec.box.size_m = size;
    spec.box.divisions = Eigen::Vector3i(static_cast<int>(divisions[0]),
                                         static_cast<int>(divisions[1]),
                                         static_cast<int>(divisions[2]));
    CheckElementOrder(path, body, tree, &spec);
    // Refused here, before anything is allocated: a server would otherwise grow to many GB
    // (or be killed) while building the body.
    const sim::BodyBuildEstimate estimate = sim::EstimateBodyBuild(spec.box);
    if (estimate.bytes > sim::kMaxBodyBuildBytes) {
      Fail(box_path, box, box_tree, "divisions_x", sim::DescribeOverLimit(spec.box, estimate));
    }
    CheckMaterial(path, body, tree, &spec);
    for (int index = 0; index < body.clamped_faces_size(); ++index) {
      if (body.clamped_faces(index) == pb::BOX_FACE_UNSPECIFIED) {
        Fail(path, body, tree, "clamped_faces", "must name a face (X_MIN ... Z_MAX)", index);
      }
      spec.clamped_faces.push_back(ToFace(body.clamped_faces(index)));
    }
    if (body.driven_face() != pb::BOX_FACE_UNSPECIFIED) {
      spec.driven_face = ToFace(body.driven_face());
    }
    if (spec.clamped_faces.empty() && !spec.driven_face) {
      Fail(path, body, tree, "clamped_faces",
           "the body has no clamped and no driven face: its stiffness is singular (it can move "
           "freely); add `clamped_faces: X_MIN` or a `driven_face`");
    }
    return spec;
  }

  void CheckElementOrder(const std::string& path, const pb::Body& body, const TextFormat::ParseInfoTree* tree,
                         sim::BodySpec* spec) const {
    switch (body.element_order()) {
      case pb::TET4: spec->box.order = fem::ElementOrder::kTet4; break;
      case pb::TET10: spec->box.order = fem::ElementOrder::kTet10; break;
      default:
        Fail(path, body, tree, "element_order", "must be TET4 or TET10");
    }
  }

  void CheckMaterial(const std::string& path, const pb::Body& body, const TextFormat::ParseInfoTree* tree,
                     sim::BodySpec* out) const {
    sim::BodySpec& spec = *out;
    if (!body.has_material()) Fail(path, body, tree, "material", "is missing");
    const pb::Material& material = body.material();
    const auto* material_tree = Nested(tree, body, "material");
    const std::string material_path = path + ".material";
    if (!(material.youngs_modulus_pa() >= kMinYoungsModulusPa) ||
        !(material.youngs_modulus_pa() <= kMaxYoungsModulusPa)) {
      Fail(material_path, material, material_tree, "youngs_modulus_pa",
           "must be between " + Number(kMinYoungsModulusPa) + " Pa (a soft gel) and " +
               Number(kMaxYoungsModulusPa) + " Pa (stiffer than diamond), got " +
               Number(material.youngs_modulus_pa()));
    }
    if (!(material.poisson_ratio() > -1.0 && material.poisson_ratio() < 0.5)) {
      Fail(material_path, material, material_tree, "poisson_ratio",
           "must lie in (-1, 0.5) for a stable isotropic material, got " +
               Number(material.poisson_ratio()));
    }
    spec.material = {material.youngs_modulus_pa(), material.poisson_ratio()};
  }

  // A mesh body: Gmsh reads (or meshes) the file; its named groups become the node sets.
  void CheckMeshBody(const std::string& path, const pb::Body& body, const TextFormat::ParseInfoTree* tree,
                     sim::BodySpec* spec) const {
    const pb::MeshGeometry& mesh = body.mesh();
    const auto* mesh_tree = Nested(tree, body, "mesh");
    const std::string mesh_path = path + ".mesh";
    if (mesh.file().empty()) Fail(mesh_path, mesh, mesh_tree, "file", "is missing (a .msh or .geo file)");
    if (!(mesh.length_unit_m() > 0.0 && mesh.length_unit_m() <= 1e3)) {
      Fail(mesh_path, mesh, mesh_tree, "length_unit_m",
           "must be the metres per length unit of the file, in (0, 1000] (1 for metres, 0.001 for mm), got " +
               Number(mesh.length_unit_m()));
    }
    const Eigen::Vector3d offset(mesh.offset_m().x(), mesh.offset_m().y(), mesh.offset_m().z());
    if (!offset.allFinite() || offset.cwiseAbs().maxCoeff() > kMaxExtentM) {
      Fail(mesh_path, mesh, mesh_tree, "offset_m",
           "every coordinate must be finite and within " + Number(kMaxExtentM) + " m of the origin");
    }
    if (!(mesh.mesh_size() >= 0.0) || !std::isfinite(mesh.mesh_size())) {
      Fail(mesh_path, mesh, mesh_tree, "mesh_size", "must be a finite length >= 0, got " + Number(mesh.mesh_size()));
    }
    if (body.clamped_faces_size() > 0 || body.driven_face() != pb::BOX_FACE_UNSPECIFIED) {
      Fail(path, body, tree, body.clamped_faces_size() > 0 ? "clamped_faces" : "driven_face",
           "is for box bodies; a mesh body names its node sets with mesh.clamped_groups and mesh.driven_group",
           body.clamped_faces_size() > 0 ? 0 : -1);
    }
    if (mesh.clamped_groups_size() == 0 && mesh.driven_group().empty()) {
      Fail(mesh_path, mesh, mesh_tree, "clamped_groups",
           "the body has no clamped and no driven group: its stiffness is singular (it can move freely); "
           "name a physical group of the file in `clamped_groups` (or `driven_group` for the tool)");
    }
#ifdef HAPCO_WITH_GMSH
    namespace fs = std::filesystem;
    fs::path file(mesh.file());
    if (file.is_relative()) file = fs::path(source_).parent_path() / file;
    if (mesh.mesh_size() > 0.0 && file.extension() == ".msh") {
      // (It was ignored without a word: a user changed it and saw the same mesh; a helper.)
      Fail(mesh_path, mesh, mesh_tree, "mesh_size",
           "sizes the meshing of a .geo; a .msh is read as it is: remove mesh_size, or give the .geo to mesh it");
    }
    mesh_import::MeshRequest request;
    request.path = file.lexically_normal().string();
    request.order = spec->box.order;
    request.length_unit_m = mesh.length_unit_m();
    request.mesh_size = mesh.mesh_size();
    request.offset_m = offset;
    mesh_import::ImportedMesh imported;
    try {
      imported = mesh_import::ImportMesh(request);
    } catch (const InputError& error) {
      Fail(mesh_path, mesh, mesh_tree, "file", error.what());
    }
    auto body_mesh = std::make_shared<sim::MeshBody>();
    body_mesh->source = request.path;
    const auto group = [&](const std::string& name, const char* field, int index) -> const std::vector<int>& {
      const auto found = imported.group_nodes.find(name);
      if (found == imported.group_nodes.end()) {
        std::string known;
        for (const auto& [known_name, nodes] : imported.group_nodes) known += (known.empty() ? "" : ", ") + known_name;
        if (file.extension() == ".geo" && GeoNamesPhysicalGroup(request.path, name)) {
          Fail(mesh_path, mesh, mesh_tree, field,
               "physical group '" + name + "' is defined in " + request.path +
                   " but holds nothing, so Gmsh left it out of the mesh: its selection (a BoundingBox, an "
                   "entity list) catches no entity of the geometry; check its coordinates in the .geo's "
                   "own length unit" + (known.empty() ? "" : " (the mesh has: " + known + ")"),
               index);
        }
        Fail(mesh_path, mesh, mesh_tree, field,
             "physical group '" + name + "' is not in " + request.path +
                 (known.empty() ? " (it has no physical groups on its elements: define them in the .geo; a .msh "
                                  "saved with -save_all or Mesh.SaveAll drops them in MSH 2, so save it without)"
                                : " (it has: " + known + ")"),
             index);
      }
      if (found->second.empty()) {
        Fail(mesh_path, mesh, mesh_tree, field, "physical group '" + name + "' holds no node of the tetrahedra", index);
      }
      return found->second;
    };
    const auto merge = [](std::vector<int>* into, const std::vector<int>& nodes) {
      std::vector<int> merged;
      std::set_union(into->begin(), into->end(), nodes.begin(), nodes.end(), std::back_inserter(merged));
      *into = std::move(merged);
    };
    for (int index = 0; index < mesh.clamped_groups_size(); ++index) {
      merge(&body_mesh->clamped_nodes, group(mesh.clamped_groups(index), "clamped_groups", index));
    }
    if (!mesh.driven_group().empty()) body_mesh->driven_nodes = group(mesh.driven_group(), "driven_group", -1);
    for (int index = 0; index < mesh.contact_groups_size(); ++index) {
      merge(&body_mesh->contact_nodes, group(mesh.contact_groups(index), "contact_groups", index));
    }
    const sim::BodyBuildEstimate estimate = sim::EstimateMeshBuild(imported.mesh);
    if (estimate.bytes > sim::kMaxBodyBuildBytes) {
      Fail(mesh_path, mesh, mesh_tree, "file", request.path + ": " + sim::DescribeOverLimit(imported.mesh, estimate));
    }
    std::ostringstream summary;
    summary << request.path;
    if (imported.meshed_file != request.path) {
      summary << " (meshed at " << mesh.mesh_size() << " file units" << (imported.from_cache ? ", from the cache" : "") << ")";
    }
    const auto names = [](const google::protobuf::RepeatedPtrField<std::string>& groups) {
      std::string text;
      for (const std::string& name : groups) text += (text.empty() ? "" : " ") + name;
      return text.empty() ? std::string("-") : text;
    };
    summary << "; clamped: " << names(mesh.clamped_groups()) << ", driven: "
            << (mesh.driven_group().empty() ? "-" : mesh.driven_group())
            << ", contact: " << (mesh.contact_groups_size() == 0 ? "whole boundary" : names(mesh.contact_groups()));
    body_mesh->summary = summary.str();
    body_mesh->mesh = std::move(imported.mesh);
    spec->mesh = std::move(body_mesh);
#else
    (void)spec;
    Fail(mesh_path, mesh, mesh_tree, "file",
         "this HapCo was built without Gmsh (HAPCO_WITH_GMSH=OFF): mesh bodies need a build with libgmsh-dev");
#endif
  }

  void CheckContact(const pb::Scene& scene, sim::SceneSpec* spec) const {
    const pb::Contact& contact = scene.contact();
    const auto* tree = Nested(tree_, scene, "contact");
    if (!(contact.friction_coefficient() >= 0.0) || contact.friction_coefficient() > sim::kMaxFrictionCoefficient) {
      Fail("contact", contact, tree, "friction_coefficient",
           "must be in [0, " + Number(sim::kMaxFrictionCoefficient) + "], got " + Number(contact.friction_coefficient()));
    }
    if (!(contact.activation_gap_m() > 0.0) || !std::isfinite(contact.activation_gap_m())) {
      Fail("contact", contact, tree, "activation_gap_m",
           "must be a finite distance > 0 m, got " + Number(contact.activation_gap_m()));
    }
    if (!(contact.reach_m() >= 0.0) || !std::isfinite(contact.reach_m())) {
      Fail("contact", contact, tree, "reach_m",
           "must be a finite distance >= 0 m (0: the default 0.1 m), got " + Number(contact.reach_m()));
    }
    if (!(contact.compliance_range_m() >= 0.0) || !std::isfinite(contact.compliance_range_m())) {
      Fail("contact", contact, tree, "compliance_range_m",
           "must be a finite distance >= 0 m (0: every node pair), got " + Number(contact.compliance_range_m()));
    }
    spec->compliance_range_m = contact.compliance_range_m();
    spec->friction_coefficient = contact.friction_coefficient();
    spec->activation_gap_m = contact.activation_gap_m();
    if (contact.reach_m() > 0.0) spec->reach_m = contact.reach_m();
    switch (contact.quadratic_face_search()) {
      case pb::CORNER_TRIANGLE: spec->quadratic_face_subtriangles = false; break;
      case pb::FOUR_SUBTRIANGLES: spec->quadratic_face_subtriangles = true; break;
      default: Fail("contact", contact, tree, "quadratic_face_search", "must be CORNER_TRIANGLE or FOUR_SUBTRIANGLES");
    }
    switch (contact.reverse_pass_slaves()) {
      case pb::SHARP_EDGE_NODES: spec->reverse_pass_all_nodes = false; break;
      case pb::ALL_SURFACE_NODES: spec->reverse_pass_all_nodes = true; break;
      default: Fail("contact", contact, tree, "reverse_pass_slaves", "must be SHARP_EDGE_NODES or ALL_SURFACE_NODES");
    }
  }

  void CheckSolver(const pb::Scene& scene, sim::SceneSpec* spec) const {
    const pb::SolverSettings& solver = scene.solver();
    const auto* tree = Nested(tree_, scene, "solver");
    switch (solver.solver()) {
      case pb::LOCAL_UZAWA: spec->solver = contact::SolverKind::kLocalUzawa; break;
      case pb::GLOBAL_UZAWA_GS: spec->solver = contact::SolverKind::kGlobalUzawaGaussSeidel; break;
      case pb::GLOBAL_UZAWA_JACOBI: spec->solver = contact::SolverKind::kGlobalUzawaJacobi; break;
      case pb::REFERENCE_NSGS: spec->solver = contact::SolverKind::kReferenceNsgs; break;
      default:
        Fail("solver", solver, tree, "solver",
             "must be LOCAL_UZAWA, GLOBAL_UZAWA_GS, GLOBAL_UZAWA_JACOBI or REFERENCE_NSGS");
    }
    contact::SolverParameters& parameters = spec->solver_parameters;
    if (!(solver.global_tolerance_m() > 0.0)) {
      Fail("solver", solver, tree, "global_tolerance_m",
           "must be > 0 m (the paper's Uzawa error), got " + Number(solver.global_tolerance_m()));
    }
    parameters.global_tolerance_m = solver.global_tolerance_m();
    if (solver.local_tolerance_m() < 0.0) {
      Fail("solver", solver, tree, "local_tolerance_m", "must be >= 0 m");
    }
    if (solver.local_tolerance_m() > 0.0) parameters.local_tolerance_m = solver.local_tolerance_m();
    if (solver.max_iterations() < 1 || solver.max_iterations() > 1000000) {
      Fail("solver", solver, tree, "max_iterations",
           "must be between 1 and 1000000, got " + std::to_string(solver.max_iterations()));
    }
    parameters.max_iterations = static_cast<int>(solver.max_iterations());
    if (!(solver.time_budget_s() >= 0.0) || !std::isfinite(solver.time_budget_s())) {
      Fail("solver", solver, tree, "time_budget_s", "must be >= 0 s (0 = no budget)");
    }
    parameters.time_budget_s = solver.time_budget_s();
    parameters.warm_start = solver.warm_start();
    switch (solver.rho_rule()) {
      case pb::RHO_RULE_UNSPECIFIED:
      case pb::PAPER_GLOBAL_MIN: parameters.rho_rule = contact::RhoRule::kPaperGlobalMin; break;
      case pb::PER_CONTACT: parameters.rho_rule = contact::RhoRule::kPerContact; break;
      default: Fail("solver", solver, tree, "rho_rule", "must be PAPER_GLOBAL_MIN or PER_CONTACT");
    }
    if (solver.anderson_depth() > static_cast<uint32_t>(contact::SolverParameters::kMaxAndersonDepth)) {
      Fail("solver", solver, tree, "anderson_depth",
           "must be between 0 (off) and " + std::to_string(contact::SolverParameters::kMaxAndersonDepth) + ", got " +
               std::to_string(solver.anderson_depth()));
    }
    parameters.anderson_depth = static_cast<int>(solver.anderson_depth());
    if (solver.has_anderson_start()) {
      if (solver.anderson_start() < 1 || solver.anderson_start() > 1000000) {
        Fail("solver", solver, tree, "anderson_start",
             "must be between 1 and 1000000 sweeps, got " + std::to_string(solver.anderson_start()));
      }
      parameters.anderson_start = static_cast<int>(solver.anderson_start());
    }
  }

  void CheckTrajectory(const pb::Scene& scene, sim::SceneSpec* spec) const {
    const pb::Trajectory& trajectory = scene.trajectory();
    const auto* tree = Nested(tree_, scene, "trajectory");
    if (trajectory.phases_size() == 0) {
      Fail("", scene, tree_, "trajectory", "needs at least one phase");
    }
    const FieldDescriptor* phases_field =
        trajectory.GetDescriptor()->FindFieldByName("phases");
    long long total_steps = 0;
    for (int index = 0; index < trajectory.phases_size(); ++index) {
      const pb::TrajectoryPhase& phase = trajectory.phases(index);
      const auto* phase_tree = tree == nullptr ? nullptr : tree->GetTreeForNested(phases_field, index);
      const std::string path = "trajectory.phases[" + std::to_string(index) + "]";
      if (phase.steps() < 1 || phase.steps() > 10000000) {
        Fail(path, phase, phase_tree, "steps",
             "must be between 1 and 10000000, got " + std::to_string(phase.steps()));
      }
      total_steps += phase.steps();
      if (total_steps > sim::kMaxTrajectorySteps) {
        Fail(path, phase, phase_tree, "steps",
             "brings the trajectory to " + std::to_string(total_steps) + " steps; at most " +
                 std::to_string(sim::kMaxTrajectorySteps) + " in total");
      }
      const Eigen::Vector3d displacement(phase.displacement_m().x(), phase.displacement_m().y(),
                                         phase.displacement_m().z());
      if (!displacement.allFinite() || displacement.norm() > 1.0) {
        Fail(path, phase, phase_tree, "displacement_m",
             "must be finite and at most 1 m long");
      }
      spec->trajectory.push_back(
          {phase.name().empty() ? "phase " + std::to_string(index + 1) : phase.name(),
           displacement, static_cast<int>(phase.steps())});
    }
  }

  std::string source_;
  const TextFormat::ParseInfoTree* tree_;
};

// Whether some message type reachable from `type` (other than `except`) has a field `name`.
bool SomeMessageHasField(const google::protobuf::Descriptor* type, const std::string& name,
                         const std::string& except, std::vector<const google::protobuf::Descriptor*>* seen,
                         std::string* owner) {
  for (const auto* visited : *seen) {
    if (visited == type) return false;
  }
  seen->push_back(type);
  if (type->full_name() != except && type->FindFieldByName(name) != nullptr) {
    *owner = type->name();
    return true;
  }
  for (int k = 0; k < type->field_count(); ++k) {
    const FieldDescriptor* field = type->field(k);
    if (field->message_type() != nullptr && SomeMessageHasField(field->message_type(), name, except, seen, owner)) {
      return true;
    }
  }
  return false;
}

// The parser reports a missing `}` as an unknown field of the block left open ("Message type
// "hapco.scene.Material" has no field named "driven_face""); when the field belongs to another
// block of the scene, say that a `}` is probably missing.
std::string WithMissingBraceHint(const std::string& message) {
  static const std::string kType = "Message type \"", kField = "\" has no field named \"";
  const std::size_t type_at = message.find(kType);
  const std::size_t field_at = message.find(kField);
  if (type_at == std::string::npos || field_at == std::string::npos || field_at < type_at) return message;
  const std::string type = message.substr(type_at + kType.size(), field_at - type_at - kType.size());
  const std::size_t name_at = field_at + kField.size();
  const std::size_t name_end = message.find('"', name_at);
  if (name_end == std::string::npos) return message;
  const std::string name = message.substr(name_at, name_end - name_at);
  std::vector<const google::protobuf::Descriptor*> seen;
  std::string owner;
  if (!SomeMessageHasField(pb::Scene::descriptor(), name, type, &seen, &owner)) return message;
  return message + " (is a `}` missing before this line? `" + name + "` is a field of " + owner + ", not of " +
         type.substr(type.rfind('.') + 1) + ")";
}

}  // namespace

namespace {

// What a file that is not scene text is, from its first bytes: given a recording or an FCLIB
// file, the tools answered "...:1:13: Interpreting non ascii codepoint 249." (a helper session).
std::string NotSceneText(const std::string& text) {
  if (text.rfind("HAPCOREC", 0) == 0) {
    return "a HapCo recording, not a scene file (hapco-report reads recordings; the scene a recording was made "
           "with is in its header)";
  }
  if (text.rfind("\x89HDF\r\n", 0) == 0) return "an HDF5 file (an FCLIB problem? hapco-solve reads those), not a scene file";
  if (text.rfind("$MeshFormat", 0) == 0) return "a Gmsh mesh, not a scene file (a scene names its mesh: docs/mesh-scenes.md)";
  // Text scene files are UTF-8 text: a NUL or other control bytes early on mean a binary file.
  const std::size_t head = std::min<std::size_t>(text.size(), 4096);
  for (std::size_t i = 0; i < head; ++i) {
    const auto byte = static_cast<unsigned char>(text[i]);
    if (byte == 0 || (byte < 0x20 && byte != '\n' && byte != '\r' && byte != '\t' && byte != '\f' && byte != '\v')) {
      return "a binary file, not a scene file (scenes are protobuf text: proto/scene.proto, proto/scenes/)";
    }
  }
  return "";
}

}  // namespace

sim::SceneSpec ParseSceneText(const std::string& text, const std::string& source_name) {
  if (const std::string what = NotSceneText(text); !what.empty()) throw InputError(source_name + ": " + what);
  pb::Scene scene;
  TextFormat::Parser parser;
  FirstErrorCollector errors;
  TextFormat::ParseInfoTree tree;
  parser.RecordErrorsTo(&errors);
  parser.WriteLocationsTo(&tree);
  if (!parser.ParseFromString(text, &scene)) {
    throw InputError(source_name + ":" +
                     (errors.has_error() ? WithMissingBraceHint(errors.message()) : std::string(" syntax error")));
  }
  return SceneChecker(source_name, &tree).Check(scene);
}

sim::SceneSpec LoadSceneFile(const std::string& path) {
  // (A directory opens as an empty stream: it was reported as "format_version: is 0".)
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) throw InputError(path + ": is a directory, not a scene file");
  std::ifstream file(path);
  if (!file) throw InputError(path + ": cannot open scene file");
  std::stringstream text;
  text << file.rdbuf();
  return ParseSceneText(text.str(), path);
}

}  // namespace hapco::io
