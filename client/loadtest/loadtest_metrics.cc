#include "loadtest_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/error.h"

namespace hapco::loadtest {

ClientRecorder::ClientRecorder(int max_ticks) {
  if (max_ticks <= 0) throw InputError("load test: the number of ticks must be positive");
  ticks_.reserve(static_cast<std::size_t>(max_ticks));
  // Pose sequences are tick numbers: 1..max_ticks.
  server_forces_.resize(static_cast<std::size_t>(max_ticks) + 1);
}

void ClientRecorder::OnTick(const phantom::TickRecord& record) {
  // The loop's own count (deadlines that passed without a tick), so the ticks CSV adds up to
  // the summary's missed_ticks. (Recomputed here from wake-up gaps it counted a tick woken
  // 0.6 ms late as one missed: 983 against the loop's 568 in a 10 s run on a loaded machine.)
  const int missed = record.missed_before;
  progress_ticks.fetch_add(1, std::memory_order_relaxed);
  if (missed > 0) progress_missed.fetch_add(static_cast<uint64_t>(missed), std::memory_order_relaxed);
  progress_forces.fetch_add(record.forces.size(), std::memory_order_relaxed);

  for (const phantom::ReceivedForce& f : record.forces) {
    if (f.pose_sequence < server_forces_.size()) {
      ServerForce& s = server_forces_[f.pose_sequence];
      s.received = true;
      s.force_n = f.force_n;
    }
  }
  if (ticks_.size() == ticks_.capacity()) {
    ++dropped_ticks_;
    return;
  }
  TickSample t;
  t.tick = record.tick;
  t.time_s = record.time_s;
  t.published = record.published;
  t.stale = record.stale;
  t.missed_before = missed;
  t.forces_taken = static_cast<int>(record.forces.size());
  t.position_m = record.position_m;
  t.velocity_m_per_s = record.velocity_m_per_s;
  t.rendered_force_n = record.rendered_force_n;
  t.raw_force_n = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  if (!record.forces.empty()) {
    const phantom::ReceivedForce& newest = record.forces.back();
    t.force_sequence = static_cast<int64_t>(newest.pose_sequence);
    t.round_trip_us = newest.round_trip_us();
    t.raw_force_n = newest.force_n;
  }
  ticks_.push_back(t);
}

namespace {
Eigen::Vector3d Clamped(const Eigen::Vector3d& f, double max_n) {
  const double norm = f.norm();
  return norm > max_n ? Eigen::Vector3d(f * (max_n / norm)) : f;
}
}  // namespace

StabilityMetrics ComputeStability(const std::vector<TickSample>& ticks, const std::vector<ServerForce>& server,
                                  double max_force_n) {
  StabilityMetrics m;
  double tracking_sum = 0, server_sum = 0, d2r_sum = 0, d2s_sum = 0;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const TickSample& t = ticks[i];
    const Eigen::Vector3d& f = t.rendered_force_n;
    if (!f.allFinite()) {
      ++m.non_finite_rendered;
      continue;
    }
    m.max_rendered_n = std::max(m.max_rendered_n, f.norm());
    if (t.published) {
      const auto p = static_cast<std::size_t>(t.tick);
      if (t.forces_taken == 0) ++m.ticks_without_fresh_force;
      if (p < server.size() && server[p].received && server[p].force_n.allFinite()) {
        const Eigen::Vector3d s = Clamped(server[p].force_n, max_force_n);
        tracking_sum += (f - s).squaredNorm();
        server_sum += s.squaredNorm();
        ++m.compared_ticks;
      } else {
        ++m.unanswered_poses;
      }
    }
    // Consecutive ticks only (a missed deadline breaks the sequence).
    if (i >= 1 && t.missed_before == 0 && ticks[i - 1].rendered_force_n.allFinite()) {
      m.max_change_per_tick_n = std::max(m.max_change_per_tick_n, (f - ticks[i - 1].rendered_force_n).norm());
      if (i >= 2 && ticks[i - 1].missed_before == 0 && ticks[i - 2].rendered_force_n.allFinite()) {
        d2r_sum += (f - 2.0 * ticks[i - 1].rendered_force_n + ticks[i - 2].rendered_force_n).squaredNorm();
        ++m.d2_rendered_count;
      }
    }
  }
  for (std::size_t p = 2; p < server.size(); ++p) {
    const ServerForce &a = server[p - 2], &b = server[p - 1], &c = server[p];
    if (!a.received || !b.received || !c.received) continue;
    const Eigen::Vector3d d2 =
        Clamped(c.force_n, max_force_n) - 2.0 * Clamped(b.force_n, max_force_n) + Clamped(a.force_n, max_force_n);
    if (!d2.allFinite()) continue;
    d2s_sum += d2.squaredNorm();
    ++m.d2_server_count;
  }
  if (m.compared_ticks > 0) {
    m.tracking_ms_n2 = tracking_sum / static_cast<double>(m.compared_ticks);
    m.server_ms_n2 = server_sum / static_cast<double>(m.compared_ticks);
  }
  if (m.d2_rendered_count > 0) m.d2_rendered_ms_n2 = d2r_sum / static_cast<double>(m.d2_rendered_count);
  if (m.d2_server_count > 0) m.d2_server_ms_n2 = d2s_sum / static_cast<double>(m.d2_server_count);
  if (m.d2_server_ms_n2 > 0) m.hf_ratio = m.d2_rendered_ms_n2 / m.d2_server_ms_n2;
  return m;
}

PassivityMetrics ComputePassivity(const std::vector<TickSample>& ticks, double tick_s) {
  PassivityMetrics m;
  m.energy_j.reserve(ticks.size());
  double energy = 0, peak = 0;
  for (const TickSample& t : ticks) {
    if (t.rendered_force_n.allFinite() && t.velocity_m_per_s.allFinite()) {
      energy += -t.rendered_force_n.dot(t.velocity_m_per_s) * tick_s;
    }
    m.energy_j.push_back(energy);
    if (energy < m.min_energy_j) {
      m.min_energy_j = energy;
      m.min_energy_time_s = t.time_s;
    }
    peak = std::max(peak, energy);
    m.max_drop_j = std::max(m.max_drop_j, peak - energy);
  }
  m.final_energy_j = energy;
  return m;
}

std::vector<Eigen::Vector3d> LoopTrajectory(const std::vector<Eigen::Vector3d>& points, int ticks) {
  if (points.size() < 2) throw InputError("load test: a trajectory needs at least two points to loop");
  std::vector<Eigen::Vector3d> out;
  out.reserve(static_cast<std::size_t>(ticks) + 1);
  const int n = static_cast<int>(points.size()) - 1;
  // Point k of the ping-pong path 0..n, n..0, ...: period 2n.
  for (int k = 0; k <= ticks; ++k) {
    const int phase = k % (2 * n);
    out.push_back(points[static_cast<std::size_t>(phase <= n ? phase : 2 * n - phase)]);
  }
  return out;
}

}  // namespace hapco::loadtest
