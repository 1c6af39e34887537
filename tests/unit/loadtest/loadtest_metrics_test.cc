// The load test's measures against hand-computed values: the passivity observer on a sampled
// spring (exact sums), the tracking / high-frequency measures on known force sequences, the
// looped trajectory and the recorder's bookkeeping. No DDS.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "loadtest_metrics.h"

namespace hapco::loadtest {
namespace {

constexpr double kTick = 1e-3;

// A device pressed straight down by n steps of delta into a spring of stiffness k (force on
// the hand +k*depth along z) and pulled out again; the rendered force lags `lag` ticks.
std::vector<TickSample> SpringCycle(int n, double delta_m, double k_n_per_m, int lag) {
  std::vector<double> z;
  for (int i = 1; i <= n; ++i) z.push_back(-i * delta_m);
  for (int i = n - 1; i >= 0; --i) z.push_back(-i * delta_m);
  std::vector<TickSample> ticks;
  for (std::size_t i = 0; i < z.size(); ++i) {
    TickSample t;
    t.tick = static_cast<int>(i) + 1;
    t.time_s = static_cast<double>(i + 1) * kTick;
    t.published = true;
    const double previous = i == 0 ? 0.0 : z[i - 1];
    t.position_m = {0, 0, z[i]};
    t.velocity_m_per_s = {0, 0, (z[i] - previous) / kTick};  // backward difference, as the client
    const long j = static_cast<long>(i) - lag;
    const double depth = j < 0 ? 0.0 : -z[static_cast<std::size_t>(j)];
    t.rendered_force_n = {0, 0, k_n_per_m * depth};
    ticks.push_back(t);
  }
  return ticks;
}

TEST(Passivity, SampledSpringWithoutLagStaysPassiveWithTheExactSums) {
  const int n = 30;
  const double d = 1e-4, k = 2000;
  const PassivityMetrics p = ComputePassivity(SpringCycle(n, d, k, 0), kTick);
  // Press: sum_{i=1..n} k (i d) d = k d^2 n(n+1)/2 (positive: +z force, -z velocity).
  EXPECT_NEAR(p.energy_j[n - 1], k * d * d * n * (n + 1) / 2.0, 1e-15);
  // Release returns k d^2 n(n-1)/2: net k d^2 n >= 0, and E never went below 0.
  EXPECT_NEAR(p.final_energy_j, k * d * d * n, 1e-15);
  EXPECT_EQ(p.min_energy_j, 0.0);
  EXPECT_NEAR(p.max_drop_j, k * d * d * n * (n - 1) / 2.0, 1e-15);
}

TEST(Passivity, OneTickOfLagMakesTheSpringActive) {
  const int n = 30;
  const double d = 1e-4, k = 2000;
  const PassivityMetrics p = ComputePassivity(SpringCycle(n, d, k, 1), kTick);
  // Press with the force of the previous tick: k d^2 n(n-1)/2; release k d^2 n(n+1)/2 back.
  EXPECT_NEAR(p.energy_j[n - 1], k * d * d * n * (n - 1) / 2.0, 1e-15);
  EXPECT_NEAR(p.final_energy_j, -k * d * d * n, 1e-15);
  EXPECT_NEAR(p.min_energy_j, -k * d * d * n, 1e-15);
  EXPECT_LT(p.min_energy_j, 0.0);
}

std::vector<ServerForce> Quadratic(int poses, double c) {
  std::vector<ServerForce> s(static_cast<std::size_t>(poses) + 1);
  for (int p = 1; p <= poses; ++p) {
    s[static_cast<std::size_t>(p)].received = true;
    s[static_cast<std::size_t>(p)].force_n = {0, 0, c * p * p};
  }
  return s;
}

std::vector<TickSample> Rendering(const std::vector<ServerForce>& s, int lag) {
  std::vector<TickSample> ticks;
  for (std::size_t p = 1; p < s.size(); ++p) {
    TickSample t;
    t.tick = static_cast<int>(p);
    t.published = true;
    t.forces_taken = 1;
    const long j = static_cast<long>(p) - lag;
    t.rendered_force_n = j >= 1 ? s[static_cast<std::size_t>(j)].force_n : Eigen::Vector3d::Zero();
    ticks.push_back(t);
  }
  return ticks;
}

TEST(Stability, ExactRenderingHasNoTrackingErrorAndUnitHighFrequencyRatio) {
  const auto server = Quadratic(50, 1e-3);
  const StabilityMetrics m = ComputeStability(Rendering(server, 0), server, 7.9);
  EXPECT_EQ(m.compared_ticks, 50u);
  EXPECT_EQ(m.tracking_ms_n2, 0.0);
  // Second difference of c p^2 is 2c everywhere.
  EXPECT_NEAR(m.d2_server_ms_n2, 4e-6, 1e-18);
  EXPECT_NEAR(m.d2_rendered_ms_n2, 4e-6, 1e-18);
  EXPECT_NEAR(m.hf_ratio, 1.0, 1e-12);
  EXPECT_EQ(m.unanswered_poses, 0u);
  EXPECT_NEAR(m.max_change_per_tick_n, 1e-3 * (50 * 50 - 49 * 49), 1e-12);
}

TEST(Stability, OneTickLagOnAQuadraticGivesTheFirstDifferenceAsError) {
  const double c = 1e-3;
  const auto server = Quadratic(50, c);
  const StabilityMetrics m = ComputeStability(Rendering(server, 1), server, 7.9);
  // Tick p renders F(p-1): error c (2p - 1) for p >= 2, c for p = 1 (rendered 0).
  double sum = c * c;
  for (int p = 2; p <= 50; ++p) sum += c * c * (2 * p - 1) * (2 * p - 1);
  EXPECT_NEAR(m.tracking_ms_n2, sum / 50, 1e-15);
}

TEST(Stability, AHeldForceAfterALossIsUnansweredAndAddsHighFrequency) {
  auto server = Quadratic(20, 1e-3);
  auto ticks = Rendering(server, 0);
  server[10].received = false;        // pose 10's force was lost: tick 10 holds F(9)
  ticks[9].forces_taken = 0;
  ticks[9].rendered_force_n = server[9].force_n;
  const StabilityMetrics m = ComputeStability(ticks, server, 7.9);
  EXPECT_EQ(m.unanswered_poses, 1u);
  EXPECT_EQ(m.ticks_without_fresh_force, 1u);
  EXPECT_EQ(m.compared_ticks, 19u);
  EXPECT_GT(m.hf_ratio, 1.0);
}

TEST(Stability, TheDeviceClampIsNotCountedAsTrackingError) {
  std::vector<ServerForce> server(3);
  std::vector<TickSample> ticks;
  for (int p = 1; p <= 2; ++p) {
    server[static_cast<std::size_t>(p)] = {true, Eigen::Vector3d(0, 0, 10.0)};
    TickSample t;
    t.tick = p;
    t.published = true;
    t.forces_taken = 1;
    t.rendered_force_n = {0, 0, 7.9};
    ticks.push_back(t);
  }
  const StabilityMetrics m = ComputeStability(ticks, server, 7.9);
  EXPECT_EQ(m.tracking_ms_n2, 0.0);
  EXPECT_NEAR(m.max_rendered_n, 7.9, 1e-12);
  ticks[1].rendered_force_n.z() = std::nan("");
  EXPECT_EQ(ComputeStability(ticks, server, 7.9).non_finite_rendered, 1u);
}

TEST(LoopTrajectory, GoesBackAndForthWithoutJumps) {
  const std::vector<Eigen::Vector3d> points{{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  const auto loop = LoopTrajectory(points, 13);
  ASSERT_EQ(loop.size(), 14u);
  const double expected[] = {0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1};
  for (std::size_t i = 0; i < loop.size(); ++i) EXPECT_EQ(loop[i].x(), expected[i]) << i;
}

TEST(ClientRecorder, KeepsServerForcesByPoseAndTheLoopsMissedTicks) {
  ClientRecorder recorder(8);
  phantom::ReceivedForce f;
  f.pose_sequence = 1;
  f.client_time_ns = 1'000'000;
  f.arrival_ns = 1'400'000;
  f.force_n = {0, 0, 1.5};
  phantom::TickRecord r;
  r.tick = 1;
  r.published = true;
  r.tick_ns = 1'000'000;
  r.rendered_force_n = {0, 0, 0.25};
  r.forces = std::span<const phantom::ReceivedForce>(&f, 1);
  recorder.OnTick(r);
  r.tick = 2;
  r.tick_ns = 5'000'000;  // 4 ms later: the loop says the ticks at 2, 3 and 4 ms never ran
  r.missed_before = 3;
  r.forces = {};
  recorder.OnTick(r);
  ASSERT_EQ(recorder.ticks().size(), 2u);
  EXPECT_EQ(recorder.ticks()[0].force_sequence, 1);
  EXPECT_NEAR(recorder.ticks()[0].round_trip_us, 400.0, 1e-9);
  EXPECT_EQ(recorder.ticks()[1].force_sequence, -1);
  EXPECT_EQ(recorder.ticks()[1].missed_before, 3);
  EXPECT_EQ(recorder.progress_missed.load(), 3u);
  EXPECT_TRUE(recorder.server_forces()[1].received);
  EXPECT_EQ(recorder.server_forces()[1].force_n.z(), 1.5);
  EXPECT_FALSE(recorder.server_forces()[2].received);
}

}  // namespace
}  // namespace hapco::loadtest
