#pragma once
// What the server does with the fields of a DDS sample from any participant before it steps
// anything: bounded client ids, stateless pose checks, and the per-session stream checks
// (flood bucket, order, jumps). Pure functions and plain state, no DDS entities, so that the
// fuzz harness (tests/fuzz/pose_session_target.cc) runs exactly this code without a network.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <Eigen/Core>

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
  sim::PoseVerdict Check(const hapco_idl_DevicePose& pose, std::int64_t receive_ns,
                         const sim::PoseLimits& limits);
  // Records a stepped pose; returns how many sequence numbers were skipped since the last.
  std::uint64_t Accept(const hapco_idl_DevicePose& pose);
  // SESSION_RESET / repeated SESSION_JOIN: the next pose starts the stream again (the flood
  // bucket is kept: resetting is no way around it).
  void Reset();

  const std::optional<sim::AcceptedPose>& last() const { return last_; }

 private:
  std::optional<sim::AcceptedPose> last_;
  double flood_tokens_ = -1;  // < 0: not started
  std::int64_t flood_last_ns_ = 0;
};

}  // namespace hapco::service
