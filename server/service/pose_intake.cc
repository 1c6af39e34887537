#include "service/pose_intake.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "common/error.h"
#include "service/qos.h"

namespace hapco::service {
namespace {

bool FiniteOrientation(const hapco_idl_DevicePose& pose) {
  const auto& q = pose.orientation;
  return std::isfinite(q.w) && std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z);
}

Eigen::Vector3d PositionOf(const hapco_idl_DevicePose& pose) {
  return {pose.position_m.x, pose.position_m.y, pose.position_m.z};
}

}  // namespace

std::string ClientIdOf(const char (&field)[65]) { return std::string(field, strnlen(field, 65)); }

bool IsValidClientId(std::string_view client_id) {
  try {
    ValidateClientId(client_id);
    return true;
  } catch (const InputError&) {
    return false;
  }
}

sim::PoseVerdict CheckStatelessPose(const hapco_idl_DevicePose& pose, const sim::PoseLimits& limits) {
  if (!FiniteOrientation(pose)) return sim::PoseVerdict::kNonFinite;
  return sim::CheckPose(PositionOf(pose), pose.sequence_number, std::nullopt, limits);
}

sim::PoseVerdict PoseStream::Check(const hapco_idl_DevicePose& pose, std::int64_t receive_ns,
                                   const sim::PoseLimits& limits, const hapco_idl_DevicePose* pending) {
  if (!flood_.Take(FloodClock(pose, receive_ns), limits.flood_burst, limits.max_poses_per_ms)) {
    return sim::PoseVerdict::kFlood;
  }
  if (!FiniteOrientation(pose)) return sim::PoseVerdict::kNonFinite;
  if (pending != nullptr) {
    return sim::CheckPose(PositionOf(pose), pose.sequence_number,
                          sim::AcceptedPose{pending->sequence_number, PositionOf(*pending)}, limits);
  }
  return sim::CheckPose(PositionOf(pose), pose.sequence_number, last_, limits);
}

std::int64_t PoseStream::FloodClock(const hapco_idl_DevicePose& pose, std::int64_t receive_ns) {
  std::int64_t t = receive_ns;
  // (A monotonic clock is positive: anything else is no client time, and would overflow below.)
  if (pose.client_time_ns > 0 && receive_ns >= 0) {
    const std::int64_t offset = pose.client_time_ns - receive_ns;
    if (!client_offset_ns_ || offset > *client_offset_ns_) client_offset_ns_ = offset;
    t = pose.client_time_ns - *client_offset_ns_;  // <= receive_ns
  }
  flood_clock_ns_ = std::max(flood_clock_ns_, t);
  return flood_clock_ns_;
}

std::uint64_t PoseStream::Accept(const hapco_idl_DevicePose& pose) {
  std::uint64_t gap = 0;
  if (last_ && pose.sequence_number > last_->sequence + 1) gap = pose.sequence_number - last_->sequence - 1;
  last_ = sim::AcceptedPose{pose.sequence_number, PositionOf(pose)};
  return gap;
}

void PoseStream::Reset() { last_.reset(); }

bool PendingPoses::Push(const hapco_idl_DevicePose& pose, std::int64_t receive_ns) {
  bool superseded = false;
  if (size_ == kCapacity) {
    std::move(poses_.begin() + 1, poses_.end(), poses_.begin());
    std::move(receive_ns_.begin() + 1, receive_ns_.end(), receive_ns_.begin());
    --size_;
    superseded = true;
  }
  poses_[static_cast<std::size_t>(size_)] = pose;
  receive_ns_[static_cast<std::size_t>(size_)] = receive_ns;
  ++size_;
  return superseded;
}

int MissedPoses(const hapco_idl_DevicePose& pose, std::uint64_t newest_known, bool started,
                std::array<hapco_idl_DevicePose, hapco_idl_RECENT_SAMPLES>* out) {
  if (!started) return 0;
  int written = 0;
  const std::uint32_t count = std::min<std::uint32_t>(pose.recent_count, hapco_idl_RECENT_SAMPLES);
  for (std::uint32_t k = count; k-- > 0;) {  // oldest first
    const hapco_idl_RecentPose& recent = pose.recent[k];
    if (recent.sequence_number <= newest_known || recent.sequence_number >= pose.sequence_number) continue;
    hapco_idl_DevicePose& missed = (*out)[static_cast<std::size_t>(written++)];
    missed = pose;
    missed.sequence_number = recent.sequence_number;
    missed.client_time_ns = recent.client_time_ns;
    missed.position_m = recent.position_m;
    missed.recent_count = 0;
    newest_known = recent.sequence_number;  // repeats out of order are skipped, not reordered
  }
  return written;
}

}  // namespace hapco::service
