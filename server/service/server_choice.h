#pragma once
// Several hapco-servers on one DDS domain (docs/several-servers.md): which server serves
// which client. An explicit assignment, not DDS ownership: with EXCLUSIVE ownership every
// server would still step every pose (and pay for it) and the recorders would see the
// weaker writers' frames; an assignment makes exactly one server step a client's poses.
//   - Every server announces itself in ServerStatus (sessions, max_sessions, scenes).
//   - A joining client chooses from the announcements (ChooseServer: the least loaded that
//     serves its scene) and names the server in its SESSION_JOIN and in every pose.
//   - A server steps only the poses addressed to it; a JOIN addressed to another server
//     closes its session of that client (the client moved).
//   - Poses addressed to nobody (a client not written for several servers) are stepped only
//     by the live server with the smallest id (ServesUnaddressed).
// Pure functions over plain data, no DDS entities (unit-tested in tests/unit/service).
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "hapco_types.h"

namespace hapco::service {

// One server as its newest ServerStatus announced it.
struct ServerAnnouncement {
  std::string server_id;
  uint32_t sessions = 0;
  uint32_t max_sessions = 0;
  std::vector<std::string> scenes;  // served scene names; empty: unknown (any scene)
  int64_t heard_ns = 0;             // CLOCK_MONOTONIC of the receiver when it arrived
  // The DDS publication handle of its status writer (sample info), to match liveliness changes.
  uint64_t writer_handle = 0;
  // Its status writer's liveliness lease lapsed (StatusQos, 50 ms) and has not come back: the
  // process is gone (killed, crashed) or frozen. Not chosen, not live; a new announcement or
  // the lease coming back clears it.
  bool lease_lapsed = false;
  // CLOCK_MONOTONIC of the receiver when that lease last lapsed (-1: never), kept when it comes
  // back: a lapse and a return within one silence of the server still says it stalled or died
  // (LeaseLapsedSince).
  int64_t lapsed_ns = -1;
};

// The announcement in a ServerStatus sample (scene_names split at commas).
ServerAnnouncement AnnouncementOf(const hapco_idl_ServerStatus& status, int64_t heard_ns);

// What a liveliness change did to the announcement it concerns.
enum class LeaseChange {
  kNone,      // no announcement from that writer, or its state did not change
  kLapsed,    // alive -> lapsed
  kRegained,  // lapsed -> alive (a stalled process that resumed)
};

// Applies a liveliness change of the status writer `writer_handle` (DDS on_liveliness_changed:
// alive_count_change < 0 lapsed, > 0 alive again), seen at now_ns (CLOCK_MONOTONIC), to the
// server it announced.
LeaseChange ApplyLivelinessChange(std::span<ServerAnnouncement> servers, uint64_t writer_handle,
                                  int32_t alive_count_change, int64_t now_ns);

// The server's lease is lapsed now, or lapsed after since_ns (CLOCK_MONOTONIC) and came back.
// Why the second: a client whose own DDS receive thread stalls can see a dead server's lease
// lapse, then "come back" when the packets the server sent before it died are read late, then
// lapse again 50 ms later; in between the lapse is not visible, and a client waited for the
// round-trip rule (160.5 ms without a force in CI, several_servers_in_namespaces, 2026-12-07;
// docs/several-servers.md).
bool LeaseLapsedSince(const ServerAnnouncement& server, int64_t since_ns);

// Records a new announcement (a ServerStatus sample) among `servers` (at most `max_servers`
// kept). Returns kRegained when it replaces the announcement of a server whose lease had
// lapsed: a lease lost for longer than DDS keeps a silent writer (10 s and more) comes back as
// a new writer whose samples, not a liveliness change, end the lapse (a helper counted "lapsed
// 1, came back 0" with forces flowing again); kNone otherwise.
LeaseChange RecordAnnouncement(std::vector<ServerAnnouncement>& servers, ServerAnnouncement announcement,
                               std::size_t max_servers);

// Chooses the server for `client_id` joining `scene` ("" = the server's first scene): among
// the servers heard within max_age_ns of now_ns whose lease has not lapsed, that serve the
// scene and have a free session, not `avoid` (the server a client leaves) unless it is the
// only one, the one with the smallest fill (sessions / max_sessions); when every such server's
// lease has lapsed (the client's own stall makes them all lapse at once), one of those other
// than `avoid`. Ties are broken by rendezvous hashing of
// (client id, server id), so clients that join at once, all reading the same announcements,
// spread over the servers instead of all choosing the first. nullopt: no server qualifies.
std::optional<std::string> ChooseServer(std::span<const ServerAnnouncement> servers, std::string_view client_id,
                                        std::string_view scene, std::string_view avoid, int64_t now_ns,
                                        int64_t max_age_ns);

// True when `own_id` steps poses addressed to no server: it is the smallest id among itself
// and the other servers heard within max_age_ns of now_ns.
bool ServesUnaddressed(std::string_view own_id, std::span<const ServerAnnouncement> others, int64_t now_ns,
                       int64_t max_age_ns);

// The id in a string<64> field, bounded even without a terminator.
std::string ServerIdOf(const char (&field)[65]);

// "hapco-<hostname>-<pid>-<32 random bits>", at most 64 characters of [A-Za-z0-9_.-]:
// distinct for servers on one host and for the replicas of one compose service (which may
// share a hostname and all be pid 1).
std::string DefaultServerId();

}  // namespace hapco::service
