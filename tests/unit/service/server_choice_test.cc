// Which server serves which client (service/server_choice.h): the least loaded server that
// serves the scene, spread by rendezvous hashing when loads tie, never a full, silent or
// avoided server while another qualifies; the unaddressed poses' server is the smallest live id.
#include "service/server_choice.h"
#include "service/pose_intake.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstring>
#include <map>
#include <string>
#include <vector>

namespace hapco::service {
namespace {

constexpr int64_t kNow = 10'000'000'000LL;
constexpr int64_t kMaxAge = 3'000'000'000LL;

ServerAnnouncement Server(const std::string& id, uint32_t sessions, uint32_t max_sessions = 16,
                          std::vector<std::string> scenes = {"bench1"}, int64_t heard_ns = kNow) {
  return {id, sessions, max_sessions, std::move(scenes), heard_ns};
}

TEST(ChooseServer, TheLeastFilledServerOfTheSceneIsChosen) {
  const std::vector<ServerAnnouncement> servers = {Server("a", 5), Server("b", 2), Server("c", 3),
                                                   Server("d", 0, 16, {"other"})};
  EXPECT_EQ(ChooseServer(servers, "client-1", "bench1", "", kNow, kMaxAge), "b");
  EXPECT_EQ(ChooseServer(servers, "client-1", "other", "", kNow, kMaxAge), "d");
  EXPECT_EQ(ChooseServer(servers, "client-1", "", "", kNow, kMaxAge), "d");  // no scene named: any
  EXPECT_FALSE(ChooseServer(servers, "client-1", "unknown", "", kNow, kMaxAge).has_value());
  // Fill, not count: 4 of 32 is less loaded than 2 of 8.
  const std::vector<ServerAnnouncement> sized = {Server("small", 2, 8), Server("large", 4, 32)};
  EXPECT_EQ(ChooseServer(sized, "client-1", "bench1", "", kNow, kMaxAge), "large");
}

TEST(ChooseServer, FullSilentAndAvoidedServersAreNotChosenWhileAnotherQualifies) {
  const std::vector<ServerAnnouncement> servers = {Server("full", 16, 16), Server("silent", 0, 16, {"bench1"}, 0),
                                                   Server("busy", 12), Server("left", 1)};
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "left");
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "left", kNow, kMaxAge), "busy");  // moving away from "left"
  // The avoided server is the only one left: it is tried again rather than no server at all.
  const std::vector<ServerAnnouncement> alone = {Server("only", 3), Server("full", 16, 16)};
  EXPECT_EQ(ChooseServer(alone, "c", "bench1", "only", kNow, kMaxAge), "only");
  EXPECT_FALSE(ChooseServer(std::vector<ServerAnnouncement>{}, "c", "bench1", "", kNow, kMaxAge).has_value());
}

TEST(ChooseServer, AServerWhoseLeaseLapsedIsNeitherChosenNorLiveUntilItIsAliveAgain) {
  std::vector<ServerAnnouncement> servers = {Server("a-dead", 0), Server("b-busy", 10)};
  servers[0].writer_handle = 11;
  servers[1].writer_handle = 12;
  ASSERT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "a-dead");
  EXPECT_FALSE(ServesUnaddressed("b-busy", servers, kNow, kMaxAge));  // "a-dead" has the smaller id
  // Its status writer's lease lapsed (killed): it is not chosen, even as the only other
  // server when the client leaves "b-busy", and the next id serves unaddressed poses.
  EXPECT_EQ(ApplyLivelinessChange(servers, 11, -1, kNow), LeaseChange::kLapsed);
  EXPECT_TRUE(servers[0].lease_lapsed);
  EXPECT_FALSE(servers[1].lease_lapsed);
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "b-busy");
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "b-busy", kNow, kMaxAge), "b-busy");
  EXPECT_TRUE(ServesUnaddressed("b-busy", servers, kNow, kMaxAge));
  // A writer no announcement came from changes nothing; no change, or a repeated lapse,
  // changes nothing.
  EXPECT_EQ(ApplyLivelinessChange(servers, 99, +1, kNow), LeaseChange::kNone);
  EXPECT_EQ(ApplyLivelinessChange(servers, 11, 0, kNow), LeaseChange::kNone);
  EXPECT_EQ(ApplyLivelinessChange(servers, 11, -1, kNow), LeaseChange::kNone);
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "b-busy");
  // Alive again (a frozen process that resumed): chosen again.
  EXPECT_EQ(ApplyLivelinessChange(servers, 11, +1, kNow), LeaseChange::kRegained);
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "a-dead");
}

// After a lapse longer than DDS keeps a silent writer, the server comes back as a new writer:
// its first announcement ends the lapse and counts as the lease coming back (a helper saw
// "lapsed 1, came back 0" with forces flowing again).
TEST(ChooseServer, AnAnnouncementFromALapsedServerEndsTheLapseOnce) {
  std::vector<ServerAnnouncement> servers = {Server("a", 0)};
  servers[0].writer_handle = 11;
  ASSERT_EQ(ApplyLivelinessChange(servers, 11, -1, kNow), LeaseChange::kLapsed);
  ServerAnnouncement again = Server("a", 1);
  again.writer_handle = 21;  // rediscovered: another handle
  EXPECT_EQ(ApplyLivelinessChange(servers, 21, +1, kNow), LeaseChange::kNone) << "the new writer was never known";
  EXPECT_EQ(RecordAnnouncement(servers, again, 256), LeaseChange::kRegained);
  EXPECT_FALSE(servers[0].lease_lapsed);
  EXPECT_EQ(servers[0].writer_handle, 21u);
  EXPECT_EQ(RecordAnnouncement(servers, again, 256), LeaseChange::kNone) << "counted once";
  EXPECT_EQ(ApplyLivelinessChange(servers, 21, +1, kNow), LeaseChange::kNone) << "already alive: not counted again";
  // A new server is recorded, up to the limit.
  EXPECT_EQ(RecordAnnouncement(servers, Server("b", 0), 2), LeaseChange::kNone);
  EXPECT_EQ(RecordAnnouncement(servers, Server("c", 0), 2), LeaseChange::kNone);
  EXPECT_EQ(servers.size(), 2u);
}

// A dead server's lease seen to lapse, "come back" (its last packets read late by a client
// whose receive thread stalled) and lapse again: during the return the lapse still counts for a
// client that has had no force since before it, not for one whose last force came after it.
TEST(ChooseServer, ALeaseThatLapsedDuringASilenceCountsEvenAfterItCameBack) {
  std::vector<ServerAnnouncement> servers = {Server("a", 0)};
  servers[0].writer_handle = 11;
  constexpr int64_t kMs = 1'000'000;
  EXPECT_FALSE(LeaseLapsedSince(servers[0], kNow)) << "never lapsed";
  ASSERT_EQ(ApplyLivelinessChange(servers, 11, -1, kNow + 50 * kMs), LeaseChange::kLapsed);
  EXPECT_TRUE(LeaseLapsedSince(servers[0], kNow)) << "lapsed now";
  ASSERT_EQ(ApplyLivelinessChange(servers, 11, +1, kNow + 60 * kMs), LeaseChange::kRegained);
  EXPECT_FALSE(servers[0].lease_lapsed);
  EXPECT_TRUE(LeaseLapsedSince(servers[0], kNow)) << "lapsed after the last force at kNow, came back since";
  EXPECT_FALSE(LeaseLapsedSince(servers[0], kNow + 55 * kMs)) << "a force came after the lapse";
  // An announcement from it keeps the time of the lapse.
  ServerAnnouncement again = Server("a", 1);
  again.writer_handle = 11;
  EXPECT_EQ(RecordAnnouncement(servers, again, 256), LeaseChange::kNone);
  EXPECT_EQ(servers[0].lapsed_ns, kNow + 50 * kMs);
  EXPECT_TRUE(LeaseLapsedSince(servers[0], kNow));
}

// A client whose own DDS threads stalled sees every server's lease lapse at once. Leaving its
// (killed) server it takes another heard recently rather than none; a live one still comes
// first, and the avoided server is taken again only while it is the only live one.
TEST(ChooseServer, WhenEveryLeaseLooksLapsedAnotherRecentlyHeardServerIsChosen) {
  std::vector<ServerAnnouncement> servers = {Server("s1", 2), Server("s2", 1), Server("s3", 2),
                                             Server("old", 0, 16, {"bench1"}, kNow - 2 * kMaxAge)};
  for (uint64_t k = 0; k < servers.size(); ++k) {
    servers[k].writer_handle = 11 + k;
    ASSERT_EQ(ApplyLivelinessChange(servers, 11 + k, -1, kNow), LeaseChange::kLapsed);
  }
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "s3", kNow, kMaxAge), "s2") << "the least filled lapsed other";
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "s2");
  EXPECT_FALSE(ChooseServer(servers, "c", "other-scene", "s3", kNow, kMaxAge).has_value());
  // Never one heard longer ago than the age limit, nor the avoided one while it is lapsed.
  servers[1].heard_ns = kNow - 2 * kMaxAge;
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "s3", kNow, kMaxAge), "s1");
  servers[0].heard_ns = kNow - 2 * kMaxAge;
  EXPECT_FALSE(ChooseServer(servers, "c", "bench1", "s3", kNow, kMaxAge).has_value());
  // A live server, even the avoided one, comes before any lapsed one.
  servers[0].heard_ns = kNow;
  ASSERT_EQ(ApplyLivelinessChange(servers, 13, +1, kNow), LeaseChange::kRegained);  // s3 back
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "s3", kNow, kMaxAge), "s3");
  servers[2].sessions = 15;
  ASSERT_EQ(ApplyLivelinessChange(servers, 11, +1, kNow), LeaseChange::kRegained);  // s1 back
  EXPECT_EQ(ChooseServer(servers, "c", "bench1", "", kNow, kMaxAge), "s1");
}

TEST(ChooseServer, ClientsJoiningAtOnceSpreadOverEquallyLoadedServers) {
  // Every client reads the same announcements (all empty): the tie-break must not send them
  // all to one server. 300 ids over three servers: each gets a share near a third.
  const std::vector<ServerAnnouncement> servers = {Server("hapco-node1-17", 0), Server("hapco-node2-17", 0),
                                                   Server("hapco-node3-17", 0)};
  std::map<std::string, int> chosen;
  for (int k = 1; k <= 300; ++k) {
    const auto server = ChooseServer(servers, "phantom-" + std::to_string(k), "bench1", "", kNow, kMaxAge);
    ASSERT_TRUE(server.has_value());
    ++chosen[*server];
  }
  ASSERT_EQ(chosen.size(), 3u);
  for (const auto& [id, count] : chosen) {
    EXPECT_GT(count, 70) << id;
    EXPECT_LT(count, 130) << id;
  }
  // A client's choice is stable (the same announcements give the same server).
  EXPECT_EQ(ChooseServer(servers, "phantom-7", "bench1", "", kNow, kMaxAge),
            ChooseServer(servers, "phantom-7", "bench1", "", kNow, kMaxAge));
}

TEST(ServesUnaddressed, OnlyTheSmallestLiveIdStepsUnaddressedPoses) {
  const std::vector<ServerAnnouncement> peers = {Server("b", 0), Server("d", 0), Server("a", 0, 16, {}, 0)};
  EXPECT_FALSE(ServesUnaddressed("c", peers, kNow, kMaxAge));  // "b" is live and smaller
  EXPECT_TRUE(ServesUnaddressed("b", peers, kNow, kMaxAge));   // "a" is smaller but silent
  EXPECT_TRUE(ServesUnaddressed("z", std::vector<ServerAnnouncement>{}, kNow, kMaxAge));  // alone
}

TEST(AnnouncementOf, ReadsTheStatusFieldsAndSplitsTheSceneNames) {
  hapco_idl_ServerStatus status{};
  std::strcpy(status.server_id, "hapco-host-12");
  status.sessions = 3;
  status.max_sessions = 16;
  std::strcpy(status.scene_names, "bench1,bench2,,organ");
  const ServerAnnouncement a = AnnouncementOf(status, 42);
  EXPECT_EQ(a.server_id, "hapco-host-12");
  EXPECT_EQ(a.sessions, 3u);
  EXPECT_EQ(a.max_sessions, 16u);
  EXPECT_EQ(a.heard_ns, 42);
  EXPECT_EQ(a.scenes, (std::vector<std::string>{"bench1", "bench2", "organ"}));
  // An id field without a terminator (any participant's bytes) is read bounded.
  std::memset(status.server_id, 'x', sizeof(status.server_id));
  EXPECT_EQ(AnnouncementOf(status, 0).server_id.size(), sizeof(status.server_id));
}

TEST(DefaultServerId, IsAValidIdThatNamesTheHostAndProcess) {
  const std::string id = DefaultServerId();
  EXPECT_EQ(id.rfind("hapco-", 0), 0u) << id;
  EXPECT_LE(id.size(), 64u);
  std::string pid_part = "-";  // (built in steps: GCC 12 warns, -Wrestrict, on "-" + string + "-")
  pid_part += std::to_string(getpid());
  pid_part += '-';
  EXPECT_NE(id.find(pid_part), std::string::npos) << id;
  EXPECT_TRUE(IsValidClientId(id)) << id;  // the server checks its id like a client id
  EXPECT_NE(DefaultServerId(), id) << "two servers of one process image and pid must differ";
}

}  // namespace
}  // namespace hapco::service
