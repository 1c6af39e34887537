// hapco-server: the haptic service. Loads one or more scenes (each TwoBodyModel is shared by
// its sessions), serves any number of clients over DDS (one TwoBodySession each), one step
// per pose. Thin: the work is in hapco::service::ServerLoop and Session.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/output_file.h"
#include "common/realtime.h"
#include "common/work_pool.h"
#include "common/stop_signals.h"
#include "common/timer.h"
#include "io/scene_file.h"
#include "io/scene_model.h"
#include "service/server_loop.h"
#include "sim/two_body_model.h"

namespace {

constexpr const char* kDescription =
    R"(Serves haptic sessions over DDS: every client publishes DevicePose samples ("hapco/pose", 1 kHz); the server runs one contact step per pose on the client's own session of SCENE and answers with a FeedbackForce on partition hapco/client/<id> (docs/dds-qos.md). A session opens on a SESSION_JOIN or on the client's first valid pose (so clients resume by themselves after a server restart); after a SESSION_LEAVE the client must join again.
Several scenes: a SESSION_JOIN names its scene (the scene file's `name`; hapco-phantom sends the name in the scene file it was given); a session opened by a pose, or a JOIN without a name, gets the first scene; an unknown name is refused and logged with the served names.
Bad input is counted and logged (at most one line per second per kind), never fatal; a client whose poses are ignored is told so in its force samples (FeedbackForce.pose_verdict). Guide: docs/haptic-service.md.)";

constexpr const char* kFooter = R"(SIGINT/SIGTERM: clean shutdown, exit code 0 and a one-line summary.
Exit code: 0 after a clean shutdown, 1 on bad input (scene file, flags; also when another server on the domain already uses this --server-id), 3 on a DDS failure.)";

struct Options {
  std::vector<std::string> scene_paths;  // the first is the default scene
  std::string trace_path;
  int domain = 0;
  int rt_priority = 0;
  hapco::service::ServerOptions server;
};

// --scenes FILE: one scene path per line; blank lines and # comments skipped; a relative
// path is relative to FILE's folder (so a config file travels with its scenes).
std::vector<std::string> ReadSceneList(const std::string& list_path) {
  std::ifstream in(list_path);
  if (!in) throw hapco::InputError("cannot read scene list " + list_path);
  const std::filesystem::path folder = std::filesystem::path(list_path).parent_path();
  std::vector<std::string> paths;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    line = line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
    std::filesystem::path path(line);
    if (path.is_relative()) path = folder / path;
    if (!std::filesystem::is_regular_file(path)) {
      throw hapco::InputError(list_path + ":" + std::to_string(number) + ": no scene file " + path.string());
    }
    paths.push_back(path.string());
  }
  if (paths.empty()) throw hapco::InputError(list_path + ": lists no scene file");
  return paths;
}

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  options->server.threads = hapco::WorkPool::DefaultThreads();
  hapco::cli::CommandLine command("hapco-server", "SCENE.txtpb [SCENE.txtpb ...] [options]", kDescription, kFooter);
  command.app()
      .add_option("SCENE", options->scene_paths, "scene files; the first is the default scene")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->group("Arguments");
  std::string scene_list;
  command.AddText("--scenes", &scene_list, "FILE",
                  "scene files listed in FILE, one path per line (# comments; relative paths are relative "
                  "to FILE's folder), after those on the command line",
                  "Arguments");
  command.AddDomain(&options->domain);
  std::string security_dir;
  command.AddSecurity(&security_dir, "DIR/server");
  options->server.server_id = hapco::service::DefaultServerId();
  command.AddText("--server-id", &options->server.server_id, "ID",
                  "this server's name in ServerStatus, 1-64 of [A-Za-z0-9_.-] (default hapco-<hostname>-<pid>-<random>, new at every start); "
                  "with several servers on a domain each client is served by the one it chose "
                  "(docs/several-servers.md)",
                  hapco::cli::kGroupDds);
  command.AddNumber("--status-period-s", &options->server.status_period_s, "S",
                    "ServerStatus period, s (default 1)", hapco::cli::kGroupDds, 0,
                    hapco::cli::CommandLine::kMaxDurationS, true);
  command.AddInteger("--max-sessions", &options->server.max_sessions, "N",
                     "open sessions at most (default 16); further clients are refused", "Sessions", 1, 1000);
  command.AddNumber("--session-idle-s", &options->server.session_idle_s, "S",
                    "close a session after S s without a pose or session message from its client (a client "
                    "killed without leaving would hold its slot for good); 0 = never (default 5)",
                    // (1e12 overflowed to "nothing heard for 0.0 s" and closed every session.)
                    "Sessions", 0, hapco::cli::CommandLine::kMaxDurationS);
  command.AddInteger("--threads", &options->server.threads, "N",
                     "threads stepping sessions, the server thread included (default: one per online core); "
                     "sessions that got a pose in the same tick are stepped in parallel, each worker publishing "
                     "the force of the session it stepped",
                     "Sessions", 1, 256);
  std::string physics = "contact";
  command.AddChoice("--physics", &physics, {"contact", "none"},
                    "contact (default), or none: the zero-cost floor for load tests (same DDS path, sessions and "
                    "samples, no contact computation, zero force)",
                    "Sessions");
  bool no_local_model = false;
  command.AddFlag("--no-local-model", &no_local_model,
                  "do not send the contact's local model (stiffness, normal, friction) with the forces: saves "
                  "~5 % of a step; clients then render forces as they come (hapco-phantom --render)",
                  "Sessions");
  command.AddMultirate(&options->server.multirate.physics_every, &options->server.multirate.max_model_distance_m);
  command.AddMaxJump(&options->server.limits.max_jump_m,
                     "largest plausible position change per pose, m (default 0.002); a larger jump is ignored "
                     "(the client keeps its last force and is told)");
  command.AddWorkspace(&options->server.limits.workspace_m,
                       "poses with |position| > X m are ignored (default 0.1)");
  double time_budget_ms = -1;
  command.AddNumber("--time-budget-ms", &time_budget_ms, "X",
                    "solver wall-clock budget per step, ms (0 = none; default: the scene's "
                    "solver.time_budget_s); a step out of time answers with the forces it has and status "
                    "SOLVER_TIME_BUDGET_EXCEEDED",
                    "Solver", 0, HUGE_VAL);
  command.AddOutputFile("--trace", &options->trace_path, "FILE",
                  "write one CSV row per stepped pose (client_id, sequence, position, force sent, step_us: "
                  "from the pose's arrival to its force being ready), written before the force is "
                  "published, for debugging and tests",
                  hapco::cli::kGroupOutput);
  command.AddRtPriority(&options->rt_priority, "the server thread");
  bool quiet = false;
  command.AddQuiet(&quiet, "no log lines (the exit summary is still printed)");
  command.Deprecate("--status-period", "--status-period-s");
  if (!command.Parse(argc, argv)) return false;

  if (!scene_list.empty()) {
    for (std::string& path : ReadSceneList(scene_list)) options->scene_paths.push_back(std::move(path));
  }
  if (options->scene_paths.empty()) throw hapco::InputError("missing SCENE argument (see --help)");
  // The command line checks its own outputs against its inputs; the scenes a --scenes list
  // names are inputs too (--trace over one of them wrote the trace into the scene file).
  for (const std::string& path : options->scene_paths) {
    std::error_code error;
    if (!options->trace_path.empty() && std::filesystem::equivalent(path, options->trace_path, error) && !error) {
      throw hapco::InputError("--trace " + options->trace_path + " is also the scene " + path +
                              ": writing it would destroy the scene; give another file");
    }
  }
  if (!hapco::service::IsValidClientId(options->server.server_id)) {
    throw hapco::InputError("--server-id expects 1-64 of [A-Za-z0-9_.-], got '" + options->server.server_id + "'");
  }
  options->server.physics =
      physics == "none" ? hapco::service::SessionPhysics::kNone : hapco::service::SessionPhysics::kContact;
  if (options->server.physics == hapco::service::SessionPhysics::kNone && options->server.multirate.physics_every > 1) {
    std::fprintf(stderr, "hapco-server: note: --physics-every has no effect with --physics none (no physics to skip)\n");
  }
  if (time_budget_ms >= 0) options->server.time_budget_s = time_budget_ms * 1e-3;
  options->server.local_model = !no_local_model;
  options->server.log = !quiet;
  options->server.security = {security_dir, "server"};  // disabled when security_dir is empty
  return true;
}

int Run(const Options& options) {
  hapco::StopSignals stop_signals;  // from now on: a signal during the setup is kept

  hapco::Stopwatch setup;
  // Every scene's precomputation (factorisations, compliance) once, before serving.
  std::vector<std::unique_ptr<hapco::sim::TwoBodyModel>> models;
  std::vector<const hapco::sim::TwoBodyModel*> served;
  std::string scenes_line;
  // The scene files first (parsing and any meshing), so that two scenes of one name are refused
  // before either is prepared (they were refused after both were: seconds to minutes).
  std::vector<hapco::sim::SceneSpec> scenes;
  std::map<std::string, std::string> path_of_name;
  for (const std::string& path : options.scene_paths) {
    scenes.push_back(hapco::io::LoadSceneFile(path));
    const auto [named, fresh] = path_of_name.emplace(scenes.back().name, path);
    if (!fresh) {
      throw hapco::InputError("scenes " + named->second + " and " + path + " are both named '" + named->first +
                              "': clients choose a scene by its name, so names must differ");
    }
  }
  for (std::size_t k = 0; k < options.scene_paths.size(); ++k) {
    const std::string& path = options.scene_paths[k];
    // A mesh scene at ~100k dofs takes seconds to prepare: say what the server is doing.
    if (options.server.log) {
      std::printf("hapco-server: preparing scene %s (meshing, factorization, contact compliance)\n", path.c_str());
      std::fflush(stdout);
    }
    hapco::Stopwatch scene_watch;
    models.push_back(hapco::io::MakeSceneModel(std::move(scenes[k]), path));
    served.push_back(models.back().get());
    if (options.server.log) {
      const hapco::sim::TwoBodyModelStats& stats = models.back()->stats();
      std::printf("hapco-server: scene %s prepared in %.2f s (bodies' assembly + factorization %.2f s, compliance "
                  "blocks %.2f s)\n",
                  models.back()->scene().name.c_str(), scene_watch.ElapsedSeconds(), stats.build_seconds,
                  stats.compliance_seconds);
      std::fflush(stdout);
    }
    for (const std::string& note :
         {hapco::sim::StartingPositionNote(*models.back()), hapco::sim::ContactGroupsNote(*models.back()),
          hapco::sim::LockingNote(*models.back()), hapco::sim::RigidBodyNote(*models.back()),
          hapco::sim::ReachNote(*models.back(), options.server.limits.workspace_m, "--workspace-m")}) {
      if (!note.empty()) std::printf("hapco-server: scene %s: note: %s\n", models.back()->scene().name.c_str(), note.c_str());
    }
    scenes_line += (scenes_line.empty() ? "" : ", ") + models.back()->scene().name + " (" +
                   std::to_string(models.back()->tool_candidates().size()) + " tool + " +
                   std::to_string(models.back()->obstacle_candidates().size()) + " obstacle surface nodes)";
  }
  hapco::service::ServerOptions server_options = options.server;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> trace(nullptr, &std::fclose);
  if (!options.trace_path.empty()) {
    trace.reset(std::fopen(options.trace_path.c_str(), "w"));
    if (!trace) throw hapco::InputError("cannot write " + options.trace_path);
    // A line per stepped pose, written (by the thread that stepped it) before its force is
    // published: a server killed mid-run (a host gone) leaves a trace of every force it sent.
    std::setvbuf(trace.get(), nullptr, _IOLBF, 1024);
    std::fprintf(trace.get(), "client_id,sequence,x_m,y_m,z_m,fx_n,fy_n,fz_n,step_us\n");
    if (std::fflush(trace.get()) != 0 || std::ferror(trace.get()) != 0) {
      throw hapco::InputError("cannot write " + options.trace_path + ": " + std::strerror(errno) + " (disk full?)");
    }
    server_options.trace = trace.get();
  }
  hapco::UseRealtimePriority(options.rt_priority, "hapco-server");
  hapco::service::ServerLoop server(served, options.domain, server_options);
  std::printf("hapco-server: scene%s %s, domain %d, server id %s, %d stepping thread%s%s, %s compliance kernels, "
              "ready in %.2f s\n",
              served.size() > 1 ? "s" : "", scenes_line.c_str(), options.domain, server_options.server_id.c_str(),
              server_options.threads,
              server_options.threads > 1 ? "s" : "",
              server_options.physics == hapco::service::SessionPhysics::kNone ? ", physics none (zero force)" : "",
              hapco::sim::ComplianceKernelName(hapco::sim::FastestComplianceKernel()), setup.ElapsedSeconds());
  if (server_options.multirate.physics_every > 1 && server_options.physics == hapco::service::SessionPhysics::kContact) {
    std::printf("hapco-server: multirate: a contact step on at least every %d poses; the poses between, within %.3g m "
                "of the last step's pose, answered by its contacts solved again there (sim/multirate.h)\n",
                server_options.multirate.physics_every, server_options.multirate.max_model_distance_m);
  }
  std::fflush(stdout);

  const auto watching = stop_signals.Watch([&server] { server.RequestStop(); });
  server.Run();
  std::printf("%s; stopped by %s\n", server.Summary().c_str(),
              stop_signals.ReceivedName(server.stopped_because().empty() ? "request" : "a duplicate --server-id"));
  // A trace that lost rows (the disk filled up mid-run) is not a complete record: say so.
  hapco::CloseOutputFile(trace.release(), options.trace_path);
  if (!server.stopped_because().empty()) throw hapco::InputError(server.stopped_because());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-server", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
