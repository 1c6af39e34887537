#include "mesh_import/gmsh_mesh.h"

#include <gmsh.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <numeric>
#include <sstream>
#include <unordered_map>

#include "common/error.h"
#include "common/hash.h"
#include "common/progress.h"

namespace hapco::mesh_import {
namespace {

namespace fs = std::filesystem;

// A .msh larger than this is refused before Gmsh reads it (Gmsh holds several times the file
// in memory), bytes.
constexpr std::uintmax_t kMaxMeshFileBytes = std::uintmax_t{2} << 30;
// Corner nodes per (mesh size)^3 of bounding-box volume in a Gmsh Delaunay mesh: ~0.7 measured
// (sphere, cylinder, ellipsoid at 3 sizes); 1.5 leaves room for local refinement.
constexpr double kCornerNodesPerCell = 1.5;
// Tet10 node count per corner node (corners + one midside per edge; ~7 edges per node / 2 + 1,
// measured 4.6-5.3 on the same meshes).
constexpr double kTet10NodesPerCorner = 6.0;

[[noreturn]] void Fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

std::string ReadWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot be read (permissions?)");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Gmsh's `Exit;` ends the whole process (exit(0)) while it parses the file: a server or tool
// reading a batch-style .geo ("Mesh 3; Save ...; Exit;") vanished without a word and with exit
// status 0 (found by a helper session). The command is refused before Gmsh reads the file,
// with its line, in the file and in the files it Includes; ExitGuard catches what a scan
// cannot see.
void RefuseExitCommand(const std::string& top_path, const std::string& path, int include_depth) {
  const std::string text = ReadWholeFile(path);
  int line = 1;
  auto is_word = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
    } else if (c == '/' && i + 1 < text.size() && text[i + 1] == '/') {
      while (i + 1 < text.size() && text[i + 1] != '\n') ++i;
    } else if (c == '/' && i + 1 < text.size() && text[i + 1] == '*') {
      for (i += 2; i + 1 < text.size() && !(text[i] == '*' && text[i + 1] == '/'); ++i) line += text[i] == '\n';
      ++i;
    } else if (c == '"') {
      for (++i; i < text.size() && text[i] != '"'; ++i) {
        if (text[i] == '\\') ++i;
        else line += text[i] == '\n';
      }
    } else if (is_word(c) && (i == 0 || !is_word(text[i - 1]))) {
      std::size_t end = i;
      while (end < text.size() && is_word(text[end])) ++end;
      const std::string word = text.substr(i, end - i);
      if (word == "Exit") {
        Fail(top_path, (path == top_path ? std::string() : "included file " + path + ", ") + "line " + std::to_string(line) +
                       ": `Exit` would end this program while Gmsh reads the file; remove it (HapCo meshes the "
                       "geometry and caches the mesh itself: no Mesh, Save or Exit commands are needed)");
      }
      if (word == "Include" && include_depth < 16) {
        // Include "file"; relative to the including file's folder.
        std::size_t q = text.find('"', end);
        const std::size_t q_end = q == std::string::npos ? q : text.find('"', q + 1);
        if (q != std::string::npos && q_end != std::string::npos && text.find_first_not_of(" \t\r\n", end) == q) {
          fs::path included = text.substr(q + 1, q_end - q - 1);
          if (included.is_relative()) included = fs::path(path).parent_path() / included;
          std::error_code error;
          if (fs::is_regular_file(included, error)) RefuseExitCommand(top_path, included.string(), include_depth + 1);
        }
      }
      i = end - 1;
    }
  }
}

// Set while Gmsh reads or meshes a file: if Gmsh ends the process then (an Exit the scan
// missed), say so on stderr and exit with status 1 (bad input), not Gmsh's 0.
class ExitGuard {
 public:
  explicit ExitGuard(const std::string& path) {
    static const bool registered = [] { return std::atexit(&ExitGuard::OnExit) == 0; }();
    (void)registered;
    Path() = path;
  }
  ~ExitGuard() { Path().clear(); }
  ExitGuard(const ExitGuard&) = delete;
  ExitGuard& operator=(const ExitGuard&) = delete;

 private:
  static std::string& Path() {
    static std::string path;
    return path;
  }
  static void OnExit() {
    if (Path().empty()) return;
    std::fprintf(stderr, "error: %s: Gmsh ended the program while reading it (an Exit command?); remove it\n",
                 Path().c_str());
    std::fflush(stderr);
    _exit(1);
  }
};

// Gmsh writes its messages to a logger we start per import; the first "Error" is the user's.
class GmshSession {
 public:
  GmshSession() : lock_(Mutex()) {
    static bool initialized = false;
    if (initialized && Broken()) {
      // A Gmsh error unwinds out of its parser or mesher and leaves state behind (the next
      // .geo read finds an empty model): start a fresh Gmsh instead.
      gmsh::finalize();
      initialized = false;
    }
    if (!initialized) {
      gmsh::initialize(0, nullptr, /*readConfigFiles=*/false);
      gmsh::option::setNumber("General.Terminal", 0);  // no output on the server's stdout
      gmsh::option::setNumber("General.NumThreads", 1);
      initialized = true;
      Broken() = false;
    }
    gmsh::clear();
    gmsh::logger::start();
  }
  // Called when a Gmsh call threw: the next session restarts Gmsh.
  void MarkBroken() { Broken() = true; }
  ~GmshSession() {
    gmsh::logger::stop();
    gmsh::clear();  // free the model's memory
  }
  GmshSession(const GmshSession&) = delete;
  GmshSession& operator=(const GmshSession&) = delete;

  // Throws InputError with Gmsh's first error message, if it logged one since the last call.
  void ThrowOnError(const std::string& path, const std::string& doing) {
    std::vector<std::string> log;
    gmsh::logger::get(log);
    gmsh::logger::stop();
    gmsh::logger::start();
    for (const std::string& line : log) {
      if (line.rfind("Error", 0) == 0) {
        std::string message = line.substr(line.find(':') == std::string::npos ? 0 : line.find(':') + 1);
        while (!message.empty() && message.front() == ' ') message.erase(message.begin());
        // Gmsh says only that loading failed for a file cut short or with wrong counts.
        const bool bare = message.rfind("Error loading", 0) == 0 || message.empty();
        Fail(path, "Gmsh could not " + doing + ": " + message +
                       (bare ? " (is the file complete, and do its $Nodes and $Elements counts match its lines? "
                               "Run `gmsh FILE -check` for details)"
                             : ""));
      }
    }
  }

 private:
  static bool& Broken() {
    static bool broken = false;
    return broken;
  }
  static std::mutex& Mutex() {
    static std::mutex mutex;
    return mutex;
  }
  std::lock_guard<std::mutex> lock_;
};

// Gmsh's local node order of a tetrahedron type -> fem::Mesh's (VTK) order: position k of the
// result is the Gmsh local index of fem node k. Derived from Gmsh's own reference coordinates
// (getElementProperties), not from a table: corners are the reference vertices, a midside is
// the midpoint of two of them.
std::vector<int> GmshToFemOrder(int gmsh_type, fem::ElementOrder order) {
  std::string name;
  int dim = 0, element_order = 0, num_nodes = 0, num_primary = 0;
  std::vector<double> local;
  gmsh::model::mesh::getElementProperties(gmsh_type, name, dim, element_order, num_nodes, local, num_primary);
  HAPCO_ASSERT(dim == 3 && num_nodes == fem::NodesPerElement(order), "Gmsh tetrahedron type with an unexpected layout");
  const std::array<Eigen::Vector3d, 4> corners = {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0),
                                                  Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0, 1)};
  std::vector<Eigen::Vector3d> wanted(corners.begin(), corners.end());
  if (order == fem::ElementOrder::kTet10) {
    for (const auto& edge : fem::kTet10EdgeCorners) {
      wanted.push_back(0.5 * (corners[static_cast<std::size_t>(edge[0])] + corners[static_cast<std::size_t>(edge[1])]));
    }
  }
  std::vector<int> gmsh_index(wanted.size(), -1);
  for (std::size_t k = 0; k < wanted.size(); ++k) {
    for (int g = 0; g < num_nodes; ++g) {
      const Eigen::Vector3d x(local[3 * static_cast<std::size_t>(g)], local[3 * static_cast<std::size_t>(g) + 1],
                              local[3 * static_cast<std::size_t>(g) + 2]);
      if ((x - wanted[k]).norm() < 1e-9) gmsh_index[k] = g;
    }
    HAPCO_ASSERT(gmsh_index[k] >= 0, "Gmsh tetrahedron node layout not understood");
  }
  return gmsh_index;
}

std::string ElementTypeName(int type) {
  std::string name;
  int dim = 0, order = 0, num_nodes = 0, num_primary = 0;
  std::vector<double> local;
  gmsh::model::mesh::getElementProperties(type, name, dim, order, num_nodes, local, num_primary);
  return name + " (type " + std::to_string(type) + ")";
}

// Meshes the .geo now open in Gmsh, after estimating the node count from its bounding box.
void MeshGeo(const MeshRequest& request, GmshSession* session) {
  double x0 = 0, y0 = 0, z0 = 0, x1 = 0, y1 = 0, z1 = 0;
  gmsh::model::getBoundingBox(-1, -1, x0, y0, z0, x1, y1, z1);
  const double volume = std::max(x1 - x0, 0.0) * std::max(y1 - y0, 0.0) * std::max(z1 - z0, 0.0);
  const double h = request.mesh_size;
  double nodes = kCornerNodesPerCell * volume / (h * h * h);
  if (request.order == fem::ElementOrder::kTet10) nodes *= kTet10NodesPerCorner;
  if (!(nodes <= static_cast<double>(request.max_nodes))) {
    std::ostringstream message;
    message << "meshing with mesh_size " << h << " would make about " << static_cast<long long>(std::min(nodes, 1e18))
            << " nodes (bounding box " << x1 - x0 << " x " << y1 - y0 << " x " << z1 - z0
            << " file units), more than the " << request.max_nodes << " allowed; use a larger mesh_size";
    Fail(request.path, message.str());
  }
  if (nodes > 1e5) {
    // (A helper's .geo meshed for 59 s without a word, then was refused for its memory.)
    std::ostringstream line;
    line << "meshing " << request.path << " with mesh_size " << h << ": about " << static_cast<long long>(nodes)
         << " nodes, which can take a minute or more (its memory is judged after meshing)";
    ReportProgress(line.str());
  }
  gmsh::option::setNumber("Mesh.MeshSizeMax", h);
  gmsh::model::mesh::generate(3);
  session->ThrowOnError(request.path, "mesh it");
  if (request.order == fem::ElementOrder::kTet10) {
    gmsh::model::mesh::setOrder(2);
    session->ThrowOnError(request.path, "make its mesh quadratic");
  }
}

// Small disjoint-set forest over node ids: the mesh's connected pieces.
int Root(std::vector<int>& parent, int i) {
  while (parent[static_cast<std::size_t>(i)] != i) {
    parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
    i = parent[static_cast<std::size_t>(i)];
  }
  return i;
}

ImportedMesh ImportMeshWithGmsh(const MeshRequest& request, GmshSession* session);

}  // namespace

int GmshTetrahedronType(fem::ElementOrder order) { return order == fem::ElementOrder::kTet10 ? 11 : 4; }

std::string DefaultCacheDirectory() {
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0') {
    return std::string(xdg) + "/hapco/meshes";
  }
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') {
    return std::string(home) + "/.cache/hapco/meshes";
  }
  return {};
}

ImportedMesh ImportMesh(const MeshRequest& request) {
  GmshSession session;
  try {
    return ImportMeshWithGmsh(request, &session);
  } catch (const InputError&) {
    throw;
  } catch (const std::bad_alloc&) {
    session.MarkBroken();
    Fail(request.path, "ran out of memory while Gmsh read or meshed it");
  } catch (...) {
    session.MarkBroken();
    // Gmsh's API throws (a string) after logging an error: a syntax error in a .geo, an
    // unwritable output, an internal failure. Its log has the message.
    session.ThrowOnError(request.path, "read it");
    Fail(request.path, "Gmsh failed without a message");
  }
}

namespace {

ImportedMesh ImportMeshWithGmsh(const MeshRequest& request, GmshSession* session_pointer) {
  const std::string& path = request.path;
  std::error_code error;
  if (!fs::exists(path, error)) Fail(path, "does not exist");
  if (!fs::is_regular_file(path, error)) Fail(path, "is not a regular file");
  const std::string extension = Lower(fs::path(path).extension().string());
  if (extension != ".msh" && extension != ".geo") {
    Fail(path, "is neither a Gmsh mesh (.msh) nor a Gmsh geometry (.geo)");
  }
  if (!(std::isfinite(request.length_unit_m) && request.length_unit_m > 0.0)) {
    Fail(path, "length unit must be a finite number of metres > 0");
  }
  const std::uintmax_t bytes = fs::file_size(path, error);
  if (!error && bytes > kMaxMeshFileBytes) {
    Fail(path, std::to_string(bytes >> 20) + " MiB is more than the " + std::to_string(kMaxMeshFileBytes >> 20) +
                   " MiB a mesh file may have");
  }

  ImportedMesh imported;
  imported.gmsh_element_type = GmshTetrahedronType(request.order);
  GmshSession& session = *session_pointer;
  if (extension == ".msh") {
    if (access(path.c_str(), R_OK) != 0) Fail(path, "cannot be read (permissions?)");
    gmsh::open(path);
    session.ThrowOnError(path, "read it");
    imported.meshed_file = path;
  } else {
    if (!(std::isfinite(request.mesh_size) && request.mesh_size > 0.0)) {
      Fail(path, "a .geo needs a mesh_size > 0 (the largest element edge, in the file's length unit)");
    }
    const std::string geo = ReadWholeFile(path);
    std::ostringstream key;
    key << GMSH_API_VERSION << ' ' << request.mesh_size << ' ' << static_cast<int>(request.order);
    std::ostringstream name;
    // The cache key (common/hash.h): a collision would only hand back another file's mesh,
    // which the group and size checks would then see; the key also names the Gmsh version.
    name << std::hex << Fnv1a64(key.str(), Fnv1a64(geo)) << ".msh";
    const std::string cache_dir = request.cache_dir.empty() ? DefaultCacheDirectory() : request.cache_dir;
    const std::string cached = cache_dir.empty() ? std::string() : cache_dir + "/" + name.str();
    if (!cached.empty() && fs::exists(cached, error)) {
      gmsh::open(cached);
      session.ThrowOnError(cached, "read this cached mesh (delete it to mesh again)");
      imported.meshed_file = cached;
      imported.from_cache = true;
    } else {
      // Set before the .geo is read, so that it can size refined regions from it
      // (`h = Mesh.MeshSizeMax;`, as tests/data/meshes/hertz_*.geo do).
      gmsh::option::setNumber("Mesh.MeshSizeMax", request.mesh_size);
      RefuseExitCommand(path, path, 0);
      const ExitGuard guard(path);
      gmsh::open(path);
      session.ThrowOnError(path, "read it");
      MeshGeo(request, &session);
      imported.meshed_file = path;
      if (!cached.empty()) {
        // Written under a temporary name and renamed: a reader never sees half a file.
        fs::create_directories(cache_dir, error);
        // (Gmsh picks the format from the extension: it must stay .msh.)
        const std::string partial = cached.substr(0, cached.size() - 4) + ".part" + std::to_string(getpid()) + ".msh";
        if (!error) {
          gmsh::write(partial);
          if (fs::exists(partial, error)) {
            fs::rename(partial, cached, error);
            if (!error) imported.meshed_file = cached;
          }
        }
        gmsh::logger::stop();  // a cache that cannot be written is not an error of the file
        gmsh::logger::start();
      }
    }
  }

  // Element blocks: exactly the requested tetrahedra among the 3-D elements.
  std::vector<int> types;
  gmsh::model::mesh::getElementTypes(types, 3);
  const int wanted_type = imported.gmsh_element_type;
  std::string others;
  for (int type : types) {
    if (type != wanted_type) others += (others.empty() ? "" : ", ") + ElementTypeName(type);
  }
  if (std::find(types.begin(), types.end(), wanted_type) == types.end()) {
    // The other order's tetrahedra: the fix is the scene's element_order (or meshing again).
    const bool tet10 = request.order == fem::ElementOrder::kTet10;
    const int other_order_type = GmshTetrahedronType(tet10 ? fem::ElementOrder::kTet4 : fem::ElementOrder::kTet10);
    const bool other_order = std::find(types.begin(), types.end(), other_order_type) != types.end();
    std::string fix;
    if (other_order) fix = tet10 ? "; set element_order: TET4, or mesh with order 2" : "; set element_order: TET10";
    Fail(path, std::string("holds no ") + fem::ToString(request.order) + " tetrahedra (Gmsh type " +
                   std::to_string(wanted_type) + ")" +
                   (others.empty() ? ": it has no volume elements (mesh it in 3-D)" : "; it has " + others) + fix);
  }
  if (!others.empty()) {
    Fail(path, "mixes other volume elements with the " + std::string(fem::ToString(request.order)) +
                   " tetrahedra: " + others + "; a body has one element type");
  }
  std::vector<std::size_t> element_tags, element_nodes;
  gmsh::model::mesh::getElementsByType(wanted_type, element_tags, element_nodes);
  const int per_element = fem::NodesPerElement(request.order);

  std::vector<std::size_t> node_tags;
  std::vector<double> coordinates, parametric;
  gmsh::model::mesh::getNodes(node_tags, coordinates, parametric, -1, -1, false, false);
  std::unordered_map<std::size_t, int> tag_to_gmsh_index;
  tag_to_gmsh_index.reserve(node_tags.size());
  for (std::size_t i = 0; i < node_tags.size(); ++i) tag_to_gmsh_index.emplace(node_tags[i], static_cast<int>(i));

  // Only the nodes of tetrahedra, numbered in order of their Gmsh tags.
  std::vector<char> used(node_tags.size(), 0);
  for (std::size_t tag : element_nodes) {
    const auto found = tag_to_gmsh_index.find(tag);
    if (found == tag_to_gmsh_index.end()) Fail(path, "an element refers to node " + std::to_string(tag) + ", which the file does not define");
    used[static_cast<std::size_t>(found->second)] = 1;
  }
  std::vector<int> by_tag(node_tags.size());
  std::iota(by_tag.begin(), by_tag.end(), 0);
  std::sort(by_tag.begin(), by_tag.end(), [&](int a, int b) { return node_tags[static_cast<std::size_t>(a)] < node_tags[static_cast<std::size_t>(b)]; });
  std::unordered_map<std::size_t, int> tag_to_node;
  int num_nodes = 0;
  for (int i : by_tag) {
    if (used[static_cast<std::size_t>(i)]) tag_to_node.emplace(node_tags[static_cast<std::size_t>(i)], num_nodes++);
  }
  if (num_nodes > request.max_nodes) {
    Fail(path, std::to_string(num_nodes) + " nodes is more than the " + std::to_string(request.max_nodes) +
                   " allowed; use a coarser mesh");
  }
  fem::Mesh& mesh = imported.mesh;
  mesh.order = request.order;
  mesh.nodes_m.resize(num_nodes, 3);
  for (const auto& [tag, node] : tag_to_node) {
    const std::size_t g = static_cast<std::size_t>(tag_to_gmsh_index.at(tag));
    for (int a = 0; a < 3; ++a) {
      const double x = coordinates[3 * g + static_cast<std::size_t>(a)];
      // (A NaN made its tetrahedra "degenerate (zero volume)": name the node instead.)
      if (!std::isfinite(x)) Fail(path, "node " + std::to_string(tag) + " has a non-finite coordinate (" + std::to_string(x) + ")");
      mesh.nodes_m(node, a) = x * request.length_unit_m + request.offset_m[a];
    }
  }
  const std::vector<int> gmsh_local = GmshToFemOrder(wanted_type, request.order);
  const int num_elements = static_cast<int>(element_tags.size());
  mesh.elements.resize(num_elements, per_element);
  for (int e = 0; e < num_elements; ++e) {
    for (int k = 0; k < per_element; ++k) {
      const std::size_t tag = element_nodes[static_cast<std::size_t>(e) * static_cast<std::size_t>(per_element) +
                                            static_cast<std::size_t>(gmsh_local[static_cast<std::size_t>(k)])];
      mesh.elements(e, k) = tag_to_node.at(tag);
    }
  }

  // Inverted or degenerate tetrahedra, named by their Gmsh tag (the user's file's numbering)
  // with their corners. Each is judged on its own size, its volume against its longest edge
  // cubed (a regular one: 0.118): measured against the mesh's largest volume, one node at 1e300
  // made an unrelated tetrahedron "degenerate", and a flat one with a volume of -1e-20 by
  // round-off was called inverted (a helper session).
  std::vector<std::size_t> tag_of_node(static_cast<std::size_t>(num_nodes));
  for (const auto& [tag, node] : tag_to_node) tag_of_node[static_cast<std::size_t>(node)] = tag;
  for (int e = 0; e < num_elements; ++e) {
    double longest_m = 0.0;
    for (int a = 0; a < 4; ++a) {
      for (int b = a + 1; b < 4; ++b) {
        longest_m = std::max(longest_m, (mesh.nodes_m.row(mesh.elements(e, a)) - mesh.nodes_m.row(mesh.elements(e, b))).norm());
      }
    }
    const double volume = fem::ElementVolume(mesh, e);
    const double cube_m3 = longest_m * longest_m * longest_m;
    const bool flat = !(std::abs(volume) > 1e-9 * cube_m3) || !std::isfinite(cube_m3);
    if (!flat && volume > 0.0) continue;
    std::string corners;
    for (int a = 0; a < 4; ++a) {
      const auto node = static_cast<Eigen::Index>(mesh.elements(e, a));
      char text[160];
      std::snprintf(text, sizeof(text), "%snode %zu at (%.6g, %.6g, %.6g) m", a == 0 ? "" : ", ",
                    tag_of_node[static_cast<std::size_t>(node)], mesh.nodes_m(node, 0), mesh.nodes_m(node, 1),
                    mesh.nodes_m(node, 2));
      corners += text;
    }
    Fail(path, "tetrahedron " + std::to_string(element_tags[static_cast<std::size_t>(e)]) + " is " +
                   (flat ? "degenerate (zero volume: its corners lie in one plane or far apart from each other)"
                         : "inverted (negative volume: its corners are in left-handed order)") +
                   "; corners " + corners);
  }
  try {
    fem::ValidateMesh(mesh);
  } catch (const InputError& invalid) {
    Fail(path, invalid.what());
  }

  // One piece: a body in several pieces would need Dirichlet nodes on every piece.
  std::vector<int> parent(static_cast<std::size_t>(num_nodes));
  std::iota(parent.begin(), parent.end(), 0);
  for (int e = 0; e < num_elements; ++e) {
    const int first = Root(parent, mesh.elements(e, 0));
    for (int k = 1; k < 4; ++k) parent[static_cast<std::size_t>(Root(parent, mesh.elements(e, k)))] = first;
  }
  std::map<int, int> piece_elements;
  for (int e = 0; e < num_elements; ++e) ++piece_elements[Root(parent, mesh.elements(e, 0))];
  if (piece_elements.size() > 1) {
    std::vector<int> sizes;
    for (const auto& [root, count] : piece_elements) sizes.push_back(count);
    std::sort(sizes.rbegin(), sizes.rend());
    std::ostringstream message;
    message << "has " << sizes.size() << " disconnected pieces (of " << sizes[0] << ", " << sizes[1]
            << (sizes.size() > 2 ? ", ..." : "") << " tetrahedra); a body is one piece: split it into two bodies "
            << "or join the volumes (Coherence in the .geo)";
    Fail(path, message.str());
  }

  // Physical groups as node sets; a group without a name is known by its number.
  gmsh::vectorpair groups;
  gmsh::model::getPhysicalGroups(groups);
  for (const auto& [dim, tag] : groups) {
    std::string name;
    gmsh::model::getPhysicalName(dim, tag, name);
    if (name.empty()) name = std::to_string(tag);
    std::vector<std::size_t> tags;
    std::vector<double> unused;
    gmsh::model::mesh::getNodesForPhysicalGroup(dim, tag, tags, unused);
    std::vector<int>& nodes = imported.group_nodes[name];
    for (std::size_t t : tags) {
      const auto found = tag_to_node.find(t);
      if (found != tag_to_node.end()) nodes.push_back(found->second);
    }
    std::sort(nodes.begin(), nodes.end());
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  }
  session.ThrowOnError(path, "read its physical groups");
  return imported;
}

}  // namespace

}  // namespace hapco::mesh_import
