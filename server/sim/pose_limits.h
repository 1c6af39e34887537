#pragma once
// Plausibility limits of a device pose stream (design.md: input is never trusted), shared by
// the server's sessions and the offline tools, so offline and online runs step the same poses.
#include <cstdint>
#include <optional>

#include <Eigen/Core>

namespace hapco::sim {

struct PoseLimits {
  double workspace_m = 0.10;  // |d| above this is out of the device workspace, m
  // Largest plausible position change per sequence step, m (0.1 m/s at 1 kHz would be
  // 0.1 mm; 2 mm leaves room for hand-held motion). Scaled by the sequence gap (at most 10x).
  // A jump is ignored (no step, the client keeps its last force); a client that really is
  // elsewhere recovers with SESSION_RESET or SESSION_JOIN (the next pose starts the stream).
  double max_jump_m = 0.002;
  // Flood limit (server only): a token bucket refilled at max_poses_per_ms per ms holding at
  // most flood_burst poses. A 1 kHz client with scheduling or network jitter never empties
  // it; a client sending more than ~2 poses per ms for longer than ~30 ms does (extras
  // dropped).
  double max_poses_per_ms = 2.0;
  // 32: what a server takes from one 1 kHz client in one loop after a stall of its own (the
  // pose reader's history of 16, PendingPoses::kCapacity, plus the 12 poses the oldest of them
  // repeats, DevicePose.recent), and 4 more that arrive while it takes them; also a burst of
  // poses bunched by network jitter (±5 ms bunches ~10) with their repeats. None is refused:
  // with 24, the 4 newest poses of such a burst were, and on a loaded host clients timed out on
  // live servers (2026-12-05); with 28, an overloaded server's every loop (20-40 ms with deep
  // contacts) refused the poses that arrived while it took the 28 (a helper session's
  // failover run, 2026-12-06). The average stays bounded by max_poses_per_ms.
  double flood_burst = 32.0;
};

// Why a pose was not stepped.
enum class PoseVerdict { kAccept, kNonFinite, kOutOfWorkspace, kJump, kOutOfOrder, kDuplicate, kFlood };

const char* VerdictName(PoseVerdict verdict);  // "accepted", "position jump", ...

// The last pose that was stepped: its sequence number and position, m.
struct AcceptedPose {
  std::uint64_t sequence = 0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
};

// In order: non-finite, out of the workspace, then against the last stepped pose (if any):
// repeated or older sequence, a jump larger than max_jump_m × min(sequence gap, 10).
PoseVerdict CheckPose(const Eigen::Vector3d& position_m, std::uint64_t sequence,
                      const std::optional<AcceptedPose>& last, const PoseLimits& limits);

}  // namespace hapco::sim
