#pragma once
// Collision detection between the tool (the paper's green body) and the obstacle (red body):
// node-to-surface pairs between candidate tool nodes and obstacle boundary triangles, with the
// contact frame of algorithms.md §2 (n points from the red surface towards the green body,
// local vectors ordered [n, t1, t2], u_n >= 0 separated).
//
// A face is searched as the flat triangle through its three corner nodes, also for Tet10
// faces: the projection (barycentric coordinates) and the frame come from that flat triangle.
// For a Tet10 face the weights that spread the obstacle point onto its six nodes are the
// quadratic 6-node triangle shape functions at those barycentric coordinates, and the point
// and the gap are those of the quadratic surface there (Σ N_i x_i), which is what the solver
// constrains (the problem's gap is n·(x_tool − Σ N_i x_i), step_pipeline.cc). Measured to the
// flat triangle instead, a pair the solver had closed could read past the activation gap once
// the load dimpled the face: a held pose then cycled 24 / 25 contacts for ever
// (docs/free-interaction.md, "Gap to the quadratic surface"). While a face's midside nodes
// stay at their edge midpoints (straight edges) both points coincide; on a curved (deformed)
// Tet10 face they differ by the order of the face curvature times the squared face size.
// Where the projection itself goes wrong (a tool smaller than the faces presses a dimple into
// one face, and the node's projection jumps between faces), the caller searches each 6-node
// face as its four flat sub-triangles through the midside nodes (FourSubtriangles) and gives
// the detector each sub-triangle's face: the gap and the closest point then come from the
// sub-triangle, and the weights stay the face's quadratic ones at the face's parametric point
// (docs/free-interaction.md, "Quadratic faces").
//
// Search cost: an AABB tree over the obstacle triangles is built once (topology) and refitted
// on every Detect (the obstacle deforms). The refit is linear in the triangles given to the
// detector (pass only the faces that can ever be touched); each query visits O(log n) boxes
// and tests only the few triangles whose inflated box holds the node.
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "fem/mesh.h"

namespace hapco::sim {

using PointsRef = Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, 3>>;

// One of the four flat sub-triangles of a 6-node face (corners c, midsides m, m_k on edge
// (c_k, c_k+1)): which = k < 3 is (c_k, m_k, m_k-1), the one at corner k; which = 3 is
// (m_0, m_1, m_2). Each has the face's orientation.
struct SubtriangleOfFace {
  fem::SurfaceTriangle face;  // the 6-node face
  int which = 0;              // 0..3
};

// The four sub-triangles of a 6-node face, in the order of SubtriangleOfFace::which; they
// carry no midsides (each is searched as a flat 3-node face).
std::array<fem::SurfaceTriangle, 4> FourSubtriangles(const fem::SurfaceTriangle& face);

// Every 6-node face as its four sub-triangles, with the face each one belongs to: the
// triangles and subtriangle_faces a ContactDetector searches.
struct SubtriangleSplit {
  std::vector<fem::SurfaceTriangle> triangles;
  std::vector<SubtriangleOfFace> faces;  // one per triangle
};
SubtriangleSplit SplitIntoSubtriangles(const std::vector<fem::SurfaceTriangle>& faces);

// The face's barycentric (parametric) coordinates of the point with barycentric coordinates
// `sub_barycentric` in its sub-triangle `which` (the map is affine on each sub-triangle).
Eigen::Vector3d FaceBarycentricOfSubtriangle(int which, const Eigen::Vector3d& sub_barycentric);

// One active contact: a tool node facing a point on an obstacle surface triangle.
struct ContactPoint {
  int tool_node = -1;          // node id in the tool mesh
  int node_slot = -1;          // position of tool_node in the detector's node list
  int obstacle_triangle = -1;  // index into the detector's obstacle triangle list
  // Barycentric coordinates of obstacle_point_m in the flat face (corners 0, 1, 2); for a
  // sub-triangle (SubtriangleOfFace), in the sub-triangle.
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();
  // Nodes carrying the obstacle side: 3 corners (Tet4 face) or 3 corners then the midsides on
  // edges (c0,c1) (c1,c2) (c2,c0) (Tet10 face); unused entries are -1 with weight 0.
  std::array<int, 6> obstacle_nodes{};
  // Shape-function weights of the obstacle point (sum to 1), dimensionless.
  std::array<double, 6> weights{};
  int num_obstacle_nodes = 0;  // 3 or 6
  // Rows n, t1, t2 in world axes: n is the outward normal of the obstacle face (towards the
  // tool); t1 = normalized e_x minus its normal part (e_y when n is near ±e_x), t2 = n × t1,
  // so t1 × t2 = n (right-handed, deterministic from n).
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();
  Eigen::Vector3d obstacle_point_m = Eigen::Vector3d::Zero();  // closest point on the face, m
  // Signed normal gap (tool node − obstacle point)·n, m: >= 0 separated, < 0 penetrating.
  double gap_m = 0.0;
};

struct CollisionParameters {
  // A pair is active when gap < activation_gap_m, m (>= 0).
  double activation_gap_m = 5e-4;
  // Pairs deeper than this are ignored (a node that far behind a face is on the wrong side,
  // e.g. facing the opposite face of the obstacle), m (>= 0). Keep it below half the
  // obstacle's thickness.
  double max_penetration_m = 1e-3;
  // Barycentric slack, dimensionless: a node whose normal projection lies within this of a
  // face's edges counts as inside it, so a node exactly on an edge or vertex is found despite
  // round-off (and is then assigned to one face only, see ContactDetector).
  double edge_tolerance = 1e-9;
  // Normal compatibility, dimensionless: with tool normals given, a face qualifies only when
  // −n_face·n_tool >= this, both reference normals (0.5: the face normal within 60° of the
  // reversed tool normal).
  // It keeps a tool node lying on an obstacle edge on the face it rests on, not on the side.
  double min_normal_opposition = 0.5;
  // Persistence, dimensionless cosine: a node whose contact of the previous step was on face
  // F (DetectionContext::previous_triangle) keeps a face whose normal is within this of F's
  // (0.7071: 45°), at any depth, before any other face is considered. Without it a node
  // pressed below an obstacle edge could be matched to the side face it is nearest to.
  double persistence_min_cosine = 0.7071067811865476;
  // Barycentric slack for the persistent faces, dimensionless: deformed faces fold at their
  // shared edges, so a node on such an edge can project just outside both (measured: 1e-5);
  // 0.05 keeps it on them (the closest point of the face is used).
  double persistent_edge_tolerance = 0.05;
};

// Optional per-call inputs of Detect.
struct DetectionContext {
  // Per tool node (tool_nodes order): the obstacle triangle of its contact in the previous
  // step, or -1. That face and the faces sharing a corner with it are tested at any depth.
  const std::vector<int>* previous_triangle = nullptr;
  // Per obstacle triangle / per tool node: 0 skips it (faces whose nodes have stale
  // positions, nodes out of the broad phase's region). nullptr: everything is enabled.
  const std::vector<char>* triangle_enabled = nullptr;
  const std::vector<char>* node_enabled = nullptr;
  // Optional, with triangle_enabled: the ids of the enabled triangles (any order, each once).
  // Then only their boxes and the tree nodes above them are refitted, so the detector's cost
  // follows the faces near the tool and not the surface's size.
  const std::vector<int>* enabled_triangles = nullptr;
  // Optional, per obstacle triangle: how far the face's own deformation moved it outwards
  // along its reference normal since the last detection, m (>= 0). The caller's bound on a
  // new contact's depth (max_penetration_m) covers the device's travel; a pair on a face that
  // rose by δ may be up to 2δ deeper: a face springs back up under a node once the load that
  // pressed it down lets go. Only for a node over the face's undeformed triangle (a deformed
  // face can tilt far enough to reach under a node beyond the body). The tree's boxes grow by
  // the largest allowance.
  const std::vector<double>* triangle_rise_m = nullptr;
};

// Work counters of the last Detect call, for tests and benchmarks.
struct DetectorStats {
  std::int64_t queries = 0;             // tool nodes searched
  std::int64_t triangles_tested = 0;    // exact point-triangle tests
  std::int64_t bvh_nodes_visited = 0;   // boxes tested (0 for the brute-force path)
  std::int64_t triangles_total = 0;     // obstacle triangles in the detector
};

class ContactDetector {
 public:
  // obstacle_triangles: the obstacle's boundary faces (fem::BoundaryTriangles, possibly
  // filtered to the faces that can ever be touched), outward right-hand normals.
  // obstacle_reference_positions_m: the obstacle's nodes (N_o x 3) in the reference
  // configuration; they shape the tree topology, later calls only refit the boxes.
  // tool_nodes: candidate tool node ids (the tool's boundary). The reverse pass of the step
  // pipeline uses a second detector with the roles swapped: obstacle edge nodes as the
  // "tool" nodes, the tool's boundary faces as the "obstacle" triangles.
  // tool_normals: outward unit normal of the tool's candidate surface at each tool node
  // (reference configuration, see CandidateNodeNormals), or empty to skip the normal check.
  // Throws InputError for an empty triangle list, node ids out of range, a degenerate face,
  // a face with only some midsides, negative tool node ids, or a normal count / length that
  // does not match.
  // subtriangle_faces: empty, or one per obstacle triangle when the triangles are the
  // sub-triangles of 6-node faces (FourSubtriangles): a contact then carries that face's six
  // nodes and quadratic weights. Throws InputError when its size does not match or an entry
  // is not the sub-triangle it claims to be.
  ContactDetector(std::vector<fem::SurfaceTriangle> obstacle_triangles,
                  const PointsRef& obstacle_reference_positions_m, std::vector<int> tool_nodes,
                  std::vector<Eigen::Vector3d> tool_normals = {},
                  std::vector<SubtriangleOfFace> subtriangle_faces = {});

  // Current (deformed) node positions: obstacle N_o x 3, tool N_t x 3 (reference +
  // displacement), m. Only the nodes of the given triangles (corners and midsides) and the
  // candidate tool nodes are read, so rows of other nodes may be stale. Fills *contacts (cleared first, in tool_nodes order). For each tool
  // node: among faces whose flat normal projection holds the node (within edge_tolerance),
  // that pass the normal check, with -max_penetration <= gap < activation_gap, the one with
  // the smallest |gap|; ties within round-off (a node on an edge shared by coplanar faces) go
  // to the lowest triangle index, so every node gives at most one contact. A node whose
  // projection misses every face (beyond a convex edge, outside the footprint) has none.
  // Allocation-free once *contacts has capacity for all tool nodes (reserve it, or reuse).
  // Throws InputError for position arrays too short or invalid parameters.
  // With a context: nodes and faces disabled there are skipped; a node with a previous
  // triangle also tests that face and its corner neighbours with no depth limit and prefers,
  // among all faces that qualify, those within persistence_min_cosine of the previous face's
  // normal (reference normals); without history the rules above apply unchanged. With
  // triangle rises, a face that rose by δ accepts gaps down to -(max_penetration + 2δ), the
  // part beyond max_penetration only for a node over the face's undeformed triangle.
  void Detect(const PointsRef& obstacle_positions_m, const PointsRef& tool_positions_m,
              const CollisionParameters& parameters, std::vector<ContactPoint>* contacts,
              const DetectionContext& context = {});

  // Same rules, every triangle tested for every node: the reference for tests/benchmarks.
  void DetectBruteForce(const PointsRef& obstacle_positions_m, const PointsRef& tool_positions_m,
                        const CollisionParameters& parameters,
                        std::vector<ContactPoint>* contacts);

  const DetectorStats& last_stats() const { return stats_; }
  const std::vector<fem::SurfaceTriangle>& obstacle_triangles() const { return triangles_; }
  const std::vector<int>& tool_nodes() const { return tool_nodes_; }
  // Outward unit normal of each obstacle triangle in the reference configuration: what the
  // normal-compatibility test (CollisionParameters::min_normal_opposition) reads.
  const std::vector<Eigen::Vector3d>& reference_normals() const { return reference_normals_; }
  int bvh_node_count() const { return static_cast<int>(nodes_.size()); }

 private:
  struct Box {
    Eigen::Vector3d min = Eigen::Vector3d::Zero();
    Eigen::Vector3d max = Eigen::Vector3d::Zero();
  };
  // Leaves hold order_[first, first + count); an internal node (count == 0) has its left
  // child right after it and its right child at `right`. Children follow their parent.
  struct BvhNode {
    Box box;
    int first = 0;
    int count = 0;
    int right = -1;
  };
  struct Candidate {
    int triangle = -1;
    double gap_m = 0.0;
    Eigen::Vector3d point_m = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();
    bool persistent = false;  // within the persistence cone of the node's previous face
    double outside = 0.0;     // how far the projection lies outside the face (barycentric, >= 0)
    double max_depth_m = 0.0;  // deepest gap this pair may have as a new contact, m
  };

  // A face's geometry in the current positions, computed once per Detect, on the face's first
  // test: a face is tested by every tool node near it (about ten per step), and its normal and
  // the dot products of ProjectionBarycentric were most of each test.
  struct FaceGeometry {
    Eigen::Vector3d a = Eigen::Vector3d::Zero();   // corner 0, m
    Eigen::Vector3d ab = Eigen::Vector3d::Zero();  // corner 1 − corner 0, m
    Eigen::Vector3d ac = Eigen::Vector3d::Zero();  // corner 2 − corner 0, m
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // unit, outward
    double d00 = 0.0, d01 = 0.0, d11 = 0.0, denom = 0.0;  // ab·ab, ab·ac, ac·ac, d00 d11 − d01², m², m⁴
    bool valid = false;  // false: collapsed or non-finite (no normal)
    // 6-node faces: midside k's offset from the midpoint of its edge (c_k, c_k+1), m, and a
    // bound on how far the quadratic surface lies from the flat triangle along the normal,
    // (4/3) max_k |n·offset_k|, m (Σ_k 4 l_k l_k+1 <= 4/3). Zero for 3-node faces.
    std::array<Eigen::Vector3d, 3> midside_offset_m{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                                    Eigen::Vector3d::Zero()};
    double bulge_m = 0.0;
    bool quadratic = false;
  };

  int BuildNode(const std::vector<Eigen::Vector3d>& centroids, int begin, int end, int depth);
  void UpdateFaceGeometry(const PointsRef& obstacle_positions_m, int triangle);
  void ValidateCall(const PointsRef& obstacle_positions_m, const PointsRef& tool_positions_m,
                    const CollisionParameters& parameters) const;
  void Refit(const PointsRef& obstacle_positions_m, const CollisionParameters& parameters,
             const std::vector<char>* triangle_enabled);
  // The same boxes, computed for the enabled triangles and the nodes above them only; every
  // other box is empty (kept so between calls: refit_empty_elsewhere_).
  void RefitEnabled(const PointsRef& obstacle_positions_m, const CollisionParameters& parameters,
                    const std::vector<int>& enabled_triangles);
  Box InflatedBox(const PointsRef& obstacle_positions_m, const CollisionParameters& parameters, int triangle) const;
  // A node's box from its triangles' (leaf) or children's (internal) boxes.
  void FitNode(int index);
  // Exact test of one triangle; appends to candidates_ when the pair qualifies.
  // max_depth_m: deepest gap accepted; previous_normal: unit normal of the node's previous
  // face (zero without history).
  void TestTriangle(int triangle, const Eigen::Vector3d& x, int tool_index,
                    const PointsRef& obstacle_positions_m, const CollisionParameters& parameters,
                    double max_depth_m, double edge_tolerance, const Eigen::Vector3d& previous_normal);
  // Picks the winner among candidates_ and appends the contact.
  void Select(int tool_index, const CollisionParameters& parameters,
              std::vector<ContactPoint>* contacts) const;

  std::vector<fem::SurfaceTriangle> triangles_;
  std::vector<SubtriangleOfFace> subtriangle_faces_;  // empty, or one per triangle
  std::vector<int> tool_nodes_;
  std::vector<Eigen::Vector3d> tool_normals_;
  int num_obstacle_nodes_ = 0;
  int max_tool_node_ = -1;
  double tie_tolerance_m_ = 0.0;  // |gap| differences below this are ties (round-off)

  std::vector<int> order_;          // triangle ids in leaf order
  std::vector<BvhNode> nodes_;      // nodes_[0] is the root
  std::vector<Box> triangle_boxes_;  // per order_ slot, inflated by the search margin
  // For RefitEnabled: each triangle's slot in order_, each slot's leaf, each node's parent
  // (-1 at the root) and depth; the slots and nodes it made non-empty, nodes bucketed by depth
  // (deepest refitted first, so children come before their parents).
  std::vector<int> slot_of_triangle_, leaf_of_slot_, parent_, node_depth_;
  std::vector<int> refitted_slots_, refitted_nodes_;
  std::vector<std::vector<int>> nodes_by_depth_;
  std::vector<char> node_refitted_;
  bool refit_empty_elsewhere_ = false;  // every box outside refitted_* is empty
  std::vector<int> stack_;          // traversal stack, sized once
  std::vector<Candidate> candidates_;  // per-query scratch, capacity reused
  const std::vector<double>* triangle_rise_m_ = nullptr;  // Detect's context, during the call
  // Faces sharing a corner with each face (itself included): CSR offsets and ids.
  std::vector<int> neighbour_offsets_, neighbours_;
  std::vector<Eigen::Vector3d> reference_normals_;  // per face, reference configuration
  std::vector<std::array<Eigen::Vector3d, 3>> reference_corners_m_;  // per face, reference configuration, m
  std::vector<FaceGeometry> face_geometry_;         // per face, current positions
  std::vector<std::uint64_t> face_geometry_call_;   // per face: the Detect call it is from
  std::uint64_t detect_call_ = 0;                   // Detect/DetectBruteForce calls so far
  DetectorStats stats_;
};

// Barycentric coordinates (of a, b, c) of the point of triangle abc closest to p.
Eigen::Vector3d ClosestPointBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                        const Eigen::Vector3d& c);

// Barycentric coordinates (of a, b, c) of the normal projection of p onto the plane of abc.
Eigen::Vector3d ProjectionBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                      const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// Contact frame for a unit normal n: rows n, t1, t2 (algorithms.md §2); t1 is e_x minus its
// normal part (e_y when n is close to ±e_x), t2 = n × t1.
Eigen::Matrix3d FrameFromNormal(const Eigen::Vector3d& n);

// Outward unit normal at each of `nodes`: the area-weighted mean of the normals of the
// triangles of `surface` whose three corners all belong to `nodes` (the candidate patch
// itself, so a node on the patch's rim is not tilted by the adjacent side face). Throws
// InputError for a node that touches no such triangle.
std::vector<Eigen::Vector3d> CandidateNodeNormals(const fem::Mesh& mesh,
                                                  const std::vector<fem::SurfaceTriangle>& surface,
                                                  const std::vector<int>& nodes);

}  // namespace hapco::sim
