#pragma once

#include <array>
#include <vector>

#include <Eigen/Dense>

namespace hapco::sim {

// A bounding-volume tree over fixed axis-aligned boxes, built once: which boxes overlap a
// query box, in O(log n + hits) instead of a pass over all n. The step's broad phase asks it
// for the faces near the tool (TwoBodySession::BroadPhase), so that the step's cost follows
// the tool's neighbourhood and not the surface's size (issue 11, item 5).
class StaticBoxTree {
 public:
  StaticBoxTree() = default;
  // Box i is [min_m[i], max_m[i]] (m; a point when min = max). Both vectors have one entry
  // per box.
  StaticBoxTree(const std::vector<Eigen::Vector3d>& min_m, const std::vector<Eigen::Vector3d>& max_m);

  int size() const { return static_cast<int>(box_min_m_.size()); }
  // Deepest root-to-leaf path (nodes): a traversal stack never holds more than this.
  int depth() const { return depth_; }

  // Appends to *hits the ids of the boxes that overlap [lo, hi] (closed: touching counts), in
  // no particular order. *stack is scratch; reserve depth() + 1 entries for an
  // allocation-free call.
  void Overlapping(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::vector<int>* hits,
                   std::vector<int>* stack) const;
  // Calls visit(id) for the boxes that overlap [lo, hi] (closed) until it returns true; true
  // if one did. No scratch, no allocation, safe from several threads at once (a stack on the
  // call's frame; trees deeper than kMaxDepth are not built: the median split of n boxes is
  // about log2(n) deep).
  template <typename Visit>
  bool AnyOverlapping(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, Visit visit) const {
    if (nodes_.empty()) return false;
    std::array<int, kMaxDepth + 2> stack{};
    int top = 0;
    stack[static_cast<std::size_t>(top++)] = 0;
    auto overlaps = [&lo, &hi](const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) {
      return (min_m.array() <= hi.array()).all() && (max_m.array() >= lo.array()).all();
    };
    while (top > 0) {
      const int self = stack[static_cast<std::size_t>(--top)];
      const Node& node = nodes_[static_cast<std::size_t>(self)];
      if (!overlaps(node.min_m, node.max_m)) continue;
      if (node.count == 0) {
        stack[static_cast<std::size_t>(top++)] = node.right;
        stack[static_cast<std::size_t>(top++)] = self + 1;
        continue;
      }
      for (int k = node.first; k < node.first + node.count; ++k) {
        const int id = order_[static_cast<std::size_t>(k)];
        if (overlaps(box_min_m_[static_cast<std::size_t>(id)], box_max_m_[static_cast<std::size_t>(id)]) && visit(id)) {
          return true;
        }
      }
    }
    return false;
  }
  // Whether any box overlaps [lo, hi] (closed), stopping at the first found.
  bool AnyOverlapping(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
    return AnyOverlapping(lo, hi, [](int) { return true; });
  }
  // The same for the boxes that contain the point x (closed).
  template <typename Visit>
  bool AnyContaining(const Eigen::Vector3d& x, Visit visit) const {
    return AnyOverlapping(x, x, visit);
  }
  static constexpr int kMaxDepth = 60;

 private:
  // Leaves hold order_[first, first + count); an internal node (count == 0) has its left
  // child right after it and its right child at `right`.
  struct Node {
    Eigen::Vector3d min_m, max_m;
    int first = 0, count = 0, right = -1;
  };
  int Build(int begin, int end, int depth);

  std::vector<Eigen::Vector3d> box_min_m_, box_max_m_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
  int depth_ = 0;
};

}  // namespace hapco::sim
