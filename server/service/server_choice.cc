#include "service/server_choice.h"

#include <sys/random.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>

#include "common/hash.h"
#include "service/pose_intake.h"

namespace hapco::service {
namespace {

// FNV-1a over "client\0server": a fixed hash (std::hash may differ between builds, and the
// clients of one deployment must agree only with themselves, but a fixed one is testable).
uint64_t RendezvousWeight(std::string_view client_id, std::string_view server_id) {
  uint64_t h = Fnv1a64(client_id);
  h = Fnv1a64(std::string_view("\0", 1), h);  // separator: ("ab", "c") and ("a", "bc") differ
  h = Fnv1a64(server_id, h);
  // Finaliser (splitmix64): FNV's low bits alone spread poorly over similar ids.
  h ^= h >> 30;
  h *= 0xbf58476d1ce4e5b9ULL;
  h ^= h >> 27;
  h *= 0x94d049bb133111ebULL;
  h ^= h >> 31;
  return h;
}

bool IsIdCharacter(char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
         c == '-';
}

bool Serves(const ServerAnnouncement& server, std::string_view scene) {
  if (scene.empty() || server.scenes.empty()) return true;
  return std::find(server.scenes.begin(), server.scenes.end(), scene) != server.scenes.end();
}

bool Live(const ServerAnnouncement& server, int64_t now_ns, int64_t max_age_ns) {
  return !server.lease_lapsed && now_ns - server.heard_ns <= max_age_ns;
}

}  // namespace

std::string ServerIdOf(const char (&field)[65]) { return ClientIdOf(field); }  // the same bounded read

ServerAnnouncement AnnouncementOf(const hapco_idl_ServerStatus& status, int64_t heard_ns) {
  ServerAnnouncement a;
  a.server_id = ServerIdOf(status.server_id);
  a.sessions = status.sessions;
  a.max_sessions = status.max_sessions;
  a.heard_ns = heard_ns;
  const std::string names(status.scene_names, strnlen(status.scene_names, sizeof(status.scene_names)));
  std::size_t begin = 0;
  while (begin < names.size()) {
    std::size_t end = names.find(',', begin);
    if (end == std::string::npos) end = names.size();
    if (end > begin) a.scenes.push_back(names.substr(begin, end - begin));
    begin = end + 1;
  }
  return a;
}

LeaseChange ApplyLivelinessChange(std::span<ServerAnnouncement> servers, uint64_t writer_handle,
                                  int32_t alive_count_change, int64_t now_ns) {
  if (writer_handle == 0 || alive_count_change == 0) return LeaseChange::kNone;
  for (ServerAnnouncement& s : servers) {
    if (s.writer_handle != writer_handle) continue;
    const bool lapsed = alive_count_change < 0;
    if (s.lease_lapsed == lapsed) return LeaseChange::kNone;
    s.lease_lapsed = lapsed;
    if (lapsed) s.lapsed_ns = now_ns;
    return lapsed ? LeaseChange::kLapsed : LeaseChange::kRegained;
  }
  return LeaseChange::kNone;
}

bool LeaseLapsedSince(const ServerAnnouncement& server, int64_t since_ns) {
  return server.lease_lapsed || (server.lapsed_ns >= 0 && server.lapsed_ns > since_ns);
}

LeaseChange RecordAnnouncement(std::vector<ServerAnnouncement>& servers, ServerAnnouncement announcement,
                               std::size_t max_servers) {
  auto known = std::find_if(servers.begin(), servers.end(), [&announcement](const ServerAnnouncement& s) {
    return s.server_id == announcement.server_id;
  });
  if (known == servers.end()) {
    if (servers.size() < max_servers) servers.push_back(std::move(announcement));
    return LeaseChange::kNone;
  }
  const bool was_lapsed = known->lease_lapsed;
  const int64_t lapsed_ns = known->lapsed_ns;
  *known = std::move(announcement);  // its data came: alive (lease_lapsed false)
  known->lapsed_ns = lapsed_ns;
  return was_lapsed ? LeaseChange::kRegained : LeaseChange::kNone;
}

std::optional<std::string> ChooseServer(std::span<const ServerAnnouncement> servers, std::string_view client_id,
                                        std::string_view scene, std::string_view avoid, int64_t now_ns,
                                        int64_t max_age_ns) {
  enum class Tier { kLiveOthers, kLiveAvoided, kLapsedOthers };
  auto choose = [&](Tier tier) -> std::optional<std::string> {
    const ServerAnnouncement* best = nullptr;
    double best_fill = 0;
    uint64_t best_weight = 0;
    for (const ServerAnnouncement& s : servers) {
      if (s.server_id.empty() || now_ns - s.heard_ns > max_age_ns || !Serves(s, scene)) continue;
      if (s.lease_lapsed != (tier == Tier::kLapsedOthers)) continue;
      if (tier != Tier::kLiveAvoided && s.server_id == avoid) continue;
      if (s.max_sessions > 0 && s.sessions >= s.max_sessions) continue;  // full
      const double fill = s.max_sessions > 0 ? static_cast<double>(s.sessions) / s.max_sessions : 0.0;
      const uint64_t weight = RendezvousWeight(client_id, s.server_id);
      if (best == nullptr || fill < best_fill || (fill == best_fill && weight > best_weight)) {
        best = &s;
        best_fill = fill;
        best_weight = weight;
      }
    }
    if (best == nullptr) return std::nullopt;
    return best->server_id;
  };
  if (auto chosen = choose(Tier::kLiveOthers)) return chosen;
  if (auto chosen = choose(Tier::kLiveAvoided)) return chosen;  // the avoided one is the only live one: again
  // No live server at all: every lease heard looks lapsed, as when the client's own DDS threads
  // stall (a loaded host) and the leases of every server lapse at once, to come back when it
  // reads their packets. Without this tier a client leaving a killed server retried every
  // 100 ms until one came back: in several_servers_in_namespaces at load 8 two clients moved
  // at exactly 505 ms without a force, on the retry grid after the lease decided at ~105 ms
  // (2026-12-07). A server heard within max_age_ns is a better guess than none; a dead one
  // costs a second move.
  return choose(Tier::kLapsedOthers);
}

bool ServesUnaddressed(std::string_view own_id, std::span<const ServerAnnouncement> others, int64_t now_ns,
                       int64_t max_age_ns) {
  for (const ServerAnnouncement& s : others) {
    if (s.server_id != own_id && Live(s, now_ns, max_age_ns) && s.server_id < own_id) return false;
  }
  return true;
}

std::string DefaultServerId() {
  char host[64] = {};
  if (gethostname(host, sizeof(host) - 1) != 0) std::strcpy(host, "host");
  std::string name;
  for (const char c : std::string(host)) name += IsIdCharacter(c) ? c : '-';
  // Host and pid alone collide: compose replicas may share a hostname and each be pid 1.
  uint32_t salt = 0;
  if (getrandom(&salt, sizeof(salt), 0) != static_cast<ssize_t>(sizeof(salt))) {
    salt = static_cast<uint32_t>(std::chrono::steady_clock::now().time_since_epoch().count());
  }
  char suffix[32];
  std::snprintf(suffix, sizeof(suffix), "-%d-%08x", static_cast<int>(getpid()), salt);
  std::string id = "hapco-";
  id.append(name, 0, 64 - id.size() - std::strlen(suffix));
  id.append(suffix);
  return id;
}

}  // namespace hapco::service
