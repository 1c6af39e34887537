#include "sim/two_body_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>
#include <utility>

#include "common/error.h"
#include "common/memory.h"
#include "common/progress.h"
#include "common/timer.h"

namespace hapco::sim {
namespace {

Eigen::Vector3d Position(const fem::Mesh& mesh, int node) { return mesh.nodes_m.row(node).transpose(); }

std::vector<int> IndexOf(const std::vector<int>& nodes, int num_nodes) {
  std::vector<int> index(static_cast<std::size_t>(num_nodes), -1);
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i) index[static_cast<std::size_t>(nodes[i])] = i;
  return index;
}

double SmallestExtent(const fem::Mesh& mesh) {
  return (mesh.nodes_m.colwise().maxCoeff() - mesh.nodes_m.colwise().minCoeff()).minCoeff();
}

// A node of one body strictly inside the other, and its distance to that body's boundary.
struct NodeInside {
  int node = -1;
  double depth_m = 0.0;
};

// The deepest node of `other` (any node, interior ones included) that lies in a tetrahedron of
// `body` (its corners: straight faces; on a face, edge or corner counts, as nodes of matching
// grids do), with its distance to body's boundary triangles (corners), m: a node on the
// boundary has depth 0. The start check by contact detection only sees a node within 0.45 of
// a body's thickness of a face it can face; a tool placed wholly inside the obstacle, or deeper
// than that, passes it and then meets no face at all (0 N for ever, found by a helper session).
// `locator` is body's (TetrahedronLocator).
NodeInside DeepestNodeInside(const TetrahedronLocator& locator, const fem::Mesh& body, const fem::Mesh& other) {
  NodeInside deepest;
  const std::vector<fem::SurfaceTriangle> boundary = fem::BoundaryTriangles(body);
  for (int n = 0; n < other.num_nodes(); ++n) {
    const Eigen::Vector3d x = Position(other, n);
    if (!locator.Contains(x)) continue;
    double depth_m = std::numeric_limits<double>::infinity();
    for (const fem::SurfaceTriangle& tri : boundary) {
      const Eigen::Vector3d a = Position(body, tri.corners[0]), b = Position(body, tri.corners[1]),
                            c = Position(body, tri.corners[2]);
      const Eigen::Vector3d l = ClosestPointBarycentric(x, a, b, c);
      depth_m = std::min(depth_m, (x - (l[0] * a + l[1] * b + l[2] * c)).norm());
    }
    if (depth_m > deepest.depth_m) deepest = {n, depth_m};
  }
  return deepest;
}

// Corner and midside nodes of the faces, sorted, once each: a surface's contact candidates.
std::vector<int> FaceNodes(const std::vector<fem::SurfaceTriangle>& faces) {
  std::vector<int> nodes;
  for (const fem::SurfaceTriangle& face : faces) {
    for (int node : face.corners) nodes.push_back(node);
    for (int node : face.midsides) {
      if (node >= 0) nodes.push_back(node);
    }
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  return nodes;
}

// Everything of a ContactSurface except the compliance, from its faces; 6-node faces are split
// into their four sub-triangles when `subtriangles` (scene quadratic_face_search).
ContactSurface DescribeSurface(const fem::Mesh& mesh, std::vector<fem::SurfaceTriangle> triangles, bool subtriangles,
                               int sort_axis = -1) {
  ContactSurface surface;
  if (subtriangles && !triangles.empty() && triangles.front().midsides[0] >= 0) {
    SubtriangleSplit split = SplitIntoSubtriangles(triangles);
    surface.triangles = std::move(split.triangles);
    surface.subtriangle_faces = std::move(split.faces);
  } else {
    surface.triangles = std::move(triangles);
  }
  const auto num_triangles = surface.triangles.size();
  std::vector<Eigen::Vector3d> normals(num_triangles);
  for (std::size_t t = 0; t < num_triangles; ++t) {
    const auto& tri = surface.triangles[t];
    const Eigen::Vector3d p0 = Position(mesh, tri.corners[0]);
    const Eigen::Vector3d p1 = Position(mesh, tri.corners[1]);
    const Eigen::Vector3d p2 = Position(mesh, tri.corners[2]);
    normals[t] = (p1 - p0).cross(p2 - p0).normalized();
    surface.triangle_min_m.push_back(p0.cwiseMin(p1).cwiseMin(p2));
    surface.triangle_max_m.push_back(p0.cwiseMax(p1).cwiseMax(p2));
    surface.triangle_frames.push_back(FrameFromNormal(normals[t]));
    surface.longest_edge_m =
        std::max({surface.longest_edge_m, (p1 - p0).norm(), (p2 - p1).norm(), (p0 - p2).norm()});
  }
  surface.triangle_tree = StaticBoxTree(surface.triangle_min_m, surface.triangle_max_m);
  surface.nodes = FaceNodes(surface.triangles);
  if (sort_axis >= 0) {
    // Banded compliance: along the axis, so that each node's stored partners are one run.
    std::stable_sort(surface.nodes.begin(), surface.nodes.end(),
                     [&](int a, int b) { return mesh.nodes_m(a, sort_axis) < mesh.nodes_m(b, sort_axis); });
  }
  surface.node_index = IndexOf(surface.nodes, mesh.num_nodes());

  // Sharp edges: two faces of the surface meeting at more than kFeatureEdgeAngleRad. An edge
  // with one face only (where the reach filter cut the surface) is not a body edge.
  std::map<std::pair<int, int>, std::vector<std::pair<std::size_t, int>>> edges;
  for (std::size_t t = 0; t < num_triangles; ++t) {
    const auto& c = surface.triangles[t].corners;
    for (int k = 0; k < 3; ++k) {
      const int a = c[static_cast<std::size_t>(k)], b = c[static_cast<std::size_t>((k + 1) % 3)];
      edges[{std::min(a, b), std::max(a, b)}].emplace_back(t, k);
    }
  }
  surface.sharp_edges.assign(num_triangles, {false, false, false});
  surface.on_sharp_edge.assign(surface.nodes.size(), 0);
  const double cos_feature = std::cos(kFeatureEdgeAngleRad);
  for (const auto& [key, faces] : edges) {
    if (faces.size() != 2) continue;
    if (normals[faces[0].first].dot(normals[faces[1].first]) >= cos_feature) continue;
    for (const auto& [t, k] : faces) {
      surface.sharp_edges[t][static_cast<std::size_t>(k)] = true;
      const auto& tri = surface.triangles[t];
      surface.on_sharp_edge[static_cast<std::size_t>(surface.node_index[static_cast<std::size_t>(key.first)])] = 1;
      surface.on_sharp_edge[static_cast<std::size_t>(surface.node_index[static_cast<std::size_t>(key.second)])] = 1;
      const int midside = tri.midsides[static_cast<std::size_t>(k)];
      if (midside >= 0) surface.on_sharp_edge[static_cast<std::size_t>(surface.node_index[static_cast<std::size_t>(midside)])] = 1;
    }
  }

  // Pseudo-normals: corner k of a face weighted by the face's angle there, so the normal at a
  // box edge or corner does not depend on how its faces were split into triangles.
  surface.node_normals.assign(surface.nodes.size(), Eigen::Vector3d::Zero());
  for (std::size_t t = 0; t < num_triangles; ++t) {
    const auto& tri = surface.triangles[t];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p = Position(mesh, tri.corners[static_cast<std::size_t>(k)]);
      const Eigen::Vector3d e1 = (Position(mesh, tri.corners[static_cast<std::size_t>((k + 1) % 3)]) - p).normalized();
      const Eigen::Vector3d e2 = (Position(mesh, tri.corners[static_cast<std::size_t>((k + 2) % 3)]) - p).normalized();
      const double angle_rad = std::acos(std::clamp(e1.dot(e2), -1.0, 1.0));
      surface.node_normals[static_cast<std::size_t>(surface.node_index[static_cast<std::size_t>(tri.corners[static_cast<std::size_t>(k)])])] +=
          angle_rad * normals[t];
      const int midside = tri.midsides[static_cast<std::size_t>(k)];
      if (midside >= 0) surface.node_normals[static_cast<std::size_t>(surface.node_index[static_cast<std::size_t>(midside)])] += normals[t];
    }
  }
  for (auto& n : surface.node_normals) n.normalize();
  return surface;
}

// Rows [begin[j], end[j]) of each column: the nodes within range_m of node j along the axis
// (`nodes` sorted along it).
void RangeBands(const fem::Mesh& mesh, const std::vector<int>& nodes, int axis, double range_m, std::vector<int>* begin,
                std::vector<int>* end) {
  std::vector<double> x(nodes.size());
  for (std::size_t i = 0; i < nodes.size(); ++i) x[i] = mesh.nodes_m(nodes[i], axis);
  begin->resize(nodes.size());
  end->resize(nodes.size());
  const double inclusive_m = range_m * (1.0 + 1e-9);  // a pair at exactly the range is kept
  for (std::size_t j = 0; j < nodes.size(); ++j) {
    (*begin)[j] = static_cast<int>(std::lower_bound(x.begin(), x.end(), x[j] - inclusive_m) - x.begin());
    (*end)[j] = static_cast<int>(std::upper_bound(x.begin(), x.end(), x[j] + inclusive_m) - x.begin());
  }
}

// The banded compliance by batched solves, a chunk of columns at a time: the dense blocks
// are never held (that is why the range is set), and each column's blocks beyond the range
// leave only their norm, in far_bound_m_per_n.
void ComputeBandedCompliance(const fem::ElasticBody& body, ContactSurface* surface) {
  const int n = static_cast<int>(surface->nodes.size());
  std::vector<int> begin, end;
  RangeBands(body.mesh(), surface->nodes, surface->range_axis, surface->range_m, &begin, &end);
  surface->compliance_m_per_n = BlockedCompliance::Banded(n, std::move(begin), std::move(end));
  surface->far_bound_m_per_n.assign(static_cast<std::size_t>(n), 0.0);
  BlockedCompliance& c = surface->compliance_m_per_n;
  const int chunk = std::clamp(4'000'000 / std::max(1, 9 * n), 1, 64);  // ~32 MB of columns
  // Minutes on a user's mesh with its whole boundary in contact (13 k surface nodes, 42 k-node
  // body: more than 10 minutes with no output, a helper session): say what runs, and how far.
  ReportProgress("obstacle compliance: " + std::to_string(n) + " contact surface nodes, stored within " +
                 std::to_string(surface->range_m) + " m of each other, by solves with the body's factor; " +
                 "obstacle.mesh.contact_groups naming only the faces a tool can touch makes this shorter");
  const Stopwatch watch;
  double last_report_s = 0.0;
  body.ForEachComplianceColumnChunk(surface->nodes, chunk, [&](int first, int count, const Eigen::MatrixXd& columns) {
    const double elapsed_s = watch.ElapsedSeconds();
    if (elapsed_s - last_report_s >= 10.0) {
      last_report_s = elapsed_s;
      const double done = static_cast<double>(first + count) / n;
      char line[160];
      std::snprintf(line, sizeof(line), "obstacle compliance: %d of %d nodes (%.0f %%) in %.0f s, about %.0f s left",
                    first + count, n, 100.0 * done, elapsed_s, elapsed_s * (1.0 - done) / done);
      ReportProgress(line);
    }
    for (int k = 0; k < count; ++k) {
      const int j = first + k;
      double& far = surface->far_bound_m_per_n[static_cast<std::size_t>(j)];
      for (int i = 0; i < n; ++i) {
        const auto block = columns.block<3, 3>(3 * i, 3 * k);
        if (c.stored(i, j)) {
          Eigen::Map<Eigen::Matrix3d>(c.mutable_block(i, j)) = block;
        } else {
          for (int a = 0; a < 3; ++a) far = std::max(far, block.row(a).norm());
        }
      }
    }
  });
}

void ComputeCompliance(const fem::ElasticBody& body, ContactSurface* surface) {
  // Computed in the blocked layout's own storage and reordered there: the precomputation's
  // peak is the operator (and the body's factor), not the operator twice.
  if (surface->range_axis >= 0) {
    ComputeBandedCompliance(body, surface);
  } else {
    // (Its cost was announced before the factorization: ReportDenseComplianceCost.)
    surface->compliance_m_per_n = BlockedCompliance::FromDenseInPlace(
        static_cast<int>(surface->nodes.size()), [&](double* dense) { body.ComplianceBlockInto(surface->nodes, dense); });
  }
  // Cells of about two face sizes: fine enough that a clamped end's cells get small bounds,
  // coarse enough that the per-step bound costs cells x loaded nodes, not nodes x nodes.
  const auto& mesh = body.mesh();
  const auto n = static_cast<Eigen::Index>(surface->nodes.size());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int node : surface->nodes) {
    lo = lo.cwiseMin(Position(mesh, node));
    hi = hi.cwiseMax(Position(mesh, node));
  }
  const double cell_m = std::max(2.0 * surface->longest_edge_m, 1e-12);
  Eigen::Vector3i cells;
  for (int a = 0; a < 3; ++a) cells[a] = std::max(1, static_cast<int>(std::ceil((hi[a] - lo[a]) / cell_m)));
  surface->num_cells = cells.prod();
  surface->node_cell.resize(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d x = Position(mesh, surface->nodes[static_cast<std::size_t>(i)]);
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a) c[a] = std::min(cells[a] - 1, static_cast<int>((x[a] - lo[a]) / cell_m));
    surface->node_cell[static_cast<std::size_t>(i)] = c[0] + cells[0] * (c[1] + cells[1] * c[2]);
  }
  surface->cell_axis_bound_m_per_n = Eigen::MatrixXd::Zero(3 * surface->num_cells, n);
  const BlockedCompliance& c = surface->compliance_m_per_n;
  for (int j = 0; j < static_cast<int>(n); ++j) {
    for (int i = c.band_begin(j); i < c.band_end(j); ++i) {  // the blocks not stored are zero
      const int cell = surface->node_cell[static_cast<std::size_t>(i)];
      const auto block = c.block(i, j);
      for (int a = 0; a < 3; ++a) {
        double& bound = surface->cell_axis_bound_m_per_n(3 * cell + a, j);
        bound = std::max(bound, block.row(a).norm());
      }
    }
  }
}

// A mesh body's contact groups restrict its candidate faces to those with every corner in them.
bool OnContactSurface(const BodySpec& body, const fem::SurfaceTriangle& triangle) {
  if (body.mesh == nullptr || body.mesh->contact_nodes.empty()) return true;
  const std::vector<int>& nodes = body.mesh->contact_nodes;
  return std::all_of(triangle.corners.begin(), triangle.corners.end(),
                     [&](int corner) { return std::binary_search(nodes.begin(), nodes.end(), corner); });
}

}  // namespace

namespace {
bool AllCornersClamped(const BodySpec& body, const fem::SurfaceTriangle& triangle) {
  if (body.mesh == nullptr) return false;
  const std::vector<int>& nodes = body.mesh->clamped_nodes;
  return std::all_of(triangle.corners.begin(), triangle.corners.end(),
                     [&](int corner) { return std::binary_search(nodes.begin(), nodes.end(), corner); });
}
}  // namespace

struct TwoBodyModel::Parts {
  SceneSpec scene;
  std::vector<fem::SurfaceTriangle> obstacle_faces, tool_faces;
  fem::ElasticBody obstacle, tool;
  int obstacle_faces_in_reach = 0;  // obstacle boundary faces within reach, contact or not
  int obstacle_range_axis = -1;  // banded obstacle compliance: its axis and range, m
  double obstacle_range_m = 0.0;
  bool range_automatic = false;
};

namespace {

constexpr std::size_t kReleaseSchurFactorAboveBytes = std::size_t{512} << 20;

// The memory the operators may take, bytes (nullopt: nothing to judge by), and its source.
// The blocks take 72 n² bytes per surface of n nodes, and each body's factor keeps the Schur
// factor of its surface's dofs (8 m², m <= 3n free dofs) as a dense trailing block beside
// them, so the model needs about twice the blocks (docs/free-interaction.md "Precomputation
// cost").
std::optional<std::size_t> OperatorLimit(std::size_t max_operator_bytes, std::string* source) {
  if (max_operator_bytes != TwoBodyModel::kOperatorsWithinAvailableMemory) {
    *source = "the given limit";
    return max_operator_bytes;
  }
  const std::optional<std::size_t> available = AvailableMemoryBytes();
  if (!available) return std::nullopt;  // let the allocation decide
  *source = "half of the " + std::to_string(*available >> 20) +
            " MiB this machine (or container) has available, as the factors hold as much again";
  return *available / 2;
}

// The axis along which the nodes spread most.
int LongestAxis(const fem::Mesh& mesh, const std::vector<int>& nodes) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int node : nodes) {
    lo = lo.cwiseMin(Position(mesh, node));
    hi = hi.cwiseMax(Position(mesh, node));
  }
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  return axis;
}

// The blocks a banded compliance stores, bytes (72 per node pair within the range).
std::size_t BandedBytes(const fem::Mesh& mesh, std::vector<int> nodes, int axis, double range_m) {
  std::stable_sort(nodes.begin(), nodes.end(),
                   [&](int a, int b) { return mesh.nodes_m(a, axis) < mesh.nodes_m(b, axis); });
  std::vector<int> begin, end;
  RangeBands(mesh, nodes, axis, range_m, &begin, &end);
  std::size_t blocks = 0;
  for (std::size_t j = 0; j < nodes.size(); ++j) blocks += static_cast<std::size_t>(end[j] - begin[j]);
  return sizeof(double) * 9 * blocks;
}

// For a message about the bodies' placement: a hint when a body is larger than a haptic scene
// is (a helper session's tool read in mm as m was refused as "6022 mm deep" with no word on why).
std::string LengthUnitHint(const fem::Mesh& obstacle_mesh, const fem::Mesh& tool_mesh) {
  std::string hint;
  for (const auto& [name, mesh] : {std::pair<const char*, const fem::Mesh*>{"obstacle", &obstacle_mesh},
                                   std::pair<const char*, const fem::Mesh*>{"tool", &tool_mesh}}) {
    const double extent_m = (mesh->nodes_m.colwise().maxCoeff() - mesh->nodes_m.colwise().minCoeff()).maxCoeff();
    if (extent_m > 1.0) {
      std::ostringstream text;
      text << "; the " << name << " is " << extent_m << " m across: if its mesh file is in millimetres, its "
           << "mesh.length_unit_m is 0.001";
      hint += text.str();
    }
  }
  return hint;
}

// A dense compliance of n surface nodes comes from the factor's dense Schur complement of
// order 3n: (3n)^3 / 3 flops and 8 (3n)^2 bytes while the body is factored, then 72 n^2 bytes of
// blocks. 2 000 nodes take seconds; a helper session's cylinder with its whole boundary in
// contact (9 002 nodes) ran for minutes at 8 GB with nothing printed for the first 60 s. Said
// before the factorization starts, with an estimate at the ~20 GFLOP/s measured here (benchmark
// 1's reference: 3 170 nodes in 13 s), so a user can stop and name fewer contact faces.
void ReportDenseComplianceCost(const std::string& name, std::size_t nodes) {
  if (nodes < 2000) return;
  const double order = 3.0 * static_cast<double>(nodes);
  const double seconds = order * order * order / 3.0 / 2e10;
  const double gib = (8.0 * order * order + 72.0 * static_cast<double>(nodes) * static_cast<double>(nodes)) / (1 << 30);
  char line[400];
  std::snprintf(line, sizeof(line),
                "%s compliance: %zu contact surface nodes, dense, from a Schur complement of order %.0f: about "
                "%.0f s and %.1f GiB at 20 GFLOP/s (scales as the cube of the nodes); %s.mesh.contact_groups "
                "naming only the faces a tool can touch makes this shorter",
                name.c_str(), nodes, order, seconds, gib, name.c_str());
  ReportProgress(line);
}

}  // namespace

TwoBodyModel::Parts TwoBodyModel::MakeParts(SceneSpec scene, std::size_t max_operator_bytes) {
  if (!(std::isfinite(scene.reach_m) && scene.reach_m > 0.0)) {
    throw InputError("scene reach_m must be a finite distance > 0 m, got " + std::to_string(scene.reach_m));
  }
  // The candidate faces need only the meshes; finding them before the bodies are factored lets
  // each factor order its candidates' dofs last (one factorization gives both the solves and
  // the compliance block, algorithms.md section 6).
  fem::Mesh obstacle_mesh = BodyMesh(scene.obstacle);
  fem::Mesh tool_mesh = BodyMesh(scene.tool);

  // The obstacle faces the tool can reach: the tool's home box grown by the device workspace.
  const double margin_m = scene.reach_m + scene.activation_gap_m;
  const Eigen::Vector3d reach_min = tool_mesh.nodes_m.colwise().minCoeff().transpose().array() - margin_m;
  const Eigen::Vector3d reach_max = tool_mesh.nodes_m.colwise().maxCoeff().transpose().array() + margin_m;
  std::vector<fem::SurfaceTriangle> reachable;
  int in_reach = 0;
  for (const fem::SurfaceTriangle& triangle : fem::BoundaryTriangles(obstacle_mesh)) {
    Eigen::Vector3d lo = Position(obstacle_mesh, triangle.corners[0]), hi = lo;
    for (int corner : triangle.corners) {
      lo = lo.cwiseMin(Position(obstacle_mesh, corner));
      hi = hi.cwiseMax(Position(obstacle_mesh, corner));
    }
    if ((hi.array() >= reach_min.array()).all() && (lo.array() <= reach_max.array()).all()) {
      if (OnContactSurface(scene.obstacle, triangle)) {
        reachable.push_back(triangle);
        ++in_reach;
      } else if (!AllCornersClamped(scene.obstacle, triangle)) {
        ++in_reach;  // (a clamped face rests on its support: the tool cannot press it)
      }
    }
  }
  if (reachable.empty()) {
    std::ostringstream message;
    message << "no obstacle face is within reach_m = " << scene.reach_m
            << " m of the tool: move the bodies closer or raise contact.reach_m";
    throw InputError(message.str());
  }
  std::vector<fem::SurfaceTriangle> tool_faces;
  for (const fem::SurfaceTriangle& triangle : fem::BoundaryTriangles(tool_mesh)) {
    if (OnContactSurface(scene.tool, triangle)) tool_faces.push_back(triangle);
  }
  if (tool_faces.empty()) {
    throw InputError("the tool's contact groups hold no boundary face of the tool: name a surface group of its boundary");
  }
  std::vector<int> obstacle_candidates = FaceNodes(reachable);
  std::vector<int> tool_candidates = FaceNodes(tool_faces);

  // Refused before either body is factored if the operators cannot be held. A dense obstacle
  // compliance that does not fit is stored banded instead (BlockedCompliance::Banded) when
  // that fits: the pairs within a range of each other, which is all a step reads.
  if (!(std::isfinite(scene.compliance_range_m) && scene.compliance_range_m >= 0.0)) {
    throw InputError("scene compliance_range_m must be a finite distance >= 0 m, got " +
                     std::to_string(scene.compliance_range_m));
  }
  std::string limit_source;
  const std::optional<std::size_t> limit = OperatorLimit(max_operator_bytes, &limit_source);
  const std::size_t obstacle_dense = BlockedCompliance::DenseBytes(obstacle_candidates.size());
  const std::size_t tool_bytes = BlockedCompliance::DenseBytes(tool_candidates.size());
  double range_m = scene.compliance_range_m;
  bool automatic = false;
  if (range_m == 0.0 && limit && obstacle_dense + tool_bytes > *limit) {
    const Eigen::Vector3d tool_extent = tool_mesh.nodes_m.colwise().maxCoeff() - tool_mesh.nodes_m.colwise().minCoeff();
    range_m = kAutomaticRangeToolExtents * tool_extent.maxCoeff();
    automatic = true;
  }
  const int axis = range_m > 0.0 ? LongestAxis(obstacle_mesh, obstacle_candidates) : -1;
  const std::size_t obstacle_bytes =
      range_m > 0.0 ? BandedBytes(obstacle_mesh, obstacle_candidates, axis, range_m) : obstacle_dense;
  if (limit && obstacle_bytes + tool_bytes > *limit) {
    std::ostringstream message;
    message << "the dense compliance of the contact surfaces would need " << (obstacle_dense + tool_bytes) / double(1 << 20)
            << " MiB (" << obstacle_candidates.size() << " obstacle + " << tool_candidates.size()
            << " tool surface nodes, 72·n² bytes each)";
    if (range_m > 0.0) {
      message << ", and stored within a range of " << range_m << " m " << (obstacle_bytes + tool_bytes) / double(1 << 20)
              << " MiB";
    }
    message << ", above " << limit_source << " (" << *limit / double(1 << 20)
            << " MiB): use fewer divisions, a smaller contact.reach_m, Tet4 elements, or a smaller "
               "contact.compliance_range_m";
    throw InputError(message.str());
  }
  // A banded obstacle gets its compliance by solves: its factor keeps CHOLMOD's own order.
  if (range_m > 0.0) obstacle_candidates.clear();
  ReportDenseComplianceCost("obstacle", obstacle_candidates.size());
  ReportDenseComplianceCost("tool", tool_candidates.size());
  fem::ElasticBody obstacle = BuildBody(scene.obstacle, std::move(obstacle_mesh), std::move(obstacle_candidates));
  fem::ElasticBody tool = BuildBody(scene.tool, std::move(tool_mesh), std::move(tool_candidates));
  Parts parts{std::move(scene), std::move(reachable), std::move(tool_faces), std::move(obstacle), std::move(tool)};
  parts.obstacle_faces_in_reach = in_reach;
  parts.obstacle_range_axis = axis;
  parts.obstacle_range_m = range_m;
  parts.range_automatic = automatic;
  return parts;
}

TwoBodyModel::TwoBodyModel(SceneSpec scene, std::size_t max_operator_bytes)
    : TwoBodyModel(MakeParts(std::move(scene), max_operator_bytes)) {}

TwoBodyModel::TwoBodyModel(Parts parts)
    : scene_(std::move(parts.scene)), obstacle_(std::move(parts.obstacle)), tool_(std::move(parts.tool)) {
  Stopwatch total;
  stats_.build_seconds = obstacle_.stats().assembly_seconds + obstacle_.stats().factorization_seconds +
                         tool_.stats().assembly_seconds + tool_.stats().factorization_seconds;
  const fem::Mesh& obstacle_mesh = obstacle_.mesh();
  const fem::Mesh& tool_mesh = tool_.mesh();
  obstacle_thickness_m_ = SmallestExtent(obstacle_mesh);
  tool_thickness_m_ = SmallestExtent(tool_mesh);
  stats_.faces_in_reach = parts.obstacle_faces_in_reach;
  stats_.faces_in_reach_without_contact = parts.obstacle_faces_in_reach - static_cast<int>(parts.obstacle_faces.size());
  obstacle_surface_ = DescribeSurface(obstacle_mesh, std::move(parts.obstacle_faces), scene_.quadratic_face_subtriangles,
                                      parts.obstacle_range_axis);
  obstacle_surface_.range_axis = parts.obstacle_range_axis;
  obstacle_surface_.range_m = parts.obstacle_range_m;
  stats_.range_chosen_automatically = parts.range_automatic;
  tool_surface_ = DescribeSurface(tool_mesh, std::move(parts.tool_faces), scene_.quadratic_face_subtriangles);
  // Reverse-pass slaves: the sharp-edge nodes, or every candidate node (full two-pass).
  for (std::size_t i = 0; i < obstacle_surface_.nodes.size(); ++i) {
    if (scene_.reverse_pass_all_nodes || obstacle_surface_.on_sharp_edge[i]) {
      obstacle_reverse_slaves_.push_back(obstacle_surface_.nodes[i]);
      obstacle_reverse_slave_normals_.push_back(obstacle_surface_.node_normals[i]);
    }
  }

  // A tool that starts inside the obstacle has no meaningful first step: say how deep.
  obstacle_locator_ = TetrahedronLocator(obstacle_mesh);
  // (The whole tool, not only its contact candidates: the box must hold all of it.)
  tool_lo_m_ = tool_mesh.nodes_m.colwise().minCoeff().transpose();
  tool_hi_m_ = tool_mesh.nodes_m.colwise().maxCoeff().transpose();
  {
    ContactDetector detector(obstacle_surface_.triangles, obstacle_mesh.nodes_m, tool_surface_.nodes,
                             tool_surface_.node_normals, obstacle_surface_.subtriangle_faces);
    CollisionParameters probe;
    probe.activation_gap_m = scene_.reach_m;
    probe.max_penetration_m = 0.45 * obstacle_thickness_m_;
    std::vector<ContactPoint> contacts;
    detector.Detect(obstacle_mesh.nodes_m, tool_mesh.nodes_m, probe, &contacts);
    initial_gap_m_ = std::numeric_limits<double>::infinity();
    const ContactPoint* deepest = nullptr;
    for (const ContactPoint& c : contacts) {
      if (c.gap_m < initial_gap_m_) {
        initial_gap_m_ = c.gap_m;
        deepest = &c;
      }
    }
    // The press direction of a session's approach (TwoBodySession::Step): the mean outward
    // normal of the obstacle faces nearest the tool at the start.
    for (const ContactPoint& c : contacts) {
      if (c.gap_m <= initial_gap_m_ + 1e-6) approach_normal_ += c.frame.row(0).transpose();
    }
    if (approach_normal_.norm() > 0) approach_normal_.normalize();
    const double tolerance_m = 1e-9 * (obstacle_thickness_m_ + tool_thickness_m_);
    if (deepest != nullptr && initial_gap_m_ < -tolerance_m) {
      const Eigen::Vector3d x = Position(tool_mesh, deepest->tool_node);
      std::ostringstream message;
      message << "the tool starts inside the obstacle: tool node " << deepest->tool_node << " at ("
              << x.x() << ", " << x.y() << ", " << x.z() << ") m is " << -initial_gap_m_ * 1e3
              << " mm deep; move the tool (its box, or its mesh's offset_m) so the bodies touch at most (zero gap)"
              << LengthUnitHint(obstacle_mesh, tool_mesh);
      throw InputError(message.str());
    }
    // Deeper than detection reaches, or wholly inside: a node of one body inside the other's
    // volume. Shallower than 5 % of the thinner body it is left to the test above: a quadratic
    // face's curved boundary lies off its straight corner faces by up to a few per cent of
    // the curvature radius, which this test would take for an overlap.
    const double deep_m = 0.05 * std::min(obstacle_thickness_m_, tool_thickness_m_);
    const NodeInside tool_node = DeepestNodeInside(obstacle_locator_, obstacle_mesh, tool_mesh);
    const NodeInside obstacle_node = DeepestNodeInside(TetrahedronLocator(tool_mesh), tool_mesh, obstacle_mesh);
    const bool tool_deeper = tool_node.depth_m >= obstacle_node.depth_m;
    const NodeInside& node = tool_deeper ? tool_node : obstacle_node;
    if (node.node >= 0 && node.depth_m > deep_m) {
      const Eigen::Vector3d x = Position(tool_deeper ? tool_mesh : obstacle_mesh, node.node);
      std::ostringstream message;
      message << "the tool starts inside the obstacle: " << (tool_deeper ? "tool" : "obstacle") << " node " << node.node
              << " at (" << x.x() << ", " << x.y() << ", " << x.z() << ") m is " << node.depth_m * 1e3 << " mm inside the "
              << (tool_deeper ? "obstacle" : "tool") << "; move the tool (its box, or its mesh's offset_m) so the bodies touch at most (zero gap)"
              << LengthUnitHint(obstacle_mesh, tool_mesh);
      throw InputError(message.str());
    }
  }

  Stopwatch compliance;
  ComputeCompliance(obstacle_, &obstacle_surface_);
  ComputeCompliance(tool_, &tool_surface_);
  stats_.compliance_seconds = compliance.ElapsedSeconds();
  // A large surface's dense Schur factor stays in its body's factor as large as its compliance
  // blocks, for nothing the step needs: factor once more without it (ElasticBody::
  // ReleaseComplianceOrder). Smaller ones are kept: there the refactorization would cost more
  // time than the memory is worth (the shipped scenes' are 0.3-250 MiB, and their
  // precomputation is mostly the factorization).
  for (fem::ElasticBody* body : {&obstacle_, &tool_}) {
    if (body->stats().schur_factor_bytes > kReleaseSchurFactorAboveBytes) body->ReleaseComplianceOrder();
  }
  rigid_contact_compliance_m_per_n_ = std::numeric_limits<double>::infinity();
  for (const ContactSurface* surface : {&obstacle_surface_, &tool_surface_}) {
    const BlockedCompliance& c = surface->compliance_m_per_n;
    for (int i = 0; i < c.nodes(); ++i) {
      for (int a = 0; a < 3; ++a) {
        const double diagonal = c.block(i, i)(a, a);
        if (diagonal > 0.0) rigid_contact_compliance_m_per_n_ = std::min(rigid_contact_compliance_m_per_n_, diagonal);
      }
    }
  }
  if (!std::isfinite(rigid_contact_compliance_m_per_n_)) {
    throw InputError("neither body has a free surface node: every surface node is clamped or driven");
  }

  const Eigen::MatrixXd& fields = tool_.unit_driven_translation_fields();
  const auto& tool_nodes = tool_surface_.nodes;
  tool_unit_fields_.resize(3 * static_cast<Eigen::Index>(tool_nodes.size()), 3);
  for (int i = 0; i < static_cast<int>(tool_nodes.size()); ++i) {
    tool_unit_fields_.middleRows(3 * i, 3) = fields.middleRows(3 * tool_nodes[static_cast<std::size_t>(i)], 3);
  }
  stats_.operator_bytes = obstacle_surface_.compliance_m_per_n.bytes() + tool_surface_.compliance_m_per_n.bytes() +
                          sizeof(double) * static_cast<std::size_t>(tool_unit_fields_.size());
  stats_.total_seconds = stats_.build_seconds + total.ElapsedSeconds();
}

bool TwoBodyModel::ToolInsideObstacle(const Eigen::Vector3d& device_translation_m) const {
  const fem::Mesh& tool_mesh = tool_.mesh();
  // Touching is not inside: a node within 1 % of the obstacle's thickness of one of its
  // contact faces is left to detection. (On a tetrahedron's face or corner counts as in it:
  // with matching grids the tool's nodes lie on the obstacle's internal faces.)
  const Eigen::Vector3d touching = Eigen::Vector3d::Constant(0.01 * obstacle_thickness_m_);
  std::vector<int> hits, stack;
  for (int node : tool_surface_.nodes) {
    const Eigen::Vector3d x = Position(tool_mesh, node) + device_translation_m;
    if (!obstacle_locator_.Contains(x)) continue;
    hits.clear();
    obstacle_surface_.triangle_tree.Overlapping(x - touching, x + touching, &hits, &stack);
    if (hits.empty()) return true;
  }
  return false;
}

bool TwoBodyModel::RigidToolClearOfObstacle(const Eigen::Vector3d& device_translation_m) const {
  const Eigen::Vector3d lo = tool_lo_m_ + device_translation_m, hi = tool_hi_m_ + device_translation_m;
  if (obstacle_surface_.triangle_tree.AnyOverlapping(lo, hi)) return false;
  // No face near: wholly outside, or wholly inside (one node tells: a tree query, and only
  // inside the obstacle's box).
  return tool_surface_.nodes.empty() ||
         !obstacle_locator_.Contains(Position(tool_.mesh(), tool_surface_.nodes.front()) + device_translation_m);
}

std::string StartingPositionNote(const TwoBodyModel& model) {
  if (!std::isfinite(model.initial_gap_m())) {
    return "no tool node faces the obstacle at the start: the device must travel before any force";
  }
  if (model.initial_gap_m() <= model.scene().activation_gap_m) return "";
  std::ostringstream note;
  note << "the tool starts " << model.initial_gap_m() * 1e3
       << " mm from the obstacle: no force until the device has travelled that far";
  return note.str();
}

std::string ReachNote(const TwoBodyModel& model, double device_reach_m, const std::string& what) {
  const double reach_m = model.scene().reach_m;
  if (!(device_reach_m > reach_m)) return "";
  std::ostringstream note;
  note << "the device may move " << device_reach_m * 1e3 << " mm from its start (" << what << "), beyond the scene's "
       << "contact.reach_m = " << reach_m * 1e3 << " mm: obstacle faces farther than that from the tool's start are "
       << "no contact candidates, and the tool passes through them there; raise contact.reach_m to at least "
       << device_reach_m << " m";
  return note.str();
}

std::string ContactGroupsNote(const TwoBodyModel& model) {
  const TwoBodyModelStats& stats = model.stats();
  if (stats.faces_in_reach_without_contact <= 0) return "";
  const auto& surface = model.obstacle_surface();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const fem::SurfaceTriangle& t : surface.triangles) {
    for (int corner : t.corners) {
      lo = lo.cwiseMin(Position(model.obstacle().mesh(), corner));
      hi = hi.cwiseMax(Position(model.obstacle().mesh(), corner));
    }
  }
  std::ostringstream note;
  note << "obstacle.mesh.contact_groups leave " << stats.faces_in_reach_without_contact << " of the obstacle's "
       << stats.faces_in_reach << " boundary faces within reach without contact: a tool pressed there passes "
       << "through them with no force. The contact faces lie within x " << lo.x() * 1e3 << ".." << hi.x() * 1e3
       << ", y " << lo.y() * 1e3 << ".." << hi.y() * 1e3 << ", z " << lo.z() * 1e3 << ".." << hi.z() * 1e3
       << " mm (name more groups in contact_groups, or leave it out for the whole boundary)";
  return note.str();
}

std::string RigidBodyNote(const TwoBodyModel& model) {
  std::string note;
  for (const auto& [name, body, held] : {std::tuple<const char*, const fem::ElasticBody*, const char*>{
                                             "obstacle", &model.obstacle(), "clamped"},
                                         std::tuple<const char*, const fem::ElasticBody*, const char*>{
                                             "tool", &model.tool(), "driven"}}) {
    if (body->num_free_dofs() > 0) continue;
    char text[320];
    std::snprintf(text, sizeof(text),
                  "%severy node of the %s (%d) is %s: it is rigid, and only the other body deforms (if a group "
                  "names its volume, name the surface to hold instead)",
                  note.empty() ? "" : "; ", name, body->mesh().num_nodes(), held);
    note += text;
  }
  return note;
}

std::string LockingNote(const TwoBodyModel& model) {
  std::string note;
  for (const auto& [name, body] : {std::pair<const char*, const BodySpec*>{"obstacle", &model.scene().obstacle},
                                   std::pair<const char*, const BodySpec*>{"tool", &model.scene().tool}}) {
    if (body->box.order != fem::ElementOrder::kTet4 || body->material.poisson_ratio <= 0.45) continue;
    char text[320];
    std::snprintf(text, sizeof(text),
                  "%sthe %s has Tet4 elements and Poisson's ratio %.6g: linear tetrahedra lock when nearly "
                  "incompressible and come out far too stiff (set its element_order: TET10)",
                  note.empty() ? "" : "; ", name, body->material.poisson_ratio);
    note += text;
  }
  return note;
}

}  // namespace hapco::sim
