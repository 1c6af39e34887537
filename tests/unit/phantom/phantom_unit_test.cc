// hapco_phantom_lib: expected values from the definitions (a multiple of the quantum, the
// clamp and rate limits as stated in SafetyParameters, a spring's rest position).
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "phantom.h"

namespace hapco::phantom {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

TEST(PhantomQuantize, RoundsToTheNearestMultipleOfTheQuantum) {
  const double q = kPositionQuantumM;
  EXPECT_DOUBLE_EQ(Quantize(Eigen::Vector3d(0.4 * q, 0.6 * q, -1.4 * q)).x(), 0.0);
  EXPECT_DOUBLE_EQ(Quantize(Eigen::Vector3d(0.4 * q, 0.6 * q, -1.4 * q)).y(), q);
  EXPECT_DOUBLE_EQ(Quantize(Eigen::Vector3d(0.4 * q, 0.6 * q, -1.4 * q)).z(), -q);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3d x(u(rng), u(rng), u(rng));
    const Eigen::Vector3d y = Quantize(x);
    for (int a = 0; a < 3; ++a) {
      EXPECT_LE(std::abs(y[a] - x[a]), 0.5 * q * (1 + 1e-9));
      const double multiple = y[a] / q;
      EXPECT_NEAR(multiple, std::round(multiple), 1e-6);
    }
  }
}

// Random raw forces incl. NaN, Inf, huge values and gaps: the invariants hold every tick.
TEST(PhantomSafety, NeverRendersNanNorExceedsClampNorRateLimit) {
  SafetyParameters p;
  SafetyFilter filter(p);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-20.0, 20.0);
  std::uniform_int_distribution<int> kind(0, 9);
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  int nan_sent = 0;
  for (int tick = 0; tick < 20000; ++tick) {
    const int k = kind(rng);
    Eigen::Vector3d raw(u(rng), u(rng), u(rng));
    bool fresh = k < 8;
    if (k == 0) {
      raw.y() = kNan;
      ++nan_sent;
    }
    if (k == 1) raw.x() = std::numeric_limits<double>::infinity();
    if (k == 1) ++nan_sent;
    if (tick > 5000 && tick < 5200) fresh = false;  // a long outage
    const Eigen::Vector3d f = filter.Update(fresh, raw, tick * p.tick_s);
    ASSERT_TRUE(f.allFinite()) << tick;
    ASSERT_LE(f.norm(), p.max_force_n * (1 + 1e-12)) << tick;
    ASSERT_LE((f - previous).norm(), p.max_change_per_tick_n * (1 + 1e-12)) << tick;
    previous = f;
  }
  EXPECT_GT(filter.rejected_non_finite(), 0u);
  EXPECT_LE(filter.rejected_non_finite(), static_cast<uint64_t>(nan_sent));
  EXPECT_GT(filter.clamped(), 0u);
}

TEST(PhantomSafety, ReachesAConstantForceAndClampsIt) {
  SafetyParameters p;
  SafetyFilter filter(p);
  Eigen::Vector3d f;
  const Eigen::Vector3d raw(3.0, -4.0, 12.0);  // |raw| = 13 N
  for (int tick = 0; tick < 100; ++tick) f = filter.Update(true, raw, tick * p.tick_s);
  EXPECT_NEAR(f.norm(), p.max_force_n, 1e-12);
  EXPECT_NEAR((f / f.norm() - raw / 13.0).norm(), 0.0, 1e-12);  // direction kept
  // A NaN after that changes nothing.
  f = filter.Update(true, Eigen::Vector3d(kNan, 0, 0), 100 * p.tick_s);
  EXPECT_NEAR(f.norm(), p.max_force_n, 1e-12);
}

TEST(PhantomSafety, TimeoutRampsToZeroThenResumes) {
  SafetyParameters p;  // timeout 50 ms, ramp 20 ms
  SafetyFilter filter(p);
  const Eigen::Vector3d raw(0.0, 0.0, 2.0);
  int tick = 0;
  for (; tick < 20; ++tick) filter.Update(true, raw, tick * p.tick_s);
  EXPECT_NEAR(filter.rendered().z(), 2.0, 1e-12);
  const int last_fresh = tick - 1;
  // No force: held while within the timeout.
  for (; tick <= last_fresh + 50; ++tick) {
    EXPECT_NEAR(filter.Update(false, raw, tick * p.tick_s).z(), 2.0, 1e-12) << tick;
  }
  EXPECT_FALSE(filter.stale());
  // Past the timeout: monotone decrease to exactly zero within ramp_s (+1 tick).
  double previous = 2.0;
  const int ramp_ticks = static_cast<int>(p.ramp_s / p.tick_s);
  for (int i = 0; i < ramp_ticks + 1; ++i, ++tick) {
    const double z = filter.Update(false, raw, tick * p.tick_s).z();
    EXPECT_LE(z, previous + 1e-15);
    previous = z;
  }
  EXPECT_TRUE(filter.stale());
  EXPECT_EQ(filter.rendered().norm(), 0.0);
  EXPECT_GT(filter.stale_ticks(), 0u);
  // Forces return: the filter resumes, rate limited, and reaches the new value.
  const Eigen::Vector3d back(1.0, 0.0, 0.0);
  Eigen::Vector3d f = filter.Update(true, back, tick * p.tick_s);
  EXPECT_FALSE(filter.stale());
  EXPECT_NEAR(f.x(), p.max_change_per_tick_n, 1e-12);
  for (int i = 0; i < 10; ++i) f = filter.Update(true, back, (++tick) * p.tick_s);
  EXPECT_NEAR((f - back).norm(), 0.0, 1e-12);
}

// The timeout ramp is linear in time from the moment the timeout expired and at least
// |F| / 250 N/s long (the rate limit), so with ticks on time the force is zero by last force +
// timeout + ramp. A stalled client (ticks late around the timeout; the motors held the last
// force meanwhile) still changes the force by at most 0.25 N per tick: it follows the line
// down from the force it held, never jumping to it (a late tick used to render the line's
// value at once: 4.9 N -> 0 N in one tick after an 83 ms stall, seen by a helper session).
TEST(PhantomSafety, TimeoutRampFollowsTheLineAndNeverJumpsAfterAStall) {
  SafetyParameters p;  // timeout 50 ms, ramp 20 ms, 0.25 N per 1 ms tick
  const double ramp_s = 7.9 / 250.0;  // longer than ramp_s = 20 ms: the rate limit rules
  for (const double tick_gap_s : {0.001, 0.007, 0.045, 0.083}) {  // on time; 6 of 7 ticks missed; stalls
    SCOPED_TRACE(tick_gap_s);
    SafetyFilter filter(p);
    const Eigen::Vector3d raw(0.0, 7.9, 0.0);
    double t = 0.0;
    for (int tick = 0; tick < 40; ++tick, t += p.tick_s) filter.Update(true, raw, t);
    ASSERT_NEAR(filter.rendered().y(), 7.9, 1e-12);
    const double last_fresh = t - p.tick_s;
    const double ramp_start = last_fresh + p.timeout_s;
    double previous = 7.9;
    int ticks_after_line_reached_zero = 0;
    for (t = last_fresh + tick_gap_s; filter.rendered().norm() > 0.0 || t < ramp_start + ramp_s; t += tick_gap_s) {
      const double y = filter.Update(false, raw, t).y();
      // The line 7.9 N * (1 - (t - ramp_start) / ramp), from the timeout's expiry, then 0.
      const double line = t <= ramp_start ? 7.9 : std::max(0.0, 7.9 * (1.0 - (t - ramp_start) / ramp_s));
      // Down the line, or 0.25 N below the last tick where the line is further down: never both
      // above the line and more than one tick's change from the last force.
      EXPECT_NEAR(y, std::max(line, previous - p.max_change_per_tick_n), 1e-9) << "t = " << t;
      EXPECT_LE(previous - y, p.max_change_per_tick_n + 1e-12) << "t = " << t;
      EXPECT_GE(y, 0.0);
      previous = y;
      if (line == 0.0) ++ticks_after_line_reached_zero;
      ASSERT_LT(ticks_after_line_reached_zero, 40) << "the force never reached zero";
    }
    EXPECT_TRUE(filter.stale());
    EXPECT_EQ(filter.rendered().norm(), 0.0);
    if (tick_gap_s == 0.001) {
      // On time: zero by the line's end (within a tick).
      EXPECT_LE(t, ramp_start + ramp_s + 2 * p.tick_s);
    } else {
      // After a stall: the whole 7.9 N in 0.25 N steps, 32 ticks.
      EXPECT_GE(ticks_after_line_reached_zero, 1);
    }
  }
}

TEST(PhantomHand, ConvergesToAFixedTarget) {
  HandModel hand({}, Eigen::Vector3d::Zero());
  const Eigen::Vector3d target(0.01, -0.02, 0.005);
  for (int i = 0; i < 3000; ++i) hand.Step(target, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 1e-3);
  EXPECT_NEAR((hand.position_m() - target).norm(), 0.0, 1e-9);
  EXPECT_NEAR(hand.velocity_m_per_s().norm(), 0.0, 1e-8);
}

// With a constant push F the rest position is target + F/k_h (spring equilibrium).
TEST(PhantomHand, RestsWhereTheSpringBalancesTheRenderedForce) {
  HandParameters p;
  HandModel hand(p, Eigen::Vector3d::Zero());
  const Eigen::Vector3d target(0.0, 0.0, -0.003);
  const Eigen::Vector3d push(0.0, 0.0, 1.5);
  for (int i = 0; i < 5000; ++i) hand.Step(target, Eigen::Vector3d::Zero(), push, 1e-3);
  EXPECT_NEAR(hand.position_m().z(), -0.003 + 1.5 / p.hand_stiffness_n_per_m, 1e-9);
}

// Following a ramp at constant velocity, the steady-state lag of a spring-damper driven at
// the same velocity is c_d v / k_h (only the device damping resists). Semi-implicit Euler
// evaluates the spring at the position before the step and then advances it by v dt, so the
// lag measured after a step is c_d v / k_h - v dt.
TEST(PhantomHand, FollowsARampWithTheDampingLag) {
  HandParameters p;
  HandModel hand(p, Eigen::Vector3d::Zero());
  const Eigen::Vector3d v(0.05, 0.0, 0.0);
  double t = 0;
  for (int i = 0; i < 4000; ++i) {
    t += 1e-3;
    hand.Step(v * t, v, Eigen::Vector3d::Zero(), 1e-3);
  }
  const double lag = v.x() * t - hand.position_m().x();
  EXPECT_NEAR(lag, p.device_damping_n_s_per_m * v.x() / p.hand_stiffness_n_per_m - v.x() * 1e-3, 1e-9);
}

}  // namespace
}  // namespace hapco::phantom
