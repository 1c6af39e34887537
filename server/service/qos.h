#pragma once
// QoS for every HapCo topic, one named profile per topic, with the reason next to it.
// docs/dds-qos.md is the long form; the measurements behind the choices are in
// /work/shared/platform-notes.md ("Cyclone DDS 0.10.2").
//
// The same profile is used for the topic, its writers and its readers: Cyclone fills
// unset writer/reader policies from the topic, and request/offer matching then holds
// trivially. Cyclone's defaults differ by entity (writers are reliable, readers best
// effort), so every profile sets reliability, history and durability explicitly.
#include <dds/dds.h>

#include <cstdint>
#include <string>
#include <string_view>

namespace hapco::service {

// Owning wrapper of a dds_qos_t (dds_create_qos / dds_delete_qos), copyable.
class Qos {
 public:
  Qos();
  ~Qos();
  Qos(const Qos& other);
  Qos& operator=(const Qos& other);
  Qos(Qos&& other) noexcept;
  Qos& operator=(Qos&& other) noexcept;

  const dds_qos_t* get() const { return qos_; }

  // Reliable: lost packets are repaired. max_blocking_ns bounds how long dds_write may wait
  // when the writer's unacknowledged data exceeds the history watermark (then it fails
  // with DDS_RETCODE_TIMEOUT and the sample is dropped).
  Qos& Reliable(dds_duration_t max_blocking_ns);
  Qos& BestEffort();
  Qos& KeepLast(int32_t depth);
  Qos& Volatile();
  Qos& TransientLocal();
  // How many samples per instance a transient-local writer keeps for late-joining readers.
  // Cyclone takes this from the durability-service QoS (default 1), not from the history.
  Qos& HistoricalDepth(int32_t depth);
  Qos& LatencyBudget(dds_duration_t budget_ns);
  // AUTOMATIC liveliness with this lease: Cyclone asserts it from its own threads (a PMD
  // message every 0.8 lease, and any data of the participant), and a reader learns within
  // the lease that the writer's process stopped.
  Qos& AutomaticLiveliness(dds_duration_t lease_ns);
  Qos& Partition(std::string_view name);  // for publishers and subscribers

  // Read back, for tests and logs; false if the policy is unset.
  bool GetReliability(dds_reliability_kind_t* kind, dds_duration_t* max_blocking_ns) const;
  bool GetHistory(dds_history_kind_t* kind, int32_t* depth) const;
  bool GetDurability(dds_durability_kind_t* kind) const;
  bool GetLatencyBudget(dds_duration_t* budget_ns) const;
  bool GetLiveliness(dds_liveliness_kind_t* kind, dds_duration_t* lease_ns) const;
  // The single partition name ("" when unset or more than one name).
  std::string GetPartition() const;

 private:
  dds_qos_t* qos_;
};

// --- Profiles ---------------------------------------------------------------------------

// DevicePose (client -> server, 1 kHz) and FeedbackForce (server -> client, 1 kHz):
// best effort + KEEP_LAST 1 + volatile + latency_budget 0.
// Why: a pose or force is superseded 1 ms later, so repairing a lost one only delivers a
// stale value late and delays the next; keep-last-1 means the reader always sees the
// newest sample and the writer never holds history. latency_budget 0 keeps dds_write
// synchronous (a non-zero budget lets Cyclone batch, i.e. delay, the send).
Qos PoseQos();
Qos ForceQos();

// Default depth of the contact-state history: a recorder that falls 8 steps (8 ms at 1 kHz)
// behind starts losing the oldest frames instead of slowing the server.
inline constexpr int32_t kContactStateDepth = 8;

// ContactStateFrame (server -> recorder, per step): reliable, max_blocking_time 0,
// KEEP_LAST depth, volatile.
// Why reliable: a frame (up to 1024 contacts, ~120 kB) is fragmented; best effort loses
// the whole frame when any fragment is lost, reliable repairs the fragment.
// Why it never blocks the server: dds_write on a reliable writer waits only when the
// writer's unacknowledged bytes exceed its history high watermark (Cyclone throttle_writer).
// For a KEEP_LAST writer Cyclone sets that watermark to INT32_MAX ("aggressive keep last"):
// the writer history keeps the newest `depth` frames per client, drops older ones whether
// acknowledged or not, and dds_write never waits. max_blocking_time 0 is the second guard:
// should a watermark apply (e.g. someone switches to KEEP_ALL), dds_write returns
// DDS_RETCODE_TIMEOUT at once and that frame is dropped. Measured (service_dds_test,
// recorder process SIGSTOPped): 300 frames of 1024 contacts, all OK, throttle_count 0.
// A KEEP_LAST reader accepts and acknowledges every frame, overwriting its oldest, whether or
// not the application takes, so a slow recorder loses old frames, never slows the server.
// Why transient-local: a session's writer is created when the client joins; its first frames
// can be written before a recorder has discovered that writer. The writer keeps its newest
// `depth` frames for late-joining readers, so those first frames still reach the recorder
// (measured loss of a session's first frame under load before this; costs only memory).
// The historical depth is set explicitly: Cyclone keeps only 1 by default (durability service).
Qos ContactStateQos(int32_t depth = kContactStateDepth);

// ServerStatus (server -> anyone, ~1 Hz): reliable (max_blocking_time 0, same reason as
// contact states), transient-local, KEEP_LAST 1, AUTOMATIC liveliness with a lease of
// kServerLivelinessLeaseNs.
// Why transient-local: a monitor or recorder that starts later still receives the latest
// status at once.
// Why the lease: it tells a dead server from a slow one. A client whose forces stopped moves
// to another server; forces also stop coming from a live server on an overloaded host (9
// DDS processes on 2 cores: round trips of 40-65 ms), so without another signal a client
// waits several round trips before it moves (or bounces between live servers). Cyclone
// keeps the lease alive from its own threads, not from the server's step loop, so a server
// busy stepping stays alive, while a killed one's lease lapses kServerLivelinessLeaseNs
// after its last message, whatever the load (the participant's own lease is 10 s).
inline constexpr dds_duration_t kServerLivelinessLeaseNs = DDS_MSECS(50);
Qos StatusQos();

// SessionControl (client -> server, rare): reliable, KEEP_LAST 8, volatile,
// max_blocking_time 0. Why: a lost join/leave would leave a session open or never opened;
// depth 8 keeps a quick join-reset-leave of one client intact; 0 blocking because the
// client may send from its 1 kHz tick (it retries on DDS_RETCODE_TIMEOUT).
Qos SessionQos();

// --- Partitions ---------------------------------------------------------------------------

// Partition of one client's server->client traffic: "hapco/client/<client_id>".
// Why: with one shared force topic every reader receives (and filters) every client's forces;
// this collapsed at ~16 clients, a partition per client did not (platform-notes.md).
// A recorder subscribes to kAllClientsPartition, a DDS partition wildcard.
std::string ClientPartition(std::string_view client_id);
inline constexpr std::string_view kClientPartitionPrefix = "hapco/client/";
inline constexpr std::string_view kAllClientsPartition = "hapco/client/*";

// Throws InputError unless client_id is 1..64 characters of [A-Za-z0-9_.-]: it is a DDS key
// (string<64>) and part of a partition name, where '*' and '?' would act as wildcards.
void ValidateClientId(std::string_view client_id);

Qos PartitionQos(std::string_view name);

}  // namespace hapco::service
