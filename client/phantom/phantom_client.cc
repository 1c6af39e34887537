#include "phantom_client.h"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <mutex>

#include "common/error.h"
#include "common/realtime.h"
#include "render_chain.h"
#include "service/dds.h"
#include "service/server_choice.h"

namespace hapco::phantom {
namespace {

timespec ToTimespec(int64_t ns) {
  return timespec{static_cast<time_t>(ns / 1'000'000'000LL), static_cast<long>(ns % 1'000'000'000LL)};
}

ServerVerdict FromIdl(hapco_idl_PoseVerdict verdict) {
  switch (verdict) {
    case hapco_idl_POSE_STEPPED: return ServerVerdict::kStepped;
    case hapco_idl_POSE_IGNORED_NOT_FINITE: return ServerVerdict::kNotFinite;
    case hapco_idl_POSE_IGNORED_OUT_OF_WORKSPACE: return ServerVerdict::kOutOfWorkspace;
    case hapco_idl_POSE_IGNORED_JUMP: return ServerVerdict::kJump;
    case hapco_idl_POSE_IGNORED_OTHER_DEVICE: return ServerVerdict::kOtherDevice;
  }
  return ServerVerdict::kNotFinite;  // an unknown value: not a force to render
}

}  // namespace

const char* ServerVerdictText(ServerVerdict verdict) {
  switch (verdict) {
    case ServerVerdict::kStepped: return "stepped";
    case ServerVerdict::kNotFinite: return "NaN or Inf in the pose";
    case ServerVerdict::kOutOfWorkspace: return "position outside the server's workspace (--workspace-m)";
    case ServerVerdict::kJump: return "position jump above the server's limit (--max-jump-m)";
    case ServerVerdict::kOtherDevice:
      return "its session of this client id serves another device (the one that joined last): give each device its "
             "own --client-id";
  }
  return "unknown";
}

struct PhantomClient::Dds {
  explicit Dds(const ClientConfig& c)
      : participant(c.domain, c.security),
        pose_topic(participant),
        force_topic(participant),
        session_topic(participant),
        // Poses and session controls in the client's own partition: the server accepts a
        // sample only for the client of its writer's partition (docs/security.md).
        publisher(participant, service::ClientPartition(c.client_id)),
        subscriber(participant, service::ClientPartition(c.client_id)),
        pose_writer(publisher, pose_topic),
        session_writer(publisher, session_topic),
        // Reader history 8 (the writer keeps 1; history is not request/offered): forces that
        // arrive back to back are all taken by the listener, none overwritten unseen.
        force_reader(subscriber, force_topic, service::ForceQos().KeepLast(8)),
        status_topic(participant),
        status_subscriber(participant),
        status_reader(status_subscriber, status_topic, service::StatusQos()) {}
  // Declared first, destroyed last (children before their participant).
  service::Participant participant;
  service::Topic<hapco_idl_DevicePose> pose_topic;
  service::Topic<hapco_idl_FeedbackForce> force_topic;
  service::Topic<hapco_idl_SessionControl> session_topic;
  service::Publisher publisher;
  service::Subscriber subscriber;
  service::Writer<hapco_idl_DevicePose> pose_writer;
  service::Writer<hapco_idl_SessionControl> session_writer;
  service::Reader<hapco_idl_FeedbackForce> force_reader;
  // The servers' announcements (ServerStatus, transient-local: a new reader gets each
  // server's newest at once), kept by the receive thread, read when choosing a server.
  service::Topic<hapco_idl_ServerStatus> status_topic;
  service::Subscriber status_subscriber;
  service::Reader<hapco_idl_ServerStatus> status_reader;
  std::mutex servers_mutex;
  std::condition_variable servers_changed;
  std::vector<service::ServerAnnouncement> servers;

  void OnStatusAvailable() {
    hapco_idl_ServerStatus status{};
    dds_sample_info_t info;
    while (status_reader.Take(&status, &info)) {
      if (!info.valid_data) continue;
      service::ServerAnnouncement a = service::AnnouncementOf(status, MonotonicNowNs());
      if (a.server_id.empty()) continue;
      a.writer_handle = info.publication_handle;
      {
        std::lock_guard<std::mutex> lock(servers_mutex);
        if (service::RecordAnnouncement(servers, std::move(a), 256) == service::LeaseChange::kRegained) {
          ++leases_regained;
          last_lease_regained_ns = MonotonicNowNs();
        }
      }
      servers_changed.notify_all();
    }
  }
  // A server's status writer lost its liveliness lease (the process died or froze) or got it
  // back: recorded in its announcement, so it is neither chosen nor waited for.
  void OnLivelinessChanged(const dds_liveliness_changed_status_t& status) {
    {
      std::lock_guard<std::mutex> lock(servers_mutex);
      switch (service::ApplyLivelinessChange(servers, status.last_publication_handle, status.alive_count_change,
                                             MonotonicNowNs())) {
        case service::LeaseChange::kLapsed: ++leases_lapsed; break;
        case service::LeaseChange::kRegained:
          ++leases_regained;
          last_lease_regained_ns = MonotonicNowNs();
          break;
        case service::LeaseChange::kNone: break;
      }
    }
    servers_changed.notify_all();
  }
  // Under servers_mutex: lapses seen, lapses that came back, and when one last came back.
  uint64_t leases_lapsed = 0, leases_regained = 0;
  int64_t last_lease_regained_ns = -1;
};

namespace {
// A server whose status has not come for this long is not chosen (three default periods).
constexpr int64_t kServerMaxAgeNs = 3'000'000'000LL;

// True at most once a second per kind of log line (*last_s: when it was last true, < 0 never);
// the lines carry their counts, so none is lost.
bool LogDue(double* last_s, double now_s) {
  if (*last_s >= 0 && now_s - *last_s < 1.0) return false;
  *last_s = now_s;
  return true;
}
}  // namespace

PhantomClient::PhantomClient(ClientConfig config) : config_(std::move(config)) {
  service::ValidateClientId(config_.client_id);
  if (config_.trajectory.empty()) throw InputError("phantom client: empty trajectory");
  if (config_.ticks <= 0) throw InputError("phantom client: the number of ticks must be positive");
  stats_.round_trip_us.reserve(static_cast<std::size_t>(config_.ticks) + 64);
  stats_.render_latency_us.reserve(static_cast<std::size_t>(config_.ticks) + 64);
  stats_.server_time_us.reserve(static_cast<std::size_t>(config_.ticks) + 64);
  dds_ = std::make_unique<Dds>(config_);
  dds_->force_reader.SetOnDataAvailable([this] { OnForcesAvailable(); });
  Dds* dds = dds_.get();
  dds_->status_reader.SetOnDataAvailable([dds] { dds->OnStatusAvailable(); });
  dds_->status_reader.SetOnLivelinessChanged(
      [dds](const dds_liveliness_changed_status_t& status) { dds->OnLivelinessChanged(status); });
}

PhantomClient::~PhantomClient() {
  // No callback may run while dds_ is being reset (it reads through dds_): a force arriving
  // during the teardown crashed the phantom (seen: SIGSEGV in OnForcesAvailable on Cyclone's
  // gc thread, 1 in ~15 secured runs). ClearListener waits for a callback in progress.
  if (dds_) {
    dds_->force_reader.ClearListener();
    dds_->status_reader.ClearListener();
  }
  dds_.reset();
}

void PhantomClient::OnForcesAvailable() {
  hapco_idl_FeedbackForce force{};
  while (dds_->force_reader.Take(&force)) {
    const int64_t now = MonotonicNowNs();
    // Answers to earlier poses that never arrived on their own (a best-effort reader drops a
    // sample that comes after a newer one): recovered from the answers this one repeats,
    // oldest first, before it. Stepped forces only; a notice repeats nothing.
    if (force.pose_verdict == hapco_idl_POSE_STEPPED) {
      const uint32_t count = std::min<uint32_t>(force.recent_count, hapco_idl_RECENT_SAMPLES);
      for (uint32_t k = count; k-- > 0;) {
        const hapco_idl_RecentAnswer& a = force.recent[k];
        if (a.pose_sequence <= newest_arrival_sequence_ || a.pose_sequence >= force.pose_sequence) continue;
        PushArrival(a.pose_sequence, a.client_time_ns, now, -1,
                    Eigen::Vector3d(a.force_n.x, a.force_n.y, a.force_n.z), nullptr, true);
      }
    }
    PushArrival(force.pose_sequence, force.client_time_ns, now, force.server_send_ns - force.server_receive_ns,
                Eigen::Vector3d(force.force_n.x, force.force_n.y, force.force_n.z), &force, false);
  }
}

void PhantomClient::PushArrival(uint64_t pose_sequence, int64_t client_time_ns, int64_t now_ns, int64_t server_time_ns,
                                const Eigen::Vector3d& force_n, const ::hapco_idl_FeedbackForce* sample, bool recovered) {
  {
    const int64_t now = now_ns;
    const uint32_t head = arrivals_head_.load(std::memory_order_relaxed);
    if (head - arrivals_tail_.load(std::memory_order_acquire) >= kArrivalCapacity) {
      arrivals_overflowed_.fetch_add(1, std::memory_order_relaxed);
      return;
    }
    ReceivedForce& r = arrivals_[head % kArrivalCapacity];
    r = ReceivedForce{};
    r.pose_sequence = pose_sequence;
    r.client_time_ns = client_time_ns;
    r.arrival_ns = now;
    r.server_time_ns = server_time_ns;
    r.force_n = force_n;
    r.recovered = recovered;
    if (sample != nullptr) {
      const hapco_idl_FeedbackForce& force = *sample;
      r.separating = force.separating_count;
      r.sticking = force.sticking_count;
      r.sliding = force.sliding_count;
      r.verdict = FromIdl(force.pose_verdict);
      r.server_ignored_poses = force.ignored_poses;
      const hapco_idl_LocalContactModel& m = force.model;
      r.model.valid = m.valid;
      r.model.position_m = Eigen::Vector3d(m.position_m.x, m.position_m.y, m.position_m.z);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) r.model.stiffness_n_per_m(i, j) = m.stiffness_n_per_m[3 * i + j];
      }
      r.model.normal = Eigen::Vector3d(m.normal.x, m.normal.y, m.normal.z);
      r.model.friction_coefficient = m.friction_coefficient;
      r.model.surface_ahead = m.surface_ahead;
      r.model.surface_gap_m = m.surface_gap_m;
      r.model.surface_normal = Eigen::Vector3d(m.surface_normal.x, m.surface_normal.y, m.surface_normal.z);
    }
    if (r.verdict == ServerVerdict::kStepped) newest_arrival_sequence_ = std::max(newest_arrival_sequence_, pose_sequence);
    arrivals_head_.store(head + 1, std::memory_order_release);
  }
}

bool PhantomClient::Connect(std::string* why, const std::function<void(const std::string&)>& progress) {
  const auto timeout_ns = static_cast<dds_duration_t>(config_.connect_timeout_s * 1e9);
  // Wait for the server's pose reader in slices, saying so after 0.5 s and every 5 s after.
  bool found = false;
  dds_duration_t waited_ns = 0;
  for (dds_duration_t slice_ns = DDS_MSECS(500); waited_ns < timeout_ns; slice_ns = DDS_SECS(5)) {
    const dds_duration_t this_slice = std::min(slice_ns, timeout_ns - waited_ns);
    if (dds_->pose_writer.WaitForReaders(1, this_slice)) {
      found = true;
      break;
    }
    waited_ns += this_slice;
    if (progress && waited_ns < timeout_ns) {
      char line[200];
      std::snprintf(line, sizeof line, "waiting for a hapco-server in domain %d (%.1f s of %.0f s)...", config_.domain,
                    static_cast<double>(waited_ns) * 1e-9, config_.connect_timeout_s);
      progress(line);
    }
  }
  if (!found || !dds_->session_writer.WaitForReaders(1, std::max<dds_duration_t>(timeout_ns - waited_ns, DDS_SECS(1)))) {
    if (why != nullptr) {
      char seconds[32];
      std::snprintf(seconds, sizeof seconds, "%g", config_.connect_timeout_s);
      *why = "no hapco-server found in domain " + std::to_string(config_.domain) + " within " + seconds +
             " s (same domain id and CYCLONEDDS_URI peers?)";
    }
    return false;
  }
  if (!config_.server_id.empty()) {
    server_id_ = config_.server_id;
  } else {
    // Servers on other hosts are discovered one at a time (unicast discovery: each pair of
    // participants exchanges its own announcements), so the first one found is not all there
    // are: wait until no further server has appeared for kServerDiscoverySettle, then for the
    // announcements of every server found (transient-local status), at most 2 s in all, and
    // choose. Without the settle window six clients started beside three servers in three
    // network namespaces all chose the first server they saw.
    // A server found but not one announcement within the 2 s (a host at load 12, a helper
    // session): the client chose no server, said "served by the only server (no ServerStatus
    // seen)" with three running and sent unaddressed poses. Then it waits on for the first
    // announcement, within the connect timeout (servers announce every second).
    const auto start = std::chrono::steady_clock::now();
    const auto give_up = start + std::chrono::seconds(2);
    const auto give_up_unannounced =
        start + std::chrono::nanoseconds(std::max<dds_duration_t>(timeout_ns - waited_ns, DDS_SECS(2)));
    uint32_t servers_found = dds_->pose_writer.MatchedReaders();
    auto last_new = start;
    std::unique_lock<std::mutex> lock(dds_->servers_mutex);
    for (auto now = start; now < give_up || (dds_->servers.empty() && now < give_up_unannounced);
         now = std::chrono::steady_clock::now()) {
      dds_->servers_changed.wait_for(lock, std::chrono::milliseconds(20));
      const uint32_t now_found = dds_->pose_writer.MatchedReaders();
      now = std::chrono::steady_clock::now();
      if (now_found > servers_found) {
        servers_found = now_found;
        last_new = now;
      }
      if (now - last_new >= kServerDiscoverySettle && dds_->servers.size() >= servers_found) break;
    }
    lock.unlock();
    server_id_ = ChooseServer("");
  }
  SendJoin();
  // A full server refuses the JOIN and forgets it; a slot may free up (a client leaves, or an
  // idle session of a killed one is closed, --session-idle-s): ask again every second until
  // the timeout. (Asking once, a client refused while full waited out its whole timeout.)
  bool session = false;
  for (dds_duration_t left_ns = timeout_ns; left_ns > 0 && !session; left_ns -= DDS_SECS(1)) {
    session = dds_->force_reader.WaitForWriters(1, std::min<dds_duration_t>(left_ns, DDS_SECS(1)));
    if (!session && left_ns > DDS_SECS(1)) {
      if (config_.server_id.empty()) {
        const std::string next = ChooseServer("");
        if (!next.empty()) server_id_ = next;
      }
      SendJoin();
    }
  }
  if (!session) {
    if (why != nullptr) {
      char seconds[32];
      std::snprintf(seconds, sizeof seconds, "%g", config_.connect_timeout_s);
      *why = "the server did not open a session for '" + config_.client_id + "' within " + seconds + " s (" +
             WhyNoSession() + ")";
    }
    return false;
  }
  return true;
}

std::string PhantomClient::WhyNoSession() {
  // What the servers announced (ServerStatus): name the one asked for when it is not among
  // them, else the ones that are full or do not serve the scene. (It said "server full, or it
  // does not serve scene ...?" even when --server-id named no server at all.)
  std::lock_guard<std::mutex> lock(dds_->servers_mutex);
  std::string heard, full, other_scene;
  bool asked_for_is_there = false;
  for (const service::ServerAnnouncement& s : dds_->servers) {
    heard += (heard.empty() ? "" : ", ") + s.server_id;
    asked_for_is_there = asked_for_is_there || s.server_id == config_.server_id;
    if (s.max_sessions > 0 && s.sessions >= s.max_sessions) full += (full.empty() ? "" : ", ") + s.server_id;
    if (!s.scenes.empty() && std::find(s.scenes.begin(), s.scenes.end(), config_.scene_name) == s.scenes.end()) {
      other_scene += (other_scene.empty() ? "" : ", ") + s.server_id;
    }
  }
  if (!config_.server_id.empty() && !asked_for_is_there) {
    return "no server '" + config_.server_id + "' announced itself; " +
           (heard.empty() ? std::string("no server did") : "servers heard: " + heard) +
           " (--server-id names one of them, or leave it out to take the least loaded)";
  }
  std::string reason;
  if (!full.empty()) reason += "full: " + full;
  if (!other_scene.empty()) reason += (reason.empty() ? "" : "; ") + ("not serving scene '" + config_.scene_name + "': " + other_scene);
  if (reason.empty()) reason = "server full, or it does not serve scene '" + config_.scene_name + "'? see its log";
  return reason;
}

std::string PhantomClient::ChooseServer(const std::string& avoid) {
  std::lock_guard<std::mutex> lock(dds_->servers_mutex);
  return service::ChooseServer(dds_->servers, config_.client_id, config_.scene_name, avoid, MonotonicNowNs(),
                               kServerMaxAgeNs)
      .value_or(std::string());
}

std::string PhantomClient::DescribeServers(int64_t now_ns) {
  std::lock_guard<std::mutex> lock(dds_->servers_mutex);
  std::string text;
  for (const service::ServerAnnouncement& s : dds_->servers) {
    char line[200];
    const double heard_s = static_cast<double>(now_ns - s.heard_ns) * 1e-9;
    if (s.lease_lapsed) {
      std::snprintf(line, sizeof line, "%s (lease lapsed %.0f ms ago, heard %.1f s ago, %u/%u sessions)",
                    s.server_id.c_str(), static_cast<double>(now_ns - s.lapsed_ns) * 1e-6, heard_s, s.sessions,
                    s.max_sessions);
    } else {
      std::snprintf(line, sizeof line, "%s (heard %.1f s ago, %u/%u sessions)", s.server_id.c_str(), heard_s,
                    s.sessions, s.max_sessions);
    }
    text += (text.empty() ? "" : ", ") + std::string(line);
  }
  return text.empty() ? "no server announced itself" : text;
}

bool PhantomClient::ServerLeaseLapsedAndTrusted(const std::string& server_id, int64_t now_ns,
                                                 bool silent_twice_timeout, int64_t last_force_ns) {
  std::lock_guard<std::mutex> lock(dds_->servers_mutex);
  if (!silent_twice_timeout && dds_->last_lease_regained_ns >= 0 &&
      now_ns - dds_->last_lease_regained_ns < kLeaseDistrustNs) {
    return false;
  }
  for (const service::ServerAnnouncement& s : dds_->servers) {
    if (s.server_id != server_id) continue;
    // Silent for twice the timeout: a lapse since the last force counts even if the lease
    // came back since (LeaseLapsedSince).
    return silent_twice_timeout ? service::LeaseLapsedSince(s, last_force_ns) : s.lease_lapsed;
  }
  return false;
}

void PhantomClient::SendJoin() {
  hapco_idl_SessionControl control{};
  service::SetClientId(control.client_id, config_.client_id);
  control.command = hapco_idl_SESSION_JOIN;
  std::snprintf(control.scene_name, sizeof(control.scene_name), "%s", config_.scene_name.c_str());
  std::snprintf(control.server_id, sizeof(control.server_id), "%s", server_id_.c_str());
  control.client_time_ns = MonotonicNowNs();
  service::CheckReturn(dds_->session_writer.Write(control), "SESSION_JOIN");
  stats_.server_id = server_id_;
}

void PhantomClient::Leave() {
  auto control = service::MakeSample<hapco_idl_SessionControl>();
  service::SetClientId(control->client_id, config_.client_id);
  control->command = hapco_idl_SESSION_LEAVE;
  std::snprintf(control->server_id, sizeof(control->server_id), "%s", server_id_.c_str());
  control->client_time_ns = MonotonicNowNs();
  dds_->session_writer.Write(*control);
  dds_->session_writer.WaitForAcks(DDS_MSECS(500));
}

void PhantomClient::Run(const std::atomic<bool>& stop, const std::function<void(const TickRecord&)>& on_tick,
                        const std::function<void(const std::string&)>& log) {
  const double tick_s = config_.safety.tick_s;
  const auto period_ns = static_cast<int64_t>(std::llround(tick_s * 1e9));
  const auto& trajectory = config_.trajectory;
  const int trajectory_ticks = static_cast<int>(trajectory.size()) - 1;
  RenderChain chain(config_.render, config_.safety);
  const ForceRenderer& renderer = chain.renderer();
  const SafetyFilter& safety = chain.safety();
  HandModel hand(config_.hand, trajectory[0]);

  hapco_idl_DevicePose pose{};
  service::SetClientId(pose.client_id, config_.client_id);
  pose.orientation = {1.0, 0.0, 0.0, 0.0};
  pose.reported_round_trip_ns = -1;
  pose.recent_count = 0;  // the poses sent before, newest first (a server that missed one steps it)
  std::snprintf(pose.server_id, sizeof(pose.server_id), "%s", server_id_.c_str());

  std::vector<ReceivedForce> taken;
  taken.reserve(kArrivalCapacity);
  uint64_t last_force_sequence = 0;
  bool any_force = false, was_stale = false;
  double last_notice_log_s = -1;  // when the last "server ignores poses" line was logged
  double last_foreign_log_s = -1;  // when the last "forces for poses never sent" line was logged
  double last_no_server_log_s = -1;  // when the last "no other server to move to" line was logged
  double last_stale_answer_log_s = -1;  // when the last "answers to poses ... old" line was logged
  double last_waiting_log_s = -1;       // when the last "still no force" line was logged
  double stale_since_s = 0;             // when the current force timeout began
  double last_other_device_s = -1;      // when the last "serves another device" notice came
  // Send time of the last kSentPoses poses by sequence % kSentPoses (8 s at 1 kHz: an answer
  // later than that is stale anyway); 0 = none sent (MonotonicNowNs is never 0 after boot).
  std::vector<int64_t> sent_time_ns(kSentPoses, 0);
  Eigen::Vector3d rendered = Eigen::Vector3d::Zero();
  Eigen::Vector3d previous_position = trajectory[0];
  constexpr int64_t kMoveRetryNs = 100'000'000, kMinMoveIntervalNs = 1'000'000'000;
  int64_t last_move_try_ns = 0, last_move_ns = -kMinMoveIntervalNs;
  // A server that answers late is not a dead one. On an overloaded host (nine DDS processes
  // on 2 cores: round trip p99 50 ms) the force timeout fires on live servers, and clients
  // moved 4-7 times in 8 s, each move restarting the session. So the force still ramps to
  // zero after the safety timeout, but the client moves only once
  //   - the server's DDS liveliness lease has lapsed (StatusQos: 50 ms without any message
  //     from its process, whatever the host's load: it died or froze), or
  //   - no force has come for max(timeout, kMoveRoundTrips x the recent round-trip high), the
  //     high decaying with a 2 s time constant (a live server that stopped answering this
  //     client: on an idle network that is the timeout itself, round trips ~1 ms).
  // The lease alone decides on a loaded host: waiting 4 round-trip highs there (160-260 ms)
  // broke the 100 ms take-over bound when a server was killed. But on a host so overloaded
  // that live servers' leases lapse and come back (nine containers on 2 cores: round trip p99
  // 120-135 ms), trusting lapses moved every client 4-5 times in 20 s; so for 10 s after any
  // lease came back, only the round-trip rule moves a client.
  constexpr double kMoveRoundTrips = 4.0;
  const double round_trip_decay = std::exp(-tick_s / 2.0);
  double round_trip_high_ns = 0.0;
  int64_t last_force_arrival_ns = -1;
  const auto timeout_ns = static_cast<int64_t>(std::llround(config_.safety.timeout_s * 1e9));
  const int64_t start_ns = MonotonicNowNs();
  int64_t deadline_ns = start_ns + period_ns;
  int drained = 0;
  for (int tick = 1; !stop.load(std::memory_order_relaxed); ++tick) {
    const bool publishing = tick <= config_.ticks;
    if (!publishing) {
      if (last_force_sequence >= static_cast<uint64_t>(config_.ticks) || drained >= config_.drain_ticks) break;
      ++drained;
    }
    const timespec wake = ToTimespec(deadline_ns);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr) != 0) {
    }
    const int64_t now = MonotonicNowNs();
    int64_t missed_before = 0;
    if (now - deadline_ns > period_ns) {
      // Overrun: count the ticks that never ran and realign to the grid (no burst of poses).
      missed_before = (now - deadline_ns) / period_ns;
      stats_.missed_ticks += static_cast<uint64_t>(missed_before);
      deadline_ns += missed_before * period_ns;
    }
    deadline_ns += period_ns;
    const double now_s = static_cast<double>(now - start_ns) * 1e-9;
    ++stats_.ticks_run;

    // Device position this tick.
    const int k = std::min(tick, trajectory_ticks);
    Eigen::Vector3d position = previous_position;
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
    if (publishing) {
      const Eigen::Vector3d& target = trajectory[static_cast<std::size_t>(k)];
      if (config_.mode == DriveMode::kKinematic) {
        position = target;
        velocity = (position - previous_position) / tick_s;
      } else {
        // The hand's target velocity: the trajectory's, zero once it holds its last point.
        const int previous = tick > trajectory_ticks ? k : std::max(0, k - 1);
        const Eigen::Vector3d target_velocity = (target - trajectory[static_cast<std::size_t>(previous)]) / tick_s;
        hand.Step(target, target_velocity, rendered, tick_s);
        position = Quantize(hand.position_m());
        velocity = hand.velocity_m_per_s();
      }
      pose.sequence_number = static_cast<uint64_t>(tick);
      pose.client_time_ns = MonotonicNowNs();
      pose.position_m = {position.x(), position.y(), position.z()};
      sent_time_ns[static_cast<std::size_t>(pose.sequence_number % kSentPoses)] = pose.client_time_ns;
      if (dds_->pose_writer.Write(pose) == DDS_RETCODE_OK) {
        ++stats_.poses_published;
      } else {
        ++stats_.pose_write_errors;
      }
      // This pose becomes the newest of the next one's recent list.
      std::move_backward(pose.recent, pose.recent + hapco_idl_RECENT_SAMPLES - 1, pose.recent + hapco_idl_RECENT_SAMPLES);
      pose.recent[0] = {pose.sequence_number, pose.client_time_ns, pose.position_m};
      pose.recent_count = std::min<uint32_t>(pose.recent_count + 1, hapco_idl_RECENT_SAMPLES);
    }
    previous_position = position;

    // Every force that arrived since the last tick; the newest is rendered.
    taken.clear();
    bool fresh = false;
    Eigen::Vector3d raw = Eigen::Vector3d::Constant(std::nan(""));
    ReceivedModel model;
    round_trip_high_ns *= round_trip_decay;
    for (uint32_t tail = arrivals_tail_.load(std::memory_order_relaxed);
         tail != arrivals_head_.load(std::memory_order_acquire); ++tail) {
      const ReceivedForce r = arrivals_[tail % kArrivalCapacity];
      arrivals_tail_.store(tail + 1, std::memory_order_release);
      // An answer to a pose this device sent carries that pose's sequence and send time. Two
      // devices started with the same --client-id each rendered the other's forces (one
      // hovering 5 mm above the bar felt 5.8 N), and neither was told (a helper session). A
      // notice about another device's pose is not this device's either (it was told of the
      // other's position jumps).
      const bool own = sent_time_ns[static_cast<std::size_t>(r.pose_sequence % kSentPoses)] == r.client_time_ns;
      if (!own && r.verdict != ServerVerdict::kStepped) continue;
      if (r.verdict == ServerVerdict::kOtherDevice) {
        // Its poses are not stepped at all: no force comes, and the safety filter ramps to zero.
        ++stats_.other_device_notices;
        last_other_device_s = now_s;
        if (log && LogDue(&last_notice_log_s, now_s)) {
          char line[320];
          std::snprintf(line, sizeof(line),
                        "t=%.3f s: the server serves another device under the client id '%s' (the one that joined "
                        "last): no forces for this one; give each device its own --client-id",
                        now_s, config_.client_id.c_str());
          log(line);
        }
        continue;
      }
      if (r.verdict != ServerVerdict::kStepped) {
        // The server ignored a pose: no new force (the safety filter's timeout still applies),
        // but the user hears why, at most once a second.
        ++stats_.ignored_notices;
        stats_.server_ignored_poses = r.server_ignored_poses;
        if (log && LogDue(&last_notice_log_s, now_s)) {
          char line[200];
          std::snprintf(line, sizeof(line), "t=%.3f s: the server ignores this device's poses: %s (%llu so far)", now_s,
                        ServerVerdictText(r.verdict), static_cast<unsigned long long>(r.server_ignored_poses));
          log(line);
        }
        continue;
      }
      if (!own) {
        ++stats_.foreign_forces;
        if (log && LogDue(&last_foreign_log_s, now_s)) {
          char line[240];
          std::snprintf(line, sizeof(line),
                        "t=%.3f s: forces for poses this device never sent (%llu so far, not rendered): another "
                        "device uses the client id '%s'? Give each device its own --client-id",
                        now_s, static_cast<unsigned long long>(stats_.foreign_forces), config_.client_id.c_str());
          log(line);
        }
        continue;
      }
      if (any_force && r.pose_sequence <= last_force_sequence) {
        ++stats_.forces_reordered;
        continue;
      }
      // An answer to a pose long past (delivered after an outage) says nothing about where the
      // device is now: not a new force, so the timeout ramp goes on (SafetyParameters).
      const double age_s = static_cast<double>(now - r.client_time_ns) * 1e-9;
      if (age_s > config_.safety.max_answer_age_s) {
        ++stats_.stale_answers;
        stats_.oldest_stale_answer_s = std::max(stats_.oldest_stale_answer_s, age_s);
        if (log && LogDue(&last_stale_answer_log_s, now_s)) {
          char line[200];
          std::snprintf(line, sizeof(line),
                        "t=%.3f s: answers to poses %.1f ms old arrive (%llu so far): not rendered "
                        "(--max-answer-age-ms %.0f)",
                        now_s, age_s * 1e3, static_cast<unsigned long long>(stats_.stale_answers),
                        config_.safety.max_answer_age_s * 1e3);
          log(line);
        }
        continue;
      }
      if (!any_force) stats_.first_force_arrival_ns = r.arrival_ns;
      any_force = true;
      ++stats_.forces_received;
      if (r.recovered) ++stats_.answers_recovered;
      fresh = true;
      last_force_sequence = r.pose_sequence;
      raw = r.force_n;
      model = r.model;
      stats_.round_trip_us.push_back(r.round_trip_us());
      stats_.render_latency_us.push_back(static_cast<double>(now - r.client_time_ns) * 1e-3);
      if (!r.recovered) stats_.server_time_us.push_back(static_cast<double>(r.server_time_ns) * 1e-3);
      pose.reported_round_trip_ns = r.arrival_ns - r.client_time_ns;
      round_trip_high_ns = std::max(round_trip_high_ns, static_cast<double>(pose.reported_round_trip_ns));
      last_force_arrival_ns = r.arrival_ns;
      taken.push_back(r);
    }
    rendered = chain.Tick(fresh, raw, model, position, velocity, now_s);
    const Eigen::Vector3d& command = chain.command_n();
    stats_.peak_rendered_n = std::max(stats_.peak_rendered_n, rendered.norm());
    const bool stale = safety.stale();
    if (stale && !was_stale) {
      stale_since_s = now_s;
      last_waiting_log_s = now_s;  // the first "still no force" line a second from now
      ++stats_.server_losses;
      if (log) {
        char line[160];
        std::snprintf(line, sizeof(line), "t=%.3f s: no force for %.0f ms: ramping the force to zero in %.0f ms",
                      now_s, config_.safety.timeout_s * 1e3, config_.safety.ramp_s * 1e3);
        log(line);
      }
    } else if (!stale && was_stale) {
      ++stats_.resumptions;
      if (log) {
        char line[120];
        std::snprintf(line, sizeof(line), "t=%.3f s: forces resumed (pose %llu)", now_s,
                      static_cast<unsigned long long>(last_force_sequence));
        log(line);
      }
    }
    // A restarted server takes seconds to prepare its scene and be found: the device said nothing
    // for 4-7 s between "ramping the force to zero" and "moving ..." (a helper session).
    if (stale && log && LogDue(&last_waiting_log_s, now_s)) {
      char line[240];
      // (A server that serves another device under this id is not waited for: it is told. Only
      // while its notices come (one every 100 ms at most): a notice long past does not explain a
      // later stall, which this line once blamed on it.)
      const bool other_device_now = last_other_device_s >= 0 && now_s - last_other_device_s < 1.0;
      std::snprintf(line, sizeof(line), "t=%.3f s: still no force after %.0f s: waiting for a server%s", now_s,
                    now_s - stale_since_s,
                    other_device_now ? " that serves this device (the one found serves another under this client id)"
                    : config_.server_id.empty() ? " serving the scene (any will do)"
                                                : "");
      log(line);
    }
    was_stale = stale;
    // Its server stopped answering: move to another one that serves the scene, if any (tried
    // every 100 ms while no force comes, so a server that appears later is found too; at
    // most one move a second, so a loaded machine's stalls do not bounce a client around).
    // It starts from the reference configuration at the device's position; the safety filter
    // ramps the force back up. The old server, if only slow, sees the JOIN or a pose
    // addressed elsewhere and closes its session: no client is ever answered by two servers.
    const double move_after_ns = std::max(static_cast<double>(timeout_ns), kMoveRoundTrips * round_trip_high_ns);
    const bool may_move = stale && config_.server_id.empty() && now - last_move_try_ns >= kMoveRetryNs &&
                          now - last_move_ns >= kMinMoveIntervalNs;
    const bool silent_long = last_force_arrival_ns < 0 || static_cast<double>(now - last_force_arrival_ns) >= move_after_ns;
    // (The lease is read under the server list's lock: only while stale, not on every tick.)
    const bool silent_twice_timeout =
        last_force_arrival_ns >= 0 && now - last_force_arrival_ns >= 2 * static_cast<int64_t>(timeout_ns);
    const bool lease_lapsed =
        may_move && !silent_long &&
        ServerLeaseLapsedAndTrusted(server_id_, now, silent_twice_timeout, last_force_arrival_ns);
    if (may_move && (silent_long || lease_lapsed)) {
      last_move_try_ns = now;
      const std::string next = ChooseServer(server_id_);
      if (!next.empty() && next != server_id_) {
        if (log) {
          char line[320];
          const double silent_ms =
              last_force_arrival_ns < 0 ? 0.0 : static_cast<double>(now - last_force_arrival_ns) * 1e-6;
          std::snprintf(line, sizeof(line), "t=%.3f s: moving from server '%s' to '%s' (no force for %.0f ms%s)", now_s,
                        server_id_.c_str(), next.c_str(), silent_ms,
                        lease_lapsed ? ", its DDS liveliness lease lapsed" : "");
          log(line);
        }
        server_id_ = next;
        last_move_ns = now;
        ++stats_.server_moves;
        SendJoin();
        std::snprintf(pose.server_id, sizeof(pose.server_id), "%s", server_id_.c_str());
      } else if (log && LogDue(&last_no_server_log_s, now_s)) {
        char when[32];
        std::snprintf(when, sizeof when, "t=%.3f s", now_s);
        log(std::string(when) + ": no other server to move to from '" + server_id_ + "' (servers heard: " +
            DescribeServers(now) + ")");
      }
    }
    if (on_tick) {
      TickRecord record;
      record.tick = tick;
      record.published = publishing;
      record.pose_sequence = publishing ? static_cast<uint64_t>(tick) : 0;
      record.time_s = now_s;
      record.tick_ns = now;
      record.missed_before = static_cast<int>(missed_before);
      record.position_m = position;
      record.velocity_m_per_s = velocity;
      record.forces = taken;
      record.commanded_force_n = command;
      record.rendered_force_n = rendered;
      record.stale = stale;
      on_tick(record);
    }
  }
  stats_.render = renderer.stats();
  stats_.passivity_dissipated_j = renderer.passivity().dissipated_j();
  stats_.passivity_forgiven_j = renderer.passivity().forgiven_j();
  stats_.passivity_min_energy_j = renderer.passivity().min_energy_j();
  stats_.passivity_final_energy_j = renderer.passivity().energy_j();
  stats_.passivity_active_ticks = renderer.passivity().active_ticks();
  stats_.stale_ticks = safety.stale_ticks();
  stats_.rejected_non_finite = safety.rejected_non_finite();
  stats_.clamped = safety.clamped();
  stats_.arrivals_overflowed = arrivals_overflowed_.load();
  {
    std::lock_guard<std::mutex> lock(dds_->servers_mutex);
    stats_.server_leases_lapsed = dds_->leases_lapsed;
    stats_.server_leases_regained = dds_->leases_regained;
  }
}

}  // namespace hapco::phantom
