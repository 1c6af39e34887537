#pragma once
// What the server does with the fields of a DDS sample from any participant before it steps
// anything: bounded client ids, stateless pose checks, and the per-session stream checks
// (flood bucket, order, jumps). Pure functions and plain state, no DDS entities, so that the
// fuzz harness (tests/fuzz/pose_session_target.cc) runs exactly this code without a network.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "common/token_bucket.h"
#include "hapco_types.h"
#include "sim/pose_limits.h"

namespace hapco::service {

// The id in a string<64> field, bounded even without a terminator (a sample's bytes are
// whatever the writer sent).
std::string ClientIdOf(const char (&field)[65]);

// ValidateClientId without the exception: 1..64 of [A-Za-z0-9_.-].
bool IsValidClientId(std::string_view client_id);

// Checks that need no session state (a pose that would open a session): finite orientation,
// then sim::CheckPose without a previous pose.
sim::PoseVerdict CheckStatelessPose(const hapco_idl_DevicePose& pose, const sim::PoseLimits& limits);

// The validation state of one client's pose stream.
class PoseStream {
 public:
  // Classifies a pose: flood bucket (every pose seen takes a token), finite orientation,
  // then sim::CheckPose against the last accepted pose. Changes only the flood bucket.
  // receive_ns: server CLOCK_MONOTONIC (never decreasing).
  // pending: the newest pose accepted but not yet stepped (PendingPoses::last()), or nullptr;
  // order and jump are checked against it then, so a burst is checked pose to pose.
  sim::PoseVerdict Check(const hapco_idl_DevicePose& pose, std::int64_t receive_ns,
                         const sim::PoseLimits& limits, const hapco_idl_DevicePose* pending = nullptr);
  // Records a stepped pose; returns how many sequence numbers were skipped since the last.
  std::uint64_t Accept(const hapco_idl_DevicePose& pose);
  // SESSION_RESET / repeated SESSION_JOIN: the next pose starts the stream again (the flood
  // bucket is kept: resetting is no way around it).
  void Reset();

  const std::optional<sim::AcceptedPose>& last() const { return last_; }

 private:
  // The flood bucket's clock, ns: the client's own (client_time_ns) aligned to the server's by
  // the largest client - server offset seen (the smallest delay), so never ahead of the
  // server's; the server's receive time for a pose without a client time. A backlog the
  // server's own stall releases (SIGSTOP 0.3-3 s: 134 "floods" of a 1 kHz phantom, a helper
  // session) is 1 ms apart on the client's clock; a client sending faster than its clock says
  // makes the offset grow, and the bucket then runs on the server's time.
  std::int64_t FloodClock(const hapco_idl_DevicePose& pose, std::int64_t receive_ns);

  std::optional<sim::AcceptedPose> last_;
  TokenBucket flood_;  // every pose seen takes a token (sim::PoseLimits::flood_burst)
  std::optional<std::int64_t> client_offset_ns_;  // max over poses of client_time_ns - receive_ns
  std::int64_t flood_clock_ns_ = 0;               // the bucket's clock, never decreasing
};

// The poses of one client waiting for the next step batch (ServerLoop::StepQueued), in
// strictly increasing sequence order, at most kCapacity: a burst from a jittery network, the
// poses recovered from a pose's repeats, or poses that arrived while the server was busy.
class PendingPoses {
 public:
  static constexpr int kCapacity = 16;
  int size() const { return size_; }
  const hapco_idl_DevicePose& pose(int k) const { return poses_[static_cast<std::size_t>(k)]; }
  std::int64_t receive_ns(int k) const { return receive_ns_[static_cast<std::size_t>(k)]; }
  const hapco_idl_DevicePose* last() const { return size_ > 0 ? &poses_[static_cast<std::size_t>(size_ - 1)] : nullptr; }
  // Appends (the caller keeps the order); when full the oldest gives way: returns true then
  // (a superseded pose).
  bool Push(const hapco_idl_DevicePose& pose, std::int64_t receive_ns);
  void Clear() { size_ = 0; }

 private:
  std::array<hapco_idl_DevicePose, kCapacity> poses_{};
  std::array<std::int64_t, kCapacity> receive_ns_{};
  int size_ = 0;
};

// The poses `pose` repeats (DevicePose.recent, at most RECENT_SAMPLES, newest first) that come
// after newest_known and before `pose` itself, oldest first, as DevicePoses (client id,
// orientation, buttons of `pose`; no repeats of their own): the poses a best-effort reader
// dropped for arriving after a newer one, or that the network lost. started = false (the
// session has no pose yet): none, the repeats are from before it. Returns how many were written.
int MissedPoses(const hapco_idl_DevicePose& pose, std::uint64_t newest_known, bool started,
                std::array<hapco_idl_DevicePose, hapco_idl_RECENT_SAMPLES>* out);

}  // namespace hapco::service
