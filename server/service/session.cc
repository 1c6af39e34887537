#include "service/session.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <ctime>

#include "common/realtime.h"
#include "contact/projection.h"

namespace hapco::service {
namespace {

hapco_idl_SolverStatus ToIdl(contact::SolverStatus status, int contacts) {
  if (contacts == 0) return hapco_idl_SOLVER_NO_CONTACT;
  switch (status) {
    case contact::SolverStatus::kConverged: return hapco_idl_SOLVER_CONVERGED;
    case contact::SolverStatus::kMaxIterations: return hapco_idl_SOLVER_MAX_ITERATIONS;
    case contact::SolverStatus::kTimeBudgetExceeded: return hapco_idl_SOLVER_TIME_BUDGET_EXCEEDED;
    case contact::SolverStatus::kDiverged: return hapco_idl_SOLVER_DIVERGED;
  }
  return hapco_idl_SOLVER_DIVERGED;
}


hapco_idl_Vec3 ToIdl(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

Session::Session(std::string client_id, const sim::TwoBodyModel& model,
                 const Participant& participant,
                 const Topic<hapco_idl_FeedbackForce>& force_topic,
                 const Topic<hapco_idl_ContactStateFrame>& contact_topic, double time_budget_s,
                 SessionPhysics physics, bool local_model, std::string_view server_id,
                 sim::MultirateParameters multirate)
    : client_id_(std::move(client_id)),
      physics_(physics),
      local_model_(local_model),
      sim_(model),
      answerer_(sim_, local_model_builder_, multirate),
      publisher_(participant, ClientPartition(client_id_)),
      force_topic_(&force_topic),
      contact_writer_(publisher_, contact_topic),
      created_ns_(MonotonicNowNs()),
      frame_(MakeSample<hapco_idl_ContactStateFrame>()) {
  if (time_budget_s >= 0) sim_.parameters.time_budget_s = time_budget_s;
  // The surface-ahead search's trees are built here, not on the session's first 1 kHz step.
  if ((local_model_ || multirate.physics_every > 1) && physics_ == SessionPhysics::kContact) {
    local_model_builder_.Prepare(model);
  }
  SetClientId(force_.client_id, client_id_);
  SetClientId(frame_->client_id, client_id_);
  // The answering server in every force and frame: a client (and a recorder) sees when it
  // moves between servers (server_choice.h). Bounded like an id; longer ones are cut.
  const std::size_t id_length = std::min(server_id.size(), sizeof(force_.server_id) - 1);
  std::memcpy(force_.server_id, server_id.data(), id_length);
  std::memcpy(frame_->server_id, server_id.data(), id_length);
  const auto capacity = static_cast<uint32_t>(
      std::min<std::size_t>(model.tool_candidates().size() + model.obstacle_reverse_slaves().size(),
                            hapco_idl_MAX_CONTACT_SAMPLES));
  ReserveContacts(frame_.get(), capacity);
  // A hello frame (step 0, no contacts, never recorded): TryOpen waits until the readers
  // present have acknowledged it. A reader that has matched this writer on the server's side
  // may not yet know the writer on its own, and drops what it sends meanwhile: with the
  // recorder ready first, a session's step-1 frame was still lost in 3 of 40 sessions on a
  // loaded host (a helper session). An acknowledged hello means the step-1 frame reaches it.
  frame_->step = 0;
  frame_->pose_sequence = 0;
  frame_->contacts._length = 0;
  frame_->server_receive_ns = frame_->server_send_ns = created_ns_;
  contact_writer_.Write(*frame_);
}

bool Session::TryOpen(uint32_t recorders, int64_t now_ns, bool device_waiting) {
  if (open()) return true;
  // (A pose received before this session was created is stamped earlier than its creation.)
  now_ns = std::max(now_ns, created_ns_);
  const uint32_t matched = contact_writer_.MatchedReaders();
  // (A zero timeout only looks: the hello frame acknowledged by every matched reader.)
  if (matched >= recorders && readers_matched_ns_ < 0) readers_matched_ns_ = now_ns;
  const bool acknowledged = matched >= recorders && contact_writer_.WaitForAcks(0) == DDS_RETCODE_OK;
  if (!acknowledged && !device_waiting && now_ns - created_ns_ < kRecorderWaitNs) return false;
  opened_ns_ = now_ns;
  recorders_missing_at_open_ = matched < recorders ? recorders - matched : 0;
  recorders_unconfirmed_at_open_ = !acknowledged;
  force_writer_.emplace(publisher_, *force_topic_);
  return true;
}

PoseVerdict Session::Check(const hapco_idl_DevicePose& pose, int64_t receive_ns, const PoseLimits& limits,
                           const hapco_idl_DevicePose* pending) {
  return stream_.Check(pose, receive_ns, limits, pending);
}

int64_t Session::StepAndPublish(const hapco_idl_DevicePose& pose, int64_t receive_ns) {
  const Eigen::Vector3d p(pose.position_m.x, pose.position_m.y, pose.position_m.z);
  counters_.sequence_gaps += stream_.Accept(pose);
  static const sim::StepOutput kNoPhysics{};  // zero force, no contact, step 0
  const int64_t start_ns = MonotonicNowNs();
  // Multirate (sim/multirate.h): the answerer steps and linearizes, or answers from the model.
  const bool multirate = physics_ == SessionPhysics::kContact && answerer_.parameters().physics_every > 1;
  sim::MultirateAnswer answer;
  bool turned = false;  // a step at the turning pose came before this answer (multirate.h)
  if (multirate) {
    answer = answerer_.Answer(p);
    turned = static_cast<uint64_t>(answerer_.turn_steps()) != counters_.turn_steps;
    counters_.turn_steps = static_cast<uint64_t>(answerer_.turn_steps());
  } else if (physics_ == SessionPhysics::kContact) {
    sim_.Step(p);
  }
  const sim::StepOutput& out = physics_ == SessionPhysics::kContact ? sim_.last_output() : kNoPhysics;
  const bool stepped = answer.source == sim::AnswerSource::kStep;
  const int64_t physics_ns = MonotonicNowNs();
  Eigen::Vector3d force_n = stepped ? out.device_force_n : answer.device_force_n;
  if (stepped) {
    ++counters_.steps;
    ++stream_steps_;
    if (out.compliance_out_of_range) ++counters_.beyond_compliance_range;
  } else {
    ++counters_.model_answers;
  }
  const bool force_finite = force_n.allFinite();
  if (!force_finite) {
    // Never send a NaN: the last good force, counted. (The next steps may recover: the
    // session keeps its state; a persistent failure shows in the counter.)
    ++counters_.non_finite_forces;
    force_n = last_good_force_n_;
  } else {
    last_good_force_n_ = force_n;
  }
  force_.pose_sequence = pose.sequence_number;
  force_.client_time_ns = pose.client_time_ns;
  force_.server_receive_ns = receive_ns;
  force_.force_n = ToIdl(force_n);
  force_.pose_verdict = hapco_idl_POSE_STEPPED;
  force_.ignored_poses = counters_.ignored_poses;
  switch (answer.source) {
    case sim::AnswerSource::kStep: force_.answer_source = hapco_idl_ANSWER_STEP; break;
    case sim::AnswerSource::kModel: force_.answer_source = hapco_idl_ANSWER_MODEL; break;
    case sim::AnswerSource::kApart: force_.answer_source = hapco_idl_ANSWER_APART; break;
  }
  if (stepped) {
    force_.solver_status = ToIdl(out.status, out.num_contacts);
    force_.iterations = static_cast<uint32_t>(std::max(0, out.iterations));
    force_.separating_count = static_cast<uint32_t>(out.state_counts[0]);
    force_.sticking_count = static_cast<uint32_t>(out.state_counts[1]);
    force_.sliding_count = static_cast<uint32_t>(out.state_counts[2]);
    // (The multirate answerer has linearized this step already.)
    // An approach's answer (TwoBodySession::Step) is at a pose short of the device's: no model
    // to render the device's pose from.
    FillLocalModel(force_finite && !out.approaching, /*linearized=*/multirate);
  } else {
    force_.iterations = 0;  // the status and contact counts stay the last step's
    if (turned) FillLocalModel(out.device_force_n.allFinite(), /*linearized=*/true);  // the turn's step
    AnchorModelAtAnswer(p);
  }
  force_.server_send_ns = MonotonicNowNs();
  if (trace_ != nullptr) {
    const auto& x = pose.position_m;
    std::fprintf(trace_, "%s,%llu,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.3f\n", client_id_.c_str(),
                 static_cast<unsigned long long>(pose.sequence_number), x.x, x.y, x.z, force_n.x(), force_n.y(),
                 force_n.z(), static_cast<double>(force_.server_send_ns - receive_ns) * 1e-3);
  }
  if (force_writer_->Write(force_) != DDS_RETCODE_OK) ++counters_.force_write_errors;
  const int64_t written_ns = MonotonicNowNs();
  // This answer becomes the newest of the next force's repeated answers.
  std::move_backward(force_.recent, force_.recent + hapco_idl_RECENT_SAMPLES - 1, force_.recent + hapco_idl_RECENT_SAMPLES);
  force_.recent[0] = {force_.pose_sequence, force_.client_time_ns, force_.force_n};
  force_.recent_count = std::min<uint32_t>(force_.recent_count + 1, hapco_idl_RECENT_SAMPLES);
  if (!stepped) {
    // A model answer has no contact state of its own: no frame (the recorder counts it).
    stage_times_.physics_ns += physics_ns - start_ns;
    stage_times_.force_write_ns += written_ns - force_.server_send_ns;
    stage_times_.model_ns += force_.server_send_ns - physics_ns;
    ++stage_times_.poses;
    return written_ns - receive_ns;
  }
  // The contact frame goes after the force: the force is the latency-critical sample.
  FillContactFrame(pose.sequence_number);
  frame_->server_receive_ns = receive_ns;
  frame_->server_send_ns = force_.server_send_ns;
  frame_->client_round_trip_ns = pose.reported_round_trip_ns;
  frame_->device_position_m = pose.position_m;
  frame_->contact_force_n = ToIdl(out.contact_force_n);
  frame_->device_force_n = force_.force_n;
  frame_->solver_status = force_.solver_status;
  frame_->iterations = force_.iterations;
  frame_->solver_error = out.paper_error_m;
  frame_->separating_count = force_.separating_count;
  frame_->sticking_count = force_.sticking_count;
  frame_->sliding_count = force_.sliding_count;
  if (contact_writer_.Write(*frame_) != DDS_RETCODE_OK) ++counters_.contact_frames_dropped;
  const int64_t end_ns = MonotonicNowNs();
  stage_times_.physics_ns += physics_ns - start_ns;
  stage_times_.model_ns += force_.server_send_ns - physics_ns;
  stage_times_.force_write_ns += written_ns - force_.server_send_ns;
  stage_times_.frame_ns += end_ns - written_ns;
  ++stage_times_.poses;
  return end_ns - receive_ns;
}

void Session::NotifyIgnored(const hapco_idl_DevicePose& pose, int64_t receive_ns, PoseVerdict verdict) {
  hapco_idl_PoseVerdict idl_verdict;
  switch (verdict) {
    case PoseVerdict::kNonFinite: idl_verdict = hapco_idl_POSE_IGNORED_NOT_FINITE; break;
    case PoseVerdict::kOutOfWorkspace: idl_verdict = hapco_idl_POSE_IGNORED_OUT_OF_WORKSPACE; break;
    case PoseVerdict::kJump: idl_verdict = hapco_idl_POSE_IGNORED_JUMP; break;
    default: return;  // duplicates, reordering and floods are the network's, not the user's
  }
  ++counters_.ignored_poses;
  if (any_notice_ && receive_ns - last_notice_ns_ < kNoticePeriodNs) return;
  any_notice_ = true;
  last_notice_ns_ = receive_ns;
  // The last force sent, as sent (force_ holds it; zero before the first step), answering
  // this pose: the device keeps rendering what it has.
  hapco_idl_FeedbackForce notice = force_;
  SetClientId(notice.client_id, client_id_);
  notice.force_n = ToIdl(last_good_force_n_);
  notice.pose_sequence = pose.sequence_number;
  notice.client_time_ns = pose.client_time_ns;
  notice.server_receive_ns = receive_ns;
  notice.pose_verdict = idl_verdict;
  notice.model.valid = false;  // a notice is no new force, and carries no model
  notice.recent_count = 0;
  notice.ignored_poses = counters_.ignored_poses;
  WriteNotice(&notice);
}

void Session::WriteNotice(hapco_idl_FeedbackForce* notice) {
  notice->server_send_ns = MonotonicNowNs();
  if (!open()) return;
  if (force_writer_->Write(*notice) == DDS_RETCODE_OK) {
    ++counters_.ignored_notices;
  } else {
    ++counters_.force_write_errors;
  }
}

void Session::NotifyOtherDevice(const hapco_idl_DevicePose& pose, int64_t receive_ns) {
  if (any_other_device_notice_ && receive_ns - last_other_device_notice_ns_ < kNoticePeriodNs) return;
  any_other_device_notice_ = true;
  last_other_device_notice_ns_ = receive_ns;
  hapco_idl_FeedbackForce notice = force_;
  SetClientId(notice.client_id, client_id_);
  notice.force_n = ToIdl(Eigen::Vector3d::Zero());  // the served device's force is not this device's
  notice.pose_sequence = pose.sequence_number;
  notice.client_time_ns = pose.client_time_ns;
  notice.server_receive_ns = receive_ns;
  notice.pose_verdict = hapco_idl_POSE_IGNORED_OTHER_DEVICE;
  notice.model = hapco_idl_LocalContactModel{};
  notice.recent_count = 0;
  notice.separating_count = notice.sticking_count = notice.sliding_count = 0;
  WriteNotice(&notice);
}

void Session::FillLocalModel(bool force_is_from_this_step, bool linearized) {
  hapco_idl_LocalContactModel& m = force_.model;
  m = hapco_idl_LocalContactModel{};
  if (!local_model_ || physics_ != SessionPhysics::kContact || !force_is_from_this_step) return;
  // The pose answered, also without a model: a client keeps its model when that pose is
  // outside the model's surface (client/phantom/force_renderer.h).
  m.position_m = ToIdl(sim_.last_output().device_translation_m);
  const sim::LocalContactModel& local = linearized ? local_model_builder_.model() : local_model_builder_.Linearize(sim_);
  if (local.surface_ahead && local.surface_normal.allFinite() && std::isfinite(local.surface_gap_m)) {
    m.surface_ahead = true;
    m.surface_gap_m = local.surface_gap_m;
    m.surface_normal = ToIdl(local.surface_normal);
  }
  // A model needs a contact pushing (its normal) and finite numbers; otherwise none is sent
  // and a client renders the force as it came.
  if (local.normal_device.isZero() || !local.stiffness_n_per_m.allFinite() || !local.device_force_n.allFinite()) {
    return;
  }
  m.valid = true;
  m.position_m = ToIdl(local.device_translation_m);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m.stiffness_n_per_m[3 * i + j] = local.stiffness_n_per_m(i, j);
  }
  m.normal = ToIdl(local.normal_device);
  m.friction_coefficient = local.friction_coefficient;
}

void Session::AnchorModelAtAnswer(const Eigen::Vector3d& pose_m) {
  hapco_idl_LocalContactModel& m = force_.model;
  if (!m.valid && !m.surface_ahead) return;  // nothing a client evaluates at x0
  const Eigen::Vector3d anchor(m.position_m.x, m.position_m.y, m.position_m.z);
  if (m.surface_ahead) {
    // The plane ahead moves with its anchor: gap(x) = gap0 + n·(x - x0) (local_model.h). An
    // apart answer comes only while that gap stays open (multirate.h).
    const Eigen::Vector3d normal(m.surface_normal.x, m.surface_normal.y, m.surface_normal.z);
    m.surface_gap_m = std::max(0.0, m.surface_gap_m + normal.dot(pose_m - anchor));
  }
  m.position_m = ToIdl(pose_m);
}

void Session::FillContactFrame(uint64_t pose_sequence) {
  frame_->step = stream_steps_;
  frame_->pose_sequence = pose_sequence;
  if (physics_ == SessionPhysics::kNone) {
    frame_->contacts._length = 0;
    return;
  }
  const auto& contacts = sim_.contacts();
  const uint32_t capacity = frame_->contacts._maximum;
  if (contacts.size() > capacity) ++counters_.contacts_truncated;
  const auto n = static_cast<uint32_t>(std::min<std::size_t>(contacts.size(), capacity));
  const auto& result = sim_.last_result();
  const bool have_result = result.force_n.size() >= 3 * static_cast<Eigen::Index>(n) &&
                           result.displacement_m.size() >= 3 * static_cast<Eigen::Index>(n);
  uint32_t written = 0;
  for (uint32_t alpha = 0; alpha < n && have_result; ++alpha) {
    const sim::ContactSample sample = sim_.SampleContact(static_cast<int>(alpha));
    hapco_idl_ContactSample& s = frame_->contacts._buffer[written++];
    s.id = static_cast<uint32_t>(sample.tool_node);
    s.position_m = ToIdl(sample.position_m);
    s.normal = ToIdl(sample.normal);
    s.force_n = ToIdl(sample.force_n);
    s.gap_m = sample.gap_m;
    s.slip_m = sample.slip_m;
    s.state = static_cast<hapco_idl_ContactState>(sample.state);
  }
  frame_->contacts._length = written;
}

void Session::Reset() {
  sim_.Reset();
  answerer_.Reset();
  stream_.Reset();
  last_good_force_n_.setZero();
  any_notice_ = false;
  force_.recent_count = 0;  // answers of the previous stream are not this one's
  // The frames' step numbers start again: a recorder (and hapco-report) sees a new session,
  // as for a re-opened one. A take-over by a restarted client used to read as one session
  // whose force fell from 12.7 N at 2 mm to 0.6 N at 0.1 mm in one step (a helper session).
  stream_steps_ = 0;
}

}  // namespace hapco::service
