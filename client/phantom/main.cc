// hapco-phantom: a simulated haptic device. 1 kHz absolute-time servo tick: device position
// (the scene's trajectory, or a hand dragging the device along it) -> quantised pose ->
// DDS -> newest force (never waiting) -> safety filter -> "motors". Counts missed ticks,
// stale-force ticks and the round trip of each force (client time echoed by the server).
// The device model is hapco_phantom_lib (phantom.h); DDS via hapco::service.
#include <atomic>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/output_file.h"
#include "common/realtime.h"
#include "common/statistics.h"
#include "io/scene_file.h"
#include "io/trajectory_file.h"
#include "phantom.h"
#include "phantom_client.h"
#include "service/dds.h"
#include "service/dds_log.h"

namespace {

constexpr const char* kDescription =
    R"(A simulated haptic device that drives a hapco-server session at 1 kHz: every tick it publishes the device's pose, takes the newest force (never waiting) and renders it through the safety filter. It counts missed ticks, stale-force ticks and the round trip of each force, and prints a summary at the end. Guide: docs/haptic-service.md.)";

constexpr const char* kFooter =
    R"(Safety (every tick): a NaN/Inf force is never rendered (the last good one is kept), the magnitude is clamped to 7.9 N, the change per tick is limited to 0.25 N (250 N/s) plus, with a local model, what a spring of the model stiffness cap (3000 N/m by default) gives for the device's own motion that tick (a wall pushes back as fast as it is entered); after 50 ms without a new force it ramps to zero.
SIGINT/SIGTERM: the run stops, the session is left and the summary printed.
Exit code: 0 done, 1 bad input, 2 no server found, 3 DDS failure.)";

struct Options {
  std::string scene_path, client_id, mode = "kinematic", trajectory = "scene", csv_path, security_dir, server_id;
  std::string render = "auto";
  int domain = 0, rt_priority = 0;
  double max_answer_age_ms = 500;
  double duration_s = 0, timeout_ms = 50, connect_timeout_s = 30, max_model_stiffness_n_per_m = 3000;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco-phantom", "SCENE.txtpb --client-id ID [options]", kDescription, kFooter);
  // Checked below, so that an unknown option is named before a missing scene.
  command.AddScene(&o->scene_path, "scene file (proto/scene.proto): its trajectory and its name, sent in the "
                                   "SESSION_JOIN so that the server opens a session of that scene");
  command.AddText("--client-id", &o->client_id, "ID", "session id, 1..64 of [A-Za-z0-9_.-] (required)", "Device");
  command.AddChoice("--mode", &o->mode, {"kinematic", "hand"},
                    "kinematic (default): tick k publishes exactly the trajectory's step k (no quantisation, so "
                    "forces compare with hapco-sim); hand: a hand (spring-damper, 300 N/m, 6 N s/m) drags a 0.05 kg "
                    "device with 0.5 N s/m damping along the trajectory, pushed back by the rendered force; "
                    "positions quantised to 0.023 mm",
                    "Device");
  command.AddForceTimeout(&o->timeout_ms);
  command.AddMaxAnswerAge(&o->max_answer_age_ms);
  command.AddRendering(&o->render, &o->max_model_stiffness_n_per_m);
  command.AddText("--trajectory", &o->trajectory, "T",
                  "scene (default: the scene's phases, one step per tick) or a CSV file, one row per tick, columns "
                  "x_m,y_m,z_m or dx_m,dy_m,dz_m found by header name (hapco-server --trace, hapco-sim --csv, "
                  "hapco-report --csv)",
                  "Run");
  command.AddDuration(&o->duration_s,
                      "run S seconds, holding the trajectory's last point after its end (default: the "
                      "trajectory's length)");
  command.AddDomain(&o->domain);
  command.AddText("--server-id", &o->server_id, "ID",
                  "be served by this server only (its --server-id); default: the least loaded server serving the "
                  "scene, and another one if it stops answering (docs/several-servers.md)",
                  hapco::cli::kGroupDds);
  command.AddSecurity(&o->security_dir, "DIR/<client id>");
  command.AddConnectTimeout(&o->connect_timeout_s, "wait at most S s for the server (default 30)");
  command.AddCsv(&o->csv_path,
                 "one row per tick (tick, time, pose sequence, position, force sequence, raw force, rendered "
                 "force, round trip, render latency, stale flag, where the force's local model is anchored; "
                 "force sequence -1 = no new force), plus a row per extra force received within the same tick");
  command.AddRtPriority(&o->rt_priority, "the servo tick");
  command.Deprecate("--timeout-ms", "--force-timeout-ms");
  command.Deprecate("--duration", "--duration-s");
  if (!command.Parse(argc, argv)) return false;

  if (o->client_id.empty()) throw hapco::InputError("--client-id is required (see --help)");
  hapco::service::ValidateClientId(o->client_id);
  return true;
}

// Trajectory points 0..N (point 0 = start), m.
std::vector<Eigen::Vector3d> LoadTrajectory(const Options& o, const hapco::sim::SceneSpec& scene) {
  // A trace of several clients gives this device's own rows (its --client-id).
  if (o.trajectory != "scene") return hapco::io::LoadTrajectoryCsv(o.trajectory, o.client_id, /*client_id_if_listed=*/true);
  return scene.DeviceTrajectory();
}

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

void WriteCsvRows(std::FILE* csv, const hapco::phantom::TickRecord& t) {
  // One row per force taken this tick (the last one is rendered), or one row without a force.
  // model_*_m: where the force's local model is anchored (the pose it answered; NaN without a
  // contact model or surface ahead).
  const Eigen::Vector3d none = Eigen::Vector3d::Constant(std::nan(""));
  const auto row = [&](long long force_sequence, const Eigen::Vector3d& raw, double round_trip_us,
                       double render_latency_us, const Eigen::Vector3d& model_at) {
    std::fprintf(csv, "%d,%.6f,%lld,%.12g,%.12g,%.12g,%lld,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.1f,%.1f,%d,%.17g,%.17g,%.17g\n",
                 t.tick, t.time_s, t.published ? static_cast<long long>(t.pose_sequence) : -1LL, t.position_m.x(),
                 t.position_m.y(), t.position_m.z(), force_sequence, raw.x(), raw.y(), raw.z(), t.rendered_force_n.x(),
                 t.rendered_force_n.y(), t.rendered_force_n.z(), round_trip_us, render_latency_us, t.stale ? 1 : 0,
                 model_at.x(), model_at.y(), model_at.z());
  };
  if (t.forces.empty()) {
    row(-1, none, -1.0, -1.0, none);
    return;
  }
  for (const auto& f : t.forces) {
    row(static_cast<long long>(f.pose_sequence), f.force_n, f.round_trip_us(),
        static_cast<double>(t.tick_ns - f.client_time_ns) * 1e-3,
        f.model.valid || f.model.surface_ahead ? f.model.position_m : none);
  }
}

int Run(const Options& o) {
  using namespace hapco;
  const sim::SceneSpec scene = io::LoadSceneFile(o.scene_path);
  phantom::ClientConfig config;
  config.client_id = o.client_id;
  config.domain = o.domain;
  config.security = {o.security_dir, o.client_id};  // disabled without --security
  config.mode = o.mode == "hand" ? phantom::DriveMode::kHand : phantom::DriveMode::kKinematic;
  config.trajectory = LoadTrajectory(o, scene);
  const int trajectory_ticks = static_cast<int>(config.trajectory.size()) - 1;
  config.ticks = o.duration_s > 0 ? static_cast<int>(std::lround(o.duration_s / config.safety.tick_s)) : trajectory_ticks;
  config.scene_name = scene.name;
  config.server_id = o.server_id;
  config.safety.timeout_s = o.timeout_ms * 1e-3;
  config.safety.max_answer_age_s = o.max_answer_age_ms * 1e-3;
  config.connect_timeout_s = o.connect_timeout_s;
  config.drain_ticks = static_cast<int>(std::lround(o.timeout_ms));
  phantom::ParseRendering(o.render, config.mode == phantom::DriveMode::kHand, &config.render);  // a checked choice
  config.render.max_stiffness_n_per_m = o.max_model_stiffness_n_per_m;

  std::FILE* csv = nullptr;
  if (!o.csv_path.empty()) {
    csv = std::fopen(o.csv_path.c_str(), "w");
    if (csv == nullptr) throw InputError("cannot write " + o.csv_path);
    std::fprintf(csv, "tick,time_s,sequence,x_m,y_m,z_m,force_sequence,raw_fx_n,raw_fy_n,raw_fz_n,"
                      "fx_n,fy_n,fz_n,round_trip_us,render_latency_us,stale,model_x_m,model_y_m,model_z_m\n");
  }
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
  hapco::UseRealtimePriority(o.rt_priority, "hapco-phantom");

  // Start-up cost as a user sees it: participant (and, secured, the handshakes), discovery,
  // session, first force (docs/security.md measures it with and without security).
  const int64_t start_ns = MonotonicNowNs();
  phantom::PhantomClient client(config);
  std::string why;
  if (!client.Connect(&why, [&o](const std::string& line) {
        std::fprintf(stderr, "hapco-phantom %s: %s\n", o.client_id.c_str(), line.c_str());
      })) {
    std::fprintf(stderr, "hapco-phantom: %s\n", why.c_str());
    if (csv != nullptr) std::fclose(csv);
    return 2;
  }
  const int64_t connected_ns = MonotonicNowNs();
  std::fprintf(stderr, "hapco-phantom %s: served by %s\n", o.client_id.c_str(),
               client.stats().server_id.empty() ? "the only server (no ServerStatus seen)"
                                                : ("server '" + client.stats().server_id + "'").c_str());
  client.Run(
      g_stop,
      [csv](const phantom::TickRecord& t) {
        if (csv != nullptr) WriteCsvRows(csv, t);
      },
      [&o](const std::string& line) { std::fprintf(stderr, "hapco-phantom %s: %s\n", o.client_id.c_str(), line.c_str()); });
  client.Leave();
  // After the summary: a run whose CSV could not be written still says what it did.
  std::string csv_error;
  try {
    CloseOutputFile(csv, o.csv_path);
  } catch (const InputError& error) {
    csv_error = error.what();
  }

  const phantom::ClientStats& s = client.stats();
  std::printf("hapco-phantom %s: %d ticks, %llu poses, %llu forces received%s\n"
              "  round trip (pose sampled -> force arrived): p50 %.0f us, p99 %.0f us, p99.9 %.0f us, max %.0f us\n"
              "  render latency (pose sampled -> rendering tick): p50 %.0f us, p99 %.0f us; server step+publish p50 %.0f us, p99 %.0f us\n"
              "  missed ticks %llu, stale ticks %llu, force timeouts %llu, resumed %llu, NaN forces %llu, clamped %llu, "
              "peak rendered force %.3f N, pose write errors %llu (sends DDS logged as failed in the network %llu)\n"
              "  served by '%s' at the end, moved to another server %llu times; leases of any server on the domain lapsed %llu, came back %llu\n",
              o.client_id.c_str(), s.ticks_run, static_cast<unsigned long long>(s.poses_published),
              static_cast<unsigned long long>(s.forces_received), g_stop.load() ? " (stopped by signal)" : "",
              hapco::QuantileOf(s.round_trip_us, 0.5), hapco::QuantileOf(s.round_trip_us, 0.99), hapco::QuantileOf(s.round_trip_us, 0.999), hapco::QuantileOf(s.round_trip_us, 1.0),
              hapco::QuantileOf(s.render_latency_us, 0.5), hapco::QuantileOf(s.render_latency_us, 0.99), hapco::QuantileOf(s.server_time_us, 0.5),
              hapco::QuantileOf(s.server_time_us, 0.99), static_cast<unsigned long long>(s.missed_ticks),
              static_cast<unsigned long long>(s.stale_ticks), static_cast<unsigned long long>(s.server_losses),
              static_cast<unsigned long long>(s.resumptions), static_cast<unsigned long long>(s.rejected_non_finite),
              static_cast<unsigned long long>(s.clamped), s.peak_rendered_n,
              static_cast<unsigned long long>(s.pose_write_errors),
              static_cast<unsigned long long>(hapco::service::DdsSendFailuresLogged()), s.server_id.c_str(),
              static_cast<unsigned long long>(s.server_moves),
              static_cast<unsigned long long>(s.server_leases_lapsed),
              static_cast<unsigned long long>(s.server_leases_regained));
  if (s.stale_answers > 0) {
    std::printf("  %llu answers to poses older than %.0f ms (the oldest %.0f ms: after an outage?) not rendered\n",
                static_cast<unsigned long long>(s.stale_answers), o.max_answer_age_ms, s.oldest_stale_answer_s * 1e3);
  }
  if (s.other_device_notices > 0) {
    std::printf("  %llu notices that the server serves another device under the client id '%s' (the one that joined "
                "last): give each device its own --client-id\n",
                static_cast<unsigned long long>(s.other_device_notices), o.client_id.c_str());
  }
  if (s.foreign_forces > 0) {
    std::printf("  %llu forces for poses this device never sent, not rendered: another device uses the client id "
                "'%s'? Give each device its own --client-id\n",
                static_cast<unsigned long long>(s.foreign_forces), o.client_id.c_str());
  }
  if (config.render.mode == phantom::RenderMode::kLocalModel || config.render.passivity) {
    std::printf("  rendering %s: %llu ticks from a contact model, %llu from the surface ahead (%llu models; stiffness "
                "capped %llu, extrapolation capped %llu ticks, pull prevented %llu, friction cone %llu)\n",
                phantom::RenderingName(config.render).c_str(), static_cast<unsigned long long>(s.render.model_ticks),
                static_cast<unsigned long long>(s.render.surface_ticks),
                static_cast<unsigned long long>(s.render.models_received),
                static_cast<unsigned long long>(s.render.stiffness_capped),
                static_cast<unsigned long long>(s.render.extrapolation_capped),
                static_cast<unsigned long long>(s.render.pull_prevented), static_cast<unsigned long long>(s.render.cone_limited));
  }
  if (config.render.passivity) {
    // E: the energy the device's rendered forces took from the hand, J (passive: >= 0, or
    // within the dead band with a local model; passivity.h).
    std::printf("  passivity: E min %.3g J, final %.3g J; the damper asked for %.4f J on %lld ticks, %.4f J of debt "
                "forgiven\n",
                s.passivity_min_energy_j, s.passivity_final_energy_j, s.passivity_dissipated_j,
                static_cast<long long>(s.passivity_active_ticks), s.passivity_forgiven_j);
  }
  if (s.first_force_arrival_ns >= 0) {
    std::printf("  start-up: connected after %.3f s, first force %.3f s after start\n",
                static_cast<double>(connected_ns - start_ns) * 1e-9,
                static_cast<double>(s.first_force_arrival_ns - start_ns) * 1e-9);
  }
  if (!csv_error.empty()) {
    std::fprintf(stderr, "hapco-phantom: %s\n", csv_error.c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-phantom", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
