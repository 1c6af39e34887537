// network_haptics_study: the closed loop of scripts/loadtest-network --haptics without a network
// (docs/network-haptics.md): a hand drags the device along the same intent; every tick's pose
// reaches an in-process server session (the same TwoBodySession and LocalModelBuilder the
// server runs) half a round trip later, its answer (force and local model) reaches the device
// the other half later, with losses drawn at a fixed seed, and the device renders through the
// same RenderChain as hapco-phantom and hapco-loadtest. What it leaves out is DDS and the
// machine: no jitter, no missed servo ticks, a server that answers at once. It writes the
// loadtest's per-case layout (DIR/<case>/<mode>/ticks-nh-1.csv, summary.csv, case.txt), so
// scripts/network_haptics.py analyse computes the same metrics from it. Prints numbers only.
#include <Eigen/Dense>

#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "io/scene_file.h"
#include "io/trajectory_file.h"
#include "render_chain.h"
#include "sim/local_model.h"
#include "sim/step_pipeline.h"

namespace {

using namespace hapco;  // NOLINT: a short study

constexpr double kTickS = 1e-3;

struct Case {
  int round_trip_ms = 0;
  double loss_pct = 0.0;  // per direction
};

// What the machine adds to the network's delay (docs/network-haptics.md, "chatter"): each
// message's one-way delay gets U[0, jitter] more, and the device's servo thread stalls for
// stall_ms every stall_every_s (its missed ticks are skipped and the newest answer rendered,
// as hapco-phantom does). Both 0: the loop is deterministic tick for tick.
struct Disturbance {
  double jitter_ms = 0.0;
  double stall_every_s = 0.0;
  double stall_ms = 0.0;
};

struct Answer {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();
  phantom::ReceivedModel model;
};

struct RunSummary {
  double min_energy_j = 0.0, dissipated_j = 0.0, lost_pct = 0.0;
  // Tick-to-tick change of the rendered force beyond what the local model's stiffness gives
  // for the device's own motion over the tick, N: the safety filter lets at most 0.25 N
  // through, so more is the passivity damper's (chatter).
  double max_excess_change_n = 0.0;
  unsigned long excess_change_ticks = 0;  // ticks where that exceeds 0.25 N
  // Ticks whose force change reverses the previous tick's, both over 0.05 N: a 500 Hz buzz
  // (an explicit damper at its stability limit) even where the rate limit holds.
  unsigned long chatter_ticks = 0;
  unsigned long model_ticks = 0, surface_ticks = 0, timeouts = 0;
};

phantom::ReceivedModel ToReceived(const sim::LocalContactModel& m) {
  phantom::ReceivedModel r;
  r.valid = !m.normal_device.isZero() && m.stiffness_n_per_m.allFinite() && m.device_force_n.allFinite();
  r.position_m = m.device_translation_m;
  r.stiffness_n_per_m = m.stiffness_n_per_m;
  r.normal = m.normal_device;
  r.friction_coefficient = m.friction_coefficient;
  r.surface_ahead = m.surface_ahead;
  r.surface_gap_m = m.surface_gap_m;
  r.surface_normal = m.surface_normal;
  return r;
}

RunSummary RunLoop(const sim::TwoBodyModel& model, const std::vector<Eigen::Vector3d>& intent, const Case& c,
                   const Disturbance& disturbance, const phantom::RendererParameters& render,
                   const std::string& ticks_csv, unsigned seed) {
  sim::TwoBodySession session(model);
  sim::LocalModelBuilder builder;
  phantom::SafetyParameters safety;
  phantom::RenderChain chain(render, safety);
  phantom::HandModel hand(phantom::HandParameters{}, intent.front());
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> uniform(0.0, 100.0);
  std::uniform_real_distribution<double> jitter(0.0, disturbance.jitter_ms);
  // A pose reaches the server round_trip/2 (+ jitter) after it was sampled, its answer the
  // device the rest of the round trip (+ jitter) later, at least the next tick (a local round
  // trip is ~0.5 ms). Times are the wall clock, ms: a stalled servo thread runs no ticks while
  // the network and the server go on.
  const double up_ms = 0.5 * c.round_trip_ms;
  const double down_ms = std::max(1.0, c.round_trip_ms - up_ms);
  std::multimap<double, std::pair<long, Eigen::Vector3d>> to_server;  // arrival ms -> (sequence, pose)
  std::multimap<double, std::pair<long, Answer>> to_device;           // arrival ms -> (sequence, answer)
  std::vector<std::pair<long, Eigen::Vector3d>> waiting;  // lost poses, recovered by the next one's repeats
  std::FILE* csv = std::fopen(ticks_csv.c_str(), "w");
  if (csv == nullptr) throw InputError("cannot write " + ticks_csv);
  std::fprintf(csv, "tick,time_s,published,x_m,y_m,z_m,vx_m_per_s,vy_m_per_s,vz_m_per_s,fx_n,fy_n,fz_n,energy_j\n");
  RunSummary summary;
  Eigen::Vector3d rendered = Eigen::Vector3d::Zero(), rendered_before = Eigen::Vector3d::Zero();
  double energy_j = 0.0, stalled_ms = 0.0;
  long lost_answers = 0, last_stepped = 0, last_rendered = 0;
  const long ticks = static_cast<long>(intent.size()) - 1;
  const long stall_period_ticks = std::lround(disturbance.stall_every_s / kTickS);
  bool was_stale = false;
  for (long tick = 1; tick <= ticks; ++tick) {
    if (stall_period_ticks > 0 && tick % stall_period_ticks == 0) stalled_ms += disturbance.stall_ms;
    const double now_ms = static_cast<double>(tick) + stalled_ms;
    // The hand moves the device with last tick's force; the pose is sampled (as hapco-phantom).
    const Eigen::Vector3d& target = intent[static_cast<std::size_t>(tick)];
    const Eigen::Vector3d target_velocity = (target - intent[static_cast<std::size_t>(tick - 1)]) / kTickS;
    const Eigen::Vector3d previous_rendered = rendered;
    const Eigen::Vector3d previous_change = rendered - rendered_before;
    rendered_before = rendered;
    const Eigen::Vector3d previous_position = phantom::Quantize(hand.position_m());
    hand.Step(target, target_velocity, rendered, kTickS);
    const Eigen::Vector3d position = phantom::Quantize(hand.position_m());
    const Eigen::Vector3d velocity = hand.velocity_m_per_s();
    // Up: a lost pose travels with the next one's repeats (DevicePose.recent).
    if (uniform(random) < c.loss_pct) {
      waiting.emplace_back(tick, position);
    } else {
      const double arrival_ms = now_ms + up_ms + (disturbance.jitter_ms > 0 ? jitter(random) : 0.0);
      for (const auto& p : waiting) to_server.emplace(arrival_ms, p);
      waiting.clear();
      to_server.emplace(arrival_ms, std::make_pair(tick, position));
    }
    // The server steps every pose that has arrived, in arrival order, and answers each; a pose
    // older than one it already stepped is superseded (as hapco-server).
    while (!to_server.empty() && to_server.begin()->first <= now_ms) {
      const double arrived_ms = to_server.begin()->first;
      const auto [sequence, pose] = to_server.begin()->second;
      to_server.erase(to_server.begin());
      if (sequence <= last_stepped) continue;
      last_stepped = sequence;
      session.Step(pose);
      Answer a;
      a.force_n = session.last_output().device_force_n;
      a.model = ToReceived(builder.Linearize(session));
      // Down: a lost answer is never rendered (the next one is newer).
      if (uniform(random) < c.loss_pct) {
        ++lost_answers;
      } else {
        const double delay_ms = down_ms + (disturbance.jitter_ms > 0 ? jitter(random) : 0.0);
        to_device.emplace(std::max(arrived_ms + delay_ms, now_ms + 1.0), std::make_pair(sequence, a));
      }
    }
    // Every answer that has arrived; the newest is rendered, older ones dropped (as hapco-phantom).
    bool fresh = false;
    Answer newest;
    while (!to_device.empty() && to_device.begin()->first <= now_ms) {
      const auto& [sequence, answer] = to_device.begin()->second;
      if (sequence > last_rendered) {
        last_rendered = sequence;
        newest = answer;
        fresh = true;
      }
      to_device.erase(to_device.begin());
    }
    rendered = chain.Tick(fresh, newest.force_n, newest.model, position, velocity, now_ms * 1e-3);
    const bool stale = chain.safety().stale();
    if (stale && !was_stale) ++summary.timeouts;
    was_stale = stale;
    // The change the safety filter allows: its rate limit plus the model's response to the
    // device's motion (bounded here by the renderer's stiffness cap times the tick's travel).
    const double allowed_n =
        safety.max_change_per_tick_n + render.max_stiffness_n_per_m * (position - previous_position).norm();
    const double excess_n = (rendered - previous_rendered).norm() - allowed_n;
    summary.max_excess_change_n = std::max(summary.max_excess_change_n, excess_n);
    if (excess_n > 1e-9) ++summary.excess_change_ticks;
    const Eigen::Vector3d change = rendered - previous_rendered;
    constexpr double kChatterN = 0.05;
    if (change.norm() > kChatterN && previous_change.norm() > kChatterN && change.dot(previous_change) < 0) {
      ++summary.chatter_ticks;
    }
    energy_j += -rendered.dot(velocity) * kTickS;
    summary.min_energy_j = std::min(summary.min_energy_j, energy_j);
    std::fprintf(csv, "%ld,%.6f,1,%.17g,%.17g,%.17g,%.6g,%.6g,%.6g,%.17g,%.17g,%.17g,%.9g\n", tick, now_ms * 1e-3,
                 position.x(), position.y(), position.z(), velocity.x(), velocity.y(), velocity.z(), rendered.x(),
                 rendered.y(), rendered.z(), energy_j);
  }
  std::fclose(csv);
  summary.dissipated_j = chain.renderer().passivity().dissipated_j();
  summary.model_ticks = chain.renderer().stats().model_ticks;
  summary.surface_ticks = chain.renderer().stats().surface_ticks;
  summary.lost_pct = 100.0 * static_cast<double>(lost_answers) / static_cast<double>(std::max(1L, ticks));
  return summary;
}

struct Options {
  std::string scene = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark1.txtpb";
  std::string trajectory;
  std::string out_dir = "network-haptics-offline";
  std::string round_trips = "0,2,5,10,20,50,100,200";
  std::string loss_cases = "20:1,20:5,20:10,100:10,200:10";
  std::string modes = "direct,direct+passivity,local-model,local-model+passivity";
  double max_stiffness_n_per_m = 3000.0;
  double max_damping_n_s_per_m = phantom::RendererParameters{}.max_damping_n_s_per_m;
  bool first_version = false;
  bool no_surface_ahead = false;
  Disturbance disturbance;
};

std::vector<std::string> Split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) {
    if (!part.empty()) parts.push_back(part);
  }
  return parts;
}

constexpr const char* kDescription =
    R"(The closed loop of scripts/loadtest-network --haptics without a network: the hand intent of TRAJECTORY (scripts/network_haptics.py trajectory), an in-process server session of SCENE (the server's step and local model), a delay of half the round trip each way with losses at a fixed seed, the device rendering through hapco-phantom's RenderChain. Writes DIR/<case>/<mode>/ticks-nh-1.csv and summary.csv in the loadtest's layout; scripts/network_haptics.py analyse --runs-dir DIR computes the metrics and charts. No DDS; jitter and servo stalls only as --jitter-ms and --stall-every-s/--stall-ms give them (the network lab measures the real ones, docs/network-haptics.md).)";

bool Parse(int argc, char** argv, Options* o) {
  cli::CommandLine command("network_haptics_study", "[SCENE] --trajectory CSV [options]", kDescription,
                           "Exit code: 0 when the study ran, 1 on bad input.");
  command.AddScene(&o->scene, "scene file (default: benchmark 1 of the source tree)")->required(false);
  command.AddText("--trajectory", &o->trajectory, "CSV", "the hand intent, one row per tick (required)", "Run")
      ->required();
  command.AddText("--round-trips-ms", &o->round_trips, "LIST", "round trips without loss, ms (default 0,2,5,10,20,50,100,200)",
                  "Run");
  command.AddText("--loss-cases", &o->loss_cases, "LIST",
                  "ROUND_TRIP_MS:LOSS_PCT pairs, the loss per direction (default 20:1,20:5,20:10,100:10,200:10)", "Run");
  command.AddText("--modes", &o->modes, "LIST", "rendering modes (default: all four)", "Run");
  command.AddNumber("--max-model-stiffness-n-per-m", &o->max_stiffness_n_per_m, "K",
                    "the renderer's stiffness cap (default 3000)", "Device", 1.0, 1e6);
  command.AddNumber("--max-damping-n-s-per-m", &o->max_damping_n_s_per_m, "B",
                    "the passivity controller's damping cap (default: the clients', force_renderer.h)", "Device", 0.01,
                    1e4);
  command.AddFlag("--first-version", &o->first_version,
                  "render contact models as the first version did (F0 + K (x - x0), K capped by its stiffest "
                  "direction, the model's tangential force) and no surface ahead",
                  "Device");
  command.AddFlag("--no-surface-ahead", &o->no_surface_ahead, "ignore the surface ahead (the contact plane and the device's friction kept)",
                  "Device");
  command.AddNumber("--jitter-ms", &o->disturbance.jitter_ms, "MS",
                    "each message's one-way delay is longer by U[0, MS] (default 0: no jitter)", "Network", 0.0, 1000.0);
  command.AddNumber("--stall-every-s", &o->disturbance.stall_every_s, "S",
                    "the device's servo thread stalls every S seconds (default 0: never)", "Network", 0.0, 1e3);
  command.AddNumber("--stall-ms", &o->disturbance.stall_ms, "MS", "how long each stall lasts (default 0)", "Network",
                    0.0, 1000.0);
  command.AddOutputDirectory("--output", &o->out_dir, "DIR", "runs directory (default ./network-haptics-offline)",
                  cli::kGroupOutput);
  return command.Parse(argc, argv);
}

// A non-negative number of a list option, or InputError naming the option.
double ListNumber(const std::string& text, const char* option) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !std::isfinite(value) || value < 0) {
    throw InputError(std::string(option) + " expects non-negative numbers, got '" + text + "'");
  }
  return value;
}

int Run(const Options& options) {
  const sim::SceneSpec scene = io::LoadSceneFile(options.scene);
  const sim::TwoBodyModel model(scene);
  const std::vector<Eigen::Vector3d> intent = io::LoadTrajectoryCsv(options.trajectory);
  std::vector<Case> cases;
  for (const std::string& r : Split(options.round_trips, ',')) {
    cases.push_back({static_cast<int>(ListNumber(r, "--round-trips-ms")), 0.0});
  }
  for (const std::string& pair : Split(options.loss_cases, ',')) {
    const std::vector<std::string> parts = Split(pair, ':');
    if (parts.size() != 2) throw InputError("--loss-cases expects ROUND_TRIP_MS:LOSS_PCT pairs, got '" + pair + "'");
    cases.push_back({static_cast<int>(ListNumber(parts[0], "--loss-cases")), ListNumber(parts[1], "--loss-cases")});
  }
  std::vector<std::string> modes = Split(options.modes, ',');
  std::printf("%-10s %-9s %-23s %12s %12s %12s %8s %14s %10s %8s\n", "round trip", "loss", "mode", "min E (J)",
              "dissipated", "surface ticks", "lost", "max excess dF", "ticks >0", "chatter");
  for (const Case& c : cases) {
    char case_name[64];
    std::snprintf(case_name, sizeof(case_name), "rt%03d_loss%04.1f", c.round_trip_ms, c.loss_pct);
    std::string case_dir = options.out_dir + "/" + case_name;
    const Disturbance& d = options.disturbance;
    if (d.jitter_ms > 0 || d.stall_ms > 0) {  // a case of its own beside the undisturbed one
      char suffix[64];
      std::snprintf(suffix, sizeof(suffix), "_jit%04.1f_stall%g-%g", d.jitter_ms, d.stall_ms, d.stall_every_s);
      case_dir += suffix;
    }
    std::filesystem::create_directories(case_dir);
    // round trip, loss, jitter (ms), load (0: no machine here), as scripts/loadtest-network.
    std::ofstream(case_dir + "/case.txt") << c.round_trip_ms << " " << c.loss_pct << " " << d.jitter_ms << " 0\n";
    std::vector<std::string> case_modes = modes;
    if (c.round_trip_ms == 0 && c.loss_pct == 0) case_modes.push_back("direct-repeat");
    for (const std::string& mode : case_modes) {
      phantom::RendererParameters render;
      const std::string name = mode == "direct-repeat" ? "direct" : mode;
      if (!phantom::ParseRendering(name, /*hand_held=*/true, &render)) throw InputError("unknown mode '" + mode + "'");
      render.max_stiffness_n_per_m = options.max_stiffness_n_per_m;
      render.max_damping_n_s_per_m = options.max_damping_n_s_per_m;
      render.surface_ahead = !options.first_version && !options.no_surface_ahead;
      if (options.first_version) render.contact_rendering = phantom::ContactRendering::kLinear;
      const std::string dir = case_dir + "/" + mode;
      std::filesystem::create_directories(dir);
      // The repeat differs from the reference only in its loss draws' seed: with no loss it is
      // the same run (a deterministic loop: the run-to-run floor of the network lab is 0 here).
      const RunSummary s = RunLoop(model, intent, c, options.disturbance, render, dir + "/ticks-nh-1.csv", mode == "direct-repeat" ? 2 : 1);
      std::ofstream summary(dir + "/summary.csv");
      summary << "client,passivity_min_j,server_losses,passivity_dissipated_j,model_ticks,lost_pct,"
                 "max_excess_change_n,excess_change_ticks,chatter_ticks\n"
              << "all," << s.min_energy_j << "," << s.timeouts << "," << s.dissipated_j << "," << s.model_ticks << ","
              << s.lost_pct << "," << s.max_excess_change_n << "," << s.excess_change_ticks << "," << s.chatter_ticks << "\n";
      std::printf("%7d ms %7.1f %% %-23s %12.3g %12.3g %12lu %7.2f%% %12.3f N %10lu %8lu\n", c.round_trip_ms,
                  c.loss_pct, mode.c_str(), s.min_energy_j, s.dissipated_j, s.surface_ticks, s.lost_pct,
                  s.max_excess_change_n, s.excess_change_ticks, s.chatter_ticks);
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("network_haptics_study", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
