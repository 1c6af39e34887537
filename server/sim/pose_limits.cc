#include "sim/pose_limits.h"

#include <algorithm>

namespace hapco::sim {
namespace {

// A lost pose legitimately allows a longer move: the jump limit scales with the sequence gap,
// up to this (else a pose with a huge sequence number could move anywhere).
constexpr std::uint64_t kMaxJumpScale = 10;

}  // namespace

const char* VerdictName(PoseVerdict verdict) {
  switch (verdict) {
    case PoseVerdict::kAccept: return "accepted";
    case PoseVerdict::kNonFinite: return "non-finite pose";
    case PoseVerdict::kOutOfWorkspace: return "pose out of workspace";
    case PoseVerdict::kJump: return "position jump";
    case PoseVerdict::kOutOfOrder: return "out-of-order sequence";
    case PoseVerdict::kDuplicate: return "repeated sequence";
    case PoseVerdict::kFlood: return "pose flood";
  }
  return "?";
}

PoseVerdict CheckPose(const Eigen::Vector3d& position_m, std::uint64_t sequence,
                      const std::optional<AcceptedPose>& last, const PoseLimits& limits) {
  if (!position_m.allFinite()) return PoseVerdict::kNonFinite;
  if (position_m.norm() > limits.workspace_m) return PoseVerdict::kOutOfWorkspace;
  if (last) {
    if (sequence == last->sequence) return PoseVerdict::kDuplicate;
    if (sequence < last->sequence) return PoseVerdict::kOutOfOrder;
    const double gap = static_cast<double>(std::min<std::uint64_t>(sequence - last->sequence, kMaxJumpScale));
    if ((position_m - last->position_m).norm() > limits.max_jump_m * gap) return PoseVerdict::kJump;
  }
  return PoseVerdict::kAccept;
}

}  // namespace hapco::sim
