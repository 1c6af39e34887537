// Free interaction study (issue "Free interaction", docs/free-interaction.md): forces along
// device paths that leave the scene's scripted footprint. For each scene (benchmarks 1 and 2,
// the shipped Tet4 tool and a Tet10 tool) and each path it writes DIR/<scene>_<tool>_<path>.csv
// (one row per 0.1 mm step) and prints a summary row:
//   steps, not converged, peak |F|, largest step-to-step |Δ|F|| / |F| where |F| > 10 % of the
//   path's peak, the force direction at the end of the path, monotonic presses.
// The sweep out and back over the top face also gives the direction dependence: the largest
// relative difference of |F| between the two visits of the same pose.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "common/load_average.h"
#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/timer.h"
#include "io/scene_file.h"
#include "sim/device_path.h"
#include "sim/step_pipeline.h"

namespace {

using namespace hapco;  // NOLINT: a short study

struct PathSpec {
  std::string name;
  std::vector<Eigen::Vector3d> waypoints;  // device translations, m
  bool benchmark2_only = false;             // needs the free end at x = 0.1 m
};

struct PathSummary {
  int steps = 0, not_converged = 0;
  double peak_n = 0, max_relative_change = 0, max_change_at_x_m = 0;
  double direction_dependence = 0;  // sweeps only
  Eigen::Vector3d final_force_n = Eigen::Vector3d::Zero();
  bool press_monotonic = true;
  double worst_step_s = 0;
  std::vector<Eigen::Vector3d> poses_m, forces_n;  // per step
};

// Tool home: x ∈ [0.04, 0.06], y ∈ [0, 0.02], z ∈ [0.02, 0.03] m on a 0.1 x 0.02 x 0.02 m bar.
std::vector<PathSpec> Paths() {
  const double depth = -0.003;
  std::vector<PathSpec> paths;
  // The whole top face at 3 mm: the tool's edges reach both ends of the bar, out and back.
  paths.push_back({"top-sweep",
                   {{0, 0, 0}, {0, 0, depth}, {-0.04, 0, depth}, {0.04, 0, depth}, {0, 0, depth}, {0, 0, 0}}});
  // Across the clamped edge at x = 0 (5 mm beyond it) and back.
  paths.push_back({"over-clamped-edge", {{0, 0, 0}, {0, 0, depth}, {-0.045, 0, depth}, {-0.03, 0, depth}}});
  // Presses to half the bar's thickness: mid-span, next to the clamp at x = 0, at the free end.
  auto press = [](double dx) {
    return std::vector<Eigen::Vector3d>{{0, 0, 0}, {0, 0, 0.001}, {dx, 0, 0.001}, {dx, 0, -0.010}};
  };
  paths.push_back({"press-mid", press(0.0)});
  paths.push_back({"press-clamp", press(-0.0375)});
  paths.push_back({"press-end", press(0.0375), true});
  // Sideways pushes: against the end face x = 0.1 m (clamped in benchmark 1, free in 2) and
  // against the side face y = 0.02 m, 3 mm below the top.
  paths.push_back({"push-end-face", {{0, 0, 0}, {0, 0, 0.001}, {0.0625, 0, 0.001}, {0.0625, 0, depth}, {0.0585, 0, depth}}});
  paths.push_back({"push-side-face", {{0, 0, 0}, {0, 0, 0.001}, {0, 0.0225, 0.001}, {0, 0.0225, depth}, {0, 0.0185, depth}}});
  // Off the free side of the end, 12 mm lower, and back into the end face.
  paths.push_back({"below-end-and-back",
                   {{0, 0, 0}, {0, 0, 0.001}, {0.0625, 0, 0.001}, {0.0625, 0, -0.012}, {0.0525, 0, -0.012}}});
  return paths;
}

PathSummary RunPath(const sim::TwoBodyModel& model, const PathSpec& spec, const std::string& csv_path) {
  const std::vector<Eigen::Vector3d> path = sim::PolylinePath(spec.waypoints, 1e-4);
  sim::TwoBodySession session(model);
  std::FILE* csv = std::fopen(csv_path.c_str(), "w");
  if (csv == nullptr) throw InputError("cannot write " + csv_path);
  std::fprintf(csv, "step,dx_m,dy_m,dz_m,fx_n,fy_n,fz_n,force_n,contacts,edge_contacts,status,iterations,step_s\n");
  PathSummary summary;
  std::vector<double> magnitude;
  for (std::size_t k = 1; k < path.size(); ++k) {
    const sim::StepOutput& out = session.Step(path[k]);
    const Eigen::Vector3d f = out.contact_force_n;
    magnitude.push_back(f.norm());
    ++summary.steps;
    if (out.status != contact::SolverStatus::kConverged) ++summary.not_converged;
    summary.peak_n = std::max(summary.peak_n, f.norm());
    summary.worst_step_s = std::max(summary.worst_step_s, out.total_seconds);
    summary.final_force_n = f;
    summary.poses_m.push_back(path[k]);
    summary.forces_n.push_back(f);
    std::fprintf(csv, "%zu,%.6g,%.6g,%.6g,%.9g,%.9g,%.9g,%.9g,%d,%d,%s,%d,%.6g\n", k, path[k].x(), path[k].y(),
                 path[k].z(), f.x(), f.y(), f.z(), f.norm(), out.num_contacts, out.num_edge_contacts,
                 std::string(contact::StatusName(out.status)).c_str(), out.iterations, out.total_seconds);
  }
  std::fclose(csv);
  // Smoothness where the force is established (> 10 % of the path's peak).
  for (std::size_t k = 1; k < magnitude.size(); ++k) {
    const double base = std::max(magnitude[k], magnitude[k - 1]);
    if (base < 0.1 * summary.peak_n) continue;
    const double change = std::abs(magnitude[k] - magnitude[k - 1]) / base;
    if (change > summary.max_relative_change) {
      summary.max_relative_change = change;
      summary.max_change_at_x_m = path[k + 1].x();
    }
  }
  // Presses: the last segment goes straight down; |F| must not decrease once in contact.
  if (spec.name.rfind("press", 0) == 0) {
    const std::size_t down = path.size() - 1 - 110;  // the 11 mm descent in 0.1 mm steps
    for (std::size_t k = down + 1; k < magnitude.size(); ++k) {
      if (magnitude[k - 1] > 1e-6 && magnitude[k] < magnitude[k - 1] * (1 - 1e-9)) summary.press_monotonic = false;
    }
  }
  // Sweeps visit each pose twice (out and back): compare |F| at equal poses in the -x→+x and
  // +x→-x passes, where both exceed 10 % of the peak.
  if (spec.name.rfind("top-sweep", 0) == 0) {
    // Path indices: press 1..30, -x to -0.04 m 31..430, +x to +0.04 m 431..1230, -x back to 0
    // 1231..1630. Pose x = -0.04 + i·0.1 mm is index 430 + i going +x, and 430 - i (i <= 400)
    // or 2030 - i (i >= 400) going -x; magnitude[k - 1] belongs to path index k.
    for (std::size_t i = 0; i <= 800; ++i) {
      const std::size_t forward = 430 + i, backward = i <= 400 ? 430 - i : 2030 - i;
      if (backward < 1 || forward > magnitude.size() || backward > magnitude.size()) continue;
      const double a = magnitude[forward - 1], b = magnitude[backward - 1];
      if (std::max(a, b) < 0.1 * summary.peak_n) continue;
      summary.direction_dependence = std::max(summary.direction_dependence, std::abs(a - b) / std::max(a, b));
    }
  }
  return summary;
}

struct Options {
  std::string out_dir = "free-interaction";
  bool with_tet10 = true;
  bool reference = false;
  std::string reference_obstacle = "30,6,6";  // box divisions of the reference's obstacle (Tet10)
  std::string reference_tool = "6,6,3";       // and of its tool (Tet10)
};

// "NX,NY,NZ" -> divisions, or InputError naming the option.
Eigen::Vector3i Divisions(const std::string& text, const char* option) {
  int x = 0, y = 0, z = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%d,%d,%d%c", &x, &y, &z, &tail) != 3 || x < 1 || y < 1 || z < 1 || x > 200 ||
      y > 200 || z > 200) {
    throw InputError(std::string(option) + " expects three divisions NX,NY,NZ in 1..200, got '" + text + "'");
  }
  return {x, y, z};
}

constexpr const char* kDescription =
    R"(Forces along device paths that leave the scene's scripted footprint (docs/free-interaction.md): the whole top face at 3 mm depth, presses next to the clamps and at the free end, pushes against end and side faces, below the end and back; benchmarks 1 and 2, the shipped Tet4 tool and a Tet10 tool. Writes DIR/<scene>_<tool>_<path>.csv (one row per 0.1 mm step) and DIR/summary.csv, and prints a summary row per path (convergence, largest step-to-step |dF|/|F|, direction dependence, monotonic presses); scripts/plot_free_interaction.py draws them. Prints numbers, never asserts.)";

constexpr const char* kFooter = "Exit code: 0 when the study ran, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("free_interaction_study", "[options]", kDescription, kFooter);
  bool no_tet10 = false;
  command.AddFlag("--no-tet10", &no_tet10, "only the shipped Tet4 tool", "Run");
  command.AddFlag("--reference", &o->reference,
                  "also a refined reference (obstacle 30x6x6 Tet10, tool 6x6x3 Tet10 unless set below, global "
                  "Uzawa, per-contact rho, 1e-8 m; ~1 GB) on the top-face sweep and the presses, and each model's "
                  "|F| error against it",
                  "Run");
  command.AddText("--reference-obstacle", &o->reference_obstacle, "NX,NY,NZ",
                  "the reference's obstacle divisions, Tet10 (default 30,6,6; 40,8,8 checks that one)", "Run");
  command.AddText("--reference-tool", &o->reference_tool, "NX,NY,NZ",
                  "the reference's tool divisions, Tet10 (default 6,6,3)", "Run");
  command.AddOutputDirectory("--output", &o->out_dir, "DIR",
                  "directory for the per-path CSVs and summary.csv, created if missing (default ./free-interaction)",
                  hapco::cli::kGroupOutput);
  command.Deprecate("--out", "--output");
  if (!command.Parse(argc, argv)) return false;
  o->with_tet10 = !no_tet10;
  return true;
}

int Run(const Options& options) {
  const std::string& out_dir = options.out_dir;
  const bool with_tet10 = options.with_tet10;
  const bool reference = options.reference;
  const Eigen::Vector3i reference_obstacle = Divisions(options.reference_obstacle, "--reference-obstacle");
  const Eigen::Vector3i reference_tool = Divisions(options.reference_tool, "--reference-tool");
  std::filesystem::create_directories(out_dir);
  std::printf("load average at start: %s\n", hapco::LoadAverageText().c_str());
  std::FILE* summary_csv = std::fopen((out_dir + "/summary.csv").c_str(), "w");
  if (summary_csv == nullptr) throw InputError("cannot write " + out_dir + "/summary.csv");
  std::fprintf(summary_csv, "scene,tool,path,steps,not_converged,peak_n,max_relative_change,at_x_m,"
                            "direction_dependence,final_fx_n,final_fy_n,final_fz_n,press_monotonic,worst_step_s\n");
  std::printf("%-10s %-5s %-19s %6s %5s %9s %9s %8s %8s  %-28s %s\n", "scene", "tool", "path", "steps", "fail",
              "peak N", "max dF/F", "at x m", "dir.dep", "final force (N)", "monotonic");
  std::map<std::string, PathSummary> results;
  for (const char* scene_name : {"benchmark1", "benchmark2"}) {
    for (const fem::ElementOrder order : {fem::ElementOrder::kTet4, fem::ElementOrder::kTet10}) {
      if (order == fem::ElementOrder::kTet10 && !with_tet10) continue;
      sim::SceneSpec scene = io::LoadSceneFile(std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/" + scene_name + ".txtpb");
      scene.tool.box.order = order;
      Stopwatch build;
      const sim::TwoBodyModel model(scene);
      const char* tool = fem::ToString(order);
      std::fprintf(stderr, "%s/%s: model %.1f s (%zu obstacle + %zu tool surface nodes, %zu edge nodes)\n",
                   scene_name, tool, build.ElapsedSeconds(), model.obstacle_candidates().size(),
                   model.tool_candidates().size(), model.obstacle_reverse_slaves().size());
      // Frictionless twin of the shipped model: without friction the quasi-static answer is
      // path independent, so the sweep's out/back difference there is the model's own, and
      // with friction the rest is what friction explains.
      sim::SceneSpec frictionless_scene = scene;
      frictionless_scene.friction_coefficient = 0.0;
      std::unique_ptr<sim::TwoBodyModel> frictionless;
      if (order == fem::ElementOrder::kTet4) frictionless = std::make_unique<sim::TwoBodyModel>(frictionless_scene);
      std::vector<PathSpec> paths = Paths();
      if (frictionless) paths.push_back({"top-sweep-frictionless", paths.front().waypoints});
      for (const PathSpec& spec : paths) {
        if (spec.benchmark2_only && std::string(scene_name) != "benchmark2") continue;
        const std::string csv = out_dir + "/" + scene_name + "_" + tool + "_" + spec.name + ".csv";
        const bool is_frictionless = spec.name == "top-sweep-frictionless";
        const PathSummary s = RunPath(is_frictionless ? *frictionless : model, spec, csv);
        results[std::string(scene_name) + "/" + tool + "/" + spec.name] = s;
        const Eigen::Vector3d f = s.final_force_n;
        std::printf("%-10s %-5s %-19s %6d %5d %9.3f %9.4f %8.4f %8.4f  (%8.3f %8.3f %8.3f) %s\n", scene_name, tool,
                    spec.name.c_str(), s.steps, s.not_converged, s.peak_n, s.max_relative_change, s.max_change_at_x_m,
                    s.direction_dependence, f.x(), f.y(), f.z(),
                    spec.name.rfind("press", 0) == 0 ? (s.press_monotonic ? "yes" : "NO") : "-");
        std::fprintf(summary_csv, "%s,%s,%s,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%.6g\n", scene_name, tool,
                     spec.name.c_str(), s.steps, s.not_converged, s.peak_n, s.max_relative_change,
                     s.max_change_at_x_m, s.direction_dependence, f.x(), f.y(), f.z(), s.press_monotonic ? 1 : 0,
                     s.worst_step_s);
        std::fflush(stdout);
      }
    }
  }
  std::fclose(summary_csv);
  if (reference) {
    // A tightly converged finer model: each shipped choice's |F| error against it, where the
    // tool stays at least 3 mm from a clamped end (closer, the clamp is a stiffness singularity
    // that no mesh here resolves: docs/free-interaction.md).
    std::printf("\nagainst the refined reference (obstacle %dx%dx%d Tet10, tool %dx%dx%d Tet10, 1e-8 m), "
                "presses: |F| > 10 %% of their peak; sweeps: |F| > 0.5 N, tool >= 3 mm from a clamped end:\n",
                reference_obstacle.x(), reference_obstacle.y(), reference_obstacle.z(), reference_tool.x(),
                reference_tool.y(), reference_tool.z());
    std::printf("%-10s %-14s %-6s %12s %12s %12s %12s\n", "scene", "path", "model", "max |F| err", "p90 err", "median err",
                "ref peak N");
    for (const char* scene_name : {"benchmark1", "benchmark2"}) {
      sim::SceneSpec scene = io::LoadSceneFile(std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/" + scene_name + ".txtpb");
      scene.obstacle.box.divisions = reference_obstacle;
      scene.tool.box.divisions = reference_tool;
      scene.tool.box.order = fem::ElementOrder::kTet10;
      // Global Uzawa GS with one rho per contact at 1e-8 m: converged to 1e-5 of the force
      // like the NSGS reference on this mesh, at ~1/100 of its time (NSGS: 1.6 s per step).
      scene.solver = contact::SolverKind::kGlobalUzawaGaussSeidel;
      scene.solver_parameters.rho_rule = contact::RhoRule::kPerContact;
      scene.solver_parameters.global_tolerance_m = 1e-8;
      scene.solver_parameters.max_iterations = 20000;
      Stopwatch build;
      const sim::TwoBodyModel model(scene);
      std::fprintf(stderr, "%s/reference: model %.1f s\n", scene_name, build.ElapsedSeconds());
      for (const PathSpec& spec : Paths()) {
        if (spec.name != "top-sweep" && spec.name.rfind("press", 0) != 0) continue;
        if (spec.benchmark2_only && std::string(scene_name) != "benchmark2") continue;
        const PathSummary ref =
            RunPath(model, spec, out_dir + "/" + scene_name + "_reference_" + spec.name + ".csv");
        for (const char* tool : {"Tet4", "Tet10"}) {
          const auto it = results.find(std::string(scene_name) + "/" + tool + "/" + spec.name);
          if (it == results.end()) continue;
          std::vector<double> errors;
          const auto clamped = [&](fem::BoxFace face) {
            return std::find(scene.obstacle.clamped_faces.begin(), scene.obstacle.clamped_faces.end(), face) !=
                   scene.obstacle.clamped_faces.end();
          };
          const bool sweep = spec.name == "top-sweep";
          for (std::size_t k = 0; k < ref.forces_n.size() && k < it->second.forces_n.size(); ++k) {
            const double tool_left_m = scene.tool.box.min_corner_m.x() + ref.poses_m[k].x();
            const double tool_right_m = tool_left_m + scene.tool.box.size_m.x();
            if (sweep && ((clamped(fem::BoxFace::kXMin) && tool_left_m < 0.003) ||
                          (clamped(fem::BoxFace::kXMax) && tool_right_m > 0.097))) {
              continue;
            }
            const double f_ref = ref.forces_n[k].norm();
            // Sweeps: the pressed part where the reference force exceeds 0.5 N; presses: > 10 %
            // of their peak (the onset of contact is not a relative-error question).
            if (sweep && std::abs(ref.poses_m[k].z() + 0.003) > 1e-12) continue;
            if (f_ref < (sweep ? 0.5 : 0.1 * ref.peak_n)) continue;
            errors.push_back(std::abs(it->second.forces_n[k].norm() - f_ref) / f_ref);
          }
          std::sort(errors.begin(), errors.end());
          const double worst = errors.empty() ? 0.0 : errors.back();
          if (errors.empty()) continue;
          const double median = errors[errors.size() / 2];
          const double p90 = errors[errors.size() * 9 / 10];
          std::printf("%-10s %-14s %-6s %11.2f%% %11.2f%% %11.2f%% %12.3f\n", scene_name, spec.name.c_str(), tool,
                      100 * worst, 100 * p90, 100 * median, ref.peak_n);
          std::fflush(stdout);
        }
      }
    }
  }
  std::printf("load average at end: %s\n", hapco::LoadAverageText().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("free_interaction_study", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
