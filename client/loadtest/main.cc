// hapco-loadtest: N emulated PHANToM clients (one thread and one DDS participant each,
// PhantomClient) against a running hapco-server, with staggered starts. Measures the round
// trip, missed ticks, stale forces, force stability (tracking error, high-frequency content,
// passivity observer) and reads the server's step times and CPU use from ServerStatus.
// Definitions: docs/load-and-network.md.
#include <csignal>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <latch>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/memory.h"
#include "common/realtime.h"
#include "common/statistics.h"
#include "io/scene_file.h"
#include "io/trajectory_file.h"
#include "loadtest_metrics.h"
#include "phantom.h"
#include "phantom_client.h"
#include "service/dds.h"

namespace {

constexpr const char* kDescription =
    R"(Runs N emulated PHANToM devices (one thread and one DDS participant each, client ids P-1..P-N) against a running hapco-server for S seconds each, at 1 kHz, and reports per client and in total: round trip (pose sampled -> force arrived) p50/p99/p99.9/max, missed servo ticks, poses never answered, stale-force ticks, force stability (tracking error against the server's force for the same pose, high-frequency ratio, passivity-observer energy) and the server's step times and CPU use (ServerStatus). Definitions: docs/load-and-network.md.)";

constexpr const char* kFooter =
    R"(Progress on stderr about once a second (unless --quiet): elapsed time, clients running, forces/s received, missed ticks in the last second, the server's sessions, pose received to answered p99 (queueing included) and CPU (latest status).
Exit code: 0 when it ran (also if it measured misses), 1 bad input, 2 no server found (no client connected), 3 DDS failure.)";

struct Options {
  std::string scene_path, mode = "kinematic", prefix = "lt", csv_dir, security_dir, render = "auto";
  std::string trajectory = "scene";
  int clients = 0, domain = 0, rt_priority = 0;
  double max_answer_age_ms = 500;
  double duration_s = 0, stagger_ms = 100, timeout_ms = 50, connect_timeout_s = 30, max_model_stiffness_n_per_m = 3000;
  bool loop = false, plots = false, quiet = false;
  hapco::phantom::RendererParameters rendering;  // --render resolved (auto -> by --mode)
};

// "out", "out/" and "./out" are the same directory.
bool SameDirectory(const std::string& a, const std::string& b) {
  const auto normal = [](const std::string& path) {
    std::error_code error;
    return std::filesystem::absolute(std::filesystem::path(path) / ".", error).lexically_normal();
  };
  return normal(a) == normal(b);
}

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco-loadtest", "SCENE.txtpb --clients N --duration-s S [options]", kDescription,
                                  kFooter);
  // Checked below: an old `--plots SCENE` may have taken the scene as its value, and an unknown
  // option is named before a missing scene.
  command.AddScene(&o->scene_path, "scene file the server runs (proto/scene.proto): every client follows its "
                                   "trajectory and joins a session of its name")
      ->required(false);
  command.AddInteger("--clients", &o->clients, "N", "emulated devices, 1..100 (required)", "Run", 1, 100);
  command.AddDuration(&o->duration_s, "seconds each client runs (required)");
  // (1e9 was taken and the run waited for a client due in 11 days.)
  command.AddNumber("--stagger-ms", &o->stagger_ms, "M",
                    "client i starts i*M ms after client 0, at most 60000 (default 100)", "Run", 0, 60000);
  command.AddText("--trajectory", &o->trajectory, "T",
                  "scene (default: the scene's phases, one step per tick) or a CSV file, one row per tick, columns "
                  "x_m,y_m,z_m or dx_m,dy_m,dz_m found by header name (as hapco-phantom --trajectory)",
                  "Run");
  command.AddFlag("--trajectory-loop", &o->loop,
                  "go back and forth along the scene's trajectory for the whole run (default: run it once, then "
                  "hold its last point)",
                  "Run");
  command.AddChoice("--mode", &o->mode, {"kinematic", "hand"},
                    "kinematic (default): the device follows the trajectory exactly; hand: a hand model drags the "
                    "device (hapco-phantom --help)",
                    "Device");
  command.AddForceTimeout(&o->timeout_ms);
  command.AddMaxAnswerAge(&o->max_answer_age_ms);
  command.AddRendering(&o->render, &o->max_model_stiffness_n_per_m);
  command.AddDomain(&o->domain);
  command.AddSecurity(&o->security_dir,
                      "DIR/loadtest-<prefix>, one identity for every client and the status view (scripts/dds-security "
                      "add-load-tester DIR PREFIX)");
  command.AddText("--client-prefix", &o->prefix, "P", "client ids P-1..P-N (default lt)", hapco::cli::kGroupDds);
  command.AddConnectTimeout(&o->connect_timeout_s, "wait at most S s for the server (default 30)");
  CLI::Option* csv_dir = command.AddOutputDirectory("--csv-dir", &o->csv_dir, "DIR",
                  "write DIR/summary.csv (one row per client + \"all\"), DIR/ticks-ID.csv (one row per tick), "
                  "DIR/roundtrip.csv (every force's round trip)",
                  hapco::cli::kGroupOutput);
  std::string plots_dir;
  CLI::Option* plots = command.AddOutputDirectory("--plots", &plots_dir, "DIR",
                                       "write the CSVs (those of --csv-dir) and their charts "
                                       "(roundtrip-cdf.png, forces.png) to DIR, via scripts/plot_loadtest.py "
                                       "(needs /usr/bin/python3 with matplotlib)",
                                       hapco::cli::kGroupOutput);
  plots->expected(0, 1);  // the old form `--csv-dir DIR --plots` had no value
  command.WritesInto(csv_dir, {"summary.csv", "ticks-*.csv", "roundtrip.csv"});
  command.WritesInto(plots, {"summary.csv", "ticks-*.csv", "roundtrip.csv", "*.png"});
  command.AddRtPriority(&o->rt_priority, "the clients");
  command.AddQuiet(&o->quiet, "no progress line (the results are still printed)");
  command.Deprecate("--timeout-ms", "--force-timeout-ms");
  command.Deprecate("--duration", "--duration-s");
  if (!command.Parse(argc, argv)) return false;
  hapco::phantom::ParseRendering(o->render, o->mode == "hand", &o->rendering);  // a checked choice
  o->rendering.max_stiffness_n_per_m = o->max_model_stiffness_n_per_m;

  if (plots->count() > 0) {
    std::error_code error;
    if (!plots_dir.empty() && std::filesystem::is_regular_file(plots_dir, error)) {
      // `--plots SCENE.txtpb ...`: the old valueless --plots before the scene argument.
      if (!o->scene_path.empty()) throw hapco::InputError("--plots expects a directory, got the file '" + plots_dir + "'");
      o->scene_path = plots_dir;
      plots_dir.clear();
    }
    if (plots_dir.empty()) {
      if (o->csv_dir.empty()) throw hapco::InputError("--plots needs a directory: --plots DIR (see --help)");
      std::fprintf(stderr, "hapco-loadtest: note: --plots without a directory is deprecated, use --plots DIR\n");
    } else if (o->csv_dir.empty()) {
      o->csv_dir = plots_dir;
    } else if (!SameDirectory(o->csv_dir, plots_dir)) {
      throw hapco::InputError("--plots " + plots_dir + " and --csv-dir " + o->csv_dir +
                              " name different directories: the charts are drawn from the CSVs in their own "
                              "directory (--plots DIR writes both)");
    }
    o->plots = true;
  }
  if (o->scene_path.empty()) throw hapco::InputError("missing SCENE argument (see --help)");
  if (o->clients == 0) throw hapco::InputError("--clients is required (see --help)");
  if (o->duration_s == 0) throw hapco::InputError("--duration-s is required (see --help)");
  // The longest id must still be valid (1..64 of [A-Za-z0-9_.-]).
  hapco::service::ValidateClientId(o->prefix + "-" + std::to_string(o->clients));
  return true;
}

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

double SecondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// ServerStatus samples, each stamped on arrival (steady clock).
struct StatusSample {
  double arrival_s = 0;  // since the load test started
  hapco_idl_ServerStatus status{};
};

// Reads "hapco/status" in its own participant and thread until stopped.
class StatusMonitor {
 public:
  StatusMonitor(int domain, const hapco::service::SecurityIdentity& identity, std::chrono::steady_clock::time_point t0)
      : t0_(t0), participant_(domain, identity), topic_(participant_), subscriber_(participant_), reader_(subscriber_, topic_) {
    thread_ = std::thread([this] { Loop(); });
  }
  ~StatusMonitor() { Stop(); }
  void Stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
  }
  std::vector<StatusSample> samples() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return samples_;
  }
  bool latest(StatusSample* out) const {
    std::lock_guard<std::mutex> lock(mutex_);
    if (samples_.empty()) return false;
    *out = samples_.back();
    return true;
  }

 private:
  void Loop() {
    while (!stop_.load()) {
      if (!reader_.WaitForData(DDS_MSECS(100))) continue;
      StatusSample s;
      while (reader_.Take(&s.status)) {
        s.arrival_s = SecondsSince(t0_);
        std::lock_guard<std::mutex> lock(mutex_);
        samples_.push_back(s);
      }
    }
  }
  std::chrono::steady_clock::time_point t0_;
  hapco::service::Participant participant_;
  hapco::service::Topic<hapco_idl_ServerStatus> topic_;
  hapco::service::Subscriber subscriber_;
  hapco::service::Reader<hapco_idl_ServerStatus> reader_;
  mutable std::mutex mutex_;
  std::vector<StatusSample> samples_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

struct ClientRun {
  std::string id;
  std::unique_ptr<hapco::phantom::PhantomClient> client;
  std::unique_ptr<hapco::loadtest::ClientRecorder> recorder;
  std::atomic<int> state{0};  // 0 connecting, 1 connected, 2 running, 3 done, -1 no server
  std::string why;
  double start_s = 0, end_s = 0;  // since the load test started
};

// One row of the summary (a client, or "all").
struct Row {
  std::string client;
  int ticks_run = 0;
  uint64_t poses = 0, forces = 0, reordered = 0, missed = 0, stale = 0, losses = 0, resumptions = 0;
  uint64_t non_finite_received = 0, clamped = 0, overflowed = 0;
  double rt_p50 = 0, rt_p99 = 0, rt_p999 = 0, rt_max = 0, render_p50 = 0, render_p99 = 0;
  hapco::loadtest::StabilityMetrics stability;
  double passivity_min_j = 0, passivity_final_j = 0, passivity_max_drop_j = 0;
  double dissipated_j = 0;     // by the client's passivity controller (--passivity), J
  uint64_t model_ticks = 0;    // ticks rendered from a local model (--render local-model)
  double tracking_sum = 0, d2r_sum = 0, d2s_sum = 0;  // for pooling
};

// Ticks the client should have run: published ones plus those missed.
double MissedPct(const Row& r) {
  const double scheduled = static_cast<double>(r.ticks_run) + static_cast<double>(r.missed);
  return scheduled > 0 ? 100.0 * static_cast<double>(r.missed) / scheduled : 0.0;
}
// Lost end to end: the tick never ran, or its pose never got a force back.
double LostPct(const Row& r) {
  const double scheduled = static_cast<double>(r.poses) + static_cast<double>(r.missed);
  return scheduled > 0 ? 100.0 * static_cast<double>(r.missed + r.stability.unanswered_poses) / scheduled : 0.0;
}

struct ServerSummary {
  int periods = 0;
  double step_p50_us = 0, step_p99_us = 0, step_max_us = 0, cpu_use = 0;
  // Mean per stepped pose over the periods (ServerStatus): physics, local model, force write,
  // contact frame, us.
  double physics_us = 0, model_us = 0, force_write_us = 0, frame_us = 0;
  unsigned sessions_max = 0;
  uint64_t steps = 0, superseded = 0, non_finite = 0;
};

ServerSummary SummarizeServer(const std::vector<StatusSample>& all, double window_begin_s, double window_end_s) {
  std::vector<const StatusSample*> in;
  for (const auto& s : all) {
    if (s.arrival_s >= window_begin_s && s.arrival_s <= window_end_s) in.push_back(&s);
  }
  if (in.empty()) {  // short runs: every status with a session open
    for (const auto& s : all) {
      if (s.status.sessions > 0) in.push_back(&s);
    }
  }
  ServerSummary out;
  out.periods = static_cast<int>(in.size());
  if (in.empty()) return out;
  std::vector<double> p50, p99;
  for (const auto* s : in) {
    p50.push_back(s->status.step_time_p50_us);
    p99.push_back(s->status.step_time_p99_us);
    out.step_max_us = std::max(out.step_max_us, s->status.step_time_max_us);
    out.cpu_use += s->status.cpu_use;
    out.physics_us += s->status.physics_mean_us;
    out.model_us += s->status.model_mean_us;
    out.force_write_us += s->status.force_write_mean_us;
    out.frame_us += s->status.frame_mean_us;
    out.sessions_max = std::max(out.sessions_max, static_cast<unsigned>(s->status.sessions));
  }
  out.step_p50_us = hapco::QuantileOf(p50, 0.5);
  out.step_p99_us = hapco::QuantileOf(p99, 0.5);
  out.cpu_use /= static_cast<double>(in.size());
  out.physics_us /= static_cast<double>(in.size());
  out.model_us /= static_cast<double>(in.size());
  out.force_write_us /= static_cast<double>(in.size());
  out.frame_us /= static_cast<double>(in.size());
  out.steps = in.back()->status.steps - in.front()->status.steps;
  out.superseded = in.back()->status.superseded - in.front()->status.superseded;
  out.non_finite = in.back()->status.non_finite_forces - in.front()->status.non_finite_forces;
  return out;
}

std::FILE* OpenCsv(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw hapco::InputError("cannot write " + path + " (is the --csv-dir / --plots directory writable?)");
  return f;
}

void WriteTicksCsv(const std::string& path, const hapco::loadtest::ClientRecorder& rec,
                   const hapco::loadtest::PassivityMetrics& passivity) {
  std::FILE* f = OpenCsv(path);
  // Positions and rendered forces at full precision: tests recheck limits and energy from them.
  std::fprintf(f, "tick,time_s,published,missed_before,x_m,y_m,z_m,vx_m_per_s,vy_m_per_s,vz_m_per_s,forces_taken,"
                  "force_sequence,round_trip_us,raw_fx_n,raw_fy_n,raw_fz_n,server_fx_n,server_fy_n,server_fz_n,"
                  "fx_n,fy_n,fz_n,stale,energy_j\n");
  const auto& server = rec.server_forces();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < rec.ticks().size(); ++i) {
    const auto& t = rec.ticks()[i];
    // The server's force for this tick's own pose (NaN: not published or never answered).
    Eigen::Vector3d s = Eigen::Vector3d::Constant(nan);
    const auto p = static_cast<std::size_t>(t.tick);
    if (t.published && p < server.size() && server[p].received) s = server[p].force_n;
    std::fprintf(f, "%d,%.9f,%d,%d,%.17g,%.17g,%.17g,%.6g,%.6g,%.6g,%d,%lld,%.1f,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.17g,%.17g,%.17g,%d,%.9g\n",
                 t.tick, t.time_s, t.published ? 1 : 0, t.missed_before, t.position_m.x(), t.position_m.y(),
                 t.position_m.z(), t.velocity_m_per_s.x(), t.velocity_m_per_s.y(), t.velocity_m_per_s.z(),
                 t.forces_taken, static_cast<long long>(t.force_sequence), t.round_trip_us, t.raw_force_n.x(),
                 t.raw_force_n.y(), t.raw_force_n.z(), s.x(), s.y(), s.z(), t.rendered_force_n.x(),
                 t.rendered_force_n.y(), t.rendered_force_n.z(), t.stale ? 1 : 0, passivity.energy_j[i]);
  }
  std::fclose(f);
}

constexpr const char* kSummaryHeader =
    "client,clients,mode,duration_s,timeout_ms,ticks_run,poses,forces,forces_reordered,missed_ticks,missed_pct,"
    "unanswered_poses,lost_pct,ticks_without_fresh_force,stale_ticks,server_losses,resumptions,non_finite_received,"
    "clamped,arrivals_overflowed,non_finite_rendered,peak_rendered_n,max_change_per_tick_n,rt_p50_us,rt_p99_us,"
    "rt_p999_us,rt_max_us,render_p50_us,render_p99_us,tracking_rms_n,server_rms_n,d2_rendered_ms_n2,"
    "d2_server_ms_n2,hf_ratio,passivity_min_j,passivity_final_j,passivity_max_drop_j,passivity_violated,"
    "server_step_p50_us,server_step_p99_us,server_step_max_us,server_cpu,server_status_periods,server_sessions_max,"
    "server_superseded,render,passivity_controller,passivity_dissipated_j,model_ticks,server_physics_us,"
    "server_model_us,server_force_write_us,server_frame_us\n";

void WriteSummaryRow(std::FILE* f, const Row& r, const Options& o, const ServerSummary& s, double tolerance_j) {
  const auto& st = r.stability;
  std::fprintf(f,
               "%s,%d,%s,%g,%g,%d,%llu,%llu,%llu,%llu,%.4f,%llu,%.4f,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%.6f,%.6f,"
               "%.1f,%.1f,%.1f,%.1f,%.1f,%.1f,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%.1f,%.1f,%.1f,%.3f,%d,%u,%llu,"
               "%s,%d,%.6g,%llu,%.1f,%.1f,%.1f,%.1f\n",
               r.client.c_str(), o.clients, o.mode.c_str(), o.duration_s, o.timeout_ms, r.ticks_run,
               static_cast<unsigned long long>(r.poses), static_cast<unsigned long long>(r.forces),
               static_cast<unsigned long long>(r.reordered), static_cast<unsigned long long>(r.missed), MissedPct(r),
               static_cast<unsigned long long>(st.unanswered_poses), LostPct(r),
               static_cast<unsigned long long>(st.ticks_without_fresh_force), static_cast<unsigned long long>(r.stale),
               static_cast<unsigned long long>(r.losses), static_cast<unsigned long long>(r.resumptions),
               static_cast<unsigned long long>(r.non_finite_received), static_cast<unsigned long long>(r.clamped),
               static_cast<unsigned long long>(r.overflowed), static_cast<unsigned long long>(st.non_finite_rendered),
               st.max_rendered_n, st.max_change_per_tick_n, r.rt_p50, r.rt_p99, r.rt_p999, r.rt_max, r.render_p50,
               r.render_p99, std::sqrt(st.tracking_ms_n2), std::sqrt(st.server_ms_n2), st.d2_rendered_ms_n2,
               st.d2_server_ms_n2, st.hf_ratio, r.passivity_min_j, r.passivity_final_j, r.passivity_max_drop_j,
               r.passivity_min_j < -tolerance_j ? 1 : 0, s.step_p50_us, s.step_p99_us, s.step_max_us, s.cpu_use,
               s.periods, s.sessions_max, static_cast<unsigned long long>(s.superseded),
               hapco::phantom::RenderingName(o.rendering).c_str(), o.rendering.passivity ? 1 : 0, r.dissipated_j,
               static_cast<unsigned long long>(r.model_ticks), s.physics_us, s.model_us, s.force_write_us, s.frame_us);
}

void PrintRow(const Row& r) {
  const auto& st = r.stability;
  std::printf("%-10s rt p50 %6.0f p99 %6.0f p99.9 %6.0f max %7.0f us | missed %llu (%.2f%%) lost %.2f%% stale %llu "
              "timeouts %llu | track rms %.3f N hf %.2f | E min %.2e J final %.2e J\n",
              r.client.c_str(), r.rt_p50, r.rt_p99, r.rt_p999, r.rt_max, static_cast<unsigned long long>(r.missed),
              MissedPct(r), LostPct(r), static_cast<unsigned long long>(r.stale),
              static_cast<unsigned long long>(r.losses), std::sqrt(st.tracking_ms_n2), st.hf_ratio, r.passivity_min_j,
              r.passivity_final_j);
}

// Passivity tolerance, J: E may dip this far below 0 without calling it a violation. 1e-4 J
// is ~1 % of the elastic energy one 3 mm press of benchmark 1 stores (1/2 x 5 N x 3 mm =
// 7.5 mJ): smaller dips are the observer's sampling error, not energy the link creates
// (docs/load-and-network.md, "Force stability").
constexpr double kPassivityToleranceJ = 1e-4;

int Run(const Options& o) {
  using namespace hapco;
  const auto t0 = std::chrono::steady_clock::now();
  const sim::SceneSpec scene = io::LoadSceneFile(o.scene_path);
  const std::vector<Eigen::Vector3d> points =
      o.trajectory == "scene" ? scene.DeviceTrajectory() : io::LoadTrajectoryCsv(o.trajectory);

  phantom::ClientConfig base;
  base.domain = o.domain;
  base.mode = o.mode == "hand" ? phantom::DriveMode::kHand : phantom::DriveMode::kKinematic;
  base.ticks = static_cast<int>(std::lround(o.duration_s / base.safety.tick_s));
  base.trajectory = o.loop ? loadtest::LoopTrajectory(points, base.ticks) : points;
  base.scene_name = scene.name;
  base.safety.timeout_s = o.timeout_ms * 1e-3;
  base.safety.max_answer_age_s = o.max_answer_age_ms * 1e-3;
  base.connect_timeout_s = o.connect_timeout_s;
  base.drain_ticks = static_cast<int>(std::lround(o.timeout_ms));
  base.render = o.rendering;
  const double tick_s = base.safety.tick_s;
  {
    // Every tick of every client is kept (allocated up front: nothing allocates at 1 kHz), so a
    // long run must fit: --duration-s 1e6 ran out of memory, 1e5 took 3.2 GB before a server was
    // found (a helper session). Samples of the loadtest and the phantom, per tick and client.
    const double ticks = static_cast<double>(base.ticks + base.drain_ticks + 16);
    const double bytes = static_cast<double>(o.clients) * ticks *
                         static_cast<double>(loadtest::ClientRecorder::kBytesPerTick + 3 * sizeof(double));
    const std::optional<std::size_t> available = AvailableMemoryBytes();
    if (available && bytes > 0.5 * static_cast<double>(*available)) {
      char message[320];
      std::snprintf(message, sizeof(message),
                    "--duration-s %g with %d clients keeps %.1f GiB of per-tick samples, more than half of the "
                    "%.1f GiB this machine has available: run shorter or with fewer clients",
                    o.duration_s, o.clients, bytes / (1 << 30), static_cast<double>(*available) / (1 << 30));
      throw InputError(message);
    }
  }

  if (!o.csv_dir.empty()) std::filesystem::create_directories(o.csv_dir);
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
  // Before the first participant: Cyclone's threads inherit the policy (realtime.h).
  UseRealtimePriority(o.rt_priority, "hapco-loadtest");

  // Secured: every participant of this process runs as one identity, loadtest-<prefix>
  // (Cyclone 0.10.2 checks all secured participants of a process against one participant's
  // permissions; docs/security.md).
  const hapco::service::SecurityIdentity identity{o.security_dir, "loadtest-" + o.prefix};  // disabled without --security
  StatusMonitor status(o.domain, identity, t0);
  std::vector<std::unique_ptr<ClientRun>> runs;
  for (int i = 1; i <= o.clients; ++i) {
    auto run = std::make_unique<ClientRun>();
    run->id = o.prefix + "-" + std::to_string(i);
    phantom::ClientConfig config = base;
    config.client_id = run->id;
    config.security = identity;
    run->client = std::make_unique<phantom::PhantomClient>(std::move(config));
    run->recorder = std::make_unique<loadtest::ClientRecorder>(base.ticks + base.drain_ticks + 16);
    runs.push_back(std::move(run));
  }

  // Connect all, then start client i at start + i * stagger.
  std::latch connected(o.clients);  // every client has connected (or given up)
  std::latch go(1);                  // start_s is set
  std::atomic<double> start_s{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < o.clients; ++i) {
    threads.emplace_back([&, i] {
      ClientRun& r = *runs[static_cast<std::size_t>(i)];
      const bool ok = r.client->Connect(&r.why);
      r.state.store(ok ? 1 : -1);
      connected.count_down();
      go.wait();
      if (!ok || g_stop.load()) return;
      const auto begin = t0 + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                  std::chrono::duration<double>(start_s.load() + i * o.stagger_ms * 1e-3));
      while (std::chrono::steady_clock::now() < begin && !g_stop.load()) {
        std::this_thread::sleep_until(std::min(begin, std::chrono::steady_clock::now() + std::chrono::milliseconds(50)));
      }
      r.start_s = SecondsSince(t0);
      r.state.store(2);
      r.client->Run(
          g_stop, [&r](const phantom::TickRecord& t) { r.recorder->OnTick(t); },
          [&r](const std::string& line) { std::fprintf(stderr, "hapco-loadtest %s: %s\n", r.id.c_str(), line.c_str()); });
      r.end_s = SecondsSince(t0);
      r.client->Leave();
      r.state.store(3);
    });
  }
  // The start time is only known once everyone has connected.
  connected.wait();
  start_s.store(SecondsSince(t0) + 0.05);
  go.count_down();

  // Progress about once a second until every client is done.
  uint64_t last_forces = 0, last_missed = 0;
  double last_t = SecondsSince(t0);
  for (;;) {
    int done = 0, running = 0, failed = 0;
    for (const auto& r : runs) {
      const int s = r->state.load();
      done += (s == 3 || s == -1) ? 1 : 0;
      running += s == 2 ? 1 : 0;
      failed += s == -1 ? 1 : 0;
    }
    if (done == o.clients) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const double now = SecondsSince(t0);
    if (now - last_t < 1.0) continue;
    uint64_t forces = 0, missed = 0;
    for (const auto& r : runs) {
      forces += r->recorder->progress_forces.load();
      missed += r->recorder->progress_missed.load();
    }
    if (!o.quiet) {
      StatusSample latest;
      char server[160] = "server: no status yet";
      if (status.latest(&latest)) {
        std::snprintf(server, sizeof(server), "server: %u sessions, pose-to-answer p99 %.0f us, cpu %.2f",
                      static_cast<unsigned>(latest.status.sessions), latest.status.step_time_p99_us,
                      latest.status.cpu_use);
      }
      std::fprintf(stderr, "hapco-loadtest: t %5.1f s | clients %d running, %d done, %d failed of %d | %6.0f forces/s | "
                           "missed %llu in the last %.1f s | %s\n",
                   now, running, done - failed, failed, o.clients,
                   static_cast<double>(forces - last_forces) / (now - last_t),
                   static_cast<unsigned long long>(missed - last_missed), now - last_t, server);
    }
    last_forces = forces;
    last_missed = missed;
    last_t = now;
  }
  for (auto& t : threads) t.join();
  status.Stop();

  // Results.
  std::vector<const ClientRun*> ran;
  for (const auto& r : runs) {
    if (r->state.load() == 3) ran.push_back(r.get());
    if (r->state.load() == -1) std::fprintf(stderr, "hapco-loadtest %s: %s\n", r->id.c_str(), r->why.c_str());
  }
  if (ran.empty()) {
    std::fprintf(stderr, "hapco-loadtest: no client connected\n");
    return 2;
  }
  double all_started = 0, first_done = std::numeric_limits<double>::infinity();
  for (const auto* r : ran) {
    all_started = std::max(all_started, r->start_s);
    first_done = std::min(first_done, r->end_s);
  }
  // Status periods that lie wholly inside the time when every client ran (a status covers
  // the period before its arrival; the default period is 1 s).
  const ServerSummary server = SummarizeServer(status.samples(), all_started + 1.05, first_done);

  Row all;
  all.client = "all";
  std::vector<double> all_rt, all_render;
  std::vector<Row> rows;
  double tracking_sum = 0, server_sq_sum = 0, d2r_sum = 0, d2s_sum = 0;
  std::FILE* rt_csv = nullptr;
  if (!o.csv_dir.empty()) {
    rt_csv = OpenCsv(o.csv_dir + "/roundtrip.csv");
    std::fprintf(rt_csv, "client,round_trip_us\n");
  }
  for (const auto* r : ran) {
    const phantom::ClientStats& s = r->client->stats();
    Row row;
    row.client = r->id;
    row.ticks_run = s.ticks_run;
    row.poses = s.poses_published;
    row.forces = s.forces_received;
    row.reordered = s.forces_reordered;
    row.missed = s.missed_ticks;
    row.stale = s.stale_ticks;
    row.losses = s.server_losses;
    row.resumptions = s.resumptions;
    row.non_finite_received = s.rejected_non_finite;
    row.clamped = s.clamped;
    row.overflowed = s.arrivals_overflowed;
    row.rt_p50 = hapco::QuantileOf(s.round_trip_us, 0.5);
    row.rt_p99 = hapco::QuantileOf(s.round_trip_us, 0.99);
    row.rt_p999 = hapco::QuantileOf(s.round_trip_us, 0.999);
    row.rt_max = hapco::QuantileOf(s.round_trip_us, 1.0);
    row.render_p50 = hapco::QuantileOf(s.render_latency_us, 0.5);
    row.render_p99 = hapco::QuantileOf(s.render_latency_us, 0.99);
    row.stability = loadtest::ComputeStability(r->recorder->ticks(), r->recorder->server_forces(),
                                               base.safety.max_force_n);
    const loadtest::PassivityMetrics passivity = loadtest::ComputePassivity(r->recorder->ticks(), tick_s);
    row.passivity_min_j = passivity.min_energy_j;
    row.passivity_final_j = passivity.final_energy_j;
    row.passivity_max_drop_j = passivity.max_drop_j;
    row.dissipated_j = s.passivity_dissipated_j;
    row.model_ticks = s.render.model_ticks;
    rows.push_back(row);
    if (!o.csv_dir.empty()) {
      WriteTicksCsv(o.csv_dir + "/ticks-" + r->id + ".csv", *r->recorder, passivity);
      for (double v : s.round_trip_us) std::fprintf(rt_csv, "%s,%.1f\n", r->id.c_str(), v);
    }

    all_rt.insert(all_rt.end(), s.round_trip_us.begin(), s.round_trip_us.end());
    all_render.insert(all_render.end(), s.render_latency_us.begin(), s.render_latency_us.end());
    all.ticks_run += row.ticks_run;
    all.poses += row.poses;
    all.forces += row.forces;
    all.reordered += row.reordered;
    all.missed += row.missed;
    all.stale += row.stale;
    all.losses += row.losses;
    all.resumptions += row.resumptions;
    all.non_finite_received += row.non_finite_received;
    all.clamped += row.clamped;
    all.overflowed += row.overflowed;
    auto& a = all.stability;
    const auto& b = row.stability;
    a.compared_ticks += b.compared_ticks;
    a.unanswered_poses += b.unanswered_poses;
    a.ticks_without_fresh_force += b.ticks_without_fresh_force;
    a.non_finite_rendered += b.non_finite_rendered;
    a.max_rendered_n = std::max(a.max_rendered_n, b.max_rendered_n);
    a.max_change_per_tick_n = std::max(a.max_change_per_tick_n, b.max_change_per_tick_n);
    a.d2_rendered_count += b.d2_rendered_count;
    a.d2_server_count += b.d2_server_count;
    tracking_sum += b.tracking_ms_n2 * static_cast<double>(b.compared_ticks);
    server_sq_sum += b.server_ms_n2 * static_cast<double>(b.compared_ticks);
    d2r_sum += b.d2_rendered_ms_n2 * static_cast<double>(b.d2_rendered_count);
    d2s_sum += b.d2_server_ms_n2 * static_cast<double>(b.d2_server_count);
    all.passivity_min_j = std::min(all.passivity_min_j, row.passivity_min_j);
    all.passivity_final_j = rows.size() == 1 ? row.passivity_final_j : std::min(all.passivity_final_j, row.passivity_final_j);
    all.passivity_max_drop_j = std::max(all.passivity_max_drop_j, row.passivity_max_drop_j);
    all.dissipated_j += row.dissipated_j;
    all.model_ticks += row.model_ticks;
  }
  if (rt_csv != nullptr) std::fclose(rt_csv);
  {
    auto& a = all.stability;
    if (a.compared_ticks > 0) {
      a.tracking_ms_n2 = tracking_sum / static_cast<double>(a.compared_ticks);
      a.server_ms_n2 = server_sq_sum / static_cast<double>(a.compared_ticks);
    }
    if (a.d2_rendered_count > 0) a.d2_rendered_ms_n2 = d2r_sum / static_cast<double>(a.d2_rendered_count);
    if (a.d2_server_count > 0) a.d2_server_ms_n2 = d2s_sum / static_cast<double>(a.d2_server_count);
    if (a.d2_server_ms_n2 > 0) a.hf_ratio = a.d2_rendered_ms_n2 / a.d2_server_ms_n2;
  }
  all.rt_p50 = hapco::QuantileOf(all_rt, 0.5);
  all.rt_p99 = hapco::QuantileOf(all_rt, 0.99);
  all.rt_p999 = hapco::QuantileOf(all_rt, 0.999);
  all.rt_max = hapco::QuantileOf(all_rt, 1.0);
  all.render_p50 = hapco::QuantileOf(all_render, 0.5);
  all.render_p99 = hapco::QuantileOf(all_render, 0.99);

  if (g_stop.load()) {
    // What each client really ran (a signal during the stagger left clients that never started,
    // and the line said "2 of 2 clients ran 2.0 s each"; a helper session).
    double shortest_s = HUGE_VAL, longest_s = 0.0;
    int not_started = 0;
    for (const ClientRun* r : ran) {
      const double ran_s = static_cast<double>(r->recorder->progress_ticks.load()) * tick_s;
      if (ran_s <= 0.0) {
        ++not_started;
        continue;
      }
      shortest_s = std::min(shortest_s, ran_s);
      longest_s = std::max(longest_s, ran_s);
    }
    std::printf("hapco-loadtest: stopped by signal: %zu of %d clients ran %.1f-%.1f s of %.1f s, %d had not started "
                "(%s, render %s%s)\n",
                ran.size() - static_cast<std::size_t>(not_started), o.clients, not_started == static_cast<int>(ran.size()) ? 0.0 : shortest_s,
                longest_s, o.duration_s, not_started + (o.clients - static_cast<int>(ran.size())), o.mode.c_str(),
                phantom::RenderingName(o.rendering).c_str(), o.loop ? ", trajectory looped" : "");
  } else {
    std::printf("hapco-loadtest: %zu of %d clients ran %.1f s each (%s, render %s%s)\n", ran.size(), o.clients,
                o.duration_s, o.mode.c_str(), phantom::RenderingName(o.rendering).c_str(),
                o.loop ? ", trajectory looped" : "");
  }
  if (o.rendering.mode == phantom::RenderMode::kLocalModel || o.rendering.passivity) {
    std::printf("rendering: %llu ticks from a local model; passivity controller dissipated %.4f J\n",
                static_cast<unsigned long long>(all.model_ticks), all.dissipated_j);
  }
  uint64_t old_answers = 0;
  for (const auto* r : ran) old_answers += r->client->stats().stale_answers;
  if (old_answers > 0) {
    std::printf("answers to poses older than %.0f ms (after an outage?), not rendered: %llu\n", o.max_answer_age_ms,
                static_cast<unsigned long long>(old_answers));
  }
  // A client whose id another device (another process) also uses is not served while that
  // device holds the session (the one that joined last is: docs/haptic-service.md): its lost
  // poses say nothing about the server's capacity (a helper's phantom under lt-2: "lost
  // 23.83 %" blamed on the server).
  std::string shared_ids;
  int shared = 0;
  for (const auto* r : ran) {
    const auto& st = r->client->stats();
    if (st.other_device_notices == 0 && st.foreign_forces == 0) continue;
    ++shared;
    if (shared <= 8) {
      shared_ids += (shared_ids.empty() ? "" : ", ") + r->id + " (" +
                    std::to_string(st.other_device_notices) + " notices, " + std::to_string(st.foreign_forces) +
                    " answers to another device's poses)";
    }
  }
  if (shared > 0) {
    std::printf("another device uses the id of %d client%s: %s%s; those clients' losses are not the server's "
                "capacity: give every device its own id\n",
                shared, shared == 1 ? "" : "s", shared_ids.c_str(), shared > 8 ? ", ..." : "");
  }
  for (const auto& row : rows) PrintRow(row);
  PrintRow(all);
  std::printf("server: pose received to answered (queueing included) p50 %.0f us, p99 %.0f us (median over %d status "
              "periods), max %.0f us, CPU %.2f cores, %u sessions at most, %llu poses superseded\n",
              server.step_p50_us, server.step_p99_us, server.periods, server.step_max_us, server.cpu_use,
              server.sessions_max, static_cast<unsigned long long>(server.superseded));
  // Where the unanswered poses went: an overloaded server loses more than it supersedes (a
  // helper's 20 clients: 103 573 unanswered, 3 131 superseded), and "superseded" alone read as
  // the whole loss.
  if (all.stability.unanswered_poses > 0) {
    const uint64_t superseded = std::min<uint64_t>(server.superseded, all.stability.unanswered_poses);
    std::printf("unanswered poses %llu: %llu superseded by the server, %llu never taken by it (its reader keeps the "
                "newest 16 poses of a client: a server more than 16 poses behind loses the older ones) or lost on "
                "the way\n",
                static_cast<unsigned long long>(all.stability.unanswered_poses),
                static_cast<unsigned long long>(superseded),
                static_cast<unsigned long long>(all.stability.unanswered_poses - superseded));
  }
  std::printf("capacity check: missed ticks %.3f %%, lost end to end (missed + unanswered poses) %.3f %%; "
              "passivity %s (min E %.3g J, tolerance %.0e J)%s\n",
              MissedPct(all), LostPct(all), all.passivity_min_j < -kPassivityToleranceJ ? "VIOLATED" : "kept",
              all.passivity_min_j, kPassivityToleranceJ,
              shared > 0 ? "; NOT A CAPACITY FIGURE: another device used some clients' ids (above)" : "");

  if (!o.csv_dir.empty()) {
    std::FILE* f = OpenCsv(o.csv_dir + "/summary.csv");
    std::fputs(kSummaryHeader, f);
    for (const auto& row : rows) WriteSummaryRow(f, row, o, server, kPassivityToleranceJ);
    WriteSummaryRow(f, all, o, server, kPassivityToleranceJ);
    std::fclose(f);
    std::printf("CSV: %s/summary.csv, ticks-*.csv, roundtrip.csv\n", o.csv_dir.c_str());
  }
  if (o.plots) {
    const char* script = std::getenv("HAPCO_PLOT_LOADTEST");
    const std::string path = script != nullptr ? script : HAPCO_SOURCE_DIR "/scripts/plot_loadtest.py";
    const std::string command = "/usr/bin/python3 '" + path + "' run --csv-dir '" + o.csv_dir + "'";
    if (std::system(command.c_str()) != 0) std::fprintf(stderr, "hapco-loadtest: plotting failed: %s\n", command.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-loadtest", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
