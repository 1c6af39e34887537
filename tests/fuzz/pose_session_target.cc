// The server's handling of DevicePose and SessionControl samples from any participant, fed
// with arbitrary field values through the functions the server loop calls (ProcessPoses /
// ProcessSessionControls order): ClientIdOf, IsValidClientId, CheckStatelessPose for a pose
// that would open a session, PoseStream::Check per session, MissedPoses for the poses a pose
// repeats (DevicePose.recent: arbitrary counts, sequences and positions), PendingPoses for
// the poses waiting for a step, Accept for each stepped pose. Stepped poses must be finite,
// inside the workspace, in strictly increasing sequence order and within the jump limit of
// the previous stepped pose.
#include <array>
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
  service::PendingPoses pending;
  std::uint64_t newest_seen = 0;  // as ServerLoop::Client
  bool seen_any = false;
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
          it->second.pending.Clear();
          it->second.newest_seen = 0;
          it->second.seen_any = false;
        }
      } else if (command == 1 && it != sessions.end()) {  // LEAVE
        sessions.erase(it);
        left.insert(id);
      } else if (command == 2 && it != sessions.end()) {  // RESET
        it->second.stream.Reset();
        it->second.pending.Clear();
        it->second.newest_seen = 0;
        it->second.seen_any = false;
      }
      continue;
    }
    if (kind % 4 == 1) {  // a server tick: step every pending pose, in order
      for (auto& [id, client] : sessions) {
        for (int k = 0; k < client.pending.size(); ++k) {
          const auto before = client.stream.last();
          const hapco_idl_DevicePose& pose = client.pending.pose(k);
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
        client.pending.Clear();
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
    // The repeats: any count (also beyond the array), sequences near the pose's or anywhere.
    pose.recent_count = f.Byte() < 0xF0 ? f.Byte() % 16 : static_cast<std::uint32_t>(f.U64());
    for (auto& recent : pose.recent) {
      const std::uint8_t how = f.Byte();
      recent.sequence_number = how < 0xE0 ? pose.sequence_number - how % 16 : f.U64();
      recent.client_time_ns = static_cast<std::int64_t>(f.U64());
      recent.position_m = how % 2 == 0 ? pose.position_m : hapco_idl_Vec3{f.Double(), f.Double(), f.Double()};
    }
    const std::string id = service::ClientIdOf(pose.client_id);
    if (!service::IsValidClientId(id)) continue;
    auto it = sessions.find(id);
    if (it == sessions.end()) {
      if (left.count(id) != 0) continue;
      if (service::CheckStatelessPose(pose, limits) != sim::PoseVerdict::kAccept) continue;
      it = sessions.emplace(id, Client{}).first;
    }
    Client& client = it->second;
    const hapco_idl_DevicePose* last = client.pending.last();
    if (last != nullptr && pose.sequence_number <= last->sequence_number) continue;
    const std::uint64_t newest_known = client.newest_seen;
    std::array<hapco_idl_DevicePose, hapco_idl_RECENT_SAMPLES> missed{};
    const int count = service::MissedPoses(pose, newest_known, client.seen_any, &missed);
    HAPCO_FUZZ_CHECK(count >= 0 && count <= hapco_idl_RECENT_SAMPLES, "more missed poses than repeats");
    for (int k = 0; k < count; ++k) {
      const hapco_idl_DevicePose& m = missed[static_cast<std::size_t>(k)];
      HAPCO_FUZZ_CHECK(m.sequence_number > newest_known && m.sequence_number < pose.sequence_number,
                       "recovered a pose outside (newest known, this pose)");
      HAPCO_FUZZ_CHECK(k == 0 || m.sequence_number > missed[static_cast<std::size_t>(k - 1)].sequence_number,
                       "recovered poses out of order");
      if (client.stream.Check(m, now_ns, limits, client.pending.last()) != sim::PoseVerdict::kAccept) continue;
      client.pending.Push(m, now_ns);
    }
    client.newest_seen = std::max(client.newest_seen, pose.sequence_number);
    client.seen_any = true;
    if (client.stream.Check(pose, now_ns, limits, client.pending.last()) != sim::PoseVerdict::kAccept) continue;
    client.pending.Push(pose, now_ns);
  }
  return 0;
}

}  // namespace hapco::fuzz
