#include "sim/box_tree.h"

#include <algorithm>
#include <limits>

#include "common/error.h"

namespace hapco::sim {
namespace {
constexpr int kLeafSize = 4;
}  // namespace

StaticBoxTree::StaticBoxTree(const std::vector<Eigen::Vector3d>& min_m, const std::vector<Eigen::Vector3d>& max_m)
    : box_min_m_(min_m), box_max_m_(max_m) {
  HAPCO_ASSERT(min_m.size() == max_m.size(), "StaticBoxTree: one min and one max per box");
  order_.resize(min_m.size());
  for (std::size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  if (!order_.empty()) depth_ = Build(0, static_cast<int>(order_.size()), 1);
  HAPCO_ASSERT(depth_ <= kMaxDepth, "StaticBoxTree: deeper than AnyContaining's stack");
}

int StaticBoxTree::Build(int begin, int end, int depth) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (int k = begin; k < end; ++k) {
    const auto id = static_cast<std::size_t>(order_[static_cast<std::size_t>(k)]);
    lo = lo.cwiseMin(box_min_m_[id]);
    hi = hi.cwiseMax(box_max_m_[id]);
  }
  nodes_[static_cast<std::size_t>(index)].min_m = lo;
  nodes_[static_cast<std::size_t>(index)].max_m = hi;
  if (end - begin <= kLeafSize) {
    nodes_[static_cast<std::size_t>(index)].first = begin;
    nodes_[static_cast<std::size_t>(index)].count = end - begin;
    return depth;
  }
  // Median split of the box centres along the longest axis of the node (ties by id, so the
  // tree does not depend on the sort implementation).
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  const int mid = begin + (end - begin) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end, [&](int l, int r) {
    const double cl = box_min_m_[static_cast<std::size_t>(l)][axis] + box_max_m_[static_cast<std::size_t>(l)][axis];
    const double cr = box_min_m_[static_cast<std::size_t>(r)][axis] + box_max_m_[static_cast<std::size_t>(r)][axis];
    return cl < cr || (cl == cr && l < r);
  });
  const int left_depth = Build(begin, mid, depth + 1);
  nodes_[static_cast<std::size_t>(index)].right = static_cast<int>(nodes_.size());
  const int right_depth = Build(mid, end, depth + 1);
  return std::max(left_depth, right_depth);
}

void StaticBoxTree::Overlapping(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, std::vector<int>* hits,
                                std::vector<int>* stack) const {
  if (nodes_.empty()) return;
  const auto overlaps = [&](const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) {
    return (min_m.array() <= hi.array()).all() && (max_m.array() >= lo.array()).all();
  };
  stack->clear();
  stack->push_back(0);
  while (!stack->empty()) {
    const Node& node = nodes_[static_cast<std::size_t>(stack->back())];
    const int self = stack->back();
    stack->pop_back();
    if (!overlaps(node.min_m, node.max_m)) continue;
    if (node.count > 0) {
      for (int k = node.first; k < node.first + node.count; ++k) {
        const int id = order_[static_cast<std::size_t>(k)];
        if (overlaps(box_min_m_[static_cast<std::size_t>(id)], box_max_m_[static_cast<std::size_t>(id)])) {
          hits->push_back(id);
        }
      }
    } else {
      stack->push_back(node.right);
      stack->push_back(self + 1);
    }
  }
}

}  // namespace hapco::sim
