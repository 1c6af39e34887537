// The CI short scenario of the load test across the network lab (scripts/netlab, two network
// namespaces): 2 clients, coarse scene, looped trajectory.
//   1. no impairment, 3 s: the baseline round trip;
//   2. 2 ms one-way delay and 1 % loss per direction, 7 s, and the server is stopped (SIGINT)
//      5 s after it started, i.e. the link to it is cut mid-run.
// Asserts: no NaN, forces within 7.9 N and 0.25 N/tick, the round trip grows by the injected
// 4 ms (2 x 2 ms), and after the cut the client's safety filter times out and ramps the force
// to exactly zero within timeout + ramp. Exit 77 (ctest: skipped) when netlab cannot build the
// lab here (not root, no namespaces).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "../process_support.h"

namespace hapco::service {
namespace {

const std::string kScene = std::string(HAPCO_SOURCE_DIR) + "/tests/data/scenes/coarse.txtpb";
const std::string kNetlab = std::string(HAPCO_SOURCE_DIR) + "/scripts/netlab";
constexpr double kMaxForceN = 7.9, kMaxChangeN = 0.25;  // phantom.h SafetyParameters
constexpr double kTimeoutS = 0.050;                      // hapco-loadtest --force-timeout-ms default
// Time from the timeout to zero force: the ramp lasts 20 ms, but its step is also held to the
// rate limit, so from 7.9 N it takes 7.9 / 0.25 = 32 ticks.
constexpr double kRampS = 0.032;
constexpr double kDelayMs = 2, kLossPct = 1;
constexpr double kAddedRoundTripUs = 2 * kDelayMs * 1000;  // both directions are impaired

bool g_skipped = false;

long long Int(const std::map<std::string, std::string>& row, const char* key) { return std::stoll(row.at(key)); }
double Num(const std::map<std::string, std::string>& row, const char* key) { return std::stod(row.at(key)); }

// Runs netlab; returns its exit code (77: the lab cannot be built here).
int RunLab(const std::string& dir, const std::string& tag, const std::vector<std::string>& impairment,
           const std::string& server_line, const std::vector<std::string>& client) {
  std::vector<std::string> args{kNetlab, "run", "--name", "ltci" + std::to_string(getpid() % 100000)};
  args.insert(args.end(), impairment.begin(), impairment.end());
#ifdef HAPCO_NETDELAY_EXE
  args.insert(args.end(), {"--netdelay", HAPCO_NETDELAY_EXE});
#endif
  args.push_back("--");
  args.push_back(server_line);
  args.push_back(":::");
  args.insert(args.end(), client.begin(), client.end());
  Process lab(args, dir + "/" + tag + ".out", dir + "/" + tag + ".err");
  return lab.Wait(180'000);
}

std::vector<std::string> LoadTest(const std::string& out_dir, const std::string& domain, const char* seconds) {
  std::filesystem::create_directories(out_dir);
  return {HAPCO_LOADTEST_EXE, kScene, "--clients", "2", "--duration-s", seconds, "--domain", domain,
          "--trajectory-loop", "--client-prefix", "ci", "--csv-dir", out_dir, "--rt-priority", "80",
          "--connect-timeout-s", "60"};
}

// Invariants of every tick of one client: finite, within the device limit and the rate limit.
void CheckTicks(const std::vector<std::map<std::string, std::string>>& ticks) {
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Eigen::Vector3d f = Vec(ticks[i], "fx_n", "fy_n", "fz_n");
    ASSERT_TRUE(f.allFinite()) << "tick " << i;
    ASSERT_LE(f.norm(), kMaxForceN + 1e-9) << "tick " << i;
    // 0.25 N per tick; during a timeout ramp (linear in time) 250 N/s over the tick's interval.
    const double dt_s = i == 0 ? 0.0 : Num(ticks[i], "time_s") - Num(ticks[i - 1], "time_s");
    const double limit = Int(ticks[i], "stale") == 1 ? std::max(kMaxChangeN, 250.0 * dt_s) : kMaxChangeN;
    ASSERT_LE((f - previous).norm(), limit + 1e-6) << "tick " << i;  // time_s is logged to 1 ns
    previous = f;
  }
}

double MinRoundTripUs(const std::string& path) {
  double m = 1e300;
  for (const auto& row : ReadCsv(path)) m = std::min(m, Num(row, "round_trip_us"));
  return m;
}

TEST(LoadTestNetwork, DelayShowsInTheRoundTripAndTheSafetyRampEngagesWhenTheLinkIsCut) {
  const std::string dir = TestDir();
  const std::string domain = std::to_string(ReserveTestDomain("LoadTestNetwork"));
  const std::string server = std::string(HAPCO_SERVER_EXE) + " " + kScene + " --domain " + domain +
                             " --rt-priority 80 --quiet";

  const int base_rc = RunLab(dir, "base", {}, server, LoadTest(dir + "/base", domain, "3"));
  if (base_rc == 77) {
    g_skipped = true;
    GTEST_SKIP() << "netlab cannot build the network lab here (needs root and network namespaces): "
                 << ReadFile(dir + "/base.err");
  }
  ASSERT_EQ(base_rc, 0) << ReadFile(dir + "/base.err");
  // The server is stopped 5 s after it started (timeout sends SIGINT; a clean exit is 0).
  const int cut_rc = RunLab(dir, "cut",
                            {"--delay-ms", std::to_string(kDelayMs), "--loss-pct", std::to_string(kLossPct)},
                            "timeout --preserve-status -s INT 5 " + server, LoadTest(dir + "/cut", domain, "7"));
  if (cut_rc == 77) {
    g_skipped = true;
    GTEST_SKIP() << "netlab cannot impair the link here: " << ReadFile(dir + "/cut.err");
  }
  ASSERT_EQ(cut_rc, 0) << ReadFile(dir + "/cut.err");
  std::printf("baseline:\n%s\nimpaired + cut:\n%s", ReadFile(dir + "/base.out").c_str(),
              ReadFile(dir + "/cut.out").c_str());

  std::map<std::string, std::map<std::string, std::string>> base, cut;
  for (const auto& row : ReadCsv(dir + "/base/summary.csv")) base[row.at("client")] = row;
  for (const auto& row : ReadCsv(dir + "/cut/summary.csv")) cut[row.at("client")] = row;
  ASSERT_EQ(base.size(), 3u);
  ASSERT_EQ(cut.size(), 3u);

  // Impairment really applied: the median grows by the injected round trip (tolerance: the
  // delay tool's wake-up, the machine's load), and no force came back faster than it.
  const double increase_us = Num(cut["all"], "rt_p50_us") - Num(base["all"], "rt_p50_us");
  std::printf("round trip p50: %.0f -> %.0f us (+%.0f us, injected +%.0f us)\n", Num(base["all"], "rt_p50_us"),
              Num(cut["all"], "rt_p50_us"), increase_us, kAddedRoundTripUs);
  EXPECT_GE(increase_us, 0.75 * kAddedRoundTripUs);
  EXPECT_LE(increase_us, kAddedRoundTripUs + 3000.0);
  EXPECT_GE(MinRoundTripUs(dir + "/cut/roundtrip.csv"), 0.95 * kAddedRoundTripUs);
  EXPECT_LT(MinRoundTripUs(dir + "/base/roundtrip.csv"), 0.5 * kAddedRoundTripUs);

  for (const std::string id : {"ci-1", "ci-2"}) {
    SCOPED_TRACE(id);
    const auto base_ticks = ReadCsv(dir + "/base/ticks-" + id + ".csv");
    CheckTicks(base_ticks);
    EXPECT_GT(Int(base[id], "forces"), 1500);

    const auto ticks = ReadCsv(dir + "/cut/ticks-" + id + ".csv");
    CheckTicks(ticks);
    EXPECT_EQ(Int(cut[id], "non_finite_rendered"), 0);
    // The link was cut: the filter timed out (1 % loss alone practically never leaves 50 ms
    // without a force; a stall of the shared machine could add a timeout before the cut, so
    // at least once) and the client ran on with stale ticks.
    EXPECT_GE(Int(cut[id], "server_losses"), 1);
    EXPECT_GT(Int(cut[id], "stale_ticks"), 500);
    double last_force_s = -1, first_tick_s = ticks.empty() ? 0 : Num(ticks.front(), "time_s");
    for (const auto& t : ticks) {
      if (Int(t, "forces_taken") > 0) last_force_s = Num(t, "time_s");
    }
    ASSERT_GT(last_force_s - first_tick_s, 1.0) << "the client had forces for less than 1 s before the cut";
    // From timeout + ramp after the last force on: zero force, stale, every tick.
    const double zero_from_s = last_force_s + kTimeoutS + kRampS + 0.003;
    int after = 0;
    for (const auto& t : ticks) {
      if (Num(t, "time_s") <= zero_from_s) continue;
      ++after;
      ASSERT_EQ(Vec(t, "fx_n", "fy_n", "fz_n"), Eigen::Vector3d::Zero()) << "t = " << Num(t, "time_s");
      ASSERT_EQ(Int(t, "stale"), 1) << "t = " << Num(t, "time_s");
    }
    EXPECT_GT(after, 500);
  }
  EXPECT_NE(ReadFile(dir + "/cut.err").find("ramping the force to zero"), std::string::npos);
}

// Network haptics in CI (docs/network-haptics.md): benchmark 1 in hand mode, the hand intent of
// scripts/network_haptics.py (hover, press, hold, slide, hold, lift), 20 ms round trip (10 ms each
// way). In the same server run, direct rendering and the best mode (local-model+passivity,
// the clients' default for a hand-held device): direct generates energy (the passivity
// observer goes well below 0), the best mode stays passive within the load tests' 1e-4 J;
// both keep 7.9 N, and the best mode's force changes stay within 0.25 N per tick plus what the
// renderer's 3000 N/m stiffness cap gives for the device's motion in that tick.
TEST(LoadTestNetwork, TheBestModeStaysPassiveAtARoundTripWhereDirectRenderingIsNot) {
  if (g_skipped) GTEST_SKIP() << "netlab cannot build the network lab here";
  const std::string dir = TestDir() + "/haptics";
  std::filesystem::create_directories(dir + "/direct");
  std::filesystem::create_directories(dir + "/best");
  const std::string intent = dir + "/hand-intent.csv";
  Process generate({"/usr/bin/python3", std::string(HAPCO_SOURCE_DIR) + "/scripts/network_haptics.py", "trajectory",
                    "--out", intent},
                   dir + "/intent.out", dir + "/intent.err");
  ASSERT_EQ(generate.Wait(30'000), 0) << ReadFile(dir + "/intent.err");
  const std::string domain = std::to_string(ReserveTestDomain("LoadTestNetworkHaptics"));
  const std::string scene = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark1.txtpb";
  const std::string server = std::string(HAPCO_SERVER_EXE) + " " + scene + " --domain " + domain + " --quiet";
  auto run = [&](const char* render, const char* out) {
    return std::string("'") + HAPCO_LOADTEST_EXE + "' '" + scene + "' --clients 1 --duration-s 4.7 --mode hand" +
           " --trajectory '" + intent + "' --render " + render + " --client-prefix nh --domain " + domain +
           " --csv-dir '" + dir + "/" + out + "' --rt-priority 80 --connect-timeout-s 60 --quiet";
  };
  const int rc = RunLab(dir, "lab", {"--delay-ms", "10"}, server,
                        {"set -e; " + run("direct", "direct") + "; " + run("local-model+passivity", "best")});
  if (rc == 77) GTEST_SKIP() << "netlab cannot impair the link here: " << ReadFile(dir + "/lab.err");
  ASSERT_EQ(rc, 0) << ReadFile(dir + "/lab.err");
  const auto direct = ReadCsv(dir + "/direct/summary.csv");
  const auto best = ReadCsv(dir + "/best/summary.csv");
  ASSERT_EQ(direct.size(), 2u);
  ASSERT_EQ(best.size(), 2u);
  std::printf("20 ms round trip: direct min E %s J, local-model+passivity min E %s J (dissipated %s J), rt p50 %s us\n",
              direct[0].at("passivity_min_j").c_str(), best[0].at("passivity_min_j").c_str(),
              best[0].at("passivity_dissipated_j").c_str(), best[0].at("rt_p50_us").c_str());
  EXPECT_GE(Num(best[0], "rt_p50_us"), 19000.0) << "the delay was applied";
  EXPECT_LT(Num(direct[0], "passivity_min_j"), -0.01) << "direct rendering generates energy at 20 ms";
  EXPECT_GE(Num(best[0], "passivity_min_j"), -1e-4) << "the best mode stays passive";
  EXPECT_EQ(best[0].at("render"), "local-model+passivity");
  EXPECT_GT(Int(best[0], "model_ticks"), 2000);
  const auto ticks = ReadCsv(dir + "/best/ticks-nh-1.csv");
  ASSERT_FALSE(ticks.empty());
  // The damper -α v (α <= 100 N s/m) comes after the rate limit and may switch on or off from
  // one tick to the next: a tick's change may add 100 N s/m times both ticks' speeds.
  Eigen::Vector3d previous_f = Eigen::Vector3d::Zero(), previous_x = Vec(ticks[0], "x_m", "y_m", "z_m");
  Eigen::Vector3d previous_v = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Eigen::Vector3d f = Vec(ticks[i], "fx_n", "fy_n", "fz_n"), x = Vec(ticks[i], "x_m", "y_m", "z_m");
    const Eigen::Vector3d v = Vec(ticks[i], "vx_m_per_s", "vy_m_per_s", "vz_m_per_s");
    ASSERT_TRUE(f.allFinite()) << "tick " << i;
    ASSERT_LE(f.norm(), kMaxForceN + 1e-9) << "tick " << i;
    const double damper_n = 100.0 * (v.norm() + previous_v.norm());
    EXPECT_LE((f - previous_f).norm(), kMaxChangeN + 3000.0 * (x - previous_x).norm() + damper_n + 1e-4)
        << "tick " << i;  // velocities are logged to 6 digits
    previous_f = f;
    previous_x = x;
    previous_v = v;
  }
}

}  // namespace
}  // namespace hapco::service

// ctest counts exit code 77 as skipped (SKIP_RETURN_CODE).
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  const int rc = RUN_ALL_TESTS();
  return rc == 0 && hapco::service::g_skipped ? 77 : rc;
}
