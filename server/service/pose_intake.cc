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
                                   const sim::PoseLimits& limits) {
  if (flood_tokens_ < 0) {
    flood_tokens_ = limits.flood_burst;
  } else {
    const double elapsed_ms = static_cast<double>(receive_ns - flood_last_ns_) * 1e-6;
    flood_tokens_ = std::min(limits.flood_burst, flood_tokens_ + elapsed_ms * limits.max_poses_per_ms);
  }
  flood_last_ns_ = receive_ns;
  if (flood_tokens_ < 1.0) return sim::PoseVerdict::kFlood;
  flood_tokens_ -= 1.0;
  if (!FiniteOrientation(pose)) return sim::PoseVerdict::kNonFinite;
  return sim::CheckPose(PositionOf(pose), pose.sequence_number, last_, limits);
}

std::uint64_t PoseStream::Accept(const hapco_idl_DevicePose& pose) {
  std::uint64_t gap = 0;
  if (last_ && pose.sequence_number > last_->sequence + 1) gap = pose.sequence_number - last_->sequence - 1;
  last_ = sim::AcceptedPose{pose.sequence_number, PositionOf(pose)};
  return gap;
}

void PoseStream::Reset() { last_.reset(); }

}  // namespace hapco::service
