#pragma once
// One emulated haptic device connected to a hapco-server: its own DDS participant, the
// absolute-time 1 kHz servo loop (clock_nanosleep), the device model of phantom.h and the
// force safety filter. Used by hapco-phantom (one device) and hapco-loadtest (N devices,
// one thread each).
//
// Pipelined (issue 5): each tick publishes the pose and renders the newest force that has
// arrived; it never waits for the server. Forces are taken on Cyclone's receive thread (a
// listener, ~30 us faster than a waitset: platform-notes.md) and stamped on arrival, so the
// round trip measured is the network's plus the server's (pose sampled -> force arrived),
// not rounded up to the next tick; the render latency (pose sampled -> the tick that
// renders its force) is reported separately.
#include <Eigen/Dense>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "force_renderer.h"
#include "phantom.h"
#include "service/security.h"

struct hapco_idl_FeedbackForce;  // idl/hapco_types.idl (the DDS types stay out of this header)

namespace hapco::phantom {

enum class DriveMode {
  kKinematic,  // the device follows the trajectory exactly (no quantisation): forces compare with hapco-sim
  kHand,       // a hand drags the device along the trajectory (HandModel), positions quantised
};

struct ClientConfig {
  std::string client_id;
  int domain = 0;                                 // DDS domain; configuration from CYCLONEDDS_URI
  DriveMode mode = DriveMode::kKinematic;
  std::vector<Eigen::Vector3d> trajectory;        // points 0..N, m; tick k targets point min(k, N)
  int ticks = 0;                                  // poses to publish (> 0)
  std::string scene_name;                         // sent with SESSION_JOIN
  // The server to be served by; empty: the least loaded one serving the scene, chosen from
  // the servers' ServerStatus, and another one when it stops answering (docs/several-servers.md).
  std::string server_id;
  SafetyParameters safety;                        // timeout, ramp, limits; tick_s is the servo period
  RendererParameters render;                      // direct / local-model, passivity (force_renderer.h)
  HandParameters hand;
  double connect_timeout_s = 30.0;
  service::SecurityIdentity security;             // enabled: secured (DIR/<client_id>)
  // After the last pose, at most this many ticks collect the forces still in flight.
  int drain_ticks = 50;
};

// Why the server did not step a pose (FeedbackForce.pose_verdict): kStepped for a force.
enum class ServerVerdict { kStepped, kNotFinite, kOutOfWorkspace, kJump, kOtherDevice };
// "position jump above the server's limit" and the like, for a user.
const char* ServerVerdictText(ServerVerdict verdict);

// A force sample as it arrived (stamped on Cyclone's receive thread).
struct ReceivedForce {
  uint64_t pose_sequence = 0;
  int64_t client_time_ns = 0;    // the pose's sampling time, echoed by the server
  int64_t arrival_ns = 0;        // CLOCK_MONOTONIC on arrival at this client
  int64_t server_time_ns = 0;    // server: pose received -> force sent
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // as received (may be non-finite)
  uint32_t separating = 0, sticking = 0, sliding = 0;
  // kStepped: a force. Otherwise a notice that the server ignored the pose (its force_n is
  // the last force sent): not a new force, never rendered as one.
  ServerVerdict verdict = ServerVerdict::kStepped;
  uint64_t server_ignored_poses = 0;  // the server's count of this session's ignored poses
  ReceivedModel model;                // FeedbackForce.model (valid with a stepped force in contact)
  // An answer recovered from a later force's repeated answers (FeedbackForce.recent): its own
  // sample never arrived (dropped for coming after a newer one). No model, no server time.
  bool recovered = false;
  double round_trip_us() const { return static_cast<double>(arrival_ns - client_time_ns) * 1e-3; }
};

// What one servo tick did, for CSV logs and force-stability analysis (called in the tick
// thread: keep the handler cheap).
struct TickRecord {
  int tick = 0;                    // 1-based
  bool published = false;          // a pose was sent this tick (false while draining)
  uint64_t pose_sequence = 0;      // = tick when published
  double time_s = 0;               // since the loop started, s
  int64_t tick_ns = 0;             // CLOCK_MONOTONIC when the tick woke, ns
  int missed_before = 0;           // servo deadlines that passed without a tick just before this one
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();        // device position (as published)
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();  // device velocity
  std::span<const ReceivedForce> forces;  // taken this tick, oldest first; the last is rendered
  Eigen::Vector3d commanded_force_n = Eigen::Vector3d::Zero(); // the renderer's, before the safety filter
  Eigen::Vector3d rendered_force_n = Eigen::Vector3d::Zero();  // after the safety filter
  bool stale = false;              // the safety filter is in (or after) a timeout ramp
};

struct ClientStats {
  int ticks_run = 0;
  uint64_t poses_published = 0, pose_write_errors = 0;
  uint64_t forces_received = 0;     // in order, new sequence
  uint64_t answers_recovered = 0;   // of which recovered from a later force's repeated answers
  uint64_t forces_reordered = 0;    // older than one already taken: logged, not rendered
  // Answers to poses this device never sent (sequence and send time match none of its own):
  // another device under the same client id. Logged, never rendered.
  uint64_t foreign_forces = 0;
  // Notices that the server serves another device under this client id (the one that joined
  // last): this device gets no forces from that server. Logged, counted.
  uint64_t other_device_notices = 0;
  // Answers older than SafetyParameters::max_answer_age_s when they arrived: not rendered.
  uint64_t stale_answers = 0;
  double oldest_stale_answer_s = 0;  // the oldest of them, s
  uint64_t arrivals_overflowed = 0; // arrival queue full (tick thread stalled): dropped
  uint64_t missed_ticks = 0;        // servo deadlines that passed without a tick
  uint64_t stale_ticks = 0, rejected_non_finite = 0, clamped = 0;
  uint64_t server_losses = 0;       // times the force timeout engaged (ramp to zero)
  uint64_t resumptions = 0;         // times forces came back after a timeout
  uint64_t ignored_notices = 0;     // notices "the server ignored pose N" received
  uint64_t server_moves = 0;        // times this client moved to another server after a timeout
  // DDS liveliness of the servers' announcements (StatusQos, 50 ms lease): lapses seen, and
  // lapses that came back (a live server that stalled 50 ms: the host is overloaded).
  uint64_t server_leases_lapsed = 0;
  uint64_t server_leases_regained = 0;
  std::string server_id;            // the server serving it at the end (empty: unaddressed)
  uint64_t server_ignored_poses = 0;  // the server's count in the newest sample
  double peak_rendered_n = 0;
  RendererStats render;                 // the force renderer's counts (force_renderer.h)
  double passivity_dissipated_j = 0;    // energy the passivity controller's damper asked for, J
  double passivity_forgiven_j = 0;      // debt forgiven by its time constant, J (passivity.h)
  double passivity_min_energy_j = 0, passivity_final_energy_j = 0;  // its books E, J
  int64_t passivity_active_ticks = 0;   // ticks it damped
  int64_t first_force_arrival_ns = -1;  // CLOCK_MONOTONIC when the first force arrived (-1: none)
  std::vector<double> round_trip_us;       // pose sampled -> force arrived
  std::vector<double> render_latency_us;   // pose sampled -> the tick that renders it
  std::vector<double> server_time_us;      // server receive -> send
};

class PhantomClient {
 public:
  // Creates the participant, topics, writers and the force reader (partition of this
  // client). Throws InputError for a bad id, DdsError if DDS cannot be set up.
  explicit PhantomClient(ClientConfig config);
  ~PhantomClient();
  PhantomClient(const PhantomClient&) = delete;
  PhantomClient& operator=(const PhantomClient&) = delete;

  // Waits for the servers' readers and announcements, chooses a server (ClientConfig::server_id),
  // sends SESSION_JOIN and waits until the server's force
  // writer for this client matches, so the first pose already gets its force. False (with
  // the reason in *why) if no server answers within connect_timeout_s. `progress` (optional)
  // gets a line after 0.5 s without a server, and again every 5 s, so a user waiting for a
  // server that is not there is told so at once.
  bool Connect(std::string* why, const std::function<void(const std::string&)>& progress = {});

  // Runs the servo loop: config.ticks poses, then up to drain_ticks ticks for forces in
  // flight; returns early when `stop` becomes true. `on_tick` (optional) sees every tick.
  // `log` (optional) gets one line per safety event (timeout engaged, forces resumed) and,
  // at most once a second, a line when the server says it ignores this device's poses.
  void Run(const std::atomic<bool>& stop, const std::function<void(const TickRecord&)>& on_tick = {},
           const std::function<void(const std::string&)>& log = {});

  // SESSION_LEAVE (reliable; waits up to 0.5 s for the acknowledgement).
  void Leave();

  const ClientStats& stats() const { return stats_; }
  const ClientConfig& config() const { return config_; }

 private:
  struct Dds;  // the DDS entities (service/dds.h stays out of this header)
  void OnForcesAvailable();  // Cyclone's receive thread
  // Appends one arrival to the queue (receive thread); sample: the FeedbackForce it came in as
  // (nullptr for a recovered answer).
  void PushArrival(uint64_t pose_sequence, int64_t client_time_ns, int64_t now_ns, int64_t server_time_ns,
                   const Eigen::Vector3d& force_n, const ::hapco_idl_FeedbackForce* sample, bool recovered);
  uint64_t newest_arrival_sequence_ = 0;  // receive thread only
  // The server for this client now (chosen from the announcements), "" for none known.
  std::string ChooseServer(const std::string& avoid);
  // Why no server opened a session, from the servers' announcements (for Connect's message).
  std::string WhyNoSession();
  // The servers heard, for a log line: "s1 (lease lapsed 120 ms ago, heard 0.3 s ago, 2/32
  // sessions), ..." (a move that found no other server says why).
  std::string DescribeServers(int64_t now_ns);
  // True while the DDS liveliness lease of `server_id`'s announcements has lapsed (the
  // process is gone or frozen; qos.h kServerLivelinessLeaseNs) and lapses can be trusted: no
  // server's lease has lapsed and come back within kLeaseDistrustNs, or `silent_twice_timeout`
  // (no force for twice the safety timeout; then a lapse after `last_force_ns` counts even if
  // the lease came back since: service::LeaseLapsedSince). Locks the server list.
  bool ServerLeaseLapsedAndTrusted(const std::string& server_id, int64_t now_ns, bool silent_twice_timeout,
                                   int64_t last_force_ns);
  // A lease that lapsed and came back means a host or network that stalls 50 ms at a time;
  // for this long after, a lapse alone is not taken as a death: it takes a lapse and twice
  // the timeout without a force (or the round-trip rule). With the lapse ignored outright, a
  // client of a killed server waited for the round-trip rule, 176-184 ms without a force,
  // whenever any lease had come back earlier in the run, even on a quiet host (the
  // namespaces test in CI, 2026-12-07: one phantom's own lapse-and-return).
  static constexpr int64_t kLeaseDistrustNs = 10'000'000'000LL;
  // SESSION_JOIN addressed to server_id_ (tick thread or Connect).
  void SendJoin();
  std::string server_id_;

  // Single-producer (receive thread) single-consumer (tick thread) queue of arrivals.
  static constexpr uint32_t kArrivalCapacity = 256;
  static constexpr std::size_t kSentPoses = 8192;  // poses remembered to tell this device's answers
  // Connect: no new server for this long = every server of the domain has been found.
  static constexpr std::chrono::milliseconds kServerDiscoverySettle{250};
  std::array<ReceivedForce, kArrivalCapacity> arrivals_;
  std::atomic<uint32_t> arrivals_head_{0};  // next slot to write (producer)
  std::atomic<uint32_t> arrivals_tail_{0};  // next slot to read (consumer)
  std::atomic<uint64_t> arrivals_overflowed_{0};

  ClientConfig config_;
  ClientStats stats_;
  std::unique_ptr<Dds> dds_;
};

}  // namespace hapco::phantom
