// hapco-recorder: records a live HapCo session. Subscribes (partition hapco/client/*) to every
// client's ContactStateFrame (reliable) and FeedbackForce (best effort), and to ServerStatus,
// and appends one recording::Step per server step and one recording::ServerStatus per status
// to a recording file (io/recording.h: checksummed records, flushed one by one, so a SIGKILL
// leaves every complete record readable). docs/recorder.md has the QoS reasoning.
//
// Threads: DDS delivers into the reader histories on its own threads; all taking, matching
// and file I/O happens on the main thread in a waitset loop (never in a listener).
// SIGINT/SIGTERM (common/stop_signals.h) turn into a waitset wake-up.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/realtime.h"
#include "common/stop_signals.h"
#include "contact/solver.h"
#include "io/recording.h"
#include "io/scene_file.h"
#include "service/dds.h"

namespace {

using hapco::service::kAllClientsPartition;

constexpr const char* kDescription =
    R"(Records a live HapCo session: every client's contact-state frames and forces (partition hapco/client/*) and the server status, into a recording file (one record per server step, checksummed and flushed record by record). Read it with hapco-report. docs/recorder.md.
Steps come from the contact-state frames; a force whose frame never arrived becomes a step with contacts_missing set. Gaps in a client's server step counter are counted as missing steps.)";

constexpr const char* kFooter =
    R"(Progress on stderr once a second (unless --quiet): records written, clients, missing steps.
SIGINT/SIGTERM: what has been received is written, then a one-line summary.
Exit code: 0 ok, 1 bad input (flags, unwritable file, scene file), 3 DDS failure.)";

// Reader history of the frame reader, per client (instance). Depth, not KEEP_ALL: a
// KEEP_LAST reader accepts and acknowledges every frame, so it never holds back the server's
// writer; 1000 frames = 1 s at 1 kHz of slack for the main thread (docs/recorder.md).
constexpr int32_t kFrameDepth = 1000;
// Forces are best effort; a deep reader history only keeps them from being overwritten
// before the main thread takes them.
constexpr int32_t kForceDepth = 256;
constexpr int32_t kStatusDepth = 16;
// Forces waiting for their frame, per client: beyond this (frames stopped arriving) the
// oldest is written on its own.
constexpr std::size_t kMaxPendingForces = 4096;
// The pose sequences of the frames recorded last, per client: a force whose frame is among
// them is a late duplicate. 8192 (8 s at 1 kHz) covers the reader histories' 1 s of slack
// with room; a window of 64 sequences took the forces of a recorder stalled 300 ms for a
// restarted client's and wrote 35-386 steps twice, out of order (a helper session).
constexpr uint64_t kRecordedRing = 8192;

struct Options {
  std::string output, scene_path, security_dir, ready_file;
  int domain = 0;
  double duration_s = 0;  // 0 = until a signal
  bool quiet = false;
  bool overwrite = false;  // replace a file that already holds data
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco-recorder", "[SCENE.txtpb] --output FILE [options]", kDescription, kFooter);
  command.AddScene(&o->scene_path,
                   "scene file the server runs: its name and text go into the header (optional; without it the "
                   "header holds no scene)")
      ->required(false);
  command.AddOutput(&o->output,
                    "recording to write (required); a file that already holds data is refused: what was "
                    "recorded live cannot be recorded again")
      ->required();
  command.AddFlag("--overwrite", &o->overwrite, "replace an --output file that already holds data", "Output");
  command.AddDomain(&o->domain);
  command.AddSecurity(&o->security_dir, "DIR/recorder");
  command.AddOutputFile("--ready-file", &o->ready_file, "FILE",
                  "create FILE once the recorder is ready: it has seen the server and matched its contact-state "
                  "writers, so every session opened from then on is recorded from its first step (a readiness "
                  "check for containers: docker/compose.yaml)",
                  "Run");
  command.AddDuration(&o->duration_s, "stop after S seconds (default: run until SIGINT/SIGTERM)");
  command.AddQuiet(&o->quiet, "no progress line (the exit summary is still printed)");
  command.Deprecate("--scene", "");
  command.Deprecate("--duration", "--duration-s");
  if (!command.Parse(argc, argv)) return false;

  if (o->output.empty()) throw hapco::InputError("--output FILE is required (see --help)");
  return true;
}

// Same spelling as hapco-sim recordings (contact::StatusName). A step without contacts ran
// no solve; hapco-sim records it as "converged", and so do we.
std::string StatusName(hapco_idl_SolverStatus status) {
  using hapco::contact::SolverStatus;
  switch (status) {
    case hapco_idl_SOLVER_CONVERGED:
    case hapco_idl_SOLVER_NO_CONTACT: return std::string(hapco::contact::StatusName(SolverStatus::kConverged));
    case hapco_idl_SOLVER_MAX_ITERATIONS: return std::string(hapco::contact::StatusName(SolverStatus::kMaxIterations));
    case hapco_idl_SOLVER_TIME_BUDGET_EXCEEDED:
      return std::string(hapco::contact::StatusName(SolverStatus::kTimeBudgetExceeded));
    case hapco_idl_SOLVER_DIVERGED: return std::string(hapco::contact::StatusName(SolverStatus::kDiverged));
  }
  return "unknown";
}

void Set(hapco::recording::Vec3* out, const hapco_idl_Vec3& v) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}

// Matching of forces to frames, per client and server (Recorder::StateOf). The server
// writes, per step, the force then the frame, both in step order; frames are reliable (they
// arrive in order, or not at all when the server's keep-last history dropped them), forces
// best effort. A force waits in
// `pending` (arrival order = server order) until the frame with its pose sequence arrives:
// then it is matched (the frame is the record) and every force before it lost its frame for
// good, so each of those is written as a step of its own (contacts_missing). If a frame's
// own force was lost, the pending forces with a lower pose sequence are the ones before it.
// Pose sequences restart when a client restarts, step counters when a session is re-opened:
// matching is by equality first, so a restart costs at most force-only records for forces
// whose frames were lost around it (docs/recorder.md).
struct ClientState {
  std::string client_id;
  bool have_frame = false;
  uint64_t last_step = 0;
  std::deque<hapco_idl_FeedbackForce> pending;
  // The newest server_send_ns of a frame recorded in this stream (the server's monotonic
  // clock, stamped once per step: its frames of later steps, in any session, are strictly
  // newer; -1: none yet). Not server_receive_ns: poses recovered from a later pose's
  // history are stepped one after another with that pose's receive time.
  int64_t newest_send_ns = -1;
  // recorded_frames[s % kRecordedRing] == s: the frame of pose sequence s (of this session)
  // is in the recording.
  std::vector<uint64_t> recorded_frames;
};

class Recorder {
 public:
  explicit Recorder(hapco::io::RecordingWriter* writer) : writer_(writer) {}

  void OnForce(const hapco_idl_FeedbackForce& force) {
    // A notice that the server ignored a pose answers no step: nothing to record.
    if (force.pose_verdict != hapco_idl_POSE_STEPPED) return;
    // A server's answer between steps (--physics-every > 1) has no frame and no contact state
    // of its own: counted, not recorded as a step (docs/recorder.md).
    if (force.answer_source != hapco_idl_ANSWER_STEP) {
      ++model_answers_;
      return;
    }
    ++forces_seen_;
    ClientState& c = StateOf(force.client_id, force.server_id);
    // Arrived after its frame, which is recorded already (a restarted client's new
    // sequence, whose frames are not, is kept).
    if (c.have_frame && force.pose_sequence != 0 && !c.recorded_frames.empty() &&
        c.recorded_frames[force.pose_sequence % kRecordedRing] == force.pose_sequence) {
      return;
    }
    c.pending.push_back(force);
    if (c.pending.size() > kMaxPendingForces) {  // frames stopped arriving: write the oldest
      WriteForceStep(force.client_id, c.pending.front(), c.last_step + 1);
      c.pending.pop_front();
    }
  }

  void OnFrame(const hapco_idl_ContactStateFrame& frame) {
    // A session's hello frame (step 0, written when it is created: the server opens the
    // session once its readers have acknowledged it, Session::TryOpen) is no step.
    if (frame.step == 0) return;
    ClientState& c = StateOf(frame.client_id, frame.server_id);
    // A frame this recorder already has, delivered again: a contact-state writer is
    // transient-local (its newest frames go to every reader that matches it later), so a
    // reader that loses and regains a writer — discovery on an overloaded host — receives that
    // writer's last frames a second time, possibly long after, in the middle of another
    // session (the likely cause of a compose run's poses 77-84 "stepped again at the origin").
    // Not newer (sent no later) than the newest frame of this client from the same server:
    // dropped and counted, never taken for a new session. (Server ids are per process:
    // server_choice.h.)
    if (c.newest_send_ns >= 0 && frame.server_send_ns <= c.newest_send_ns) {
      ++repeated_frames_;
      return;
    }
    c.newest_send_ns = frame.server_send_ns;
    // A session starts again when the server's step counter does (re-opened: a restarted
    // client, a SESSION_RESET, or the client back after a move). (The state is this server's.)
    const bool new_session = c.have_frame && frame.step <= c.last_step;
    // Steps without a frame: a gap after the previous frame, or the steps before the first
    // frame of a session (the counter starts at 1; a recorder started mid-session counts the
    // steps it did not see).
    const uint64_t previous = (c.have_frame && !new_session) ? c.last_step : 0;
    if (frame.step > previous + 1) {
      missing_steps_ += frame.step - previous - 1;
    }
    // The forces before this frame's: matched by equality, else those with lower sequences.
    std::size_t before = 0;
    bool matched = false;
    for (std::size_t i = 0; i < c.pending.size(); ++i) {
      if (c.pending[i].pose_sequence == frame.pose_sequence) {
        before = i;
        matched = true;
        break;
      }
    }
    if (!matched) {
      while (before < c.pending.size() && c.pending[before].pose_sequence < frame.pose_sequence) ++before;
    }
    // Their step numbers follow the previous frame's: exact when every force of the gap
    // arrived, else the lowest possible; before the first frame, the ones just before it.
    for (std::size_t i = 0; i < before; ++i) {
      uint64_t number = 0;  // 0 = unknown
      if (c.have_frame) {
        number = c.last_step + 1 + i;
        if (!new_session) number = std::min(number, frame.step - 1);
      } else if (frame.step > before) {
        number = frame.step - before + i;
      }
      WriteForceStep(frame.client_id, c.pending.front(), number);
      c.pending.pop_front();
    }
    if (matched) c.pending.pop_front();
    if (c.recorded_frames.empty()) c.recorded_frames.assign(kRecordedRing, 0);
    if (new_session) std::fill(c.recorded_frames.begin(), c.recorded_frames.end(), 0);
    c.recorded_frames[frame.pose_sequence % kRecordedRing] = frame.pose_sequence;
    c.have_frame = true;
    c.last_step = frame.step;
    WriteFrameStep(frame);
  }

  void OnStatus(const hapco_idl_ServerStatus& s) {
    auto* status = record_.mutable_status();
    status->Clear();
    status->set_server_id(s.server_id);
    status->set_time_ns(hapco::MonotonicNowNs());
    status->set_uptime_s(static_cast<double>(s.uptime_ns) * 1e-9);
    status->set_sessions(s.sessions);
    status->set_step_time_p50_s(s.step_time_p50_us * 1e-6);
    status->set_step_time_p99_s(s.step_time_p99_us * 1e-6);
    status->set_step_time_max_s(s.step_time_max_us * 1e-6);
    status->set_bad_pose_nan(s.counters.bad_pose_nan);
    status->set_out_of_workspace(s.counters.out_of_workspace);
    status->set_position_jumps(s.counters.position_jumps);
    status->set_out_of_order(s.counters.out_of_order);
    status->set_duplicates(s.counters.duplicates);
    status->set_unknown_clients(s.counters.unknown_clients);
    status->set_floods(s.counters.floods);
    status->set_cpu_use(s.cpu_use);
    status->set_steps(s.steps);
    status->set_superseded(s.superseded);
    status->set_contact_frames_dropped(s.contact_frames_dropped);
    status->set_non_finite_forces(s.non_finite_forces);
    status->set_answers_between_steps(s.answers_between_steps);
    status->set_turn_steps(s.turn_steps);
    writer_->Append(record_);
    ++status_records_;
  }

  // At the end: forces still waiting for a frame will not get one. Their steps are steps
  // without a frame, as those in a gap are: counted missing (they were not: a helper's recorder
  // said 1 missing step beside 2 steps from forces alone, a killed server's last step one).
  void FlushPending() {
    for (auto& [key, c] : clients_) {
      for (uint64_t number = c.last_step + 1; !c.pending.empty(); ++number) {
        WriteForceStep(c.client_id, c.pending.front(), number);
        c.pending.pop_front();
        ++missing_steps_;
      }
    }
  }

  uint64_t steps() const { return steps_; }
  uint64_t missing_steps() const { return missing_steps_; }
  uint64_t forces_seen() const { return forces_seen_; }
  uint64_t status_records() const { return status_records_; }
  uint64_t from_forces() const { return from_forces_; }
  uint64_t repeated_frames() const { return repeated_frames_; }
  uint64_t model_answers() const { return model_answers_; }
  std::size_t clients() const { return client_ids_.size(); }

 private:
  void WriteFrameStep(const hapco_idl_ContactStateFrame& f) {
    hapco::recording::Step* step = record_.mutable_step();
    step->Clear();  // keeps the repeated field's allocated elements for reuse
    step->set_step(f.step);
    step->set_client_id(f.client_id);
    step->set_server_id(f.server_id, strnlen(f.server_id, sizeof(f.server_id)));
    step->set_time_ns(f.server_receive_ns);
    Set(step->mutable_device_translation_m(), f.device_position_m);
    Set(step->mutable_contact_force_n(), f.contact_force_n);
    Set(step->mutable_device_force_n(), f.device_force_n);
    step->set_solver_status(StatusName(f.solver_status));
    step->set_iterations(f.iterations);
    step->set_solver_error_m(f.solver_error);
    step->set_separating(f.separating_count);
    step->set_sticking(f.sticking_count);
    step->set_sliding(f.sliding_count);
    for (uint32_t i = 0; i < f.contacts._length; ++i) {
      const hapco_idl_ContactSample& s = f.contacts._buffer[i];
      auto* sample = step->add_contacts();
      sample->set_id(s.id);
      Set(sample->mutable_position_m(), s.position_m);
      Set(sample->mutable_normal(), s.normal);
      Set(sample->mutable_force_n(), s.force_n);
      sample->set_gap_m(s.gap_m);
      sample->set_slip_m(s.slip_m);
      sample->set_state(static_cast<hapco::recording::ContactState>(s.state));
    }
    // 0 = none (the client reported no round trip yet, -1 on the wire).
    if (f.client_round_trip_ns > 0) step->set_round_trip_s(static_cast<double>(f.client_round_trip_ns) * 1e-9);
    step->set_pose_sequence(f.pose_sequence);
    step->set_server_time_s(static_cast<double>(f.server_send_ns - f.server_receive_ns) * 1e-9);
    writer_->Append(record_);
    ++steps_;
  }

  void WriteForceStep(const std::string& client_id, const hapco_idl_FeedbackForce& f,
                      uint64_t step_number) {
    hapco::recording::Step* step = record_.mutable_step();
    step->Clear();
    step->set_step(step_number);
    step->set_client_id(client_id);
    step->set_server_id(f.server_id, strnlen(f.server_id, sizeof(f.server_id)));
    step->set_time_ns(f.server_receive_ns);
    Set(step->mutable_device_force_n(), f.force_n);
    step->set_solver_status(StatusName(f.solver_status));
    step->set_iterations(f.iterations);
    step->set_separating(f.separating_count);
    step->set_sticking(f.sticking_count);
    step->set_sliding(f.sliding_count);
    step->set_pose_sequence(f.pose_sequence);
    step->set_server_time_s(static_cast<double>(f.server_send_ns - f.server_receive_ns) * 1e-9);
    step->set_contacts_missing(true);
    writer_->Append(record_);
    ++steps_;
    ++from_forces_;
  }

  hapco::io::RecordingWriter* writer_;
  hapco::recording::Record record_;  // reused: no allocation per step once warmed up
  // One state per client and server: a client that moved between servers has one stream of
  // frames and forces per server, and its forces are matched to frames, and numbered, within
  // the stream of the server that answered them (docs/several-servers.md).
  ClientState& StateOf(const char (&client_id)[65], const char (&server_id)[65]) {
    key_.assign(client_id, strnlen(client_id, sizeof(client_id)));
    const std::size_t client_length = key_.size();
    key_ += '\n';  // never part of an id
    key_.append(server_id, strnlen(server_id, sizeof(server_id)));
    auto [it, inserted] = clients_.try_emplace(key_);
    if (inserted) {
      it->second.client_id = key_.substr(0, client_length);
      client_ids_.insert(it->second.client_id);
    }
    return it->second;
  }
  std::string key_;  // reused: no allocation per sample for a known stream
  std::map<std::string, ClientState> clients_;
  std::set<std::string> client_ids_;
  uint64_t steps_ = 0, missing_steps_ = 0, forces_seen_ = 0, status_records_ = 0, from_forces_ = 0, repeated_frames_ = 0,
           model_answers_ = 0;
};

hapco::recording::Header MakeHeader(const Options& o) {
  hapco::recording::Header header;
  header.set_format_version(1);
  header.set_hapco_version(HAPCO_VERSION);
  header.set_writer("hapco-recorder");
  header.set_created_unix_ns(static_cast<int64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
      std::chrono::system_clock::now().time_since_epoch()).count()));
  if (!o.scene_path.empty()) {
    const hapco::sim::SceneSpec scene = hapco::io::LoadSceneFile(o.scene_path);  // validates it
    header.set_scene_name(scene.name);
    std::ifstream in(o.scene_path);
    header.set_scene_text(std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()));
    header.set_solver(std::string(hapco::contact::SolverName(scene.solver)));
  }
  return header;
}

// Removes the --ready-file marker at `path` if it is one (an empty regular file), never data.
void RemoveReadyMarker(const std::string& path) {
  std::error_code error;
  if (!path.empty() && std::filesystem::is_regular_file(path, error) && std::filesystem::file_size(path, error) == 0) {
    std::filesystem::remove(path, error);
  }
}

int Run(const Options& o) {
  hapco::StopSignals stop_signals;

  // The ready file says "this recorder is ready now": one left by an earlier run would pass a
  // health check before this one is (a helper session), so a stale one goes first, even when
  // the recording below is refused. It is an empty marker: a file with data at that path is
  // someone's (a recording given as --ready-file was deleted), so it is refused, not removed.
  if (!o.ready_file.empty()) {
    std::error_code error;
    if (std::filesystem::exists(o.ready_file, error) &&
        !(std::filesystem::is_regular_file(o.ready_file, error) && std::filesystem::file_size(o.ready_file, error) == 0)) {
      throw hapco::InputError("--ready-file " + o.ready_file +
                              " exists and is not an empty marker file: give a path of its own (it is created "
                              "when the recorder is ready and removed when it stops)");
    }
    RemoveReadyMarker(o.ready_file);
  }
  struct ReadyFileRemover {
    const std::string& path;
    ~ReadyFileRemover() { RemoveReadyMarker(path); }
  } ready_file_remover{o.ready_file};

  // The header goes first, before any DDS traffic: a recorder killed at any time leaves a
  // file with its header. An unwritable path throws InputError (exit 1).
  hapco::io::RecordingWriter writer(
      o.output, MakeHeader(o), o.overwrite ? hapco::io::ExistingFile::kReplace : hapco::io::ExistingFile::kRefuse);
  Recorder recorder(&writer);

  using namespace hapco::service;
  Participant participant(o.domain, SecurityIdentity{o.security_dir, "recorder"});  // disabled without --security
  Topic<hapco_idl_ContactStateFrame> frame_topic(participant);
  Topic<hapco_idl_FeedbackForce> force_topic(participant);
  Topic<hapco_idl_ServerStatus> status_topic(participant);
  Subscriber clients_subscriber(participant, kAllClientsPartition);
  Subscriber default_subscriber(participant);
  Reader<hapco_idl_ContactStateFrame> frame_reader(clients_subscriber, frame_topic, ContactStateQos(kFrameDepth));
  Reader<hapco_idl_FeedbackForce> force_reader(clients_subscriber, force_topic, ForceQos().KeepLast(kForceDepth));
  Reader<hapco_idl_ServerStatus> status_reader(default_subscriber, status_topic, StatusQos().KeepLast(kStatusDepth));
  WaitSet waitset(participant);
  waitset.Attach(frame_reader.data_condition(), 1);
  waitset.Attach(force_reader.data_condition(), 2);
  waitset.Attach(status_reader.data_condition(), 3);
  std::printf("hapco-recorder: domain %d, recording to %s\n", o.domain, o.output.c_str());
  std::fflush(stdout);

  std::atomic<bool> stop{false};
  const auto watching = stop_signals.Watch([&] {
    stop = true;
    waitset.Wake();
  });

  auto frame = MakeSample<hapco_idl_ContactStateFrame>();
  ReserveContacts(frame.get(), hapco_idl_MAX_CONTACT_SAMPLES);
  hapco_idl_FeedbackForce force{};
  auto status = MakeSample<hapco_idl_ServerStatus>();
  bool server_seen = false;
  // Forces first: the server writes a step's force before its frame, so the force (unless
  // lost) is already pending when its frame is matched.
  auto drain = [&] {
    while (force_reader.Take(&force)) recorder.OnForce(force);
    while (frame_reader.Take(frame.get())) recorder.OnFrame(*frame);
    while (status_reader.Take(status.get())) {
      recorder.OnStatus(*status);
      if (!server_seen) {
        server_seen = true;
        std::printf("hapco-recorder: server '%s' found\n", status->server_id);
        std::fflush(stdout);
      }
    }
  };

  // Ready once the server's recorder probe (a contact-state writer, service/server_loop.h) has
  // matched: from then on the server opens a session only when this recorder has its writer.
  bool ready = false;
  auto check_ready = [&] {
    if (ready || !server_seen || frame_reader.MatchedWriters() == 0) return;
    ready = true;
    std::printf("hapco-recorder: ready: new sessions are recorded from their first step\n");
    std::fflush(stdout);
    if (!o.ready_file.empty()) {
      std::FILE* file = std::fopen(o.ready_file.c_str(), "w");
      if (file == nullptr) throw hapco::InputError("cannot write --ready-file " + o.ready_file);
      std::fclose(file);
    }
  };
  const int64_t start_ns = hapco::MonotonicNowNs();
  const int64_t end_ns = o.duration_s > 0 ? start_ns + static_cast<int64_t>(o.duration_s * 1e9) : INT64_MAX;
  // The summary is printed however the run ends: a write error (a full disk) ended it without
  // one, so what had been recorded went unsaid (a helper session).
  const auto print_summary = [&](const char* stopped_by) {
    std::printf("hapco-recorder: %llu steps from %zu clients, %llu missing steps, %llu status records, "
                "%llu forces seen, file %s (%llu steps from forces alone, %llu frames received again and "
                "dropped; stopped by %s)\n",
                static_cast<unsigned long long>(recorder.steps()), recorder.clients(),
                static_cast<unsigned long long>(recorder.missing_steps()),
                static_cast<unsigned long long>(recorder.status_records()),
                static_cast<unsigned long long>(recorder.forces_seen()), o.output.c_str(),
                static_cast<unsigned long long>(recorder.from_forces()),
                static_cast<unsigned long long>(recorder.repeated_frames()),
                stopped_by);
  };
  try {
    int64_t next_progress_ns = start_ns + 1'000'000'000;
    while (!stop) {
      const int64_t now = hapco::MonotonicNowNs();
      if (now >= end_ns) break;
      const int64_t wait_ns = std::min<int64_t>({end_ns - now, next_progress_ns - now, 200'000'000});
      waitset.Wait(std::max<int64_t>(ready ? wait_ns : std::min<int64_t>(wait_ns, 20'000'000), 0));
      drain();
      check_ready();
      if (hapco::MonotonicNowNs() >= next_progress_ns) {
        next_progress_ns += 1'000'000'000;
        if (!o.quiet) {
          std::fprintf(stderr, "hapco-recorder: %llu records, %zu clients, %llu missing steps\n",
                       static_cast<unsigned long long>(writer.records_written()), recorder.clients(),
                       static_cast<unsigned long long>(recorder.missing_steps()));
        }
      }
    }
    drain();  // what was received before the stop
    recorder.FlushPending();
  } catch (const hapco::InputError&) {
    print_summary("a write error");
    throw;
  }
  print_summary(stop_signals.ReceivedName("--duration-s"));
  if (recorder.model_answers() > 0) {
    std::printf("hapco-recorder: %llu forces answered between steps (hapco-server --physics-every: no contact state of "
                "their own), not recorded as steps\n",
                static_cast<unsigned long long>(recorder.model_answers()));
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-recorder", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
