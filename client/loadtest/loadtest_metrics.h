#pragma once
// What hapco-loadtest measures for one emulated device, free of DDS so it can be unit-tested:
// a per-tick recorder fed from PhantomClient::Run (preallocated, cheap in the tick thread),
// and the force-stability measures computed after the run (docs/load-and-network.md,
// "Force stability"). SI units throughout.
#include <Eigen/Dense>

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "phantom_client.h"

namespace hapco::loadtest {

// One servo tick of one client.
struct TickSample {
  int tick = 0;                  // 1-based, = the pose sequence when published
  double time_s = 0;             // since the client's loop started, s
  bool published = false;        // a pose was sent this tick
  bool stale = false;            // the safety filter is in (or after) a timeout ramp
  int missed_before = 0;         // servo deadlines missed since the previous tick
  int forces_taken = 0;          // forces that arrived since the previous tick
  int64_t force_sequence = -1;   // pose sequence of the newest force taken (-1: none)
  double round_trip_us = -1;     // of that force (-1: none)
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();
  Eigen::Vector3d raw_force_n = Eigen::Vector3d::Zero();       // newest force as received (NaN: none)
  Eigen::Vector3d rendered_force_n = Eigen::Vector3d::Zero();  // after the safety filter
};

// The server's force for one pose, as it arrived (index = pose sequence).
struct ServerForce {
  bool received = false;
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
};

// Collects TickSamples and server forces during PhantomClient::Run. Storage is reserved for
// max_ticks ticks up front, so OnTick never allocates (the 1 kHz path allocates nothing,
// design.md example 4); ticks beyond max_ticks are counted but not kept.
class ClientRecorder {
 public:
  explicit ClientRecorder(int max_ticks);
  // What the constructor reserves per tick, bytes.
  static constexpr std::size_t kBytesPerTick = sizeof(TickSample) + sizeof(ServerForce);
  void OnTick(const phantom::TickRecord& record);

  const std::vector<TickSample>& ticks() const { return ticks_; }
  const std::vector<ServerForce>& server_forces() const { return server_forces_; }
  uint64_t dropped_ticks() const { return dropped_ticks_; }

  // Progress counters, read by the progress line from another thread.
  std::atomic<uint64_t> progress_forces{0};
  std::atomic<uint64_t> progress_missed{0};
  std::atomic<uint64_t> progress_ticks{0};

 private:
  std::vector<TickSample> ticks_;
  std::vector<ServerForce> server_forces_;
  uint64_t dropped_ticks_ = 0;
};

// Force stability of one client's run. F_r(t): force rendered at tick t; F_s(p): the server's
// force for pose p as received, its magnitude clamped to max_force_n (what the device could
// render at best: the clamp is the device's limit, not an instability). Definitions (docs/load-and-network.md):
//   tracking_ms  = mean over ticks t with F_s(t) received of |F_r(t) - F_s(t)|^2, N^2:
//                  how far the felt force is from what the server computed for the pose the
//                  device had at that tick (delay, rate limit, holds over losses, ramps);
//   d2_rendered  = mean over consecutive ticks of |F_r(t+1) - 2 F_r(t) + F_r(t-1)|^2, N^2;
//   d2_server    = mean over poses p-1, p, p+1 all received of |F_s(p+1) - 2 F_s(p) + F_s(p-1)|^2;
//   hf_ratio     = d2_rendered / d2_server: > 1 means the path between server and motors adds
//                  high-frequency content (steps after holds, jitter), < 1 that it smooths.
struct StabilityMetrics {
  uint64_t compared_ticks = 0;
  double tracking_ms_n2 = 0;
  double server_ms_n2 = 0;            // mean |F_s(t)|^2 over the same ticks, for scale
  uint64_t d2_rendered_count = 0, d2_server_count = 0;
  double d2_rendered_ms_n2 = 0, d2_server_ms_n2 = 0;
  double hf_ratio = 0;                // 0 when d2_server is 0
  double max_change_per_tick_n = 0;   // largest |F_r(t) - F_r(t-1)| between consecutive ticks
  double max_rendered_n = 0;
  uint64_t non_finite_rendered = 0;   // rendered forces with a NaN/Inf component (must be 0)
  uint64_t unanswered_poses = 0;      // published poses whose force never arrived
  uint64_t ticks_without_fresh_force = 0;  // published ticks that took no new force
};
StabilityMetrics ComputeStability(const std::vector<TickSample>& ticks, const std::vector<ServerForce>& server_forces,
                                  double max_force_n);

// Passivity observer (Hannaford & Ryu 2002): the energy the hand has put into the
// environment up to tick n,
//   E(n) = sum_{k<=n} -F_r(k) . v(k) dt,
// F_r = force the device renders on the hand, v = device velocity at tick k, dt = servo period.
// Pressing down into the obstacle: F_r along +z, v along -z, so the power is positive. A
// passive environment never gives back more than it received: E(n) >= 0 for all n.
struct PassivityMetrics {
  std::vector<double> energy_j;  // E(n) per recorded tick
  double min_energy_j = 0;       // min over n of E(n) (0 if E never went below 0)
  double min_energy_time_s = 0;
  double final_energy_j = 0;
  // Largest fall of E below a previous maximum, J: energy returned by the environment in one
  // stretch (elastic release is part of it; compare with the energy stored).
  double max_drop_j = 0;
};
PassivityMetrics ComputePassivity(const std::vector<TickSample>& ticks, double tick_s);

// The scene trajectory looped back and forth (points 0..N, N..0, 0..N, ...) so the device
// never jumps, long enough for `ticks` ticks (points 0..ticks). Without looping the
// trajectory is returned as it is (PhantomClient holds its last point).
std::vector<Eigen::Vector3d> LoopTrajectory(const std::vector<Eigen::Vector3d>& points, int ticks);

}  // namespace hapco::loadtest
