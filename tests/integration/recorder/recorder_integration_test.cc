// hapco-recorder with a real hapco-server and hapco-phantom (processes, UDP on loopback, own
// domain per test). The reference for what the recording must hold is the server's own
// --trace file (one row per step it made, written by the server, not by the recorder).
// No sleeps: waits are process exits (pidfd), and file growth / output text seen through
// inotify, all bounded.
#include <array>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/recording.h"
#include "service/qos.h"
#include "service/topics.h"
#include "../process_support.h"

namespace hapco::service {
namespace {

const std::string kScene = std::string(HAPCO_SOURCE_DIR) + "/tests/data/scenes/coarse.txtpb";

// The recorder is up and has discovered the server (it received the transient-local status),
// so the server knows the recorder's readers before any session writer is created.
void StartRecorder(std::unique_ptr<Process>* recorder, const std::string& dir, const std::string& domain,
                   const std::string& file) {
  *recorder = std::make_unique<Process>(
      std::vector<std::string>{HAPCO_RECORDER_EXE, kScene, "--output", file, "--domain", domain},
      dir + "/recorder.out", dir + "/recorder.err");
  ASSERT_TRUE(WaitForText(dir + "/recorder.out", "found", 60'000)) << ReadFile(dir + "/recorder.err");
}

struct TraceRow {
  std::string client_id;
  uint64_t sequence;
  Eigen::Vector3d position_m, force_n;
};

std::vector<TraceRow> ReadTrace(const std::string& path) {
  std::vector<TraceRow> rows;
  for (const auto& row : ReadCsv(path)) {
    rows.push_back({row.at("client_id"), std::stoull(row.at("sequence")), Vec(row, "x_m", "y_m", "z_m"),
                    Vec(row, "fx_n", "fy_n", "fz_n")});
  }
  return rows;
}

Eigen::Vector3d Of(const recording::Vec3& v) { return {v.x(), v.y(), v.z()}; }

std::vector<recording::Step> StepsOf(const std::vector<recording::Record>& records) {
  std::vector<recording::Step> steps;
  for (const auto& r : records) {
    if (r.has_step()) steps.push_back(r.step());
  }
  return steps;
}

// A step record against the server's trace row of the same step: what the server stepped
// (pose sequence, position) and sent (force), bit for bit (the trace prints %.17g).
// A step written from its force alone (frame lost) has no position to compare.
void ExpectSameStep(const recording::Step& step, const TraceRow& row) {
  EXPECT_EQ(step.client_id(), row.client_id);
  EXPECT_EQ(step.pose_sequence(), row.sequence) << "step " << step.step();
  if (!step.contacts_missing()) {
    EXPECT_EQ(Of(step.device_translation_m()), row.position_m) << "step " << step.step();
  }
  EXPECT_EQ(Of(step.device_force_n()), row.force_n) << "step " << step.step();
}

// The contact-state writer keeps kContactStateDepth frames; a frame is lost only when the
// recorder discovers a new session's writer later than that (seen at session start on the
// loaded machine: the new writer's first frame can reach the recorder before its discovery
// does). Its step is then still recorded, from the force (docs/recorder.md).
constexpr uint64_t kSessionStartWindow = static_cast<uint64_t>(kContactStateDepth);

// The per-contact samples agree with the step's counts and resultant (independent: the
// counts and resultant come from the solver, the samples from the per-contact states).
void ExpectContactsConsistent(const recording::Step& step) {
  std::array<uint32_t, 3> counts{0, 0, 0};
  Eigen::Vector3d sum_n = Eigen::Vector3d::Zero();
  for (const auto& c : step.contacts()) {
    ++counts[static_cast<std::size_t>(c.state())];
    sum_n += Of(c.force_n());
    EXPECT_NEAR(Of(c.normal()).norm(), 1.0, 1e-12);
  }
  EXPECT_EQ(counts[0], step.separating()) << "step " << step.step();
  EXPECT_EQ(counts[1], step.sticking()) << "step " << step.step();
  EXPECT_EQ(counts[2], step.sliding()) << "step " << step.step();
  const Eigen::Vector3d f = Of(step.contact_force_n());
  EXPECT_LT((sum_n - f).norm(), 1e-12 * (1 + f.norm())) << "step " << step.step();
}

// A server (with --trace DIR/trace.csv), a recorder writing `file` and one phantom
// (`phantom_args` added) in DIR; `during` runs while the phantom does, with the recorder.
// Server first at the end: once it has exited cleanly (its writers linger until their data is
// acknowledged), every frame is in the recorder's reader; then the recorder drains and stops.
void RunRecordedPhantom(const std::string& dir, const std::string& file, const std::vector<std::string>& phantom_args,
                        const std::function<void(Process* recorder)>& during = {}) {
  const std::string domain = std::to_string(SetUpTestDomain());
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--status-period-s", "0.2", "--trace",
                  dir + "/trace.csv", "--quiet"},
                 dir + "/server.out", dir + "/server.err");
  std::unique_ptr<Process> recorder;
  ASSERT_NO_FATAL_FAILURE(StartRecorder(&recorder, dir, domain, file));
  {
    std::vector<std::string> args = {HAPCO_PHANTOM_EXE, kScene, "--client-id", "phantom-1", "--domain", domain,
                                     "--connect-timeout-s", "60"};
    args.insert(args.end(), phantom_args.begin(), phantom_args.end());
    Process phantom(args, dir + "/phantom.out", dir + "/phantom.err");
    if (during) during(recorder.get());
    ASSERT_EQ(phantom.Wait(120'000), 0) << ReadFile(dir + "/phantom.err");
  }
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0) << ReadFile(dir + "/server.err");
  recorder->Signal(SIGTERM);
  ASSERT_EQ(recorder->Wait(30'000), 0) << ReadFile(dir + "/recorder.err");
}

// (a) Every step the server made is in the recording, in order, equal to the server's trace.
TEST(RecorderProcess, RecordingHoldsExactlyTheServersSteps) {
  const std::string dir = TestDir();
  const std::string file = dir + "/run.hapcorec";
  ASSERT_NO_FATAL_FAILURE(RunRecordedPhantom(dir, file, {}));
  const std::string summary = ReadFile(dir + "/recorder.out");
  std::printf("%s%s", ReadFile(dir + "/server.out").c_str(), summary.c_str());

  const std::vector<TraceRow> trace = ReadTrace(dir + "/trace.csv");
  ASSERT_GE(trace.size(), 100u);  // most of the 310 poses were stepped (best effort)
  io::RecordingReadReport report;
  const auto records = io::ReadRecording(file, &report);
  EXPECT_EQ(report.damaged_records, 0);
  EXPECT_FALSE(report.torn_tail);
  ASSERT_FALSE(records.empty());
  ASSERT_TRUE(records[0].has_header());
  EXPECT_EQ(records[0].header().writer(), "hapco-recorder");
  EXPECT_EQ(records[0].header().scene_name(), "coarse");
  EXPECT_FALSE(records[0].header().scene_text().empty());

  const std::vector<recording::Step> steps = StepsOf(records);
  ASSERT_EQ(steps.size(), trace.size());
  std::size_t from_forces = 0;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(steps[i].step(), i + 1);  // the server's step counter, no gap
    ExpectSameStep(steps[i], trace[i]);
    EXPECT_GT(steps[i].server_time_s(), 0);
    if (steps[i].contacts_missing()) {
      ++from_forces;
      EXPECT_LE(steps[i].step(), kSessionStartWindow) << "a frame lost mid-session";
    } else {
      ExpectContactsConsistent(steps[i]);
    }
  }
  std::printf("%zu steps recorded, %zu of them from the force alone (frame lost at session start)\n", steps.size(),
              from_forces);
  EXPECT_NE(summary.find("hapco-recorder: " + std::to_string(trace.size()) + " steps from 1 clients, " +
                         std::to_string(from_forces) + " missing steps"),
            std::string::npos)
      << summary;

  // hapco-report's CSV of an online recording: the server's time per step is known, the solve
  // and step timings of an offline run are not recorded online, so they are empty, not 0.
  Process report_process({HAPCO_REPORT_EXE, file, "--csv", dir + "/steps.csv"}, dir + "/report.out",
                         dir + "/report.err");
  ASSERT_EQ(report_process.Wait(60'000), 0) << ReadFile(dir + "/report.err");
  std::istringstream csv(ReadFile(dir + "/steps.csv"));
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  auto column_of = [&](const std::string& name) {
    std::istringstream header(line);
    std::string cell;
    for (int k = 0; std::getline(header, cell, ','); ++k) {
      if (cell == name) return k;
    }
    return -1;
  };
  const int solve_column = column_of("solve_s"), step_column = column_of("step_s"),
            server_column = column_of("server_time_s");
  ASSERT_GE(solve_column, 0);
  ASSERT_GE(step_column, 0);
  ASSERT_GE(server_column, 0);
  std::size_t rows = 0;
  while (std::getline(csv, line)) {
    std::vector<std::string> cells;
    std::istringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    ASSERT_GT(cells.size(), static_cast<std::size_t>(server_column)) << line;
    EXPECT_EQ(cells[static_cast<std::size_t>(solve_column)], "") << line;
    EXPECT_EQ(cells[static_cast<std::size_t>(step_column)], "") << line;
    EXPECT_GT(std::stod(cells[static_cast<std::size_t>(server_column)]), 0.0) << line;
    ++rows;
  }
  EXPECT_EQ(rows, steps.size());
}

// A recorder stalled three times for 300 ms mid-run (a descheduled process, a slow disk):
// when it resumes its readers hand it a backlog of frames and forces; forces whose frames it
// has just recorded are late duplicates, not new steps. With a 64-sequence window it took
// them for a restarted client's and wrote 35-386 steps twice, numbered out of order (a helper
// session; 3 runs of 3). The recording must hold exactly the server's steps, once each.
TEST(RecorderProcess, AStalledRecorderRecordsEveryStepOnce) {
  const std::string dir = TestDir();
  const std::string file = dir + "/run.hapcorec";
  ASSERT_NO_FATAL_FAILURE(RunRecordedPhantom(dir, file, {"--duration-s", "3"}, [&dir](Process* recorder) {
    // Once the server is stepping (its trace has rows), stall the recorder three times.
    for (int k = 0; k < 600 && ReadFile(dir + "/trace.csv").size() < 2000; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // polling the trace, not a wait
    }
    for (int stall = 0; stall < 3; ++stall) {
      recorder->Signal(SIGSTOP);
      std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the stall itself
      recorder->Signal(SIGCONT);
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
    }
  }));
  const std::vector<TraceRow> trace = ReadTrace(dir + "/trace.csv");
  ASSERT_GE(trace.size(), 1000u);
  io::RecordingReadReport report;
  const std::vector<recording::Step> steps = StepsOf(io::ReadRecording(file, &report));
  std::printf("%zu steps stepped, %zu recorded\n%s", trace.size(), steps.size(), ReadFile(dir + "/recorder.out").c_str());
  ASSERT_EQ(steps.size(), trace.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    ASSERT_EQ(steps[i].step(), i + 1) << "each step once, in order";
    ExpectSameStep(steps[i], trace[i]);
  }
}

// (b) A recorder killed with SIGKILL mid-run: the file reads, every record up to the last
// complete one is intact and in order; hapco-report reads it (and names a torn tail).
TEST(RecorderProcess, KilledRecorderLeavesAReadableFile) {
  const std::string dir = TestDir();
  const std::string domain = std::to_string(SetUpTestDomain());
  const std::string file = dir + "/killed.hapcorec";
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--status-period-s", "0.2", "--trace",
                  dir + "/trace.csv", "--quiet"},
                 dir + "/server.out", dir + "/server.err");
  std::unique_ptr<Process> recorder;
  ASSERT_NO_FATAL_FAILURE(StartRecorder(&recorder, dir, domain, file));
  {
    // 2 s of ticks: the trajectory, then holding its last point.
    Process phantom({HAPCO_PHANTOM_EXE, kScene, "--client-id", "phantom-1", "--domain", domain, "--duration-s", "2",
                     "--connect-timeout-s", "60"},
                    dir + "/phantom.out", dir + "/phantom.err");
    // Mid-run: once ~100 steps are on disk (~1.8 kB each), while the phantom still runs.
    const bool grew = WaitForFile(file, 60'000, [&] {
      std::error_code error;
      return std::filesystem::file_size(file, error) > 180'000;
    });
    recorder->Signal(SIGKILL);
    EXPECT_EQ(recorder->Wait(30'000), 128 + SIGKILL);
    ASSERT_TRUE(grew);
    ASSERT_EQ(phantom.Wait(120'000), 0) << ReadFile(dir + "/phantom.err");
  }
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0) << ReadFile(dir + "/server.err");

  io::RecordingReadReport report;
  const auto records = io::ReadRecording(file, &report);
  EXPECT_EQ(report.damaged_records, 0);
  ASSERT_FALSE(records.empty());
  EXPECT_TRUE(records[0].has_header());
  const std::vector<recording::Step> steps = StepsOf(records);
  ASSERT_GE(steps.size(), 50u);
  const std::vector<TraceRow> trace = ReadTrace(dir + "/trace.csv");
  ASSERT_GT(trace.size(), steps.size());  // the server went on after the kill
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (i > 0) {
      EXPECT_GT(steps[i].step(), steps[i - 1].step());
    }
    ASSERT_GE(steps[i].step(), 1u);
    ASSERT_LE(steps[i].step(), trace.size());
    ExpectSameStep(steps[i], trace[steps[i].step() - 1]);  // intact: equal to what the server did
  }
  std::printf("killed after %zu of %zu steps; %s\n", steps.size(), trace.size(), report.Summary().c_str());

  // hapco-report on the file as the kill left it, and on a copy cut inside its last record
  // (a kill during a write): exit 0, every complete record, the torn tail named.
  auto run_report = [&](const std::string& path, const std::string& name) {
    Process report_process({HAPCO_REPORT_EXE, path}, dir + "/" + name + ".out", dir + "/" + name + ".err");
    EXPECT_EQ(report_process.Wait(60'000), 0) << ReadFile(dir + "/" + name + ".err");
    return ReadFile(dir + "/" + name + ".out");
  };
  const std::string as_killed = run_report(file, "report");
  EXPECT_NE(as_killed.find("steps      " + std::to_string(steps.size()) + ";"), std::string::npos) << as_killed;
  EXPECT_EQ(as_killed.find("torn tail") != std::string::npos, report.torn_tail) << as_killed;

  const std::string cut = dir + "/cut.hapcorec";
  std::filesystem::copy_file(file, cut, std::filesystem::copy_options::overwrite_existing);
  constexpr std::int64_t kCutBytes = 7;
  std::filesystem::resize_file(cut, std::filesystem::file_size(file) - kCutBytes);
  const std::string torn = run_report(cut, "report-cut");
  EXPECT_NE(torn.find("torn tail"), std::string::npos) << torn;
  // The cut reaches the last complete record unless a longer torn tail absorbs it. That
  // record may be a status record (the recorder also stores ServerStatus), not a step: CI
  // once had a status record last and expected one step fewer than were left.
  const bool last_record_cut = !report.torn_tail || report.torn_tail_bytes < kCutBytes;
  const std::size_t complete_steps = steps.size() - (last_record_cut && records.back().has_step() ? 1 : 0);
  EXPECT_NE(torn.find("steps      " + std::to_string(complete_steps) + ";"), std::string::npos) << torn;
}

// (d) Frames delivered a second time are not recorded twice. A contact-state writer is
// transient-local: a reader that matches it again (discovery lost and regained on an
// overloaded host) gets its newest frames once more, maybe in the middle of the client's
// next session (a compose run recorded a client's poses 77-84 "again at the origin"). The
// test plays the server: session 1 on "srv-a" (steps 1-10), the client moves to "srv-b"
// (steps 1-5), srv-a's last 8 frames arrive again (the same frames), then a real new session
// on srv-a (steps 1-3, later receive times). The recording holds each step once, in order.
// Steps 4-6 of the first session share one receive time, as poses recovered from a later
// pose's history do (the server steps them one after another with that pose's receive time):
// they are three steps, not one step and two repeats (CI once lost a step that way).
TEST(RecorderProcess, FramesDeliveredAgainAreNotRecordedTwice) {
  const std::string dir = TestDir();
  const dds_domainid_t domain = SetUpTestDomain();
  const std::string file = dir + "/again.hapcorec";
  Process recorder({HAPCO_RECORDER_EXE, kScene, "--output", file, "--domain", std::to_string(domain)},
                   dir + "/recorder.out", dir + "/recorder.err");
  std::vector<std::pair<std::string, uint64_t>> expected;  // (server, step) recorded, in order
  {
    Participant participant(domain);
    Topic<hapco_idl_ContactStateFrame> topic(participant);
    Publisher publisher(participant, ClientPartition("mover-1"));
    Writer<hapco_idl_ContactStateFrame> writer(publisher, topic, ContactStateQos(64));
    ASSERT_TRUE(writer.WaitForReaders(1, DDS_SECS(60))) << ReadFile(dir + "/recorder.err");
    auto frame = MakeSample<hapco_idl_ContactStateFrame>();
    uint64_t pose = 0;
    // Sent 1000 ns after the receive time plus 100 ns per step (a step's send time is its own).
    auto write = [&](const char* server, uint64_t step, uint64_t pose_sequence, int64_t receive_ns) {
      std::snprintf(frame->client_id, sizeof(frame->client_id), "mover-1");
      std::snprintf(frame->server_id, sizeof(frame->server_id), "%s", server);
      frame->step = step;
      frame->pose_sequence = pose_sequence;
      frame->server_receive_ns = receive_ns;
      frame->server_send_ns = receive_ns + 1000 + 100 * static_cast<int64_t>(step);
      frame->device_position_m = {0.0, 0.0, -1e-5 * static_cast<double>(pose_sequence)};
      ASSERT_EQ(writer.Write(*frame), DDS_RETCODE_OK);
    };
    // Receive time of srv-a's session-1 step (steps 4-6: one pose carried the other two).
    auto srv_a_receive_ns = [](uint64_t step) { return 1'000'000 * static_cast<int64_t>(step < 4 || step > 6 ? step : 6); };
    for (uint64_t step = 1; step <= 10; ++step) {
      write("srv-a", step, ++pose, srv_a_receive_ns(step));
      expected.push_back({"srv-a", step});
    }
    for (uint64_t step = 1; step <= 5; ++step) {
      write("srv-b", step, ++pose, 500'000'000 + 1'000'000 * static_cast<int64_t>(step));
      expected.push_back({"srv-b", step});
    }
    for (uint64_t step = 3; step <= 10; ++step) write("srv-a", step, step, srv_a_receive_ns(step));
    for (uint64_t step = 1; step <= 3; ++step) {
      write("srv-a", step, ++pose, 900'000'000 + 1'000'000 * static_cast<int64_t>(step));
      expected.push_back({"srv-a", step});
    }
    ASSERT_EQ(writer.WaitForAcks(DDS_SECS(30)), DDS_RETCODE_OK);
  }
  recorder.Signal(SIGTERM);
  ASSERT_EQ(recorder.Wait(30'000), 0) << ReadFile(dir + "/recorder.err");
  const std::string out = ReadFile(dir + "/recorder.out");
  EXPECT_NE(out.find("8 frames received again and dropped"), std::string::npos) << out;
  io::RecordingReadReport report;
  const std::vector<recording::Step> steps = StepsOf(io::ReadRecording(file, &report));
  EXPECT_EQ(report.damaged_records, 0);
  ASSERT_EQ(steps.size(), expected.size()) << out;
  uint64_t previous_pose = 0;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(steps[i].server_id(), expected[i].first) << "record " << i;
    EXPECT_EQ(steps[i].step(), expected[i].second) << "record " << i;
    EXPECT_GT(steps[i].pose_sequence(), previous_pose) << "record " << i << ": a pose recorded again";
    previous_pose = steps[i].pose_sequence();
  }
}

// (c) hapco-report on a recording of two clients: three charts and one CSV row per step.
TEST(RecorderProcess, ReportWritesChartsAndOneCsvRowPerStep) {
  const std::string dir = TestDir();
  const std::string domain = std::to_string(SetUpTestDomain());
  const std::string file = dir + "/two.hapcorec";
  Process server({HAPCO_SERVER_EXE, kScene, "--domain", domain, "--status-period-s", "0.2", "--quiet"},
                 dir + "/server.out", dir + "/server.err");
  std::unique_ptr<Process> recorder;
  ASSERT_NO_FATAL_FAILURE(StartRecorder(&recorder, dir, domain, file));
  {
    Process a({HAPCO_PHANTOM_EXE, kScene, "--client-id", "alpha", "--domain", domain, "--connect-timeout-s", "60"},
              dir + "/alpha.out", dir + "/alpha.err");
    Process b({HAPCO_PHANTOM_EXE, kScene, "--client-id", "beta", "--domain", domain, "--connect-timeout-s", "60"},
              dir + "/beta.out", dir + "/beta.err");
    ASSERT_EQ(a.Wait(120'000), 0) << ReadFile(dir + "/alpha.err");
    ASSERT_EQ(b.Wait(120'000), 0) << ReadFile(dir + "/beta.err");
  }
  server.Signal(SIGTERM);
  ASSERT_EQ(server.Wait(30'000), 0) << ReadFile(dir + "/server.err");
  recorder->Signal(SIGTERM);
  ASSERT_EQ(recorder->Wait(30'000), 0) << ReadFile(dir + "/recorder.err");

  io::RecordingReadReport read_report;
  const std::vector<recording::Step> steps = StepsOf(io::ReadRecording(file, &read_report));
  std::map<std::string, int> per_client;
  for (const auto& s : steps) ++per_client[s.client_id()];
  ASSERT_EQ(per_client.size(), 2u);
  ASSERT_GT(per_client["alpha"], 0);
  ASSERT_GT(per_client["beta"], 0);

  const std::string plots = dir + "/plots";
  std::filesystem::remove_all(plots);
  Process report({HAPCO_REPORT_EXE, file, "--plots", plots}, dir + "/report.out", dir + "/report.err");
  ASSERT_EQ(report.Wait(120'000), 0) << ReadFile(dir + "/report.err");
  const std::string out = ReadFile(dir + "/report.out");
  std::printf("%s", out.c_str());
  for (const char* chart : {"force.png", "contact_states.png", "round_trip.png"}) {
    std::error_code error;
    EXPECT_GT(std::filesystem::file_size(plots + "/" + chart, error), 0u) << chart;
    EXPECT_FALSE(error) << chart;
  }
  const auto rows = ReadCsv(plots + "/steps.csv");
  EXPECT_EQ(rows.size(), steps.size());
  std::map<std::string, int> csv_per_client;
  for (const auto& row : rows) ++csv_per_client[row.at("client_id")];
  EXPECT_EQ(csv_per_client, per_client);
  for (const auto& [id, count] : per_client) {
    EXPECT_NE(out.find("client     " + id + ": " + std::to_string(count) + " steps"), std::string::npos) << out;
  }
}

}  // namespace
}  // namespace hapco::service
