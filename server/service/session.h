#pragma once
// One client's haptic session on the server: its TwoBodySession on the shared model, the
// validation state of its pose stream, and its own publisher (partition ClientPartition(id))
// with the force and contact-state writers. Created by the server thread when the client
// joins (SESSION_JOIN or its first valid pose), never inside a listener callback.
#include <cstdio>
#include <cstdint>
#include <optional>
#include <memory>
#include <string>

#include <Eigen/Dense>

#include "hapco_types.h"
#include "service/dds.h"
#include "sim/local_model.h"
#include "sim/multirate.h"
#include "sim/step_pipeline.h"
#include "sim/pose_limits.h"
#include "service/pose_intake.h"
#include "sim/two_body_model.h"

namespace hapco::service {

// Pose plausibility is shared with the offline tools (sim/pose_limits.h).
using sim::PoseLimits;
using sim::PoseVerdict;

// Per-session counters of what the server did with this client's poses and samples.
struct SessionCounters {
  uint64_t steps = 0;
  uint64_t model_answers = 0;          // poses answered between steps (--physics-every > 1)
  uint64_t turn_steps = 0;             // of the steps, those taken at a turning pose (sim/multirate.h)
  uint64_t non_finite_forces = 0;      // solve gave NaN/Inf: the last good force was sent
  uint64_t beyond_compliance_range = 0;  // steps that needed a pair beyond a banded compliance
  uint64_t force_write_errors = 0;
  uint64_t contact_frames_dropped = 0; // DDS_RETCODE_TIMEOUT (or other error) on the frame
  uint64_t contacts_truncated = 0;     // frames with more contacts than the IDL bound
  uint64_t sequence_gaps = 0;          // sequence numbers skipped between stepped poses:
                                       // superseded (also counted there), lost on the
                                       // network, or overwritten in the reader
  uint64_t ignored_poses = 0;          // not finite, out of the workspace or a jump
  uint64_t ignored_notices = 0;        // FeedbackForce notices sent about them
};

// Where the stepped poses' time went since the last TakeStageTimes (sums, ns).
struct SessionStageTimes {
  int64_t physics_ns = 0;      // TwoBodySession::Step
  int64_t model_ns = 0;        // the local model (and the surface ahead) for FeedbackForce.model
  int64_t force_write_ns = 0;  // the FeedbackForce write
  int64_t frame_ns = 0;        // filling and writing the ContactStateFrame
  uint64_t poses = 0;
};

// What a session computes per pose. kNone is the load tests' floor: the same DDS path,
// QoS, validation and samples (a force and an empty contact frame per pose), no contact
// computation and a zero force, so `capacity(contact) / capacity(none)` says how much of the
// server's limit is the physics (scripts/loadtest-capacity).
enum class SessionPhysics { kContact, kNone };

class Session {
 public:
  // Throws DdsError if the writers cannot be created. time_budget_s >= 0 replaces the scene's
  // solver time budget (the haptic deadline; 0 = none), < 0 keeps the scene's. multirate:
  // physics_every > 1 answers some poses with the last step's local model (sim/multirate.h).
  Session(std::string client_id, const sim::TwoBodyModel& model, const Participant& participant,
          const Topic<hapco_idl_FeedbackForce>& force_topic,
          const Topic<hapco_idl_ContactStateFrame>& contact_topic, double time_budget_s = -1.0,
          SessionPhysics physics = SessionPhysics::kContact, bool local_model = true,
          std::string_view server_id = {}, sim::MultirateParameters multirate = {});

  const std::string& client_id() const { return client_id_; }

  // Step trace (hapco-server --trace): one CSV row per stepped pose (client, sequence, position,
  // force, µs from arrival to the force being ready), written before the force is published,
  // so that a killed server's trace holds every pose whose force a client may have received.
  // The file is shared by the stepping threads (stdio locks it per call; line-buffered, so
  // each row is one write). nullptr: no trace.
  void set_trace(std::FILE* trace) { trace_ = trace; }

  // A session answers poses only once it is open: its force writer is created when its
  // contact-state writer has matched `recorders` readers and they have acknowledged its hello
  // frame (step 0, written at creation; a recorder ignores it) (the recorders present, so that no
  // step of the session is missing from their recordings: with DDS-Security a new writer
  // needs its keys exchanged, ~90 ms here) or kRecorderWaitNs after creation, whichever comes
  // first. The client's Connect waits for the force writer, so it starts when the recorders
  // are ready. A device already sending poses (a client that moved here from a server that
  // died, or one that never waits for its session) is not kept waiting: with
  // `device_waiting` the session opens at once, acknowledged or not. Its recorders still get
  // the frames of its first kContactStateDepth steps (transient-local history); a recorder
  // slower to find its writer misses the first steps (hapco-report: "lost at the start of a
  // later session").
  // (Waiting for them cost a moved client 200-260 ms without a force on a loaded host, against
  // the failover budget of 100 ms after the client's timeout: CI 2026-12-07.) Returns open().
  bool TryOpen(uint32_t recorders, int64_t now_ns, bool device_waiting = false);
  bool open() const { return force_writer_.has_value(); }
  // 2 s: 0.5 s was not enough on a loaded host (compose on 2 cores, CI 2026-12-06: a session
  // opened before the recorder had its writer, and its first steps were missing from the
  // recording). It only delays a client while a recorder is present but does not match.
  static constexpr int64_t kRecorderWaitNs = 2'000'000'000;
  // Recorders the session opened without (kRecorderWaitNs ran out; 0 when all had matched),
  // and whether it opened before its readers had acknowledged its hello frame.
  uint32_t recorders_missing_at_open() const { return recorders_missing_at_open_; }
  bool recorders_unconfirmed_at_open() const { return recorders_unconfirmed_at_open_; }
  // From creation to its readers matching (-1: they never did) and to opening, ns.
  int64_t readers_matched_after_ns() const { return readers_matched_ns_ < 0 ? -1 : readers_matched_ns_ - created_ns_; }
  int64_t opened_after_ns() const { return opened_ns_ - created_ns_; }

  // Classifies a pose against the limits and this session's stream (no state change except
  // the flood window, which counts every pose seen). receive_ns: server CLOCK_MONOTONIC.
  // pending: the newest pose of this session waiting for its step (order and jump are checked
  // against it), or nullptr.
  PoseVerdict Check(const hapco_idl_DevicePose& pose, int64_t receive_ns, const PoseLimits& limits,
                    const hapco_idl_DevicePose* pending = nullptr);

  // One haptic step for an accepted pose, then the force (and contact frame) is written; with
  // --physics-every > 1 a pose between steps may be answered by the last step's local model
  // instead (a force, no frame). Returns the wall time in ns (pose received -> published).
  int64_t StepAndPublish(const hapco_idl_DevicePose& pose, int64_t receive_ns);

  // Counts a pose the server ignores (not finite, outside the workspace, a jump) and tells
  // the client: a FeedbackForce answering it with the last force sent (unchanged) and the
  // verdict, at most one per kNoticePeriodNs (receive_ns, server clock) per session, so the
  // notice costs at most 10 samples/s however fast the client sends bad poses.
  void NotifyIgnored(const hapco_idl_DevicePose& pose, int64_t receive_ns, PoseVerdict verdict);
  static constexpr int64_t kNoticePeriodNs = 100'000'000;
  // Tells a device that this session serves another device under the same client id
  // (ServerLoop::Client::device): a notice answering its pose, POSE_IGNORED_OTHER_DEVICE, with
  // a zero force (never the served device's force), at most one per kNoticePeriodNs.
  void NotifyOtherDevice(const hapco_idl_DevicePose& pose, int64_t receive_ns);

  // SESSION_RESET (and a repeated SESSION_JOIN: a restarted client): reference
  // configuration, the stream restarts (any next sequence and position accepted).
  void Reset();

  const SessionCounters& counters() const { return counters_; }
  const SessionStageTimes& stage_times() const { return stage_times_; }
  // The stage times since the last call, then zeroed (server thread, between batches).
  SessionStageTimes TakeStageTimes() {
    const SessionStageTimes t = stage_times_;
    stage_times_ = {};
    return t;
  }
  const sim::StepOutput& last_output() const { return sim_.last_output(); }
  // The session's first pose was deep inside and its approach is still on the way
  // (sim::TwoBodySession::Step): only the newest pose matters then.
  bool approaching() const { return sim_.approaching(); }
  const sim::TwoBodyModel& model() const { return sim_.model(); }  // this session's scene
  uint64_t last_sequence() const { return stream_.last() ? stream_.last()->sequence : 0; }
  const Eigen::Vector3d& last_force_n() const { return last_good_force_n_; }  // last sent, N

 private:
  void FillContactFrame(uint64_t pose_sequence);
  // FeedbackForce.model from the step just made (invalid without contact force); linearized:
  // the builder holds this step's model already.
  void FillLocalModel(bool force_is_from_this_step, bool linearized);
  // A multirate answer between steps (sim/multirate.h): the last step's model, anchored at the
  // pose this force answers. A client renders F0 + (its stiffness) x (x - x0) with F0 the force
  // it received, so x0 must be that force's pose, not the step's: up to --model-distance-m
  // apart, which along the normal is a whole wall offset (force_renderer.h).
  void AnchorModelAtAnswer(const Eigen::Vector3d& pose_m);

  std::string client_id_;
  SessionPhysics physics_;
  bool local_model_;
  sim::TwoBodySession sim_;
  sim::LocalModelBuilder local_model_builder_;
  sim::MultirateAnswerer answerer_;  // on sim_ and local_model_builder_
  Publisher publisher_;
  const Topic<hapco_idl_FeedbackForce>* force_topic_;
  Writer<hapco_idl_ContactStateFrame> contact_writer_;
  std::optional<Writer<hapco_idl_FeedbackForce>> force_writer_;  // created by TryOpen
  // Stamps and writes a notice (NotifyIgnored, NotifyOtherDevice), counted.
  void WriteNotice(hapco_idl_FeedbackForce* notice);
  uint32_t recorders_missing_at_open_ = 0;
  bool recorders_unconfirmed_at_open_ = false;
  SessionStageTimes stage_times_;
  int64_t created_ns_;
  int64_t readers_matched_ns_ = -1;  // first TryOpen that saw every recorder's reader matched
  int64_t opened_ns_ = -1;
  SamplePtr<hapco_idl_ContactStateFrame> frame_;  // reserved once, reused every step
  hapco_idl_FeedbackForce force_{};
  PoseStream stream_;  // flood bucket, order and jump checks (the fuzzed code, pose_intake.h)
  Eigen::Vector3d last_good_force_n_ = Eigen::Vector3d::Zero();
  std::FILE* trace_ = nullptr;
  bool any_notice_ = false;   // an ignored-pose notice was sent (since start or reset)
  int64_t last_notice_ns_ = 0;  // its receive time, server clock
  bool any_other_device_notice_ = false;  // the same for NotifyOtherDevice
  int64_t last_other_device_notice_ns_ = 0;
  SessionCounters counters_;
  uint64_t stream_steps_ = 0;  // steps since the session opened or was reset (ContactStateFrame.step)
};

}  // namespace hapco::service
