#pragma once
// The hapco-server loop: one thread that waits on a WaitSet (pose data, session control,
// wake-up guard, status period), takes every available pose, keeps the newest per client
// (older ones are superseded = dropped, counted), then steps the sessions that got a pose on
// a pool of threads (ServerOptions::threads; sessions are independent and share only the
// immutable model) and each worker publishes the force of the session it stepped. Sessions are created here, in the server's own thread, never in a
// DDS listener (platform-notes.md: no entity creation inside a listener).
// Bad input is counted, logged at most once per second per kind, and never fatal.
#include <atomic>
#include <array>
#include <cstdint>
#include <cstdio>
#include <map>
#include <set>
#include <unordered_map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/background_deleter.h"
#include "common/token_bucket.h"
#include "common/work_pool.h"
#include "hapco_types.h"
#include "service/dds.h"
#include "service/server_choice.h"
#include "service/session.h"
#include "sim/two_body_model.h"

namespace hapco::service {

struct ServerOptions {
  // Announced in ServerStatus; clients name it in their SESSION_JOIN and poses and only this
  // server steps those (service/server_choice.h). hapco-server's default: DefaultServerId().
  std::string server_id = "hapco-server";
  double status_period_s = 1.0;  // ServerStatus period, s
  int max_sessions = 16;         // clients beyond this are refused (counted as unknown)
  int threads = 1;               // threads stepping sessions, the server thread included (>= 1)
  SessionPhysics physics = SessionPhysics::kContact;  // kNone: the load tests' zero-cost floor
  // Send the contact's local model with every force (FeedbackForce.model, sim/local_model.h):
  // ~5 % of a step (docs/network-haptics.md); clients rendering in local-model mode need it.
  bool local_model = true;
  PoseLimits limits;
  // physics_every > 1: a contact step on every pose only where the last step's local model
  // cannot answer it, at least every physics_every poses (sim/multirate.h). 1: every pose.
  sim::MultirateParameters multirate;
  // Solver wall-clock budget per step, s (0 = none); < 0 keeps the scene's. A step that
  // runs out returns SOLVER_TIME_BUDGET_EXCEEDED with the forces it has.
  double time_budget_s = -1.0;
  // A session with no pose and no session message for this long is closed, s (0 = never): a
  // client killed without a LEAVE (SIGKILL, a crash, a cable) held its slot for good, and
  // --max-sessions of them locked the server (a helper session's two killed clients: a third
  // refused for 18 s and more). A client that comes back later gets a new session.
  double session_idle_s = 5.0;
  bool log = true;               // rate-limited stderr log of bad input and sessions
  SecurityIdentity security;     // enabled: a secured participant (service/security.h)
  // Optional step trace (CSV, one row per step: client, sequence, position, force sent);
  // for tests and debugging. Not owned.
  std::FILE* trace = nullptr;
};

// Everything the server counted since start.
struct ServerCounters {
  hapco_idl_InputCounters input{};  // as published in ServerStatus
  uint64_t invalid_client_ids = 0;  // also counted in input.unknown_clients
  uint64_t refused_sessions = 0;    // --max-sessions reached; also in input.unknown_clients
  uint64_t superseded = 0;          // older poses of a client replaced by a newer one in a batch
  uint64_t steps = 0;
  uint64_t model_answers = 0;       // poses answered between steps (--physics-every, sim/multirate.h)
  uint64_t turn_steps = 0;          // steps taken at turning poses besides (not in `steps`)
  uint64_t non_finite_forces = 0;   // solve gave NaN/Inf; the last good force was sent
  uint64_t beyond_compliance_range = 0;  // steps that needed a pair beyond contact.compliance_range_m
  uint64_t force_write_errors = 0;
  uint64_t contact_frames_dropped = 0;
  uint64_t sequence_gaps = 0;       // sequences never stepped (superseded + lost + overwritten)
  uint64_t ignored_notices = 0;     // FeedbackForce notices telling a client its pose was ignored
  uint64_t sessions_opened = 0;
  uint64_t sessions_closed = 0;
  uint64_t status_published = 0;
  uint64_t poses_after_leave = 0;   // poses of a client that left (until it joins again) or moved away (sent before)
  uint64_t parallel_batches = 0;    // ticks that stepped two or more sessions on the pool
  uint64_t burst_steps = 0;         // poses stepped after another of the same client in one tick
  uint64_t recovered_poses = 0;     // poses never received, stepped from a later pose's repeats
  uint64_t poses_for_other_servers = 0;  // addressed to another server (or unaddressed, not ours)
  uint64_t sessions_moved_away = 0;  // closed because the client joined another server
  uint64_t idle_sessions_closed = 0;  // closed after ServerOptions::session_idle_s without a message
  // A session serves one device (DDS participant): poses and session messages of another
  // device under the same client id are ignored (that device is told), and a JOIN from
  // another device takes the session over (a restarted client; ServerLoop::Client::device).
  uint64_t other_device_messages = 0;
  uint64_t sessions_taken_over = 0;
};

class ServerLoop {
 public:
  // Creates the participant, topics, pose/session readers and the status writer in
  // `domain_id` (configuration from CYCLONEDDS_URI). Throws DdsError on setup failure.
  // `models`: the scenes served (not owned, non-empty, distinct scene names); a SESSION_JOIN
  // picks one by its scene_name, an empty name or a session opened by a pose gets the first.
  ServerLoop(std::vector<const sim::TwoBodyModel*> models, dds_domainid_t domain_id, const ServerOptions& options);
  ServerLoop(const sim::TwoBodyModel& model, dds_domainid_t domain_id, const ServerOptions& options)
      : ServerLoop(std::vector<const sim::TwoBodyModel*>{&model}, domain_id, options) {}
  ~ServerLoop();
  ServerLoop(const ServerLoop&) = delete;
  ServerLoop& operator=(const ServerLoop&) = delete;

  // Serves until RequestStop(). Publishes a last status before returning.
  void Run();
  // Thread-safe (not async-signal-safe: call it from a signal-waiting thread).
  void RequestStop();

  ServerCounters counters() const;  // call after Run() returned, or from the server thread
  std::size_t sessions() const { return sessions_.size(); }
  // "hapco-server: ... steps, ... sessions, counters ..." (one line).
  std::string Summary() const;
  // Why Run() stopped on its own, "" if it did not: another live server on the domain
  // announces this server's --server-id and started before it (or within 50 ms of it). Both
  // would answer the clients addressed to that id (a helper session: every pose of a client
  // stepped twice, its recording 1 516 sessions), so the newer one stops.
  const std::string& stopped_because() const { return stopped_because_; }

 private:
  static constexpr int kMaxQueuedPoses = PendingPoses::kCapacity;
  // The device behind a sample: the GUID of its writer's DDS participant (one per client
  // process: a restarted client is a new one).
  using DeviceId = std::array<unsigned char, 16>;
  struct WriterIdentity {
    std::string client_id;  // of its partition, "" for none
    DeviceId device{};
  };
  struct Client {
    std::unique_ptr<Session> session;
    // The device this session serves: the one whose JOIN or first pose opened it, or whose
    // JOIN took it over. Two devices started with one --client-id shared a session: each
    // device's poses moved the other's tool (7 mm jumps each way) and one device rendered the
    // other's press (5.3 N hovering 5 mm above the bar, CI 2026-12-07); and the first to
    // exit closed the other's session with its LEAVE.
    DeviceId device{};
    PendingPoses queued;  // stepped in order by StepQueued (service/pose_intake.h)
    // Newest sequence number this client's session has processed, stepped or refused: repeats
    // (DevicePose.recent) at or before it are never looked at again.
    uint64_t newest_seen = 0;
    bool seen_any = false;
    bool range_logged = false;  // the first step beyond contact.compliance_range_m was logged
    // client_time_ns of the first pose queued since the session opened or was reset (-1: none).
    int64_t first_client_time_ns = -1;
    // client_time_ns of the newest SESSION_JOIN this session took (-1: opened by a pose).
    int64_t joined_client_time_ns = -1;
    // When a pose or a session message of this client last arrived (CLOCK_MONOTONIC, ns).
    int64_t last_heard_ns = 0;
    // Filled by the stepping job, read by the server thread after the batch.
    PendingPoses stepped;
    int superseded_while_approaching = 0;  // queued poses left out of this batch (StepQueued)
    std::array<int64_t, kMaxQueuedPoses> step_ns{};
  };

  void ProcessSessionControls();
  // SESSION_RESET or a restarted client's JOIN: reference configuration, a new pose stream.
  void RestartStream(Client* client);
  void ProcessPoses();
  // Queues the poses `pose` repeats (DevicePose.recent) that this client's session never got.
  void RecoverMissedPoses(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns);
  void Queue(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns);
  void StepQueued();  // steps the queued poses of every session, on the pool
  void CloseIdleSessions(int64_t now_ns);  // ServerOptions::session_idle_s
  // period_end: the status period is over (step-time quantiles and CPU use restart);
  // otherwise an announcement between periods after the number of sessions changed.
  void PublishStatus(int64_t now_ns, bool period_end = true);
  // Reads the other servers' announcements (their ServerStatus).
  void ReadPeerStatus();
  // True when this server steps the poses of a client addressed by `field` (its server_id).
  bool AddressedToMe(const char (&field)[65]) const;
  // Opens the sessions whose recorders are ready (Session::TryOpen); true if any still waits.
  bool OpenWaitingSessions(int64_t now_ns);
  // Session::TryOpen, logging a session that opened without all its recorders.
  bool TryOpenSession(Client* client, uint32_t recorders, int64_t now_ns, bool device_waiting = false);
  Client* OpenSession(const std::string& client_id, const sim::TwoBodyModel& model);
  // The served scene called `scene_name` (the first one for ""), nullptr if none.
  void CloseSession(std::map<std::string, Client>::iterator it, const std::string& why);  // counters kept, logged
  const sim::TwoBodyModel* FindModel(const std::string& scene_name) const;
  std::string SceneNames() const;  // "a, b" for messages
  void Count(PoseVerdict verdict, const std::string& client_id);
  // True when `client_id` is the client the writer of a sample may speak for (the id of its
  // partition), else counted as an identity mismatch and logged. One discovery lookup per
  // writer, then a hash lookup per sample.
  // `device` receives the writer's device.
  bool FromItsOwnWriter(const std::string& client_id, dds_entity_t reader, dds_instance_handle_t writer,
                        DeviceId* device);
  // A pose of a device that is not the one `client` serves: counted, logged, and that device
  // told (a notice, POSE_IGNORED_OTHER_DEVICE).
  void RefuseOtherDevice(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns);
  void Log(int kind, const std::string& message);

  std::vector<const sim::TwoBodyModel*> models_;
  ServerOptions options_;
  // Declared first so it is destroyed last (wrappers: children before the participant).
  Participant participant_;
  Topic<hapco_idl_DevicePose> pose_topic_;
  Topic<hapco_idl_SessionControl> session_topic_;
  Topic<hapco_idl_ServerStatus> status_topic_;
  Topic<hapco_idl_FeedbackForce> force_topic_;
  Topic<hapco_idl_ContactStateFrame> contact_topic_;
  // Poses and session controls come in the clients' own partitions (hapco/client/<id>).
  Subscriber client_subscriber_;
  Publisher publisher_;
  Reader<hapco_idl_DevicePose> pose_reader_;
  Reader<hapco_idl_SessionControl> session_reader_;
  Writer<hapco_idl_ServerStatus> status_writer_;
  Subscriber peer_subscriber_;  // default partition, where every server's status is
  // Absent when DDS refuses it (a secured deployment whose permissions predate several
  // servers): then this server assumes it is alone (logged).
  std::optional<Reader<hapco_idl_ServerStatus>> peer_status_reader_;
  std::vector<ServerAnnouncement> peers_;  // the other servers' newest announcements
  bool serves_unaddressed_ = true;         // ServesUnaddressed over peers_, per loop iteration
  std::size_t announced_sessions_ = 0;     // sessions in the last status published
  // Stage times of sessions closed during the current status period (their sums are kept).
  SessionStageTimes stage_times_;
  // Never written: a contact-state writer in a partition of its own, so that its matched
  // readers are the wildcard (hapco/client/*) readers, i.e. the recorders present. A new
  // session opens once its own writer has matched as many (Session::TryOpen).
  Publisher recorder_probe_publisher_;
  Writer<hapco_idl_ContactStateFrame> recorder_probe_;
  WaitSet waitset_;
  std::map<std::string, Client> sessions_;
  // Closed sessions are destroyed here, off the loop; declared after the participant and the
  // models, so it drains before they go.
  BackgroundDeleter retired_sessions_;
  // Clients that sent SESSION_LEAVE and have not joined since, with the device that left: its
  // poses still in flight must not reopen the session; another device's poses open one for it
  // (a second device under the id was stranded when the served one left; a helper session).
  std::map<std::string, DeviceId> left_clients_;
  // Clients whose session here ended because they moved to another server (their JOIN or a
  // pose addressed there): the device, and the client time of the message that said so. Its
  // poses sent before that, addressed here and arriving late, must not open a new session (a
  // helper session saw one opened and closed again at once, logged as a client that moved here).
  struct MovedAway {
    DeviceId device{};
    int64_t client_time_ns = 0;
  };
  std::map<std::string, MovedAway> moved_clients_;
  std::unordered_map<dds_instance_handle_t, WriterIdentity> writer_identities_;  // writer -> its client and device
  std::atomic<bool> stop_{false};
  ServerCounters counters_;
  // Counters of sessions closed so far (live sessions are added on demand).
  SessionCounters closed_session_counters_;
  std::vector<double> step_times_us_;  // this status period
  WorkPool pool_;
  std::vector<Client*> stepping_;   // the sessions stepped in this batch (capacity max_sessions)
  std::array<hapco_idl_DevicePose, hapco_idl_RECENT_SAMPLES> missed_{};  // RecoverMissedPoses scratch
  int64_t start_ns_ = 0;
  dds_instance_handle_t own_status_handle_ = 0;  // this server's status writer, to tell its own samples
  std::string stopped_because_;
  // A ServerStatus with this server's id from another writer (ReadPeerStatus), whose server
  // has been up other_uptime_ns.
  void OnDuplicateServerId(int64_t other_uptime_ns, int64_t now_ns);
  int64_t last_status_ns_ = 0, last_status_cpu_ns_ = 0;  // for ServerStatus.cpu_use
  std::vector<TokenBucket> log_buckets_;  // per log kind (Log)
  std::vector<uint64_t> suppressed_logs_;
};

}  // namespace hapco::service
