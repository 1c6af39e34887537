// hapco-sim: runs a scene's device trajectory offline (no network) through the haptic step
// pipeline and writes one CSV row per step. Thin: the work is in hapco::sim.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cerrno>
#include <cstring>
#include <chrono>
#include <filesystem>
#include <iterator>
#include <fstream>
#include <memory>
#include <map>
#include <optional>
#include <string>
#include <vector>
#include <unistd.h>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#ifdef HAPCO_HAVE_FCLIB
#include "fclib/fclib_io.h"
#include "sim/global_export.h"
#endif
#include "common/timer.h"
#include "io/scene_file.h"
#include "io/scene_model.h"
#include "io/trajectory_file.h"
#include "sim/pose_limits.h"
#include "sim/multirate.h"
#include "sim/local_model.h"
#include "io/recording.h"
#include "io/vtk_export.h"
#include "sim/step_pipeline.h"

namespace {

constexpr const char* kDescription =
    R"(Runs the scene's device trajectory (the paper's five phases, or the poses of a --trajectory file) offline, without a network, through the haptic step pipeline of hapco-server: collision detection, flexibility operator, frictional contact solve, force on the device. Prints a summary; --csv, --output, --vtk and --fclib write what each step did. Solver options not given take the scene file's values.)";

constexpr const char* kFooter =
    "Exit code: 0 when every step converged, 2 when some did not (the run completes), 1 on bad input.";

struct Options {
  std::string scene_path, csv_path, vtk_dir, output_path, solver_name, compliance = "precomputed", trajectory_path,
      client_id;
  hapco::sim::PoseLimits limits;
  hapco::sim::MultirateParameters multirate;
  double tolerance_m = 0, friction = -1, rho_scale = 1;
  std::string fclib_dir;
  int max_iterations = 0, steps = 0, vtk_every = 10, fclib_every = 10, anderson_depth = -1;
  bool cold = false, quiet = false;
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("hapco-sim", "SCENE.txtpb [options]", kDescription, kFooter);
  command.AddScene(&options->scene_path);
  command.AddSolver(&options->solver_name, "the scene's solver");
  command.AddNumber("--paper-tol-m", &options->tolerance_m, "X",
                    "the paper's stop test ||dr||/rho < X, m (default: the scene's solver.global_tolerance_m)",
                    "Solver", 0, HUGE_VAL, true);
  // The range of a scene file's friction_coefficient, checked after parsing with its own message.
  char mu_help[128];
  std::snprintf(mu_help, sizeof mu_help,
                "Coulomb friction coefficient, dimensionless, in [0, %g] as in a scene file (default: the scene's)",
                hapco::sim::kMaxFrictionCoefficient);
  CLI::Option* mu = command.AddNumber("--mu", &options->friction, "X", mu_help, "Solver", -HUGE_VAL, HUGE_VAL);
  command.AddMaxIterations(&options->max_iterations, "the scene's");
  command.AddNumber("--rho-scale", &options->rho_scale, "X",
                    "multiply the paper's rho by X (stability studies; default 1)", "Solver", 0, HUGE_VAL, true);
  command.AddAndersonDepth(&options->anderson_depth, "the scene's solver.anderson_depth",
                           hapco::contact::SolverParameters::kMaxAndersonDepth);
  command.AddFlag("--cold", &options->cold, "start every step from r = 0 (the paper), not from the last forces",
                  "Solver");
  command.AddChoice("--compliance", &options->compliance, {"precomputed", "full"},
                    "precomputed (default; the compliance among the scene's contact candidates, computed once: "
                    "O(contacts) per step) or full (the paper's per-step sparse solves; slow, the reference)",
                    "Solver");
  command.AddInteger("--steps", &options->steps, "N", "stop after N steps (default: the whole trajectory)", "Run",
                     1, 100000000);
  command.AddText("--trajectory", &options->trajectory_path, "FILE",
                  "step k moves the tool to row k of FILE instead of the scene's phases: a CSV with columns "
                  "x_m,y_m,z_m (hapco-server --trace) or dx_m,dy_m,dz_m (hapco-sim --csv, hapco-report --csv), "
                  "found by header name; `scene` (the default) runs the scene's phases, as hapco-phantom's "
                  "and hapco-loadtest's --trajectory scene",
                  "Run");
  command.AddText("--client-id", &options->client_id, "ID",
                  "with --trajectory: the rows of that client_id (files of several clients)", "Run");
  command.AddWorkspace(&options->limits.workspace_m,
                       "poses with |position| > X m are ignored, as by hapco-server (default 0.1)");
  command.AddMaxJump(&options->limits.max_jump_m,
                     "a pose farther than X m from the last stepped one (x the sequence gap, at most 10) is "
                     "ignored, as by hapco-server (default 0.002)");
  command.AddMultirate(&options->multirate.physics_every, &options->multirate.max_model_distance_m);
  command.AddOutput(&options->output_path,
                    "write a HapCo recording: a header with the scene, one record per step with forces, contact "
                    "states and timings; read it with hapco-report");
  command.AddCsv(&options->csv_path, "one row per step (see the header line for columns and units)");
  CLI::Option* vtk = command.AddOutputDirectory("--vtk", &options->vtk_dir, "DIR",
                  "write ParaView files to DIR: deformed bodies and contact points every --vtk-every steps and at "
                  "the last step; open DIR/hapco.pvd",
                  hapco::cli::kGroupOutput);
  command.AddInteger("--vtk-every", &options->vtk_every, "N", "VTK output period in steps (default 10)",
                     hapco::cli::kGroupOutput, 1, 100000000);
  command.WritesInto(vtk, {"*.vtu", "hapco.pvd"});
  CLI::Option* fclib = command.AddOutputDirectory("--fclib", &options->fclib_dir, "DIR",
                  "write the contact problem of every --fclib-every-th step with contacts, and of every step that "
                  "did not converge, as FCLIB files for other solvers: DIR/step_NNNNNN_local.hdf5 (W, q, mu) and "
                  "DIR/step_NNNNNN_global.hdf5 (M = both bodies' K_ff, H = contact Jacobian, f, w); solve them "
                  "with hapco-solve",
                  hapco::cli::kGroupOutput);
  command.WritesInto(fclib, {"step_*_local.hdf5", "step_*_global.hdf5"});
  command.AddInteger("--fclib-every", &options->fclib_every, "N", "FCLIB export period in steps (default 10)",
                     hapco::cli::kGroupOutput, 1, 100000000);
  command.AddQuiet(&options->quiet, "no progress line");
  command.Deprecate("--record", "--output");
  command.Deprecate("--tol", "--paper-tol-m");
  command.Deprecate("--client", "--client-id");
  command.Deprecate("--mode", "--compliance");
  if (!command.Parse(argc, argv)) return false;

  if (mu->count() > 0 && !(options->friction >= 0 && options->friction <= hapco::sim::kMaxFrictionCoefficient)) {
    char message[128];
    std::snprintf(message, sizeof message, "--mu must be in [0, %g] as in a scene file, got %g",
                  hapco::sim::kMaxFrictionCoefficient, options->friction);
    throw hapco::InputError(message);
  }
  // The same word as hapco-phantom and hapco-loadtest (it was "cannot read trajectory scene").
  if (options->trajectory_path == "scene") options->trajectory_path.clear();
  if (!options->client_id.empty() && options->trajectory_path.empty()) {
    // (It was accepted and ignored: the scene's phases ran. A helper session.)
    throw hapco::InputError("--client-id picks rows of a --trajectory file; give the file too");
  }
  return true;
}

// Writes the step's contact problem as a local and a global FCLIB file; returns the number of
// files written (a step the global form cannot express, rigid against rigid, gets the local one).
int WriteFclibStep(const std::string& dir, int step, const std::string& scene_name,
                   const hapco::sim::TwoBodySession& session) {
#ifndef HAPCO_HAVE_FCLIB
  (void)dir, (void)step, (void)scene_name, (void)session;
  throw hapco::InputError("--fclib: this hapco-sim was built without FCLIB (-DHAPCO_WITH_FCLIB=OFF)");
#else
  char stem[64];
  std::snprintf(stem, sizeof stem, "/step_%06d", step);
  const std::string title = "hapco-sim " + scene_name + " step " + std::to_string(step);
  hapco::fclib::WriteFclibLocalProblem(dir + stem + "_local.hdf5", session.last_problem(),
                                       {title, "local problem u = W r + q (m, N)", ""});
  try {
    const hapco::sim::StepGlobalProblem global = hapco::sim::GlobalProblemOfStep(session);
    hapco::fclib::WriteFclibGlobalProblem(
        dir + stem + "_global.hdf5", global.problem,
        {title, "global problem M v = H r + f, u = H^T v + w: M = K_ff of both bodies (N/m), v in m, r in N", ""});
    return 2;
  } catch (const hapco::InputError&) {
    return 1;
  }
#endif
}

// Writes the current state of the session as three VTK files and adds them to the collection.
void WriteVtkStep(const std::string& dir, int step, const hapco::sim::TwoBodySession& session,
                  const hapco::sim::TwoBodyModel& model, hapco::io::VtkCollection* collection) {
  Eigen::VectorXd obstacle_u, tool_u, obstacle_f, tool_f;
  session.FullDisplacements(&obstacle_u, &tool_u);
  session.NodalContactForces(&obstacle_f, &tool_f);
  char name[64];
  const auto write_body = [&](const char* body, int part, const hapco::fem::Mesh& mesh,
                              const Eigen::VectorXd& u, const Eigen::VectorXd& f) {
    std::snprintf(name, sizeof(name), "%s_%05d.vtu", body, step);
    hapco::io::WriteBodyVtu(dir + "/" + name, mesh, u, f);
    collection->Add(step, part, name);
  };
  write_body("obstacle", 0, model.obstacle().mesh(), obstacle_u, obstacle_f);
  write_body("tool", 1, model.tool().mesh(), tool_u, tool_f);
  std::vector<hapco::io::ContactPointRecord> records;
  for (int alpha = 0; alpha < static_cast<int>(session.contacts().size()); ++alpha) {
    const hapco::sim::ContactSample sample = session.SampleContact(alpha);
    records.push_back({sample.position_m, sample.normal, sample.force_n, static_cast<int>(sample.state),
                       sample.gap_m});
  }
  std::snprintf(name, sizeof(name), "contacts_%05d.vtu", step);
  hapco::io::WriteContactsVtu(dir + "/" + name, records);
  collection->Add(step, 2, name);
}

hapco::recording::Vec3 ToVec3(const Eigen::Vector3d& v) {
  hapco::recording::Vec3 out;
  out.set_x(v.x());
  out.set_y(v.y());
  out.set_z(v.z());
  return out;
}

// One recording step: the step output plus every contact with its state.
hapco::recording::Step MakeStepRecord(const hapco::sim::StepOutput& out, int phase,
                                      const hapco::sim::TwoBodySession& session) {
  hapco::recording::Step record;
  record.set_step(static_cast<std::uint64_t>(out.step));
  record.set_client_id("hapco-sim");
  record.set_time_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(
                         std::chrono::steady_clock::now().time_since_epoch()).count());
  *record.mutable_device_translation_m() = ToVec3(out.device_translation_m);
  *record.mutable_contact_force_n() = ToVec3(out.contact_force_n);
  *record.mutable_device_force_n() = ToVec3(out.device_force_n);
  record.set_phase(static_cast<std::uint32_t>(phase));
  record.set_solver_status(std::string(hapco::contact::StatusName(out.status)));
  record.set_iterations(static_cast<std::uint32_t>(out.iterations));
  record.set_inner_iterations(static_cast<std::uint32_t>(out.inner_iterations));
  record.set_fc3d_error(out.fc3d_error);
  record.set_solve_s(out.solve_seconds);
  record.set_step_s(out.total_seconds);
  record.set_separating(static_cast<std::uint32_t>(out.state_counts[0]));
  record.set_sticking(static_cast<std::uint32_t>(out.state_counts[1]));
  record.set_sliding(static_cast<std::uint32_t>(out.state_counts[2]));
  for (int alpha = 0; alpha < static_cast<int>(session.contacts().size()); ++alpha) {
    const hapco::sim::ContactSample contact = session.SampleContact(alpha);
    auto* sample = record.add_contacts();
    sample->set_id(static_cast<std::uint32_t>(contact.tool_node));
    *sample->mutable_position_m() = ToVec3(contact.position_m);
    *sample->mutable_normal() = ToVec3(contact.normal);
    *sample->mutable_force_n() = ToVec3(contact.force_n);
    sample->set_gap_m(contact.gap_m);
    sample->set_slip_m(contact.slip_m);
    sample->set_state(static_cast<hapco::recording::ContactState>(contact.state));
  }
  return record;
}

// An output written under PATH.partial and moved onto PATH only when the run completes, so that
// a run that fails leaves the user's existing file as it was. A partial CSV is removed; a
// partial recording is kept (nothing recorded is thrown away) under its .partial name.
// An existing PATH that is not a regular file (/dev/null, a FIFO, /dev/stdout) is written
// directly: the rename replaced the device node with a regular file (run as root, a helper
// session's `--csv /dev/full` left /dev/full and /dev/null regular files).
class PendingOutput {
 public:
  PendingOutput(std::string path, bool keep_partial_on_failure)
      : path_(std::move(path)), partial_(PartialPathFor(path_)), keep_(keep_partial_on_failure) {}
  PendingOutput(const PendingOutput&) = delete;
  PendingOutput& operator=(const PendingOutput&) = delete;
  ~PendingOutput() {
    if (path_.empty() || committed_ || partial_ == path_) return;
    std::error_code error;
    if (!keep_) {
      std::filesystem::remove(partial_, error);
    } else if (std::filesystem::exists(partial_, error)) {
      std::fprintf(stderr, "hapco-sim: the run failed; what was recorded is in %s (%s untouched)\n", partial_.c_str(),
                   path_.c_str());
    }
  }
  const std::string& partial() const { return partial_; }
  void Commit() {
    if (path_.empty() || partial_ == path_) {
      committed_ = true;
      return;
    }
    std::error_code error;
    std::filesystem::rename(partial_, path_, error);
    if (error) throw hapco::InputError("cannot move " + partial_ + " to " + path_ + ": " + error.message());
    committed_ = true;
  }

 private:
  static std::string PartialPathFor(const std::string& path) {
    if (path.empty()) return "";
    std::error_code error;
    const auto status = std::filesystem::status(path, error);
    if (!error && std::filesystem::exists(status) && !std::filesystem::is_regular_file(status)) return path;
    return path + ".partial";
  }
  std::string path_, partial_;
  bool keep_;
  bool committed_ = false;
};

int Run(const Options& options) {
  hapco::sim::SceneSpec scene = hapco::io::LoadSceneFile(options.scene_path);
  if (options.friction >= 0) scene.friction_coefficient = options.friction;
  if (!options.solver_name.empty()) scene.solver = hapco::contact::ParseSolverKind(options.solver_name);
  if (options.tolerance_m > 0) scene.solver_parameters.global_tolerance_m = options.tolerance_m;
  if (options.max_iterations > 0) scene.solver_parameters.max_iterations = options.max_iterations;
  scene.solver_parameters.rho_scale = options.rho_scale;
  if (options.anderson_depth >= 0) scene.solver_parameters.anderson_depth = options.anderson_depth;
  if (options.cold) scene.solver_parameters.warm_start = false;

  PendingOutput csv_output(options.csv_path, false), record_output(options.output_path, true);
  std::FILE* csv = nullptr;
  if (!options.csv_path.empty()) {
    csv = std::fopen(csv_output.partial().c_str(), "w");
    if (csv == nullptr) throw hapco::InputError("cannot write " + options.csv_path + " (as " + csv_output.partial() + ")");
  }
  // The CSV stream is closed on every path out of Run (its partial file is then removed).
  const std::unique_ptr<std::FILE, int (*)(std::FILE*)> csv_closer(csv, [](std::FILE* f) { return f ? std::fclose(f) : 0; });
  hapco::Stopwatch setup;
  const std::unique_ptr<hapco::sim::TwoBodyModel> model_owner = hapco::io::MakeSceneModel(scene, options.scene_path);
  const hapco::sim::TwoBodyModel& model = *model_owner;
  const auto& model_stats = model.stats();
  const bool progress = !options.quiet && isatty(fileno(stderr));
  std::printf("scene %s: obstacle %d dofs, tool %d dofs; %zu obstacle + %zu tool candidate nodes; "
              "precomputation %.2f s (bodies' assembly + factorization %.2f s, compliance blocks %.2f s; "
              "%.1f MiB of operators)\n",
              scene.name.c_str(), model.obstacle().num_dofs(), model.tool().num_dofs(),
              model.obstacle_candidates().size(), model.tool_candidates().size(), setup.ElapsedSeconds(),
              model_stats.build_seconds, model_stats.compliance_seconds,
              static_cast<double>(model_stats.operator_bytes) / (1 << 20));
  for (const std::string& note : {hapco::sim::StartingPositionNote(model), hapco::sim::ContactGroupsNote(model),
                                  hapco::sim::LockingNote(model), hapco::sim::RigidBodyNote(model)}) {
    if (!note.empty()) std::printf("note: %s\n", note.c_str());
  }
  hapco::sim::TwoBodySession session(
      model, options.compliance == "full" ? hapco::sim::SolveMode::kFullSolve : hapco::sim::SolveMode::kPrecomputed);
  char acceleration[64] = "no acceleration";
  if (session.parameters.anderson_depth > 0) {
    std::snprintf(acceleration, sizeof acceleration, "Anderson depth %d after %d sweeps",
                  session.parameters.anderson_depth, session.parameters.anderson_start);
  }
  std::printf("solver %s, tolerance %.3g m, mu %.3g, %s start, %s, compliance %s (%s kernels)\n",
              std::string(hapco::contact::SolverName(session.solver)).c_str(),
              session.parameters.global_tolerance_m, scene.friction_coefficient,
              session.parameters.warm_start ? "warm" : "cold", acceleration, options.compliance.c_str(),
              hapco::sim::ComplianceKernelName(session.compliance_kernel));
  if (csv != nullptr) {
    std::fprintf(csv, "step,phase,dx_m,dy_m,dz_m,fx_n,fy_n,fz_n,device_fx_n,device_fy_n,device_fz_n,"
                      "contacts,separating,sticking,sliding,outer_iterations,inner_iterations,"
                      "detect_s,assemble_s,solve_s,update_s,step_s,fc3d_error,paper_error_m,status\n");
  }
  std::unique_ptr<hapco::io::RecordingWriter> recorder;
  if (!options.output_path.empty()) {
    hapco::recording::Header header;
    header.set_format_version(1);
    header.set_hapco_version(HAPCO_VERSION);
    header.set_writer("hapco-sim");
    header.set_scene_name(scene.name);
    std::ifstream scene_file(options.scene_path);
    header.set_scene_text(std::string(std::istreambuf_iterator<char>(scene_file), std::istreambuf_iterator<char>()));
    header.set_created_unix_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   std::chrono::system_clock::now().time_since_epoch()).count());
    header.set_solver(std::string(hapco::contact::SolverName(session.solver)));
    recorder = std::make_unique<hapco::io::RecordingWriter>(record_output.partial(), header);
  }
  std::unique_ptr<hapco::io::VtkCollection> collection;
  if (!options.vtk_dir.empty()) {
    std::error_code error;
    std::filesystem::create_directories(options.vtk_dir, error);
    if (error) throw hapco::InputError("cannot create VTK directory " + options.vtk_dir + ": " + error.message());
    collection = std::make_unique<hapco::io::VtkCollection>(options.vtk_dir + "/hapco.pvd");
  }
  if (!options.fclib_dir.empty()) {
    std::error_code error;
    std::filesystem::create_directories(options.fclib_dir, error);
    if (error) throw hapco::InputError("cannot create FCLIB directory " + options.fclib_dir + ": " + error.message());
  }
  int fclib_written = 0;
  // The tool's translation per step: the scene's phases, or a file's rows (phase "file").
  std::vector<Eigen::Vector3d> file_points;
  // A file of stepped poses (a server's --trace, hapco-report --csv) carries the clients' pose
  // sequences: the jump check scales with their gaps, as the server's did, and a sequence that
  // starts again is a new session (a restarted client or server), which starts from the
  // reference configuration as on a server. (With row numbers a replay refused poses the
  // server had stepped: 16.9 N off; a helper session.)
  std::vector<std::uint64_t> file_sequences;
  std::vector<bool> file_session_starts;
  if (!options.trajectory_path.empty()) {
    hapco::io::TrajectoryFile file = hapco::io::LoadTrajectoryFile(options.trajectory_path, options.client_id);
    file_points = std::move(file.points);
    file_sequences = std::move(file.sequences);
    file_session_starts = std::move(file.session_starts);
    if (file.force_only_rows_skipped > 0) {
      std::printf("note: %d rows of %s were written from a force alone (contacts_missing 1: the pose is not in the "
                  "recording) and are skipped\n",
                  file.force_only_rows_skipped, options.trajectory_path.c_str());
    }
    if (file.servers.size() > 1) {
      std::printf("note: %s holds poses stepped by %zu servers (a failover or restart); each new session starts "
                  "from the reference configuration here too\n",
                  options.trajectory_path.c_str(), file.servers.size());
    }
  }
  int sessions_in_file = 1;
  const int trajectory_steps = file_points.empty() ? scene.total_steps() : static_cast<int>(file_points.size()) - 1;
  auto translation_at = [&](int step) {
    return file_points.empty() ? scene.DeviceTranslationAtStep(step) : file_points[static_cast<std::size_t>(step)];
  };
  auto phase_name = [&](int phase) -> std::string {
    return file_points.empty() ? scene.trajectory[static_cast<std::size_t>(phase)].name : "file";
  };
  const int steps = options.steps > 0 ? std::min(options.steps, trajectory_steps) : trajectory_steps;
  {
    // Among the poses the workspace check lets through (a 1e308 row, or a file in millimetres,
    // made it say "raise contact.reach_m to at least inf m" for poses then ignored anyway).
    double farthest_m = 0.0;
    for (int step = 1; step <= steps; ++step) {
      const double distance_m = translation_at(step).norm();
      if (std::isfinite(distance_m) && distance_m <= options.limits.workspace_m) farthest_m = std::max(farthest_m, distance_m);
    }
    const std::string note = hapco::sim::ReachNote(model, farthest_m, "the trajectory's farthest pose");
    if (!note.empty()) std::printf("note: %s\n", note.c_str());
  }
  int not_converged = 0;
  int out_of_range = 0;  // steps that needed a node pair beyond a banded compliance
  int releases = 0;      // steps that dropped a loaded contact state: the tool lifted clear (StepOutput::released)
  // A release reported in the summary dropped more than this share of the run's peak force so far.
  constexpr double kReleaseShareOfPeak = 1e-3;
  int reentries = 0;     // steps that lost the last contact inside the obstacle (StepOutput::reentered)
  double peak_force_n = 0;
  long total_iterations = 0;
  hapco::Stopwatch run;
  // The server's plausibility checks (sim/pose_limits.h), so offline and online runs step the
  // same poses: a rejected pose is not stepped, as on the server.
  std::optional<hapco::sim::AcceptedPose> last_pose;
  // --physics-every K > 1: the server's multirate answering (sim/multirate.h).
  const bool multirate = options.multirate.physics_every > 1;
  hapco::sim::LocalModelBuilder model_builder;
  std::optional<hapco::sim::MultirateAnswerer> answerer;
  if (multirate) answerer.emplace(session, model_builder, options.multirate);
  long model_answers = 0;
  int approach_poses = 0;  // poses answered by the running approach (TwoBodySession::Step)
  std::map<std::string, int> ignored;
  for (int step = 1; step <= steps; ++step) {
    const Eigen::Vector3d pose_m = translation_at(step);
    std::uint64_t sequence = static_cast<std::uint64_t>(step);
    if (!file_sequences.empty()) sequence = file_sequences[static_cast<std::size_t>(step)];
    if (!file_session_starts.empty() && file_session_starts[static_cast<std::size_t>(step)]) {
      ++sessions_in_file;
      last_pose.reset();
      session.Reset();
      approach_poses = 0;
      if (answerer) answerer.emplace(session, model_builder, options.multirate);
    }
    const hapco::sim::PoseVerdict verdict = hapco::sim::CheckPose(pose_m, sequence, last_pose, options.limits);
    if (verdict != hapco::sim::PoseVerdict::kAccept) {
      ++ignored[hapco::sim::VerdictName(verdict)];
      continue;
    }
    const bool session_starts = !last_pose.has_value();
    last_pose = hapco::sim::AcceptedPose{sequence, pose_m};
    const int phase = file_points.empty() ? scene.PhaseOfStep(step) : 0;
    if (multirate) {
      // As hapco-server --physics-every: the pose may be answered by the last step's model.
      const hapco::sim::MultirateAnswer answer = answerer->Answer(pose_m);
      if (answer.source != hapco::sim::AnswerSource::kStep) {
        ++model_answers;
        const double gain = scene.force_gain;
        const Eigen::Vector3d contact_n = gain != 0 ? Eigen::Vector3d(answer.device_force_n / gain) : Eigen::Vector3d::Zero();
        peak_force_n = std::max(peak_force_n, contact_n.norm());
        if (csv != nullptr) {
          const auto& last = session.last_output();
          std::fprintf(csv, "%d,%s,%.9g,%.9g,%.9g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%d,%d,%d,%d,0,0,0,0,0,0,0,0,0,%s\n",
                       step, phase_name(phase).c_str(), pose_m.x(), pose_m.y(), pose_m.z(), contact_n.x(),
                       contact_n.y(), contact_n.z(), answer.device_force_n.x(), answer.device_force_n.y(),
                       answer.device_force_n.z(), last.num_contacts, last.state_counts[0], last.state_counts[1],
                       last.state_counts[2], hapco::sim::AnswerSourceName(answer.source));
        }
        continue;
      }
    } else {
      session.Step(pose_m);
    }
    const auto& out = session.last_output();
    if (out.approach_steps > 0 && approach_poses++ == 0) {
      std::printf("note: the first pose has the tool %.3g mm from home and inside the obstacle: approached from "
                  "home first (lift, across, press in along the start's contact normal, a few 0.25 mm steps a "
                  "pose, as on a server); until it arrives, each pose's row has the force at the pose reached\n",
                  pose_m.norm() * 1e3);
    }
    if (session_starts && out.approach_steps == 0 && pose_m.norm() > 2e-3) {
      // (A 50 mm first step straight through a 10 mm beam gave 0 N without a word: a helper.)
      std::printf("note: the first pose is %.3g mm from home with the tool outside the obstacle: the session starts "
                  "there, as on a server; the way from home is not simulated\n",
                  pose_m.norm() * 1e3);
    }
    if (approach_poses > 0 && !out.approaching) {
      std::printf("note: the approach reached the device's pose at step %d, after %d poses\n", step, approach_poses);
      approach_poses = 0;
    }
    if (out.status != hapco::contact::SolverStatus::kConverged) ++not_converged;
    if (out.compliance_out_of_range) ++out_of_range;
    // A plain lift drops only the solver's round-off (a helper: 5.5e-6 N left after a 0.08 N
    // press, reported as a release): count the releases that dropped a force.
    if (out.released && out.released_force_n > kReleaseShareOfPeak * peak_force_n) ++releases;
    if (out.reentered) ++reentries;
    peak_force_n = std::max(peak_force_n, out.contact_force_n.norm());
    total_iterations += out.iterations;
    if (csv != nullptr) {
      std::fprintf(csv, "%d,%s,%.9g,%.9g,%.9g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%d,%d,%d,%d,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%s\n",
                   step, phase_name(phase).c_str(),
                   out.device_translation_m.x(), out.device_translation_m.y(), out.device_translation_m.z(),
                   out.contact_force_n.x(), out.contact_force_n.y(), out.contact_force_n.z(),
                   out.device_force_n.x(), out.device_force_n.y(), out.device_force_n.z(),
                   out.num_contacts, out.state_counts[0], out.state_counts[1], out.state_counts[2],
                   out.iterations, out.inner_iterations, out.detect_seconds, out.assemble_seconds,
                   out.solve_seconds, out.update_seconds, out.total_seconds,
                   out.fc3d_error, out.paper_error_m,
                   std::string(hapco::contact::StatusName(out.status)).c_str());
    }
    if (recorder) recorder->AppendStep(MakeStepRecord(out, phase, session));
    if (collection && (step % options.vtk_every == 0 || step == steps)) {
      WriteVtkStep(options.vtk_dir, step, session, model, collection.get());
    }
    if (!options.fclib_dir.empty() && out.num_contacts > 0 &&
        (step % options.fclib_every == 0 || out.status != hapco::contact::SolverStatus::kConverged)) {
      fclib_written += WriteFclibStep(options.fclib_dir, step, scene.name, session);
    }
    if (progress && (step % 10 == 0 || step == steps)) {
      std::fprintf(stderr, "\rstep %d/%d  phase %-8s  |F| %7.3f N  contacts %3d  iterations %4d",
                   step, steps, phase_name(phase).c_str(),
                   out.contact_force_n.norm(), out.num_contacts, out.iterations);
    }
  }
  if (progress) std::fputc('\n', stderr);
  if (csv != nullptr && (std::fflush(csv) != 0 || std::ferror(csv) != 0)) {
    throw hapco::InputError("cannot write " + csv_output.partial() + ": " + std::strerror(errno) + " (disk full?)");
  }
  csv_output.Commit();
  if (recorder) {
    const long long records = static_cast<long long>(recorder->records_written());
    recorder.reset();  // closes the file
    record_output.Commit();
    std::printf("recording: %s (%lld records)\n", options.output_path.c_str(), records);
  }
  if (collection) std::printf("ParaView: open %s/hapco.pvd\n", options.vtk_dir.c_str());
  if (!options.fclib_dir.empty()) {
    std::printf("FCLIB: %d files in %s (solve one with hapco-solve FILE)\n", fclib_written, options.fclib_dir.c_str());
  }
  std::printf("%d steps in %.2f s: peak contact force %.3f N, %ld outer iterations, %d not converged\n",
              steps, run.ElapsedSeconds(), peak_force_n, total_iterations, not_converged);
  if (multirate) {
    std::printf("multirate (--physics-every %d, --model-distance-m %.3g): %ld of the poses answered between steps "
                "(status model / apart in the CSV), the others stepped, %ld extra steps at turning poses\n",
                options.multirate.physics_every, options.multirate.max_model_distance_m, model_answers,
                answerer->turn_steps());
  }
  if (releases > 0) {
    std::printf("the tool was lifted clear of the obstacle with forces still on it %d times: each time the contact "
                "state was dropped (the linear model's bent state after a push far into a rigid face would hold "
                "itself there; docs/free-interaction.md)\n",
                releases);
  }
  if (reentries > 0) {
    std::printf("the tool lost its last contact while inside the obstacle %d times (driven far past small strain, "
                "e.g. in from a side below the top): each time it re-entered by an approach from above, as a session "
                "opened there does (docs/free-interaction.md)\n",
                reentries);
  }
  if (model.obstacle_surface().range_axis >= 0) {
    std::printf("compliance range %.3g m: %d steps needed a node pair beyond it%s\n", model.obstacle_surface().range_m,
                out_of_range, out_of_range > 0 ? " (read as zero: raise contact.compliance_range_m)" : "");
  }
  if (sessions_in_file > 1) {
    std::printf("%d sessions in %s (a server or a pose sequence starts again %d times): each started from the "
                "reference configuration, as on a server\n",
                sessions_in_file, options.trajectory_path.c_str(), sessions_in_file - 1);
  }
  if (!ignored.empty()) {
    std::string kinds;
    int total = 0;
    for (const auto& [name, count] : ignored) {
      kinds += (kinds.empty() ? "" : ", ") + std::to_string(count) + " " + name;
      total += count;
    }
    std::printf("%d poses ignored as hapco-server would (--workspace-m %.3g, --max-jump-m %.3g): %s\n", total,
                options.limits.workspace_m, options.limits.max_jump_m, kinds.c_str());
    // Most poses outside the workspace: a file in millimetres is the usual cause.
    const auto out = ignored.find(hapco::sim::VerdictName(hapco::sim::PoseVerdict::kOutOfWorkspace));
    if (out != ignored.end() && 2 * out->second > steps) {
      std::printf("note: %d of the %d poses lie outside the workspace: the trajectory's columns are metres (a file "
                  "in millimetres reads 1000 times too far)\n",
                  out->second, steps);
    }
  }
  return not_converged > 0 ? 2 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-sim", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
