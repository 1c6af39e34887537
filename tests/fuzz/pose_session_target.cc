// The server's handling of DevicePose and SessionControl samples from any participant, fed
// with arbitrary field values through the functions the server loop calls (ProcessPoses /
// ProcessSessionControls order): ClientIdOf, IsValidClientId, CheckStatelessPose for a pose
// that would open a session, PoseStream::Check per session, Accept for the stepped pose.
// Accepted poses must be finite, inside the workspace, in strictly increasing sequence order
// and within the jump limit of the previous stepped pose.
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <set>
#include <string>

#include "common/error.h"
#include "fuzz_targets.h"
#include "service/pose_intake.h"
#include "service/qos.h"

namespace hapco::fuzz {
namespace {

class Fields {
 public:
  Fields(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  bool empty() const { return at_ >= size_; }
  std::uint8_t Byte() { return at_ < size_ ? data_[at_++] : 0; }
  std::uint64_t U64() {
    std::uint64_t v = 0;
    for (int k = 0; k < 8; ++k) v |= static_cast<std::uint64_t>(Byte()) << (8 * k);
    return v;
  }
  // Interesting values (NaN, infinities, huge, subnormal, the limits' edges) or raw bits.
  double Double() {
    static const double kValues[] = {0.0, -0.0, std::numeric_limits<double>::quiet_NaN(),
                                     std::numeric_limits<double>::infinity(),
                                     -std::numeric_limits<double>::infinity(), 1e308, -1e308,
                                     5e-324, 0.1, 0.1000000001, -0.1, 0.002, 0.0020000001, 1e-3, 0.05};
    const std::uint8_t kind = Byte();
    if (kind < 2 * std::size(kValues)) return kValues[kind / 2];
    if (kind < 0xF0) return static_cast<double>(static_cast<std::int8_t>(Byte())) * 1e-4;
    const std::uint64_t bits = U64();
    double out = 0;
    std::memcpy(&out, &bits, sizeof(out));
    return out;
  }
  // A string<64> field as it arrives: any bytes, terminated or not.
  void Id(char (&field)[65]) {
    std::memset(field, 0, sizeof(field));
    const std::size_t length = Byte() % 67;  // 65, 66: all 65 bytes set, no terminator
    for (std::size_t k = 0; k < std::min<std::size_t>(length, 65); ++k) {
      const std::uint8_t b = Byte();
      field[k] = static_cast<char>(b < 0x80 ? "ab-_.Z9"[b % 7] : b);  // mostly valid ids
    }
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

struct Client {
  service::PoseStream stream;
  bool has_pending = false;
  hapco_idl_DevicePose pending{};
};

}  // namespace

int PoseSession(const std::uint8_t* data, std::size_t size) {
  Fields f(data, size);
  sim::PoseLimits limits;
  std::map<std::string, Client> sessions;
  std::set<std::string> left;
  std::int64_t now_ns = 1'000'000'000;
  while (!f.empty()) {
    const std::uint8_t kind = f.Byte();
    now_ns += static_cast<std::int64_t>(f.Byte()) * 10'000;  // 0..2.55 ms between samples
    if (kind % 4 == 0) {  // SessionControl
      char id_field[65];
      f.Id(id_field);
      const std::string id = service::ClientIdOf(id_field);
      HAPCO_FUZZ_CHECK(id.size() <= 65, "id longer than its field");
      if (!service::IsValidClientId(id)) continue;
      HAPCO_FUZZ_CHECK(!service::ClientPartition(id).empty(), "valid id without a partition");
      const std::uint8_t command = f.Byte() % 4;  // 3: an unknown enum value
      auto it = sessions.find(id);
      if (command == 0) {  // JOIN
        left.erase(id);
        if (it == sessions.end()) {
          sessions.emplace(id, Client{});
        } else {
          it->second.stream.Reset();
          it->second.has_pending = false;
        }
      } else if (command == 1 && it != sessions.end()) {  // LEAVE
        sessions.erase(it);
        left.insert(id);
      } else if (command == 2 && it != sessions.end()) {  // RESET
        it->second.stream.Reset();
        it->second.has_pending = false;
      }
      continue;
    }
    if (kind % 4 == 1) {  // a server tick: step every pending pose
      for (auto& [id, client] : sessions) {
        if (!client.has_pending) continue;
        client.has_pending = false;
        const auto before = client.stream.last();
        const hapco_idl_DevicePose& pose = client.pending;
        const Eigen::Vector3d p(pose.position_m.x, pose.position_m.y, pose.position_m.z);
        HAPCO_FUZZ_CHECK(p.allFinite(), "stepped a non-finite pose");
        HAPCO_FUZZ_CHECK(p.norm() <= limits.workspace_m, "stepped a pose out of the workspace");
        if (before) {
          HAPCO_FUZZ_CHECK(pose.sequence_number > before->sequence, "stepped an old sequence");
          const double gap = static_cast<double>(std::min<std::uint64_t>(pose.sequence_number - before->sequence, 10));
          HAPCO_FUZZ_CHECK((p - before->position_m).norm() <= limits.max_jump_m * gap, "stepped a jump");
        }
        client.stream.Accept(pose);
      }
      continue;
    }
    hapco_idl_DevicePose pose{};
    f.Id(pose.client_id);
    pose.sequence_number = f.Byte() < 0xF0 ? f.Byte() : f.U64();
    pose.client_time_ns = static_cast<std::int64_t>(f.U64());
    pose.position_m = {f.Double(), f.Double(), f.Double()};
    pose.orientation = {f.Double(), f.Double(), f.Double(), f.Double()};
    pose.buttons = static_cast<std::uint32_t>(f.U64());
    pose.reported_round_trip_ns = static_cast<std::int64_t>(f.U64());
    const std::string id = service::ClientIdOf(pose.client_id);
    if (!service::IsValidClientId(id)) continue;
    auto it = sessions.find(id);
    if (it == sessions.end()) {
      if (left.count(id) != 0) continue;
      if (service::CheckStatelessPose(pose, limits) != sim::PoseVerdict::kAccept) continue;
      it = sessions.emplace(id, Client{}).first;
    }
    Client& client = it->second;
    if (client.has_pending && pose.sequence_number <= client.pending.sequence_number) continue;
    if (client.stream.Check(pose, now_ns, limits) != sim::PoseVerdict::kAccept) continue;
    client.pending = pose;
    client.has_pending = true;
  }
  return 0;
}

}  // namespace hapco::fuzz
