#include "service/server_loop.h"

#include <optional>

#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <ctime>

#include "common/error.h"
#include "common/statistics.h"
#include "common/realtime.h"
#include "service/pose_intake.h"

namespace hapco::service {
namespace {

// A peer server is live while its status keeps coming: three periods of the default 1 s.
constexpr int64_t kPeerMaxAgeNs = 3'000'000'000LL;
constexpr dds_attach_t kPoseToken = 1;
constexpr dds_attach_t kSessionToken = 2;
// Rate limiting is per kind; each pose verdict is a kind of its own (kLogBadPose + verdict).
enum LogKind { kLogClient = 0, kLogSession = 1, kLogFailure = 2, kLogIdentity = 3, kLogBadPose = 4, kLogKinds = kLogBadPose + 7 };
// Log lines a kind may print at once; one more each second after. Session lines name a client
// each and come in bunches (a failover moves every client of a server at once: with one a
// second the log named 2 of 4 takeovers and the rest were "+2 similar suppressed").
constexpr double kLogBurst = 1.0, kSessionLogBurst = 16.0;

}  // namespace

ServerLoop::ServerLoop(std::vector<const sim::TwoBodyModel*> models, dds_domainid_t domain_id,
                       const ServerOptions& options)
    : models_(std::move(models)),
      options_(options),
      participant_(domain_id, options.security),
      pose_topic_(participant_),
      session_topic_(participant_),
      status_topic_(participant_),
      force_topic_(participant_),
      contact_topic_(participant_),
      client_subscriber_(participant_, kAllClientsPartition),
      publisher_(participant_),
      // Reader history kMaxQueuedPoses per client (the writers keep 1): poses that arrive
      // while the server is busy are taken and stepped in order (StepQueued).
      pose_reader_(client_subscriber_, pose_topic_, PoseQos().KeepLast(kMaxQueuedPoses)),
      session_reader_(client_subscriber_, session_topic_),
      status_writer_(publisher_, status_topic_),
      peer_subscriber_(participant_),
      recorder_probe_publisher_(participant_, ClientPartition(".recorder-probe")),
      recorder_probe_(recorder_probe_publisher_, contact_topic_),
      waitset_(participant_),
      pool_(options.threads),
      log_buckets_(kLogKinds),
      suppressed_logs_(kLogKinds, 0) {
  if (models_.empty()) throw InputError("the server needs at least one scene");
  for (std::size_t i = 0; i < models_.size(); ++i) {
    HAPCO_ASSERT(models_[i] != nullptr, "ServerLoop: null model");
    for (std::size_t j = 0; j < i; ++j) {
      if (models_[j]->scene().name == models_[i]->scene().name) {
        throw InputError("two scenes are named '" + models_[i]->scene().name +
                         "': clients choose a scene by its name, so names must differ");
      }
    }
  }
  if (options_.status_period_s <= 0) throw InputError("status period must be > 0 s");
  if (options_.max_sessions < 1) throw InputError("max sessions must be >= 1");
  try {
    peer_status_reader_.emplace(peer_subscriber_, status_topic_, StatusQos());
  } catch (const DdsError& error) {
    Log(kLogFailure, std::string("cannot read other servers' status (") + error.what() +
                         "): serving as the only server on this domain (scripts/dds-security init gives "
                         "servers that permission)");
  }
  waitset_.Attach(pose_reader_.data_condition(), kPoseToken);
  waitset_.Attach(session_reader_.data_condition(), kSessionToken);
  step_times_us_.reserve(8192);
  stepping_.reserve(static_cast<std::size_t>(options_.max_sessions));
  start_ns_ = MonotonicNowNs();
  if (dds_get_instance_handle(status_writer_.handle(), &own_status_handle_) != DDS_RETCODE_OK) own_status_handle_ = 0;
}

ServerLoop::~ServerLoop() {
  // Sessions own publishers of participant_: drop them before the participant goes.
  sessions_.clear();
}

void ServerLoop::RequestStop() {
  stop_.store(true);
  waitset_.Wake();
}

void ServerLoop::Run() {
  const auto period_ns = static_cast<int64_t>(options_.status_period_s * 1e9);
  int64_t next_status_ns = MonotonicNowNs() + period_ns;
  PublishStatus(MonotonicNowNs());
  dds_attach_t tokens[4];
  bool waiting_sessions = false;
  while (!stop_.load()) {
    int64_t wait_ns = std::max<int64_t>(0, next_status_ns - MonotonicNowNs());
    if (waiting_sessions) wait_ns = std::min<int64_t>(wait_ns, 2'000'000);  // poll their recorders
    waitset_.Wait(wait_ns, tokens, 4);
    if (stop_.load()) break;
    ReadPeerStatus();
    ProcessSessionControls();
    waiting_sessions = OpenWaitingSessions(MonotonicNowNs());
    ProcessPoses();
    const int64_t now = MonotonicNowNs();
    if (now >= next_status_ns) {
      CloseIdleSessions(now);
      PublishStatus(now);
      next_status_ns = now + period_ns;
    } else if (sessions_.size() != announced_sessions_) {
      PublishStatus(now, false);  // joining clients choose by the number of sessions: say it now
    }
  }
  PublishStatus(MonotonicNowNs());
}

bool ServerLoop::OpenWaitingSessions(int64_t now_ns) {
  bool waiting = false;
  uint32_t recorders = 0;
  bool counted = false;
  for (auto& [id, client] : sessions_) {
    if (client.session->open()) continue;
    if (!counted) {
      recorders = recorder_probe_.MatchedReaders();
      counted = true;
    }
    if (!TryOpenSession(&client, recorders, now_ns)) waiting = true;
  }
  return waiting;
}

bool ServerLoop::TryOpenSession(Client* client, uint32_t recorders, int64_t now_ns, bool device_waiting) {
  Session& session = *client->session;
  if (!session.TryOpen(recorders, now_ns, device_waiting)) return false;
  // How long the client waited for its session (a moved client: part of the failover budget,
  // docs/several-servers.md), and whether the recorders were in step.
  char after[160];
  std::snprintf(after, sizeof after, "' open after %.1f ms", static_cast<double>(session.opened_after_ns()) * 1e-6);
  const std::string why = device_waiting ? "a device already sending poses (a client that moved here) is not kept waiting"
                                         : "waited 2 s";
  if (const uint32_t missing = session.recorders_missing_at_open(); missing > 0) {
    Log(kLogSession, "session of '" + session.client_id() + after + " without " + std::to_string(missing) + " of the " +
                         std::to_string(recorders) + " recorders present (their readers had not matched its writer; " +
                         why + "): its first steps may be missing from their recordings");
  } else if (session.recorders_unconfirmed_at_open()) {
    Log(kLogSession, "session of '" + session.client_id() + after + " before its recorders acknowledged its first frame (" +
                         why + "): its first steps may be missing from their recordings");
  } else if (recorders > 0) {
    Log(kLogSession, "session of '" + session.client_id() + after + ", its " + std::to_string(recorders) +
                         " recorder(s) in step");
  }
  return true;
}

const sim::TwoBodyModel* ServerLoop::FindModel(const std::string& scene_name) const {
  if (scene_name.empty()) return models_.front();
  for (const sim::TwoBodyModel* model : models_) {
    if (model->scene().name == scene_name) return model;
  }
  return nullptr;
}

std::string ServerLoop::SceneNames() const {
  std::string names;
  for (const sim::TwoBodyModel* model : models_) names += (names.empty() ? "" : ", ") + model->scene().name;
  return names;
}

ServerLoop::Client* ServerLoop::OpenSession(const std::string& client_id, const sim::TwoBodyModel& model) {
  if (static_cast<int>(sessions_.size()) >= options_.max_sessions) {
    ++counters_.refused_sessions;
    ++counters_.input.unknown_clients;
    Log(kLogClient, "session refused for '" + client_id + "': --max-sessions " +
                        std::to_string(options_.max_sessions) + " reached");
    return nullptr;
  }
  try {
    Client client;
    client.last_heard_ns = MonotonicNowNs();
    const int64_t creating_ns = client.last_heard_ns;
    client.session = std::make_unique<Session>(client_id, model, participant_, force_topic_, contact_topic_,
                                               options_.time_budget_s, options_.physics, options_.local_model,
                                               options_.server_id, options_.multirate);
    client.session->set_trace(options_.trace);
    auto [it, inserted] = sessions_.emplace(client_id, std::move(client));
    HAPCO_ASSERT(inserted, "OpenSession: session exists already");
    ++counters_.sessions_opened;
    // (Its creation, a per-session copy of the scene's state and two DDS writers, took 157 ms
    // on a stalled server: part of what a moving client waits.)
    char created_in[48];
    std::snprintf(created_in, sizeof created_in, ", created in %.1f ms)",
                  static_cast<double>(MonotonicNowNs() - creating_ns) * 1e-6);
    Log(kLogSession, "session opened for '" + client_id + "' on scene " + model.scene().name + " (" +
                         std::to_string(sessions_.size()) + " open" + created_in);
    return &it->second;
  } catch (const std::exception& error) {
    Log(kLogFailure, "cannot open a session for '" + client_id + "': " + error.what());
    return nullptr;
  }
}

void ServerLoop::CloseIdleSessions(int64_t now_ns) {
  if (!(options_.session_idle_s > 0)) return;
  const auto idle_ns = static_cast<int64_t>(options_.session_idle_s * 1e9);
  for (auto it = sessions_.begin(); it != sessions_.end();) {
    const auto next = std::next(it);
    if (now_ns - it->second.last_heard_ns > idle_ns) {
      char seconds[32];
      std::snprintf(seconds, sizeof seconds, "%.1f", static_cast<double>(now_ns - it->second.last_heard_ns) * 1e-9);
      ++counters_.idle_sessions_closed;
      CloseSession(it, std::string("nothing heard from it for ") + seconds +
                           " s (--session-idle-s); it gets a new session if it comes back");
    }
    it = next;
  }
}

void ServerLoop::CloseSession(std::map<std::string, Client>::iterator it, const std::string& why) {
  const SessionCounters& c = it->second.session->counters();
  closed_session_counters_.steps += c.steps;
  closed_session_counters_.model_answers += c.model_answers;
  closed_session_counters_.turn_steps += c.turn_steps;
  closed_session_counters_.non_finite_forces += c.non_finite_forces;
  closed_session_counters_.beyond_compliance_range += c.beyond_compliance_range;
  closed_session_counters_.force_write_errors += c.force_write_errors;
  closed_session_counters_.contact_frames_dropped += c.contact_frames_dropped;
  closed_session_counters_.sequence_gaps += c.sequence_gaps;
  closed_session_counters_.ignored_notices += c.ignored_notices;
  const SessionStageTimes t = it->second.session->TakeStageTimes();
  stage_times_.physics_ns += t.physics_ns;
  stage_times_.model_ns += t.model_ns;
  stage_times_.force_write_ns += t.force_write_ns;
  stage_times_.frame_ns += t.frame_ns;
  stage_times_.poses += t.poses;
  // One line per close, with its reason (an idle close was logged twice: a helper session).
  Log(kLogSession, "session closed for '" + it->first + "': " + why);
  // Its DDS writers are deleted on the deleter's thread: dds_delete took 97-142 ms here, a
  // stall of every other session (background_deleter.h).
  retired_sessions_.Retire(std::move(it->second.session));
  sessions_.erase(it);
  ++counters_.sessions_closed;
}

namespace {

// The client a writer may speak for: X of its only partition "hapco/client/X" ("" if it has
// none or several; nullopt if the writer is not known, e.g. already gone).
// DDS-Security's permissions let client X write only there.
std::optional<std::pair<std::string, std::array<unsigned char, 16>>> WriterIdentityOf(dds_entity_t reader,
                                                                                      dds_instance_handle_t writer) {
  dds_builtintopic_endpoint_t* endpoint = dds_get_matched_publication_data(reader, writer);
  if (endpoint == nullptr) return std::nullopt;
  std::string id;
  uint32_t count = 0;
  char** names = nullptr;
  if (dds_qget_partition(endpoint->qos, &count, &names)) {
    const std::string_view prefix = kClientPartitionPrefix;
    if (count == 1 && std::string_view(names[0]).substr(0, prefix.size()) == prefix) {
      id = std::string(names[0] + prefix.size());
    }
    for (uint32_t k = 0; k < count; ++k) dds_free(names[k]);
    dds_free(names);
  }
  std::array<unsigned char, 16> device{};
  static_assert(sizeof(endpoint->participant_key.v) == 16, "a DDS GUID is 16 bytes");
  std::memcpy(device.data(), endpoint->participant_key.v, device.size());
  dds_builtintopic_free_endpoint(endpoint);
  return std::make_pair(std::move(id), device);
}

}  // namespace

bool ServerLoop::FromItsOwnWriter(const std::string& client_id, dds_entity_t reader, dds_instance_handle_t writer,
                                  DeviceId* device) {
  auto known = writer_identities_.find(writer);
  if (known == writer_identities_.end()) {
    auto identity = WriterIdentityOf(reader, writer);
    if (!identity) {
      ++counters_.input.identity_mismatches;
      Log(kLogIdentity, "sample claiming client '" + client_id + "' from an unknown writer ignored");
      return false;
    }
    if (writer_identities_.size() >= 4096) writer_identities_.clear();  // bounded; rebuilt on demand
    known = writer_identities_.emplace(writer, WriterIdentity{std::move(identity->first), identity->second}).first;
  }
  *device = known->second.device;
  if (known->second.client_id == client_id) return true;
  ++counters_.input.identity_mismatches;
  Log(kLogIdentity, "sample claiming client '" + client_id + "' from the writer of " +
                        (known->second.client_id.empty() ? std::string("no client partition")
                                                         : "client '" + known->second.client_id + "'") +
                        " ignored");
  return false;
}

void ServerLoop::RefuseOtherDevice(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns) {
  ++counters_.other_device_messages;
  Log(kLogClient, "poses of a second device under the client id '" + client->session->client_id() +
                      "' ignored: its session serves the device that joined last (give each device its own "
                      "--client-id)");
  client->session->NotifyOtherDevice(pose, receive_ns);
}

void ServerLoop::ProcessSessionControls() {
  hapco_idl_SessionControl control{};
  dds_sample_info_t info;
  while (session_reader_.Take(&control, &info)) {
    const std::string id = ClientIdOf(control.client_id);
    if (!IsValidClientId(id)) {
      ++counters_.invalid_client_ids;
      ++counters_.input.unknown_clients;
      Log(kLogClient, "session control with an invalid client id ignored");
      continue;
    }
    DeviceId device{};
    if (!FromItsOwnWriter(id, session_reader_.handle(), info.publication_handle, &device)) continue;
    auto it = sessions_.find(id);
    if (!AddressedToMe(control.server_id)) {
      // For another server. A JOIN there means the client moved: its session here ends (it
      // never gets two servers' forces; server_choice.h).
      // (Its own device only: a second device under the id joining elsewhere ends nothing here.)
      if (control.command == hapco_idl_SESSION_JOIN && it != sessions_.end() && it->second.device == device) {
        ++counters_.sessions_moved_away;
        moved_clients_[id] = {device, control.client_time_ns};
        CloseSession(it, "it joined server '" + ServerIdOf(control.server_id) + "'");
      }
      continue;
    }
    const bool other_device = it != sessions_.end() && it->second.device != device;
    if (other_device && control.command != hapco_idl_SESSION_JOIN) {
      // A LEAVE or RESET of a device this session does not serve (the first of two devices
      // with one id to exit closed the other's session).
      ++counters_.other_device_messages;
      Log(kLogClient, "session message of a second device under the client id '" + id + "' ignored");
      continue;
    }
    if (it != sessions_.end()) it->second.last_heard_ns = MonotonicNowNs();
    switch (control.command) {
      case hapco_idl_SESSION_JOIN: {
        left_clients_.erase(id);
        moved_clients_.erase(id);
        const std::string scene_name(control.scene_name, strnlen(control.scene_name, sizeof(control.scene_name)));
        const sim::TwoBodyModel* model = FindModel(scene_name);
        if (model == nullptr) {
          ++counters_.refused_sessions;
          Log(kLogClient, "session refused for '" + id + "': unknown scene '" + scene_name +
                              "' (this server has: " + SceneNames() + ")");
          if (it != sessions_.end()) CloseSession(it, "it asked for the unknown scene '" + scene_name + "'");
          break;
        }
        if (it != sessions_.end() && &it->second.session->model() != model) {
          CloseSession(it, "it switches to scene '" + scene_name + "'");  // a new session on the new one
          it = sessions_.end();
        }
        if (it == sessions_.end()) {
          if (Client* opened = OpenSession(id, *model)) {
            opened->joined_client_time_ns = control.client_time_ns;
            opened->device = device;
          }
        } else if (other_device) {
          // Another device under this id: a restarted client (a new process), or a second
          // device started with the same --client-id. The device that joined last is served,
          // from the reference configuration; the other is told (RefuseOtherDevice).
          RestartStream(&it->second);
          it->second.device = device;
          it->second.joined_client_time_ns = control.client_time_ns;
          ++counters_.sessions_taken_over;
          Log(kLogSession, "session of '" + id + "' taken over by another device (a restarted client, or two "
                                                 "devices with one --client-id): reset");
        } else if (it->second.first_client_time_ns < 0) {
          // No pose yet: a client asking again while it waits for its session (it repeats its
          // JOIN every second): nothing to reset.
          it->second.joined_client_time_ns = control.client_time_ns;
        } else if (control.client_time_ns > 0 && it->second.first_client_time_ns >= control.client_time_ns) {
          // Every pose this session took was sent after the JOIN: they are the stream this JOIN
          // starts (a client moved here and its first poses overtook its JOIN; DDS orders no
          // two topics). The session keeps them and its state.
          it->second.joined_client_time_ns = control.client_time_ns;
        } else {
          // A restarted client (its sequence starts again): a fresh stream and scene state.
          RestartStream(&it->second);
          it->second.joined_client_time_ns = control.client_time_ns;
          Log(kLogSession, "session of '" + id + "' joined again: reset");
        }
        break;
      }
      case hapco_idl_SESSION_LEAVE:
        if (it != sessions_.end()) {
          CloseSession(it, "it left");
          // Poses of this client still in flight must not reopen the session: it has to
          // SESSION_JOIN again (a restarted server, which has no such record, still opens a
          // session on a client's first pose, so clients resume after a server restart).
          left_clients_[id] = device;
        }
        break;
      case hapco_idl_SESSION_RESET:
        if (it != sessions_.end()) {
          RestartStream(&it->second);
        }
        break;
      default:
        Log(kLogClient, "unknown session command from '" + id + "' ignored");
    }
  }
}

void ServerLoop::RestartStream(Client* client) {
  client->session->Reset();
  client->queued.Clear();
  client->newest_seen = 0;
  client->seen_any = false;
  client->first_client_time_ns = -1;
}

void ServerLoop::Count(PoseVerdict verdict, const std::string& client_id) {
  auto& in = counters_.input;
  switch (verdict) {
    case PoseVerdict::kAccept: return;
    case PoseVerdict::kNonFinite: ++in.bad_pose_nan; break;
    case PoseVerdict::kOutOfWorkspace: ++in.out_of_workspace; break;
    case PoseVerdict::kJump: ++in.position_jumps; break;
    case PoseVerdict::kOutOfOrder: ++in.out_of_order; break;
    case PoseVerdict::kDuplicate: ++in.duplicates; break;
    case PoseVerdict::kFlood: ++in.floods; break;
  }
  Log(kLogBadPose + static_cast<int>(verdict), std::string(sim::VerdictName(verdict)) + " from '" + client_id + "' ignored");
}

void ServerLoop::ProcessPoses() {
  hapco_idl_DevicePose pose{};
  dds_sample_info_t info;
  // Take everything available; keep the newest valid pose per client.
  while (pose_reader_.Take(&pose, &info)) {
    const int64_t receive_ns = MonotonicNowNs();
    const std::string id = ClientIdOf(pose.client_id);
    if (!IsValidClientId(id)) {
      ++counters_.invalid_client_ids;
      ++counters_.input.unknown_clients;
      Log(kLogClient, "pose with an invalid client id ignored");
      continue;
    }
    DeviceId device{};
    if (!FromItsOwnWriter(id, pose_reader_.handle(), info.publication_handle, &device)) continue;
    auto it = sessions_.find(id);
    if (!AddressedToMe(pose.server_id)) {
      ++counters_.poses_for_other_servers;  // another server's client: not bad input
      // It moved (its JOIN elsewhere may not have reached this server): never answer twice. Only
      // a pose sent after this session began says so: one of the stream before (addressed to
      // the server it left, still in flight or in the reader's queue) must not end it.
      if (it != sessions_.end() && it->second.device == device && pose.server_id[0] != '\0' &&
          pose.client_time_ns > std::max(it->second.joined_client_time_ns, it->second.first_client_time_ns)) {
        ++counters_.sessions_moved_away;
        moved_clients_[id] = {device, pose.client_time_ns};
        CloseSession(it, "it is served by '" + ServerIdOf(pose.server_id) + "' now");
      }
      continue;
    }
    Client* client = nullptr;
    if (it == sessions_.end()) {
      if (auto left = left_clients_.find(id); left != left_clients_.end() && left->second == device) {
        ++counters_.poses_after_leave;
        continue;  // in flight when the client left; not bad input
      }
      if (auto moved = moved_clients_.find(id); moved != moved_clients_.end() && moved->second.device == device) {
        if (pose.client_time_ns <= moved->second.client_time_ns) {
          ++counters_.poses_after_leave;
          continue;  // sent before it moved away, late; not bad input
        }
        moved_clients_.erase(moved);  // it came back (a pose sent after it moved)
      }
      const PoseVerdict first = CheckStatelessPose(pose, options_.limits);
      if (first != PoseVerdict::kAccept) {
        Count(first, id);
        continue;
      }
      client = OpenSession(id, *models_.front());
      if (client == nullptr) continue;
      client->device = device;
      left_clients_.erase(id);  // (another device than the one that left)
    } else {
      client = &it->second;
      if (client->device != device) {
        RefuseOtherDevice(client, pose, receive_ns);
        continue;
      }
    }
    client->last_heard_ns = receive_ns;
    // A pose before the session opened: a device in use (a client that moved here) is not
    // kept waiting for the recorders (Session::TryOpen).
    if (!client->session->open()) {
      TryOpenSession(client, recorder_probe_.MatchedReaders(), receive_ns, /*device_waiting=*/true);
    }
    if (const hapco_idl_DevicePose* last = client->queued.last(); last != nullptr && pose.sequence_number <= last->sequence_number) {
      Count(pose.sequence_number == last->sequence_number ? PoseVerdict::kDuplicate : PoseVerdict::kOutOfOrder, id);
      continue;
    }
    // The poses it repeats that never arrived go first (each checked on its own), then the
    // pose itself, checked against the newest of them: a burst is checked pose to pose.
    RecoverMissedPoses(client, pose, receive_ns);
    client->newest_seen = std::max(client->newest_seen, pose.sequence_number);
    client->seen_any = true;
    const PoseVerdict verdict = client->session->Check(pose, receive_ns, options_.limits, client->queued.last());
    if (verdict != PoseVerdict::kAccept) {
      Count(verdict, id);
      client->session->NotifyIgnored(pose, receive_ns, verdict);  // the client is told why
      continue;
    }
    Queue(client, pose, receive_ns);
  }
  StepQueued();
}

void ServerLoop::RecoverMissedPoses(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns) {
  // The poses this one repeats that the server never took (a best-effort reader drops a
  // sample that arrives after a newer one; jitter reorders packets), oldest first, each
  // checked (and counted against the flood limit) like a pose of its own.
  const int count = MissedPoses(pose, client->newest_seen, client->seen_any, &missed_);
  for (int k = 0; k < count; ++k) {
    const hapco_idl_DevicePose& missed = missed_[static_cast<std::size_t>(k)];
    const PoseVerdict verdict = client->session->Check(missed, receive_ns, options_.limits, client->queued.last());
    if (verdict != PoseVerdict::kAccept) {
      Count(verdict, client->session->client_id());
      continue;
    }
    Queue(client, missed, receive_ns);
    ++counters_.recovered_poses;
  }
}

void ServerLoop::Queue(Client* client, const hapco_idl_DevicePose& pose, int64_t receive_ns) {
  if (client->first_client_time_ns < 0) client->first_client_time_ns = pose.client_time_ns;
  if (client->queued.Push(pose, receive_ns)) ++counters_.superseded;  // more than a burst: the oldest gave way
}

void ServerLoop::StepQueued() {
  // Step every session that got poses, on the pool, each of its poses in order; each job
  // touches only its own session (its TwoBodySession, its writers) and its own Client slots.
  stepping_.clear();
  for (auto& [id, client] : sessions_) {
    if (client.queued.size() == 0) continue;
    stepping_.push_back(&client);
  }
  auto step = [](Client& client) {
    client.stepped = client.queued;
    client.queued.Clear();
    client.superseded_while_approaching = 0;
    for (int k = 0; k < client.stepped.size(); ++k) {
      const auto slot = static_cast<std::size_t>(k);
      if (k + 1 < client.stepped.size() && client.session->approaching()) {
        // An approach presses in to the newest pose whatever came before it, a few steps a
        // pose: each queued pose would run that work again (three deep clients taken over at
        // once queued 16 poses each and held the server's other client for 100 ms; a helper
        // session). The newest only; the ones between are superseded.
        client.step_ns[slot] = -1;
        ++client.superseded_while_approaching;
        continue;
      }
      client.step_ns[slot] = client.session->StepAndPublish(client.stepped.pose(k), client.stepped.receive_ns(k));
    }
  };
  auto job = [&](int k) { step(*stepping_[static_cast<std::size_t>(k)]); };
  pool_.Run(static_cast<int>(stepping_.size()), job);
  if (stepping_.size() >= 2) ++counters_.parallel_batches;
  for (Client* stepped : stepping_) {
    Client& client = *stepped;
    const std::string& id = client.session->client_id();
    counters_.superseded += static_cast<uint64_t>(client.superseded_while_approaching);
    for (int k = 0; k < client.stepped.size(); ++k) {
      const auto slot = static_cast<std::size_t>(k);
      const int64_t ns = client.step_ns[slot];
      if (ns < 0) continue;  // superseded while approaching
      step_times_us_.push_back(static_cast<double>(ns) * 1e-3);
      if (k > 0) ++counters_.burst_steps;
    }
    if (client.session->counters().non_finite_forces > 0 &&
        client.session->last_output().device_force_n.allFinite() == false) {
      Log(kLogFailure, "non-finite force for '" + id + "': last good force sent");
    }
    // Once per client: several poses can be stepped between two of these checks (a burst).
    if (!client.range_logged && client.session->counters().beyond_compliance_range > 0) {
      client.range_logged = true;
      Log(kLogFailure, "a step of '" + id +
                           "' needed obstacle node pairs beyond contact.compliance_range_m (read as zero, so its force is "
                           "approximate): raise the range; further such steps are counted in the summary");
    }
  }
}

ServerCounters ServerLoop::counters() const {
  ServerCounters c = counters_;
  SessionCounters s = closed_session_counters_;
  for (const auto& [id, client] : sessions_) {
    const SessionCounters& live = client.session->counters();
    s.steps += live.steps;
    s.model_answers += live.model_answers;
    s.turn_steps += live.turn_steps;
    s.non_finite_forces += live.non_finite_forces;
    s.beyond_compliance_range += live.beyond_compliance_range;
    s.force_write_errors += live.force_write_errors;
    s.contact_frames_dropped += live.contact_frames_dropped;
    s.sequence_gaps += live.sequence_gaps;
    s.ignored_notices += live.ignored_notices;
  }
  c.steps = s.steps;
  c.model_answers = s.model_answers;
  c.turn_steps = s.turn_steps;
  c.non_finite_forces = s.non_finite_forces;
  c.beyond_compliance_range = s.beyond_compliance_range;
  c.force_write_errors = s.force_write_errors;
  c.contact_frames_dropped = s.contact_frames_dropped;
  c.sequence_gaps = s.sequence_gaps;
  c.ignored_notices = s.ignored_notices;
  return c;
}

void ServerLoop::ReadPeerStatus() {
  hapco_idl_ServerStatus status{};
  dds_sample_info_t info;
  const int64_t now = MonotonicNowNs();
  while (peer_status_reader_ && peer_status_reader_->Take(&status, &info)) {
    if (!info.valid_data) continue;
    ServerAnnouncement a = AnnouncementOf(status, now);
    if (a.server_id == options_.server_id) {
      // Its own (the reader sees this participant's writer too), or another server's under the
      // same id.
      if (own_status_handle_ != 0 && info.publication_handle != own_status_handle_) {
        // Its uptime now: the announced one plus the sample's age (a transient-local sample
        // may be a status period old; clocks of one host, or synchronised ones).
        const int64_t age_ns = std::max<int64_t>(0, dds_time() - info.source_timestamp);
        OnDuplicateServerId(status.uptime_ns + age_ns, now);
      }
      continue;
    }
    if (a.server_id.empty()) continue;  // nameless
    auto known = std::find_if(peers_.begin(), peers_.end(),
                              [&a](const ServerAnnouncement& p) { return p.server_id == a.server_id; });
    if (known != peers_.end()) {
      *known = std::move(a);
    } else if (peers_.size() < 256) {
      peers_.push_back(std::move(a));
    }
  }
  // A peer is live while its status keeps coming: three of its periods (1 s by default).
  serves_unaddressed_ = ServesUnaddressed(options_.server_id, peers_, now, kPeerMaxAgeNs);
}

void ServerLoop::OnDuplicateServerId(int64_t other_uptime_ns, int64_t now_ns) {
  // The older server keeps the id; the newer stops (both stop when they started within 50 ms
  // of each other): its uptime is known to a delivery latency, so compared with a margin.
  constexpr int64_t kTieNs = 50'000'000;
  const int64_t own_uptime_ns = now_ns - start_ns_;
  char apart[96];  // how long before (+) or after (-) this one the other started
  std::snprintf(apart, sizeof apart, "%.2f s", std::abs(static_cast<double>(other_uptime_ns - own_uptime_ns)) * 1e-9);
  if (other_uptime_ns + kTieNs >= own_uptime_ns) {
    if (stopped_because_.empty()) {
      stopped_because_ = "another server on this domain already announces --server-id '" + options_.server_id +
                         "' (it started " + apart + (other_uptime_ns >= own_uptime_ns ? " before" : " after") +
                         " this one): two servers with one id would both answer its clients; give each server its "
                         "own --server-id (or leave it out for a unique default)";
      Log(kLogFailure, stopped_because_ + "; stopping");
      RequestStop();
    }
  } else {
    Log(kLogFailure, "another server on this domain announces this server's --server-id '" + options_.server_id +
                         "' (it started " + apart + " after this one): it stops, this one keeps serving");
  }
}

bool ServerLoop::AddressedToMe(const char (&field)[65]) const {
  const std::size_t length = strnlen(field, sizeof(field));
  if (length == 0) return serves_unaddressed_;
  return length == options_.server_id.size() && std::memcmp(field, options_.server_id.data(), length) == 0;
}

void ServerLoop::PublishStatus(int64_t now_ns, bool period_end) {
  auto status = MakeSample<hapco_idl_ServerStatus>();
  status->max_sessions = static_cast<uint32_t>(options_.max_sessions);
  std::string scenes;
  for (const sim::TwoBodyModel* model : models_) scenes += (scenes.empty() ? "" : ",") + model->scene().name;
  std::snprintf(status->scene_names, sizeof(status->scene_names), "%s", scenes.c_str());
  announced_sessions_ = sessions_.size();
  std::snprintf(status->server_id, sizeof(status->server_id), "%s", options_.server_id.c_str());
  status->uptime_ns = now_ns - start_ns_;
  status->sessions = static_cast<uint32_t>(sessions_.size());
  status->step_time_p50_us = Quantile(&step_times_us_, 0.50);
  status->step_time_p99_us = Quantile(&step_times_us_, 0.99);
  status->step_time_max_us = step_times_us_.empty() ? 0.0 : *std::max_element(step_times_us_.begin(), step_times_us_.end());
  status->counters = counters_.input;
  // CPU use over the period since the last status (getrusage: this process, all threads,
  // so DDS receive threads count too).
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const int64_t cpu_ns = (static_cast<int64_t>(usage.ru_utime.tv_sec) + usage.ru_stime.tv_sec) * 1'000'000'000LL +
                         (static_cast<int64_t>(usage.ru_utime.tv_usec) + usage.ru_stime.tv_usec) * 1'000LL;
  if (last_status_ns_ > 0 && now_ns > last_status_ns_) {
    status->cpu_use = static_cast<double>(cpu_ns - last_status_cpu_ns_) / static_cast<double>(now_ns - last_status_ns_);
  }
  if (period_end) {
    last_status_ns_ = now_ns;
    last_status_cpu_ns_ = cpu_ns;
  }
  const ServerCounters all = counters();
  status->steps = all.steps;
  status->superseded = all.superseded;
  status->contact_frames_dropped = all.contact_frames_dropped;
  status->non_finite_forces = all.non_finite_forces;
  status->answers_between_steps = all.model_answers;
  status->turn_steps = all.turn_steps;
  // Stage split: sessions' sums since the last period end (their times are taken only then, so
  // a status published early reports the running period).
  SessionStageTimes stages = stage_times_;
  for (auto& [id, client] : sessions_) {
    const SessionStageTimes t = period_end ? client.session->TakeStageTimes() : client.session->stage_times();
    stages.physics_ns += t.physics_ns;
    stages.model_ns += t.model_ns;
    stages.force_write_ns += t.force_write_ns;
    stages.frame_ns += t.frame_ns;
    stages.poses += t.poses;
  }
  if (stages.poses > 0) {
    const double per_pose_us = 1e-3 / static_cast<double>(stages.poses);
    status->physics_mean_us = static_cast<double>(stages.physics_ns) * per_pose_us;
    status->model_mean_us = static_cast<double>(stages.model_ns) * per_pose_us;
    status->force_write_mean_us = static_cast<double>(stages.force_write_ns) * per_pose_us;
    status->frame_mean_us = static_cast<double>(stages.frame_ns) * per_pose_us;
  }
  if (period_end) {
    step_times_us_.clear();
    stage_times_ = {};
  }
  if (status_writer_.Write(*status) == DDS_RETCODE_OK) ++counters_.status_published;
}

std::string ServerLoop::Summary() const {
  const ServerCounters c = counters();
  const auto& in = c.input;
  char line[896];
  std::snprintf(line, sizeof(line),
                "hapco-server: %llu steps (%llu ticks stepped several sessions on %d threads), "
                "%llu sessions opened, %zu open; superseded %llu, stepped in bursts %llu, recovered %llu, "
                "sequence gaps %llu; "
                "bad input: nan %llu, workspace %llu, jumps %llu, out-of-order %llu, duplicates %llu, "
                "unknown clients %llu, floods %llu, identity mismatches %llu; non-finite forces %llu, force write errors %llu, "
                "contact frames dropped %llu; ignored-pose notices sent %llu; poses for other servers %llu, "
                "sessions moved to other servers %llu",
                static_cast<unsigned long long>(c.steps), static_cast<unsigned long long>(c.parallel_batches),
                pool_.threads(), static_cast<unsigned long long>(c.sessions_opened),
                sessions_.size(), static_cast<unsigned long long>(c.superseded),
                static_cast<unsigned long long>(c.burst_steps), static_cast<unsigned long long>(c.recovered_poses),
                static_cast<unsigned long long>(c.sequence_gaps),
                static_cast<unsigned long long>(in.bad_pose_nan), static_cast<unsigned long long>(in.out_of_workspace),
                static_cast<unsigned long long>(in.position_jumps), static_cast<unsigned long long>(in.out_of_order),
                static_cast<unsigned long long>(in.duplicates), static_cast<unsigned long long>(in.unknown_clients),
                static_cast<unsigned long long>(in.floods), static_cast<unsigned long long>(in.identity_mismatches),
                static_cast<unsigned long long>(c.non_finite_forces),
                static_cast<unsigned long long>(c.force_write_errors),
                static_cast<unsigned long long>(c.contact_frames_dropped),
                static_cast<unsigned long long>(c.ignored_notices),
                static_cast<unsigned long long>(c.poses_for_other_servers),
                static_cast<unsigned long long>(c.sessions_moved_away));
  std::string summary = line;
  if (c.other_device_messages > 0 || c.sessions_taken_over > 0) {
    summary += "; messages of second devices under a served client id ignored " +
               std::to_string(c.other_device_messages) + ", sessions taken over by another device " +
               std::to_string(c.sessions_taken_over);
  }
  if (c.idle_sessions_closed > 0) {
    summary += "; sessions closed after --session-idle-s without a message " + std::to_string(c.idle_sessions_closed);
  }
  if (options_.multirate.physics_every > 1) {
    summary += "; poses answered between steps (--physics-every " + std::to_string(options_.multirate.physics_every) +
               ") " + std::to_string(c.model_answers) + ", extra steps at turning poses " + std::to_string(c.turn_steps);
  }
  if (c.beyond_compliance_range > 0) {
    summary += "; steps beyond contact.compliance_range_m " + std::to_string(c.beyond_compliance_range);
  }
  return summary;
}

void ServerLoop::Log(int kind, const std::string& message) {
  if (!options_.log) return;
  const auto k = static_cast<std::size_t>(kind);
  const int64_t now = MonotonicNowNs();
  // A token bucket per kind (kLogBurst, kSessionLogBurst; one line a second on average): a
  // flood of bad poses cannot flood the log. The number of suppressed lines is reported.
  if (!log_buckets_[k].Take(now, kind == kLogSession ? kSessionLogBurst : kLogBurst, /*rate_per_ms=*/1e-3)) {
    ++suppressed_logs_[k];
    return;
  }
  if (suppressed_logs_[k] > 0) {
    std::fprintf(stderr, "hapco-server: %s (+%llu similar suppressed)\n", message.c_str(),
                 static_cast<unsigned long long>(suppressed_logs_[k]));
  } else {
    std::fprintf(stderr, "hapco-server: %s\n", message.c_str());
  }
  suppressed_logs_[k] = 0;
}

}  // namespace hapco::service
