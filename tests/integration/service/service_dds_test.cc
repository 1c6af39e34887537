// Integration tests of hapco::service: real Cyclone DDS entities on loopback.
// Each test: own domain id (from its name) + loopback config (test_support.h). No sleeps:
// waits are waitsets (data, matching), dds_wait_for_acks, or bounded polls with a deadline.
// Tests marked "AcrossProcesses" fork a peer, so samples travel over UDP on 127.0.0.1 with
// the no-multicast discovery of the loopback config (in one process Cyclone delivers
// locally and the network path is never exercised).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <vector>

#include <dds/ddsc/dds_statistics.h>

#include "common/error.h"
#include "service/config.h"
#include "service/dds.h"
#include "service/qos.h"
#include "test_support.h"

namespace hapco::service {
namespace {

using testing::ChildProcess;
using testing::kDataTimeoutNs;
using testing::kDiscoveryTimeoutNs;
using testing::SetUpTestDomain;

void FillPose(const char* client_id, uint64_t sequence, hapco_idl_DevicePose* pose) {
  SetClientId(pose->client_id, client_id);
  pose->sequence_number = sequence;
  pose->client_time_ns = 1'000'000'007LL * static_cast<int64_t>(sequence + 1);
  pose->position_m = {0.001 * static_cast<double>(sequence), -0.25, 0.125};
  pose->orientation = {0.5, 0.5, -0.5, 0.5};  // unit quaternion
  pose->buttons = 0x5u;
}

// Best effort may lose a sample: write until the reader has one, bounded by a deadline.
template <typename T>
bool WriteUntilReceived(Writer<T>& writer, const T& sample, Reader<T>& reader) {
  const dds_time_t deadline = dds_time() + kDataTimeoutNs;
  while (dds_time() < deadline) {
    if (writer.Write(sample) != DDS_RETCODE_OK) return false;
    if (reader.WaitForData(DDS_MSECS(100))) return true;
  }
  return false;
}

TEST(ServiceDds, PoseRoundTripKeepsEveryField) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant client(domain);
  Participant server(domain);
  Topic<hapco_idl_DevicePose> client_topic(client);
  Topic<hapco_idl_DevicePose> server_topic(server);
  Publisher pub(client);
  Subscriber sub(server);
  Writer<hapco_idl_DevicePose> writer(pub, client_topic);
  Reader<hapco_idl_DevicePose> reader(sub, server_topic);
  ASSERT_TRUE(writer.WaitForReaders(1, kDiscoveryTimeoutNs));

  hapco_idl_DevicePose sent{};
  FillPose("phantom-1", 41, &sent);
  ASSERT_TRUE(WriteUntilReceived(writer, sent, reader));
  hapco_idl_DevicePose got{};
  dds_sample_info_t info;
  ASSERT_TRUE(reader.Take(&got, &info));
  EXPECT_STREQ(got.client_id, "phantom-1");
  EXPECT_EQ(got.sequence_number, 41u);
  EXPECT_EQ(got.client_time_ns, sent.client_time_ns);
  EXPECT_EQ(got.position_m.x, sent.position_m.x);
  EXPECT_EQ(got.position_m.y, -0.25);
  EXPECT_EQ(got.position_m.z, 0.125);
  EXPECT_EQ(got.orientation.w, 0.5);
  EXPECT_EQ(got.orientation.x, 0.5);
  EXPECT_EQ(got.orientation.y, -0.5);
  EXPECT_EQ(got.orientation.z, 0.5);
  EXPECT_EQ(got.buttons, 0x5u);
  EXPECT_TRUE(info.valid_data);
}

// The service loop in miniature: a forked "server" answers each pose with a force on the
// client's partition, echoing the sequence and the client timestamp.
TEST(ServiceDds, PoseForceEchoAcrossProcesses) {
  const dds_domainid_t domain = SetUpTestDomain();
  constexpr int kRounds = 5;
  ChildProcess server([domain](ChildProcess& pipe) -> int {
    Participant p(domain);
    Topic<hapco_idl_DevicePose> pose_topic(p);
    Topic<hapco_idl_FeedbackForce> force_topic(p);
    Subscriber sub(p);
    Publisher pub(p, ClientPartition("phantom-7"));
    Reader<hapco_idl_DevicePose> poses(sub, pose_topic);
    Writer<hapco_idl_FeedbackForce> forces(pub, force_topic);
    if (!forces.WaitForReaders(1, kDiscoveryTimeoutNs)) return 2;
    // Serve until the client says it is done: a best-effort force can be lost, and the
    // client then resends its pose.
    uint64_t answered = 0;
    uint64_t done = 0;
    const dds_time_t deadline = dds_time() + 2 * kDataTimeoutNs;
    while (!pipe.Receive(&done, 0) && dds_time() < deadline) {
      if (!poses.WaitForData(DDS_MSECS(20))) continue;
      hapco_idl_DevicePose pose{};
      while (poses.Take(&pose)) {
        hapco_idl_FeedbackForce f{};
        std::memcpy(f.client_id, pose.client_id, sizeof(f.client_id));
        f.pose_sequence = pose.sequence_number;
        f.client_time_ns = pose.client_time_ns;
        f.server_receive_ns = 11;
        f.server_send_ns = 12;
        f.force_n = {-pose.position_m.x * 100.0, 0.0, 2.5};  // a 100 N/m spring, say
        f.solver_status = hapco_idl_SOLVER_CONVERGED;
        f.iterations = 3;
        f.separating_count = 1;
        f.sticking_count = 2;
        f.sliding_count = 4;
        if (forces.Write(f) != DDS_RETCODE_OK) return 3;
        if (pose.sequence_number >= answered) answered = pose.sequence_number + 1;
      }
    }
    return answered >= kRounds ? 0 : 4;
  });

  Participant p(domain);
  Topic<hapco_idl_DevicePose> pose_topic(p);
  Topic<hapco_idl_FeedbackForce> force_topic(p);
  Publisher pub(p);
  Subscriber sub(p, ClientPartition("phantom-7"));
  Writer<hapco_idl_DevicePose> poses(pub, pose_topic);
  Reader<hapco_idl_FeedbackForce> forces(sub, force_topic);
  ASSERT_TRUE(poses.WaitForReaders(1, kDiscoveryTimeoutNs));
  ASSERT_TRUE(forces.WaitForWriters(1, kDiscoveryTimeoutNs));

  for (uint64_t seq = 0; seq < kRounds; ++seq) {
    hapco_idl_DevicePose pose{};
    FillPose("phantom-7", seq, &pose);
    bool echoed = false;
    const dds_time_t deadline = dds_time() + kDataTimeoutNs;
    while (!echoed && dds_time() < deadline) {
      ASSERT_EQ(poses.Write(pose), DDS_RETCODE_OK);  // resent if the echo is lost
      if (!forces.WaitForData(DDS_MSECS(100))) continue;
      hapco_idl_FeedbackForce f{};
      while (forces.Take(&f)) {
        if (f.pose_sequence != seq) continue;  // a late echo of an earlier resend
        echoed = true;
        EXPECT_STREQ(f.client_id, "phantom-7");
        EXPECT_EQ(f.client_time_ns, pose.client_time_ns);
        EXPECT_EQ(f.force_n.x, -pose.position_m.x * 100.0);
        EXPECT_EQ(f.force_n.z, 2.5);
        EXPECT_EQ(f.solver_status, hapco_idl_SOLVER_CONVERGED);
        EXPECT_EQ(f.iterations, 3u);
        EXPECT_EQ(f.separating_count + f.sticking_count + f.sliding_count, 7u);
      }
    }
    ASSERT_TRUE(echoed) << "no force for pose " << seq;
  }
  server.Send(1);
  EXPECT_EQ(server.Join(20000), 0);
}

TEST(ServiceDds, ForceOnClientPartitionIsNotSeenByAnotherClient) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant server(domain);
  Participant clients(domain);
  Topic<hapco_idl_FeedbackForce> server_topic(server);
  Topic<hapco_idl_FeedbackForce> client_topic(clients);
  Publisher pub_a(server, ClientPartition("A"));
  Publisher pub_b(server, ClientPartition("B"));
  Writer<hapco_idl_FeedbackForce> to_a(pub_a, server_topic);
  Writer<hapco_idl_FeedbackForce> to_b(pub_b, server_topic);
  Subscriber sub_a(clients, ClientPartition("A"));
  Subscriber sub_b(clients, ClientPartition("B"));
  Subscriber sub_all(clients, kAllClientsPartition);  // a recorder
  Reader<hapco_idl_FeedbackForce> reader_a(sub_a, client_topic);
  Reader<hapco_idl_FeedbackForce> reader_b(sub_b, client_topic);
  Reader<hapco_idl_FeedbackForce> recorder(sub_all, client_topic);

  ASSERT_TRUE(to_a.WaitForReaders(2, kDiscoveryTimeoutNs));  // reader_a + recorder
  ASSERT_TRUE(to_b.WaitForReaders(2, kDiscoveryTimeoutNs));  // reader_b + recorder
  ASSERT_TRUE(recorder.WaitForWriters(2, kDiscoveryTimeoutNs));
  // Matching is decided by partitions at discovery: A's writer never matched B's reader.
  EXPECT_EQ(to_a.MatchedReaders(), 2u);
  EXPECT_EQ(reader_b.MatchedWriters(), 1u);
  EXPECT_EQ(reader_a.MatchedWriters(), 1u);

  hapco_idl_FeedbackForce fa{};
  SetClientId(fa.client_id, "A");
  fa.force_n = {1.0, 0.0, 0.0};
  hapco_idl_FeedbackForce fb{};
  SetClientId(fb.client_id, "B");
  fb.force_n = {0.0, 2.0, 0.0};
  ASSERT_TRUE(WriteUntilReceived(to_a, fa, reader_a));
  ASSERT_TRUE(WriteUntilReceived(to_b, fb, reader_b));

  hapco_idl_FeedbackForce got{};
  int b_count = 0;
  while (reader_b.Take(&got)) {
    EXPECT_STREQ(got.client_id, "B");
    EXPECT_EQ(got.force_n.y, 2.0);
    ++b_count;
  }
  EXPECT_GE(b_count, 1);
  int a_count = 0;
  while (reader_a.Take(&got)) {
    EXPECT_STREQ(got.client_id, "A");
    ++a_count;
  }
  EXPECT_GE(a_count, 1);
}

TEST(ServiceDds, ReliableContactFrameOf1024SamplesRoundTripsAcrossProcesses) {
  const dds_domainid_t domain = SetUpTestDomain();
  constexpr uint64_t kStep = 77;
  ChildProcess server([domain](ChildProcess&) -> int {
    Participant p(domain);
    Topic<hapco_idl_ContactStateFrame> topic(p);
    Publisher pub(p, ClientPartition("phantom-2"));
    Writer<hapco_idl_ContactStateFrame> writer(pub, topic);
    if (!writer.WaitForReaders(1, kDiscoveryTimeoutNs)) return 2;
    auto frame = MakeSample<hapco_idl_ContactStateFrame>();
    ReserveContacts(frame.get(), hapco_idl_MAX_CONTACT_SAMPLES);
    SetClientId(frame->client_id, "phantom-2");
    frame->step = kStep;
    frame->pose_sequence = kStep + 1000;
    frame->contacts._length = hapco_idl_MAX_CONTACT_SAMPLES;
    for (uint32_t i = 0; i < hapco_idl_MAX_CONTACT_SAMPLES; ++i) {
      testing::FillContact(kStep, i, &frame->contacts._buffer[i]);
    }
    if (writer.Write(*frame) != DDS_RETCODE_OK) return 3;
    // Reliable: stay until the reader has acknowledged every fragment.
    return writer.WaitForAcks(kDataTimeoutNs) == DDS_RETCODE_OK ? 0 : 4;
  });

  Participant p(domain);
  Topic<hapco_idl_ContactStateFrame> topic(p);
  Subscriber sub(p, kAllClientsPartition);
  Reader<hapco_idl_ContactStateFrame> reader(sub, topic);
  auto frame = MakeSample<hapco_idl_ContactStateFrame>();
  ReserveContacts(frame.get(), hapco_idl_MAX_CONTACT_SAMPLES);
  const hapco_idl_ContactSample* const buffer = frame->contacts._buffer;

  ASSERT_TRUE(reader.WaitForData(kDataTimeoutNs));
  ASSERT_TRUE(reader.Take(frame.get()));
  EXPECT_EQ(frame->contacts._buffer, buffer) << "take reallocated the preallocated sequence";
  EXPECT_STREQ(frame->client_id, "phantom-2");
  EXPECT_EQ(frame->step, kStep);
  EXPECT_EQ(frame->pose_sequence, kStep + 1000);
  ASSERT_EQ(frame->contacts._length, hapco_idl_MAX_CONTACT_SAMPLES);
  int mismatches = 0;
  for (uint32_t i = 0; i < hapco_idl_MAX_CONTACT_SAMPLES; ++i) {
    hapco_idl_ContactSample expected{};
    testing::FillContact(kStep, i, &expected);
    if (!testing::SameContact(frame->contacts._buffer[i], expected)) ++mismatches;
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_EQ(server.Join(20000), 0);
}

uint64_t WriterStatistic(dds_entity_t writer, const char* name) {
  dds_statistics* stats = dds_create_statistics(writer);
  if (stats == nullptr) return 0;
  dds_refresh_statistics(stats);
  uint64_t value = 0;
  if (const dds_stat_keyvalue* kv = dds_lookup_statistic(stats, name)) {
    switch (kv->kind) {
      case DDS_STAT_KIND_UINT32: value = kv->u.u32; break;
      case DDS_STAT_KIND_UINT64: value = kv->u.u64; break;
      case DDS_STAT_KIND_LENGTHTIME: value = kv->u.lengthtime; break;
    }
  }
  dds_delete_statistics(stats);
  return value;
}

// The contact-state writer must never block the server, even when a recorder hangs.
// A forked recorder with the same QoS is stopped (SIGSTOP) once matched: it neither takes
// nor acknowledges, so the writer's unacknowledged data grows past Cyclone's watermark.
// The writer pushes kFrames frames of the maximum size (~120 kB each) back to back. Every
// dds_write must return, with OK or TIMEOUT (= frame dropped, max_blocking_time 0);
// "returns" is checked by the loop completing kFrames calls, not by timing. Then the recorder
// resumes without taking: the writer's data must all be acknowledged (a KEEP_LAST reader
// accepts frames it is not taken), and the recorder then holds at most `depth` frames, the
// newest being the last one written successfully.
TEST(ServiceDds, ContactStateWriterNeverBlocksOnAHungRecorder) {
  const dds_domainid_t domain = SetUpTestDomain();
  constexpr int kFrames = 300;
  constexpr int32_t kDepth = kContactStateDepth;
  ChildProcess recorder([domain](ChildProcess& pipe) -> int {
    Participant p(domain);
    Topic<hapco_idl_ContactStateFrame> topic(p);
    Subscriber sub(p, kAllClientsPartition);
    Reader<hapco_idl_ContactStateFrame> reader(sub, topic);
    if (!reader.WaitForWriters(1, kDiscoveryTimeoutNs)) return 2;
    pipe.Send(1);  // matched: the parent may stop us now
    uint64_t go = 0;
    if (!pipe.Receive(&go, 60000)) return 3;  // parent done writing and acknowledged
    auto frame = MakeSample<hapco_idl_ContactStateFrame>();
    ReserveContacts(frame.get(), hapco_idl_MAX_CONTACT_SAMPLES);
    uint64_t frames = 0;
    uint64_t newest = 0;
    while (reader.Take(frame.get())) {
      ++frames;
      newest = frame->step;
    }
    pipe.Send(frames);
    pipe.Send(newest);
    return 0;
  });

  Participant p(domain);
  Topic<hapco_idl_ContactStateFrame> topic(p);
  Publisher pub(p, ClientPartition("phantom-3"));
  Writer<hapco_idl_ContactStateFrame> writer(pub, topic, ContactStateQos(kDepth));
  ASSERT_TRUE(writer.WaitForReaders(1, kDiscoveryTimeoutNs));
  uint64_t matched = 0;
  ASSERT_TRUE(recorder.Receive(&matched, 20000));
  recorder.Stop();

  auto frame = MakeSample<hapco_idl_ContactStateFrame>();
  ReserveContacts(frame.get(), hapco_idl_MAX_CONTACT_SAMPLES);
  SetClientId(frame->client_id, "phantom-3");
  frame->contacts._length = hapco_idl_MAX_CONTACT_SAMPLES;
  int ok = 0;
  int timeouts = 0;
  int other = 0;
  uint64_t last_ok_step = 0;
  std::vector<int64_t> call_ns;
  call_ns.reserve(kFrames);
  for (int k = 0; k < kFrames; ++k) {
    frame->step = static_cast<uint64_t>(k + 1);
    for (uint32_t i = 0; i < hapco_idl_MAX_CONTACT_SAMPLES; i += 97) {
      testing::FillContact(frame->step, i, &frame->contacts._buffer[i]);
    }
    const int64_t t0 = testing::MonotonicNs();
    const dds_return_t rc = writer.Write(*frame);
    call_ns.push_back(testing::MonotonicNs() - t0);
    if (rc == DDS_RETCODE_OK) {
      ++ok;
      last_ok_step = frame->step;
    } else if (rc == DDS_RETCODE_TIMEOUT) {
      ++timeouts;
    } else {
      ++other;
    }
  }
  EXPECT_EQ(ok + timeouts + other, kFrames);  // every call returned
  EXPECT_EQ(other, 0);
  EXPECT_GT(ok, 0);
  std::sort(call_ns.begin(), call_ns.end());
  std::printf("non-blocking contact writer, recorder stopped: %d frames x %u contacts: %d OK, "
              "%d TIMEOUT (dropped), throttle_count %llu; dds_write median %.3f ms, max %.3f ms "
              "(informative)\n",
              kFrames, hapco_idl_MAX_CONTACT_SAMPLES, ok, timeouts,
              static_cast<unsigned long long>(WriterStatistic(writer.handle(), "throttle_count")),
              static_cast<double>(call_ns[call_ns.size() / 2]) * 1e-6,
              static_cast<double>(call_ns.back()) * 1e-6);

  recorder.Continue();
  // The resumed recorder acknowledges everything without taking (KEEP_LAST reader).
  EXPECT_EQ(writer.WaitForAcks(kDataTimeoutNs), DDS_RETCODE_OK);
  recorder.Send(1);
  uint64_t frames = 0;
  uint64_t newest = 0;
  ASSERT_TRUE(recorder.Receive(&frames, 30000));
  ASSERT_TRUE(recorder.Receive(&newest, 30000));
  EXPECT_EQ(recorder.Join(20000), 0);
  EXPECT_GE(frames, 1u);
  EXPECT_LE(frames, static_cast<uint64_t>(kDepth));  // KEEP_LAST depth per client
  EXPECT_EQ(newest, last_ok_step);  // reliable: the newest accepted frame always arrives
}

TEST(ServiceDds, StatusIsDeliveredToALateJoiner) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant server(domain);
  Topic<hapco_idl_ServerStatus> server_topic(server);
  Publisher pub(server);
  Writer<hapco_idl_ServerStatus> writer(pub, server_topic);
  hapco_idl_ServerStatus status{};
  SetClientId(status.server_id, "server-1");
  status.sessions = 3;
  status.step_time_p99_us = 250.5;
  status.counters.out_of_order = 9;
  ASSERT_EQ(writer.Write(status), DDS_RETCODE_OK);
  status.sessions = 4;  // KEEP_LAST 1: only this one is kept for late joiners
  ASSERT_EQ(writer.Write(status), DDS_RETCODE_OK);

  // The monitor appears after both writes (transient-local).
  Participant monitor(domain);
  Topic<hapco_idl_ServerStatus> monitor_topic(monitor);
  Subscriber sub(monitor);
  Reader<hapco_idl_ServerStatus> reader(sub, monitor_topic);
  ASSERT_TRUE(reader.WaitForData(kDataTimeoutNs));
  hapco_idl_ServerStatus got{};
  ASSERT_TRUE(reader.Take(&got));
  EXPECT_STREQ(got.server_id, "server-1");
  EXPECT_EQ(got.sessions, 4u);
  EXPECT_EQ(got.step_time_p99_us, 250.5);
  EXPECT_EQ(got.counters.out_of_order, 9u);
  EXPECT_FALSE(reader.Take(&got));  // the superseded status is not delivered
}

TEST(ServiceDds, ListenerDeliversSessionControl) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant p(domain);
  Topic<hapco_idl_SessionControl> topic(p);
  Publisher pub(p);
  Subscriber sub(p);
  Reader<hapco_idl_SessionControl> reader(sub, topic);
  std::mutex mutex;
  std::condition_variable cv;
  hapco_idl_SessionControl received{};
  int count = 0;
  reader.SetOnDataAvailable([&] {
    hapco_idl_SessionControl s{};
    while (reader.Take(&s)) {
      std::lock_guard<std::mutex> lock(mutex);
      received = s;
      ++count;
      cv.notify_all();
    }
  });
  Writer<hapco_idl_SessionControl> writer(pub, topic);
  ASSERT_TRUE(writer.WaitForReaders(1, kDiscoveryTimeoutNs));
  hapco_idl_SessionControl join{};
  SetClientId(join.client_id, "phantom-9");
  join.command = hapco_idl_SESSION_JOIN;
  std::snprintf(join.scene_name, sizeof(join.scene_name), "%s", "benchmark1.scene");
  ASSERT_EQ(writer.Write(join), DDS_RETCODE_OK);  // reliable
  std::unique_lock<std::mutex> lock(mutex);
  ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(10), [&] { return count >= 1; }));
  EXPECT_STREQ(received.client_id, "phantom-9");
  EXPECT_EQ(received.command, hapco_idl_SESSION_JOIN);
  EXPECT_STREQ(received.scene_name, "benchmark1.scene");
}

TEST(ServiceDds, WaitSetWakesOnDataAndOnRequest) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant p(domain);
  Topic<hapco_idl_SessionControl> topic(p);
  Publisher pub(p);
  Subscriber sub(p);
  Reader<hapco_idl_SessionControl> reader(sub, topic);
  Writer<hapco_idl_SessionControl> writer(pub, topic);
  WaitSet waitset(p);
  waitset.Attach(reader.data_condition(), 42);
  dds_attach_t tokens[4];
  EXPECT_EQ(waitset.Wait(0, tokens, 4), 0);  // nothing yet: returns at once
  waitset.Wake();
  ASSERT_EQ(waitset.Wait(kDataTimeoutNs, tokens, 4), 1);
  EXPECT_EQ(tokens[0], WaitSet::kWakeToken);
  EXPECT_EQ(waitset.Wait(0, tokens, 4), 0);  // the wake-up was consumed
  ASSERT_TRUE(writer.WaitForReaders(1, kDiscoveryTimeoutNs));
  hapco_idl_SessionControl leave{};
  SetClientId(leave.client_id, "c");
  leave.command = hapco_idl_SESSION_LEAVE;
  ASSERT_EQ(writer.Write(leave), DDS_RETCODE_OK);
  ASSERT_EQ(waitset.Wait(kDataTimeoutNs, tokens, 4), 1);
  EXPECT_EQ(tokens[0], 42);
}

TEST(ServiceDds, DockerLoopbackConfigFileDiscoversAcrossProcesses) {
  const dds_domainid_t domain = SetUpTestDomain();
  const std::string config = "file://" HAPCO_SOURCE_DIR "/docker/cyclonedds-loopback.xml";
  ChildProcess peer([domain, config](ChildProcess&) -> int {
    Domain d(domain, config);
    Participant p(domain);
    Topic<hapco_idl_SessionControl> topic(p);
    Subscriber sub(p);
    Reader<hapco_idl_SessionControl> reader(sub, topic);
    if (!reader.WaitForData(kDataTimeoutNs)) return 2;
    hapco_idl_SessionControl s{};
    return reader.Take(&s) && s.command == hapco_idl_SESSION_RESET ? 0 : 3;
  });
  Domain d(domain, config);
  Participant p(domain);
  Topic<hapco_idl_SessionControl> topic(p);
  Publisher pub(p);
  Writer<hapco_idl_SessionControl> writer(pub, topic);
  ASSERT_TRUE(writer.WaitForReaders(1, kDiscoveryTimeoutNs));
  hapco_idl_SessionControl reset{};
  SetClientId(reset.client_id, "c");
  reset.command = hapco_idl_SESSION_RESET;
  ASSERT_EQ(writer.Write(reset), DDS_RETCODE_OK);
  EXPECT_EQ(writer.WaitForAcks(kDataTimeoutNs), DDS_RETCODE_OK);
  EXPECT_EQ(peer.Join(20000), 0);
}

void ExpectDdsError(const std::function<void()>& setup, const char* call, const char* dds_text) {
  try {
    setup();
    ADD_FAILURE() << "expected DdsError from " << call;
  } catch (const DdsError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(call), std::string::npos) << what;
    EXPECT_NE(what.find(dds_text), std::string::npos) << what;
  }
}

TEST(ServiceDds, SetupErrorsThrowWithTheDdsMessage) {
  const dds_domainid_t domain = SetUpTestDomain();
  Participant p(domain);
  Topic<hapco_idl_DevicePose> poses(p);
  // A topic name with a space (DDS names allow letters, digits, '_' and '/').
  ExpectDdsError([&] { Topic<hapco_idl_DevicePose> bad(p, "bad name"); },
                 "dds_create_topic(bad name)", "Bad Parameter");
  // Domain ids above ~232 give UDP ports beyond 65535.
  ExpectDdsError([&] { Participant q(1000); }, "dds_create_participant(domain 1000", "Error");
  // The domain exists already (the participant created it implicitly).
  ExpectDdsError([&] { Domain again(domain, LoopbackConfigXml()); }, "dds_create_domain",
                 "Precondition Not Met");
  // A config that names no usable interface.
  ExpectDdsError(
      [&] {
        Domain bad(domain == 230 ? 229 : domain + 1,
                   "<CycloneDDS><Domain><General><Interfaces><NetworkInterface "
                   "name=\"no-such-if0\"/></Interfaces></General></Domain></CycloneDDS>");
        Participant q(domain == 230 ? 229 : domain + 1);
      },
      "dds_create_", "Error");

  // Hot path: no exception, an error code.
  dds_entity_t deleted_handle = 0;
  {
    Publisher pub(p);
    Writer<hapco_idl_DevicePose> writer(pub, poses);
    deleted_handle = writer.handle();
  }
  hapco_idl_DevicePose pose{};
  EXPECT_LT(dds_write(deleted_handle, &pose), 0);
  // A writer whose participant was deleted underneath it.
  auto gone = std::make_unique<Participant>(domain);
  Topic<hapco_idl_DevicePose> gone_topic(*gone);
  Publisher gone_pub(*gone);
  Writer<hapco_idl_DevicePose> writer(gone_pub, gone_topic);
  gone.reset();
  EXPECT_LT(writer.Write(pose), 0);
}

}  // namespace
}  // namespace hapco::service
