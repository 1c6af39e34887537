// What a haptic client sees when its server goes away and comes back, and when the server is
// full: real processes on loopback, own domain per test. Synchronisation is on DDS data (the
// test watches the client's poses and forces) and process exits, all bounded; no sleeps.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "../process_support.h"
#include "common/realtime.h"
#include "service/dds.h"
#include "service/qos.h"
#include "service/pose_intake.h"
#include "service/server_choice.h"

namespace hapco::service {
namespace {

const std::string kScene = std::string(HAPCO_SOURCE_DIR) + "/tests/data/scenes/coarse.txtpb";

// Safety parameters of hapco-phantom (client/phantom/phantom.h defaults; --force-timeout-ms below).
constexpr double kMaxForceN = 7.9;
constexpr double kMaxChangePerTickN = 0.25;
constexpr double kTimeoutS = 0.050;  // --force-timeout-ms 50
// The ramp to zero after a timeout: max(20 ms, |F| / 250 N/s), linear in time from the moment
// the timeout expired (phantom.h).
double RampDurationS(double force_n) { return std::max(0.020, force_n / 250.0); }

// One row per tick of a hapco-phantom CSV (the last row of a tick: its rendered force).
struct Tick {
  int tick = 0;
  double time_s = 0;              // client clock since its loop started
  long long force_sequence = -1;  // the newest force taken this tick, -1 none
  Eigen::Vector3d rendered_n = Eigen::Vector3d::Zero();
};

std::vector<Tick> ReadTicks(const std::string& path) {
  std::map<int, Tick> by_tick;
  for (const auto& row : ReadCsv(path)) {
    Tick t;
    t.tick = std::stoi(row.at("tick"));
    t.time_s = std::stod(row.at("time_s"));
    t.force_sequence = std::stoll(row.at("force_sequence"));
    t.rendered_n = Vec(row, "fx_n", "fy_n", "fz_n");
    auto [it, inserted] = by_tick.emplace(t.tick, t);
    if (!inserted && t.force_sequence > it->second.force_sequence) it->second = t;
  }
  std::vector<Tick> ticks;
  for (const auto& [k, t] : by_tick) ticks.push_back(t);
  return ticks;
}

// Press 3 mm in 0.1 mm steps, then the phantom holds the last point (--duration-s).
std::string WritePressTrajectory(const std::string& dir) {
  const std::string path = dir + "/press.csv";
  std::ofstream out(path);
  out << "x_m,y_m,z_m\n";
  for (int k = 1; k <= 30; ++k) out << "0,0," << -1e-4 * k << "\n";
  return path;
}

// The test's view of one client's poses and forces (both in the client's partition).
struct ClientWatch {
  ClientWatch(dds_domainid_t domain, const std::string& client_id)
      : participant(domain),
        pose_topic(participant),
        force_topic(participant),
        subscriber(participant, ClientPartition(client_id)),
        poses(subscriber, pose_topic),
        forces(subscriber, force_topic) {}
  Participant participant;
  Topic<hapco_idl_DevicePose> pose_topic;
  Topic<hapco_idl_FeedbackForce> force_topic;
  Subscriber subscriber;
  Reader<hapco_idl_DevicePose> poses;
  Reader<hapco_idl_FeedbackForce> forces;
};

// The sequence of the first force above 1 N after pose 100 (the server pushing back after the
// press), or 0 if none came before `deadline`.
uint64_t FirstPushingForce(Reader<hapco_idl_FeedbackForce>& force_reader, dds_time_t deadline) {
  hapco_idl_FeedbackForce force{};
  uint64_t sequence = 0;
  while (sequence == 0 && dds_time() < deadline) {
    if (!force_reader.WaitForData(DDS_MSECS(100))) continue;
    while (force_reader.Take(&force)) {
      const double norm = std::sqrt(force.force_n.x * force.force_n.x + force.force_n.y * force.force_n.y +
                                    force.force_n.z * force.force_n.z);
      if (force.pose_sequence >= 100 && norm > 1.0) sequence = force.pose_sequence;
    }
  }
  return sequence;
}

// Waits until the phantom has published pose `sequence` (its own clock: one pose a tick).
bool WaitForPose(Reader<hapco_idl_DevicePose>& pose_reader, uint64_t sequence, dds_time_t deadline) {
  hapco_idl_DevicePose pose{};
  bool reached = false;
  while (!reached && dds_time() < deadline) {
    if (!pose_reader.WaitForData(DDS_MSECS(100))) continue;
    while (pose_reader.Take(&pose)) reached = reached || pose.sequence_number >= sequence;
  }
  return reached;
}

TEST(ServerFailover, ClientRampsToZeroWhenTheServerDiesAndResumesWhenOneReturns) {
  const std::string dir = TestDir();
  const dds_domainid_t domain = SetUpTestDomain();
  const std::string trajectory = WritePressTrajectory(dir);

  ClientWatch watch(domain, "phantom-1");

  auto first_server = std::make_unique<Process>(
      std::vector<std::string>{HAPCO_SERVER_EXE, kScene, "--domain", std::to_string(domain)}, dir + "/server1.out",
      dir + "/server1.err");
  Process phantom({HAPCO_PHANTOM_EXE, kScene, "--client-id", "phantom-1", "--domain", std::to_string(domain),
                   "--trajectory", trajectory, "--duration-s", "5", "--force-timeout-ms", "50", "--csv",
                   dir + "/phantom.csv", "--connect-timeout-s", "60"},
                  dir + "/phantom.out", dir + "/phantom.err");

  // Kill the server while it is pushing back (a force above 1 N, after the press).
  const dds_time_t deadline = dds_time() + DDS_SECS(60);
  const uint64_t killed_after_sequence = FirstPushingForce(watch.forces, deadline);
  ASSERT_GT(killed_after_sequence, 0u) << "no force above 1 N: " << ReadFile(dir + "/server1.err");
  first_server->Signal(SIGKILL);
  ASSERT_EQ(first_server->Wait(10'000), 128 + SIGKILL);
  first_server.reset();

  // Let the client's own clock pass timeout + ramp + margin (its poses carry its ticks).
  ASSERT_TRUE(WaitForPose(watch.poses, killed_after_sequence + 200, deadline)) << "the phantom stopped publishing";
  Process second_server({HAPCO_SERVER_EXE, kScene, "--domain", std::to_string(domain)}, dir + "/server2.out",
                        dir + "/server2.err");
  ASSERT_EQ(phantom.Wait(60'000), 0) << ReadFile(dir + "/phantom.err");
  second_server.Signal(SIGTERM);
  ASSERT_EQ(second_server.Wait(30'000), 0) << ReadFile(dir + "/server2.err");
  const std::string phantom_out = ReadFile(dir + "/phantom.out");
  std::printf("%s", phantom_out.c_str());

  const std::vector<Tick> ticks = ReadTicks(dir + "/phantom.csv");
  ASSERT_GE(ticks.size(), 4000u);
  // Every tick: finite, within the device limit, rate limited (250 N/s: 0.25 N per tick, more
  // only across missed ticks during a timeout ramp).
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    ASSERT_TRUE(ticks[i].rendered_n.allFinite()) << ticks[i].tick;
    ASSERT_LE(ticks[i].rendered_n.norm(), kMaxForceN + 1e-12) << ticks[i].tick;
    if (i > 0) {
      // (+250 N/s x 2 us: the CSV's times are rounded to the microsecond)
      const double allowed_n = std::max(kMaxChangePerTickN, 250.0 * (ticks[i].time_s - ticks[i - 1].time_s)) + 5e-4;
      ASSERT_LE((ticks[i].rendered_n - ticks[i - 1].rendered_n).norm(), allowed_n) << ticks[i].tick;
    }
  }
  // The outage: the longest time without a force.
  std::size_t gap_begin = 0, gap_end = 0, last_fresh = 0;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    if (ticks[i].force_sequence < 0) continue;
    if (ticks[i].time_s - ticks[last_fresh].time_s > ticks[gap_end].time_s - ticks[gap_begin].time_s) {
      gap_begin = last_fresh;
      gap_end = i;
    }
    last_fresh = i;
  }
  const double before_n = ticks[gap_begin].rendered_n.norm();
  // The ramp starts from the force rendered when the timeout expires, which may still have
  // been rising (rate limited) towards the last force: bound its duration with the limit.
  const double timeout_at_s = ticks[gap_begin].time_s + kTimeoutS;
  const double zero_from_s = timeout_at_s + RampDurationS(kMaxForceN);
  ASSERT_GT(ticks[gap_end].time_s, zero_from_s + 0.02) << "no outage seen";
  EXPECT_GT(before_n, 0.5) << "the server was killed while pushing";
  // After the timeout the force never grows, and it is zero once timeout + ramp have passed
  // (+1.5 ms: the last fresh force was taken up to a tick after it arrived).
  std::size_t zero_ticks = 0;
  for (std::size_t i = gap_begin + 1; i < gap_end; ++i) {
    if (ticks[i - 1].time_s > timeout_at_s + 0.0015) {
      EXPECT_LE(ticks[i].rendered_n.norm(), ticks[i - 1].rendered_n.norm() + 1e-12) << ticks[i].tick;
    }
    if (ticks[i].time_s >= zero_from_s + 0.0015) {
      // Zero by then, unless this client stalled during the ramp: a late tick still drops the
      // force by at most kMaxChangePerTickN (no click, SafetyFilter), so until it reaches zero
      // every tick must drop by exactly that much (a CI run saw 1.175 N 2 ms past the deadline
      // after a 92-tick stall).
      const double now_n = ticks[i].rendered_n.norm(), before_tick_n = ticks[i - 1].rendered_n.norm();
      if (now_n != 0.0) {
        ASSERT_NEAR(now_n, before_tick_n - kMaxChangePerTickN, 1e-3)
            << "t = " << ticks[i].time_s << " s, outage from " << ticks[gap_begin].time_s << " s to "
            << ticks[gap_end].time_s << " s, force before " << before_n << " N: not zero and not catching up";
      } else {
        ++zero_ticks;
      }
    }
  }
  EXPECT_GT(zero_ticks, 10u);
  // Forces resumed with the new server: fresh forces after the outage, and at the end the
  // client renders (rate limited back up) what it rendered before the kill: the same held
  // pose on the same scene. 5 %: the restarted session reaches the pose in one increment,
  // the first in thirty, so friction history differs slightly.
  std::size_t fresh_after = 0;
  for (std::size_t i = gap_end; i < ticks.size(); ++i) fresh_after += ticks[i].force_sequence >= 0 ? 1 : 0;
  EXPECT_GT(fresh_after, 500u);
  EXPECT_NEAR(ticks.back().rendered_n.norm(), before_n, 0.05 * before_n);
  // At least this outage timed out and resumed (a loaded machine can stall a client for
  // longer than the timeout on its own: more pairs, always resumed).
  unsigned timeouts = 0, resumed = 0;
  const auto at = phantom_out.find("force timeouts ");
  ASSERT_NE(at, std::string::npos) << phantom_out;
  ASSERT_EQ(std::sscanf(phantom_out.c_str() + at, "force timeouts %u, resumed %u", &timeouts, &resumed), 2);
  EXPECT_GE(timeouts, 1u);
  EXPECT_EQ(resumed, timeouts);
  EXPECT_NE(ReadFile(dir + "/phantom.err").find("ramping the force to zero"), std::string::npos);
  EXPECT_NE(ReadFile(dir + "/server2.out").find("1 sessions opened"), std::string::npos);
}

// A server stalled for 0.8 s (SIGSTOP: a host that froze, a link that came back) answers, once
// it runs again, the poses queued since the stall began. Those answers are 0.8 s old: the
// device may be anywhere by then, so they are not rendered (a helper session saw a device
// lifted into free air render 1.5-2 N for 11-15 ticks as "forces resumed", from answers to
// poses 3 s old). The fresh answers after them are.
TEST(ServerFailover, AnswersToPosesLongPastAreNotRenderedAfterAServerStall) {
  const std::string dir = TestDir();
  const dds_domainid_t domain = SetUpTestDomain();
  const std::string trajectory = WritePressTrajectory(dir);
  ClientWatch watch(domain, "phantom-1");
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", std::to_string(domain)}, dir + "/server.out",
                 dir + "/server.err");
  Process phantom({HAPCO_PHANTOM_EXE, kScene, "--client-id", "phantom-1", "--domain", std::to_string(domain),
                   "--trajectory", trajectory, "--duration-s", "4", "--csv", dir + "/phantom.csv",
                   "--connect-timeout-s", "60"},
                  dir + "/phantom.out", dir + "/phantom.err");
  // Stall the server while it pushes back, for 800 of the client's ticks (its poses count them).
  const dds_time_t deadline = dds_time() + DDS_SECS(60);
  const uint64_t stalled_after = FirstPushingForce(watch.forces, deadline);
  ASSERT_GT(stalled_after, 0u) << "no force above 1 N: " << ReadFile(dir + "/server.err");
  server.Signal(SIGSTOP);
  const bool reached = WaitForPose(watch.poses, stalled_after + 800, deadline);
  server.Signal(SIGCONT);
  ASSERT_TRUE(reached) << "the phantom stopped publishing";
  ASSERT_EQ(phantom.Wait(60'000), 0) << ReadFile(dir + "/phantom.err");
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0) << ReadFile(dir + "/server.err");
  const std::string phantom_out = ReadFile(dir + "/phantom.out");
  std::printf("%s", phantom_out.c_str());

  // Whether answers to the stalled poses arrive at all depends on the server's DDS receive
  // thread: it may deliver the backlog before the loop takes it (the newest poses only: fresh
  // answers) or while it takes it (old ones first). Most runs get old ones (7, 16, 30 counted);
  // one beside the full test suite got none. The check below holds either way; the count says
  // whether this run exercised it.
  unsigned long long old_answers = 0;
  const auto at = phantom_out.find(" answers to poses older than 500 ms");
  if (at != std::string::npos) {
    ASSERT_EQ(std::sscanf(phantom_out.c_str() + phantom_out.rfind('\n', at) + 1, " %llu", &old_answers), 1);
    EXPECT_NE(ReadFile(dir + "/phantom.err").find("not rendered (--max-answer-age-ms 500)"), std::string::npos);
  }
  std::printf("answers to poses older than 500 ms that arrived: %llu\n", old_answers);
  // No force taken (rendered) was an answer to a pose older than 500 ms.
  std::size_t rows = 0, fresh_after_stall = 0;
  double before_n = 0;
  for (const auto& row : ReadCsv(dir + "/phantom.csv")) {
    ++rows;
    const long long sequence = std::stoll(row.at("force_sequence"));
    if (sequence < 0) continue;
    EXPECT_LE(std::stod(row.at("round_trip_us")), 500e3) << "tick " << row.at("tick");
    if (static_cast<uint64_t>(sequence) <= stalled_after) before_n = Vec(row, "fx_n", "fy_n", "fz_n").norm();
    if (static_cast<uint64_t>(sequence) > stalled_after + 800) ++fresh_after_stall;
  }
  EXPECT_GE(rows, 4000u);
  EXPECT_GT(fresh_after_stall, 500u) << "fresh forces resumed after the stall";
  EXPECT_GT(before_n, 1.0);
}

TEST(ServerFailover, AClientBeyondMaxSessionsIsRefusedWithAClearMessage) {
  const std::string dir = TestDir();
  const dds_domainid_t domain_id = SetUpTestDomain();
  const std::string domain = std::to_string(domain_id);
  Participant participant(domain_id);
  Topic<hapco_idl_FeedbackForce> force_topic(participant);
  Subscriber first_subscriber(participant, ClientPartition("first"));
  Reader<hapco_idl_FeedbackForce> first_forces(first_subscriber, force_topic);

  Process server({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--max-sessions", "1"}, dir + "/server.out",
                 dir + "/server.err");
  Process first({HAPCO_PHANTOM_EXE, kScene, "--client-id", "first", "--domain", domain, "--duration-s", "20",
                 "--connect-timeout-s", "60"},
                dir + "/first.out", dir + "/first.err");
  // The first client holds the only session once its forces flow.
  ASSERT_TRUE(first_forces.WaitForData(DDS_SECS(60))) << ReadFile(dir + "/first.err");
  // The second client waits for its session, which never opens: exit 2 with the reason.
  Process second({HAPCO_PHANTOM_EXE, kScene, "--client-id", "second", "--domain", domain, "--connect-timeout-s", "3"},
                 dir + "/second.out", dir + "/second.err");
  EXPECT_EQ(second.Wait(60'000), 2);
  EXPECT_NE(ReadFile(dir + "/second.err").find("did not open a session for 'second'"), std::string::npos)
      << ReadFile(dir + "/second.err");
  EXPECT_NE(ReadFile(dir + "/second.err").find("full: "), std::string::npos) << ReadFile(dir + "/second.err");
  // A client asking for a server that does not exist is told so, with the servers heard (it was
  // told "server full, or it does not serve scene ...?"); hapco-status likewise.
  Process nope({HAPCO_PHANTOM_EXE, kScene, "--client-id", "third", "--domain", domain, "--connect-timeout-s", "3",
                "--server-id", "nope"},
               dir + "/nope.out", dir + "/nope.err");
  EXPECT_EQ(nope.Wait(60'000), 2);
  EXPECT_NE(ReadFile(dir + "/nope.err").find("no server 'nope' announced itself; servers heard: hapco-"),
            std::string::npos)
      << ReadFile(dir + "/nope.err");
  Process status({HAPCO_STATUS_EXE, "--domain", domain, "--server-id", "nope", "--connect-timeout-s", "3"},
                 dir + "/status.out", dir + "/status.err");
  EXPECT_EQ(status.Wait(60'000), 1);
  EXPECT_NE(ReadFile(dir + "/status.err").find("no status of server 'nope' in domain " + domain), std::string::npos)
      << ReadFile(dir + "/status.err");
  EXPECT_NE(ReadFile(dir + "/status.err").find("servers heard: hapco-"), std::string::npos)
      << ReadFile(dir + "/status.err");
  first.Signal(SIGINT);  // a phantom stopped early leaves its session and exits 0
  EXPECT_EQ(first.Wait(30'000), 0) << ReadFile(dir + "/first.err");
  EXPECT_NE(ReadFile(dir + "/first.out").find("stopped by signal"), std::string::npos);
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0);
  EXPECT_NE(ReadFile(dir + "/server.err").find("session refused for 'second'"), std::string::npos)
      << ReadFile(dir + "/server.err");
}

// A client killed without a LEAVE (SIGKILL) held its session for good: with --max-sessions 1
// the next client was refused for as long as the server ran. After --session-idle-s without a
// pose or session message the session is closed and its slot serves the next client.
TEST(ServerFailover, AKilledClientsSessionIsClosedWhenIdleAndItsSlotServesTheNext) {
  const std::string dir = TestDir();
  const dds_domainid_t domain_id = SetUpTestDomain();
  const std::string domain = std::to_string(domain_id);
  Participant participant(domain_id);
  Topic<hapco_idl_FeedbackForce> force_topic(participant);
  Subscriber subscriber(participant, ClientPartition("killed"));
  Reader<hapco_idl_FeedbackForce> killed_forces(subscriber, force_topic);
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--max-sessions", "1", "--session-idle-s", "1",
                  "--status-period-s", "0.2"},
                 dir + "/server.out", dir + "/server.err");
  Process killed({HAPCO_PHANTOM_EXE, kScene, "--client-id", "killed", "--domain", domain, "--duration-s", "60",
                  "--connect-timeout-s", "60"},
                 dir + "/killed.out", dir + "/killed.err");
  ASSERT_TRUE(killed_forces.WaitForData(DDS_SECS(60))) << ReadFile(dir + "/killed.err");
  killed.Signal(SIGKILL);
  killed.Wait(30'000);
  // The next client waits up to 20 s for its session: it opens about 1 s after the kill.
  Process next({HAPCO_PHANTOM_EXE, kScene, "--client-id", "next", "--domain", domain, "--connect-timeout-s", "20"},
               dir + "/next.out", dir + "/next.err");
  EXPECT_EQ(next.Wait(120'000), 0) << ReadFile(dir + "/next.err");
  EXPECT_NE(ReadFile(dir + "/next.out").find("forces received"), std::string::npos) << ReadFile(dir + "/next.out");
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0);
  const std::string log = ReadFile(dir + "/server.err") + ReadFile(dir + "/server.out");
  EXPECT_NE(log.find("session closed for 'killed': nothing heard from it for"), std::string::npos) << log;
  EXPECT_NE(log.find("sessions closed after --session-idle-s without a message 1"), std::string::npos) << log;
}

// A client that moved to another server: its poses sent before the move, addressed to the
// server it left and arriving there late, open no session there (a helper session saw such a
// pose open one, logged as "a client that moved here", closed again at once). A pose it sends
// after the move, addressed here again, is a client coming back: served.
TEST(ServerFailover, APoseSentBeforeAMoveAndArrivingLateOpensNoSession) {
  const std::string dir = TestDir();
  const dds_domainid_t domain = SetUpTestDomain();
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", std::to_string(domain), "--server-id", "s1",
                  "--status-period-s", "0.05"},
                 dir + "/server.out", dir + "/server.err");
  Participant participant(domain);
  Topic<hapco_idl_DevicePose> pose_topic(participant);
  Topic<hapco_idl_SessionControl> session_topic(participant);
  Topic<hapco_idl_FeedbackForce> force_topic(participant);
  Topic<hapco_idl_ServerStatus> status_topic(participant);
  Publisher publisher(participant, ClientPartition("mover"));
  Subscriber client_subscriber(participant, ClientPartition("mover"));
  Subscriber default_partition(participant);
  Writer<hapco_idl_DevicePose> pose_writer(publisher, pose_topic);
  Writer<hapco_idl_SessionControl> session_writer(publisher, session_topic);
  Reader<hapco_idl_FeedbackForce> forces(client_subscriber, force_topic);
  Reader<hapco_idl_ServerStatus> statuses(default_partition, status_topic, StatusQos());
  ASSERT_TRUE(pose_writer.WaitForReaders(1, DDS_SECS(60))) << ReadFile(dir + "/server.err");
  ASSERT_TRUE(session_writer.WaitForReaders(1, DDS_SECS(60)));

  auto control = [&](hapco_idl_SessionCommand command, const char* server_id) {
    hapco_idl_SessionControl c{};
    SetClientId(c.client_id, "mover");
    c.command = command;
    std::snprintf(c.server_id, sizeof c.server_id, "%s", server_id);
    c.client_time_ns = MonotonicNowNs();
    ASSERT_EQ(session_writer.Write(c), DDS_RETCODE_OK);
  };
  hapco_idl_DevicePose pose{};
  SetClientId(pose.client_id, "mover");
  std::snprintf(pose.server_id, sizeof pose.server_id, "s1");
  pose.orientation = {1, 0, 0, 0};
  uint64_t sequence = 0;
  // Writes poses (client time `client_time_ns`, 0: now) until a force answers one, at most
  // `attempts` times 50 ms. True when one did.
  auto answered = [&](int64_t client_time_ns, int attempts) {
    hapco_idl_FeedbackForce force{};
    for (int k = 0; k < attempts; ++k) {
      pose.sequence_number = ++sequence;
      pose.client_time_ns = client_time_ns != 0 ? client_time_ns : MonotonicNowNs();
      EXPECT_EQ(pose_writer.Write(pose), DDS_RETCODE_OK);
      if (!forces.WaitForData(DDS_MSECS(50))) continue;
      while (forces.Take(&force)) {
        if (force.pose_verdict == hapco_idl_POSE_STEPPED) return true;
      }
    }
    return false;
  };
  auto sessions_become = [&](uint32_t count) {
    hapco_idl_ServerStatus status{};
    for (const dds_time_t deadline = dds_time() + DDS_SECS(30); dds_time() < deadline;) {
      if (!statuses.WaitForData(DDS_MSECS(100))) continue;
      while (statuses.Take(&status)) {
        if (status.sessions == count) return true;
      }
    }
    return false;
  };
  control(hapco_idl_SESSION_JOIN, "s1");
  ASSERT_TRUE(answered(0, 600)) << ReadFile(dir + "/server.err");
  const int64_t before_move_ns = MonotonicNowNs();  // the late poses' send time
  control(hapco_idl_SESSION_JOIN, "s2");            // it moves to s2
  ASSERT_TRUE(sessions_become(0)) << ReadFile(dir + "/server.err");
  // Poses sent before the move, arriving now: none answered, no session.
  EXPECT_FALSE(answered(before_move_ns, 20)) << ReadFile(dir + "/server.err");
  ASSERT_TRUE(sessions_become(0));
  // It comes back (a pose sent now, addressed here): served, the server still listening.
  EXPECT_TRUE(answered(0, 600)) << ReadFile(dir + "/server.err");
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0);
  const std::string log = ReadFile(dir + "/server.err");
  int opened = 0;
  for (std::size_t at = log.find("session opened for 'mover'"); at != std::string::npos;
       at = log.find("session opened for 'mover'", at + 1)) {
    ++opened;
  }
  EXPECT_EQ(opened, 2) << log;  // the first join and the return, nothing between
  EXPECT_NE(log.find("session closed for 'mover': it joined server 's2'"), std::string::npos) << log;
}

// Two servers started with one --server-id on one domain would both answer the clients
// addressed to it (a helper session: every pose stepped twice, the recording 1 516 sessions).
// The one started later stops with exit code 1 and says why; the first keeps serving.
TEST(ServerFailover, ASecondServerWithTheSameIdStopsAndSaysWhy) {
  const std::string dir = TestDir();
  const dds_domainid_t domain_id = SetUpTestDomain();
  const std::string domain = std::to_string(domain_id);
  Participant participant(domain_id);
  Topic<hapco_idl_ServerStatus> status_topic(participant);
  Subscriber default_partition(participant);
  Reader<hapco_idl_ServerStatus> statuses(default_partition, status_topic, StatusQos());
  Process first({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--server-id", "twin", "--status-period-s", "0.1"},
                dir + "/first.out", dir + "/first.err");
  hapco_idl_ServerStatus status{};
  bool announced = false;
  for (const dds_time_t deadline = dds_time() + DDS_SECS(60); !announced && dds_time() < deadline;) {
    if (statuses.WaitForData(DDS_MSECS(200))) announced = statuses.Take(&status);
  }
  ASSERT_TRUE(announced) << ReadFile(dir + "/first.err");
  Process second({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--server-id", "twin"}, dir + "/second.out",
                 dir + "/second.err");
  EXPECT_EQ(second.Wait(60'000), 1) << ReadFile(dir + "/second.err");
  EXPECT_NE(ReadFile(dir + "/second.err").find("already announces --server-id 'twin'"), std::string::npos)
      << ReadFile(dir + "/second.err");
  EXPECT_NE(ReadFile(dir + "/second.out").find("stopped by a duplicate --server-id"), std::string::npos);
  // The first still serves: it announces itself after the second has gone, and stops cleanly.
  while (statuses.Take(&status)) {
  }
  ASSERT_TRUE(statuses.WaitForData(DDS_SECS(30)));
  ASSERT_TRUE(statuses.Take(&status));
  EXPECT_STREQ(status.server_id, "twin");
  first.Signal(SIGTERM);
  ASSERT_EQ(first.Wait(30'000), 0) << ReadFile(dir + "/first.err");
  EXPECT_NE(ReadFile(dir + "/first.err").find("it stops, this one keeps serving"), std::string::npos)
      << ReadFile(dir + "/first.err");
}

// Several servers on one domain (docs/several-servers.md): three servers, four clients that
// choose their server from the announcements. Each client is answered by one server only; when
// the server with the most clients is killed, each of its clients moves to another server and
// has forces again within 100 ms of its safety timeout, with the device limits kept throughout;
// no pose is ever answered by two servers.
TEST(ServerFailover, ThreeServersServeEachClientOnceAndTakeOverTheClientsOfOneThatDies) {
  const std::string dir = TestDir();
  const dds_domainid_t domain_id = SetUpTestDomain();
  const std::string domain = std::to_string(domain_id);
  const std::string trajectory = WritePressTrajectory(dir);
  Participant participant(domain_id);
  Topic<hapco_idl_FeedbackForce> force_topic(participant);
  Topic<hapco_idl_ServerStatus> status_topic(participant);
  Subscriber all_clients(participant, kAllClientsPartition);
  Subscriber default_partition(participant);
  Reader<hapco_idl_FeedbackForce> forces(all_clients, force_topic, ForceQos().KeepLast(64));
  Reader<hapco_idl_ServerStatus> statuses(default_partition, status_topic, StatusQos());

  const std::vector<std::string> ids = {"s1", "s2", "s3"};
  std::map<std::string, std::unique_ptr<Process>> servers;
  for (const std::string& id : ids) {
    servers[id] = std::make_unique<Process>(
        std::vector<std::string>{HAPCO_SERVER_EXE, kScene, "--domain", domain, "--server-id", id, "--threads", "1",
                                 "--trace", dir + "/trace-" + id + ".csv"},
        dir + "/server-" + id + ".out", dir + "/server-" + id + ".err");
  }
  // All three announce themselves before any client chooses.
  std::set<std::string> announced;
  const dds_time_t deadline = dds_time() + DDS_SECS(90);
  hapco_idl_ServerStatus status{};
  while (announced.size() < ids.size() && dds_time() < deadline) {
    if (!statuses.WaitForData(DDS_MSECS(200))) continue;
    while (statuses.Take(&status)) announced.insert(ServerIdOf(status.server_id));
  }
  ASSERT_EQ(announced.size(), ids.size()) << ReadFile(dir + "/server-s1.err");
  // hapco-status lists every server of the domain, one line each.
  Process status_tool({HAPCO_STATUS_EXE, "--domain", domain}, dir + "/status.out", dir + "/status.err");
  ASSERT_EQ(status_tool.Wait(60'000), 0) << ReadFile(dir + "/status.err");
  for (const std::string& id : ids) {
    EXPECT_NE(ReadFile(dir + "/status.out").find("server " + id + ", domain " + domain + ", serving for "), std::string::npos)
        << ReadFile(dir + "/status.out");
  }
  // A recorder of every session on every server (steps carry the server that made them).
  const std::string recording = dir + "/sessions.hapcorec";
  Process recorder({HAPCO_RECORDER_EXE, kScene, "--output", recording, "--domain", domain}, dir + "/recorder.out",
                   dir + "/recorder.err");
  ASSERT_TRUE(WaitForText(dir + "/recorder.out", "found", 60'000)) << ReadFile(dir + "/recorder.err");

  constexpr int kClients = 4;
  std::vector<std::unique_ptr<Process>> phantoms;
  for (int k = 1; k <= kClients; ++k) {
    const std::string id = "phantom-" + std::to_string(k);
    phantoms.push_back(std::make_unique<Process>(
        std::vector<std::string>{HAPCO_PHANTOM_EXE, kScene, "--client-id", id, "--domain", domain, "--trajectory",
                                 trajectory, "--duration-s", "6", "--force-timeout-ms", "50", "--csv",
                                 dir + "/" + id + ".csv", "--connect-timeout-s", "60"},
        dir + "/" + id + ".out", dir + "/" + id + ".err"));
  }

  // Who answers whom, as the forces arrive here (stamped on arrival).
  struct Seen {
    std::set<std::string> servers;
    std::string last_server;
    int64_t last_arrival_ns = 0;
    std::map<uint64_t, std::string> answered_by;  // pose sequence -> server
  };
  std::map<std::string, Seen> seen;
  std::vector<std::string> doubles;  // "client sequence: server a and server b"
  auto take_forces = [&](std::map<std::string, int64_t>* first_after_kill, const std::string& killed) {
    hapco_idl_FeedbackForce f{};
    while (forces.Take(&f)) {
      if (f.pose_verdict != hapco_idl_POSE_STEPPED) continue;
      const int64_t now = MonotonicNowNs();
      const std::string client = ClientIdOf(f.client_id), server = ServerIdOf(f.server_id);
      Seen& s = seen[client];
      auto [it, inserted] = s.answered_by.emplace(f.pose_sequence, server);
      if (!inserted && it->second != server) {
        doubles.push_back(client + " " + std::to_string(f.pose_sequence) + ": " + it->second + " and " + server);
      }
      if (first_after_kill != nullptr && server != killed && s.last_server == killed &&
          first_after_kill->count(client) == 0) {
        (*first_after_kill)[client] = now - s.last_arrival_ns;  // the gap this client saw
      }
      if (first_after_kill == nullptr || server != killed) {
        s.servers.insert(server);
        s.last_server = server;
        s.last_arrival_ns = now;
      }
    }
  };
  // Every client served and pushing (its forces come from one server each) for 1 s.
  while (dds_time() < deadline) {
    if (forces.WaitForData(DDS_MSECS(100))) take_forces(nullptr, "");
    bool all = seen.size() == kClients;
    for (const auto& [client, s] : seen) all = all && s.answered_by.size() >= 1000;
    if (all) break;
  }
  ASSERT_EQ(seen.size(), static_cast<std::size_t>(kClients)) << ReadFile(dir + "/phantom-1.err");
  std::map<std::string, int> clients_of;
  for (const auto& [client, s] : seen) {
    // (One server each unless a loaded machine stalled the client past its timeout: then it
    // moved, and its old server stopped answering it.)
    if (s.servers.size() > 1) std::printf("%s moved before the kill\n", client.c_str());
    ++clients_of[s.last_server];
  }
  EXPECT_GE(clients_of.size(), 2u) << "the clients did not spread over the servers";
  std::string killed;
  for (const auto& [server, count] : clients_of) {
    if (killed.empty() || count > clients_of[killed]) killed = server;
  }
  std::printf("clients per server before the kill:");
  for (const auto& [server, count] : clients_of) std::printf(" %s %d", server.c_str(), count);
  std::printf("; killing %s\n", killed.c_str());
  servers[killed]->Signal(SIGKILL);
  ASSERT_EQ(servers[killed]->Wait(10'000), 128 + SIGKILL);

  // Until every phantom has ended: forces of the moved clients from the other servers.
  std::map<std::string, int64_t> gap_ns;
  std::vector<int> exit_codes(kClients, -1);
  for (std::size_t k = 0; k < exit_codes.size(); ++k) {
    while ((exit_codes[k] = phantoms[k]->Wait(0)) == -1 && dds_time() < deadline) {
      if (forces.WaitForData(DDS_MSECS(50))) take_forces(&gap_ns, killed);
    }
  }
  take_forces(&gap_ns, killed);
  for (std::size_t k = 0; k < exit_codes.size(); ++k) {
    const std::string id = "phantom-" + std::to_string(k + 1);
    EXPECT_EQ(exit_codes[k], 0) << id << ": " << ReadFile(dir + "/" + id + ".err");
  }
  EXPECT_TRUE(doubles.empty()) << doubles.size() << " poses answered by two servers, first " << doubles.front();
  for (const auto& [client, s] : seen) {
    const std::string out = ReadFile(dir + "/" + client + ".out");
    if (clients_of.count(killed) != 0 && gap_ns.count(client) == 0 && s.servers.count(killed) != 0) {
      ADD_FAILURE() << client << " was served by " << killed << " and never got a force from another server: "
                    << ReadFile(dir + "/" + client + ".err");
      continue;
    }
    if (gap_ns.count(client) != 0) {
      // (The gap as this test's reader saw it, which includes the test process's own stalls;
      // the bound is checked below on what the device saw.)
      std::printf("%s moved from %s to %s: %.1f ms between forces seen by the test\n", client.c_str(), killed.c_str(),
                  s.last_server.c_str(), static_cast<double>(gap_ns[client]) * 1e-6);
      EXPECT_EQ(out.find("moved to another server 0 times"), std::string::npos) << out;
    }
    // (A client of a surviving server may move too: on a loaded machine its own stalls can
    // pass the timeout. Wherever it went, it ended on a live server.)
    EXPECT_EQ(out.find("served by '" + killed + "' at the end"), std::string::npos) << out;
    EXPECT_NE(out.find("served by 's"), std::string::npos) << out;
    // The device limits in every tick, across the move.
    const std::vector<Tick> ticks = ReadTicks(dir + "/" + client + ".csv");
    ASSERT_GE(ticks.size(), 5000u) << client;
    for (std::size_t i = 1; i < ticks.size(); ++i) {
      ASSERT_TRUE(ticks[i].rendered_n.allFinite()) << client << " tick " << ticks[i].tick;
      ASSERT_LE(ticks[i].rendered_n.norm(), kMaxForceN + 1e-12) << client << " tick " << ticks[i].tick;
      const double allowed_n = std::max(kMaxChangePerTickN, 250.0 * (ticks[i].time_s - ticks[i - 1].time_s)) + 5e-4;
      ASSERT_LE((ticks[i].rendered_n - ticks[i - 1].rendered_n).norm(), allowed_n) << client << " tick " << ticks[i].tick;
    }
  }
  EXPECT_EQ(gap_ns.size(), static_cast<std::size_t>(clients_of[killed]));
  // The servers' own traces: no (client, pose) stepped by two servers, and every force a
  // client took was stepped by a server whose trace has it: a trace row is written before its
  // force is published, so the killed server's trace holds every force it sent (it used to be
  // written after a batch was published: a helper session found 8-27 forces of a killed
  // server missing from its trace).
  std::map<std::pair<std::string, std::string>, std::string> stepped_by;
  for (const std::string& id : ids) {
    if (id != killed) {
      servers[id]->Signal(SIGTERM);
      ASSERT_EQ(servers[id]->Wait(30'000), 0) << ReadFile(dir + "/server-" + id + ".err");
    }
    for (const auto& row : ReadCsv(dir + "/trace-" + id + ".csv")) {
      if (row.count("step_us") == 0) continue;  // the killed server's last row, torn by the kill
      auto [it, inserted] = stepped_by.emplace(std::make_pair(row.at("client_id"), row.at("sequence")), id);
      ASSERT_TRUE(inserted) << row.at("client_id") << " pose " << row.at("sequence") << " stepped by " << it->second
                            << " and " << id;
    }
  }
  // What each moved device saw (its own per-tick CSV, its clock): from the tick that took the
  // killed server's last force to the first that took another server's. Timeout (50 ms) + a
  // new session on another server: forces again within 100 ms of the timeout. (Measured on
  // the test's reader, a loaded CI host once stalled the test itself for 3.5 s while the
  // devices had forces again after ~70 ms.)
  for (const auto& [client, gap] : gap_ns) {
    const std::vector<Tick> ticks = ReadTicks(dir + "/" + client + ".csv");
    auto server_of = [&](long long sequence) -> std::string {
      if (sequence < 0) return "";
      const auto it = stepped_by.find({client, std::to_string(sequence)});
      return it == stepped_by.end() ? "?" : it->second;
    };
    double last_killed_s = -1, first_other_s = -1;
    for (const Tick& t : ticks) {
      const std::string server = server_of(t.force_sequence);
      if (server == killed) {
        last_killed_s = t.time_s;
      } else if (!server.empty() && server != "?" && last_killed_s >= 0 && first_other_s < 0) {
        first_other_s = t.time_s;
      }
    }
    ASSERT_GE(last_killed_s, 0) << client << ": no force of " << killed << " in its CSV";
    ASSERT_GE(first_other_s, 0) << client << ": no force of another server after " << killed << "'s last";
    const double device_gap_ms = (first_other_s - last_killed_s) * 1e3;
    std::printf("%s: %.1f ms without a force on the device (its CSV)\n", client.c_str(), device_gap_ms);
    EXPECT_LT(device_gap_ms, kTimeoutS * 1e3 + 100.0) << client;
  }
  // Each server's log names every client it took over (they come at once: at one session line
  // a second, a helper session's log named 2 of 4 takeovers).
  for (const auto& [client, gap] : gap_ns) {
    const std::string log = ReadFile(dir + "/server-" + seen[client].last_server + ".err");
    EXPECT_NE(log.find("session opened for '" + client + "'"), std::string::npos) << log;
  }
  // (Every stepped force this test's reader saw, the killed server's last ones included.)
  for (const auto& [client, s] : seen) {
    EXPECT_GT(s.answered_by.size(), 1000u) << client;
    for (const auto& [sequence, server] : s.answered_by) {
      const auto it = stepped_by.find({client, std::to_string(sequence)});
      ASSERT_NE(it, stepped_by.end()) << client << " pose " << sequence << ": its force came from " << server
                                      << ", whose trace does not have it";
      EXPECT_EQ(it->second, server) << client << " pose " << sequence;
    }
  }
  // The report tells each moved client's sessions apart: one on the killed server, then one on
  // the server it moved to, each counted from its own step 1.
  recorder.Signal(SIGTERM);
  ASSERT_EQ(recorder.Wait(30'000), 0) << ReadFile(dir + "/recorder.err");
  Process report({HAPCO_REPORT_EXE, recording}, dir + "/report.out", dir + "/report.err");
  ASSERT_EQ(report.Wait(60'000), 0) << ReadFile(dir + "/report.err");
  const std::string report_text = ReadFile(dir + "/report.out");
  for (const auto& [client, gap] : gap_ns) {
    const auto line_at = report_text.find("client     " + client + ": ");
    ASSERT_NE(line_at, std::string::npos) << report_text;
    const std::string line = report_text.substr(line_at, report_text.find('\n', line_at) - line_at);
    std::printf("%s\n", line.c_str());
    EXPECT_EQ(line.find(" in 1 session "), std::string::npos) << line;
    EXPECT_NE(line.find("1.."), std::string::npos) << line;
    EXPECT_NE(line.find(" on " + killed), std::string::npos) << line;
    EXPECT_NE(line.find(" on " + seen[client].last_server), std::string::npos) << line;
  }
  // Each server's status records and counters are its own, the killed one's included.
  EXPECT_NE(report_text.find(" servers: "), std::string::npos) << report_text;
  for (const std::string& id : {killed, seen.begin()->second.last_server}) {
    EXPECT_NE(report_text.find("server     " + id + ": "), std::string::npos) << id << "\n" << report_text;
  }
  // Most of the 4 x 6000 poses (under load some are superseded; the killed trace loses its buffer).
  EXPECT_GT(stepped_by.size(), static_cast<std::size_t>(kClients) * 3000u);
}

}  // namespace
}  // namespace hapco::service
