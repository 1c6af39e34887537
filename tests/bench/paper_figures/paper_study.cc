// hapco_paper_study: reproduces the paper's figures 6-9 (section 3.3.3) with the two-body
// haptic pipeline, and runs the stability study (docs/stability.md). Writes small CSVs; the
// plots are made by scripts/plot_paper_figures.py. Prints numbers, never asserts.
//
//   hapco_paper_study --output DIR [--study all|refcheck|fig67|fig8|fig9|stability] [--quick]
//
// "paper" runs use the paper's settings (section 3.3.3): cold start r0 = 0, one
// ρ = min_i 1/W_ii, and every threshold (ε₁, ε₂) equal to the "Uzawa error" ‖Δr‖/ρ.
// "default" runs use the shipped scene's solver settings (warm start, ε₁ = 1e-6 m,
// ε₂ = 1e-7 m). References: the exact-local-solve NSGS solver at ε₁ = 1e-12 m, warm start.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <time.h>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/timer.h"
#include "contact/solver.h"
#include "io/scene_file.h"
#include "sim/scene.h"
#include "sim/step_pipeline.h"
#include "sim/two_body_model.h"

namespace {

using hapco::Stopwatch;
using hapco::contact::RhoRule;
using hapco::contact::SolverKind;
using hapco::contact::SolverName;
using hapco::contact::SolverParameters;
using hapco::contact::SolverStatus;
using hapco::contact::StatusName;
using hapco::sim::SceneSpec;
using hapco::sim::TwoBodyModel;
using hapco::sim::TwoBodySession;

constexpr SolverKind kMethods[] = {SolverKind::kLocalUzawa, SolverKind::kGlobalUzawaGaussSeidel,
                                   SolverKind::kGlobalUzawaJacobi};

// A method as plotted in the paper figures: the three solvers at the paper's ρ, plus the
// Jacobi order at 0.1 ρ (it never converges at the paper's ρ here, see docs/stability.md).
struct Method {
  SolverKind kind;
  double rho_scale;
  const char* label;
  RhoRule rho_rule = RhoRule::kPaperGlobalMin;
};
constexpr Method kFigureMethods[] = {
    {SolverKind::kLocalUzawa, 1.0, "local-uzawa"},
    {SolverKind::kGlobalUzawaGaussSeidel, 1.0, "global-uzawa-gs"},
    {SolverKind::kGlobalUzawaJacobi, 1.0, "global-uzawa-jacobi"},
    {SolverKind::kGlobalUzawaJacobi, 0.1, "global-uzawa-jacobi-rho0.1"},
};
// Figures 6/7 also show local Uzawa with a per-contact ρ_α = 1/λ_max(W_αα) (algorithms.md §4),
// to separate the algorithm from the paper's single-ρ rule.
constexpr Method kFig67Methods[] = {
    {SolverKind::kLocalUzawa, 1.0, "local-uzawa"},
    {SolverKind::kGlobalUzawaGaussSeidel, 1.0, "global-uzawa-gs"},
    {SolverKind::kGlobalUzawaJacobi, 1.0, "global-uzawa-jacobi"},
    {SolverKind::kGlobalUzawaJacobi, 0.1, "global-uzawa-jacobi-rho0.1"},
    {SolverKind::kLocalUzawa, 1.0, "local-uzawa-rho-per-contact", RhoRule::kPerContact},
};

struct Options {
  std::string out_dir;
  std::string study = "all";
  std::string scene_dir = HAPCO_SOURCE_DIR "/proto/scenes";
  bool quick = false;  // coarse meshes, few steps: a smoke run for ctest
};

// ---------------------------------------------------------------------------------------
// One run of a trajectory.

struct StepRecord {
  int step = 0;
  int phase = 0;
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // resultant contact force on the tool, N
  int contacts = 0;
  int outer = 0;
  int inner = 0;
  double solve_s = 0.0;  // wall time of the contact solve, s
  double cpu_s = 0.0;    // thread CPU time of the whole step, s
  double fc3d = 0.0;
  SolverStatus status = SolverStatus::kConverged;
};

struct RunResult {
  std::vector<StepRecord> steps;
  double total_solve_s = 0.0;
  double total_cpu_s = 0.0;
  long total_outer = 0;
  long total_inner = 0;
  int max_outer = 0;
  int not_converged = 0;  // status != converged
  int diverged = 0;
  int nonfinite = 0;      // steps with a non-finite force (must stay 0)
  int contact_steps = 0;  // steps with at least one active contact
  double wall_s = 0.0;
};

struct RunConfig {
  SolverKind solver = SolverKind::kLocalUzawa;
  SolverParameters parameters;
};

// The paper's setting (section 3.3.3) at Uzawa error `tolerance_m`.
RunConfig PaperConfig(SolverKind solver, double tolerance_m, int max_iterations,
                      int max_inner_iterations = 1000) {
  RunConfig config;
  config.solver = solver;
  config.parameters.global_tolerance_m = tolerance_m;
  config.parameters.local_tolerance_m = tolerance_m;  // "all thresholds ε1, ε2, ε3 = Uzawa error"
  config.parameters.max_iterations = max_iterations;
  config.parameters.max_inner_iterations = max_inner_iterations;
  config.parameters.rho_rule = RhoRule::kPaperGlobalMin;
  config.parameters.rho_scale = 1.0;
  config.parameters.warm_start = false;
  return config;
}

// The shipped scene's solver settings with another method.
RunConfig DefaultConfig(const SceneSpec& scene, SolverKind solver) {
  RunConfig config;
  config.solver = solver;
  config.parameters = scene.solver_parameters;
  return config;
}

// The accuracy reference (docs/stability.md): local Uzawa with per-contact ρ, warm start,
// ε₁ = 1e-12 m, ε₂ = 1e-13 m. Cross-checked against the exact-local-solve NSGS solver
// (kReferenceNsgs, 10-30x slower here) by `--study refcheck`.
RunConfig ReferenceConfig() {
  RunConfig config;
  config.solver = SolverKind::kLocalUzawa;
  config.parameters.global_tolerance_m = 1e-12;
  config.parameters.local_tolerance_m = 1e-13;
  config.parameters.max_iterations = 100000;
  config.parameters.max_inner_iterations = 1000;
  config.parameters.rho_rule = RhoRule::kPerContact;
  config.parameters.warm_start = true;
  return config;
}

RunConfig NsgsReferenceConfig() {
  RunConfig config;
  config.solver = SolverKind::kReferenceNsgs;
  config.parameters.global_tolerance_m = 1e-10;
  config.parameters.max_iterations = 100000;
  config.parameters.warm_start = true;
  return config;
}

std::string Describe(const RunConfig& c) {
  char text[200];
  std::snprintf(text, sizeof(text), "%s tol %.0e m, rho x%g, %s start",
                std::string(SolverName(c.solver)).c_str(), c.parameters.global_tolerance_m,
                c.parameters.rho_scale, c.parameters.warm_start ? "warm" : "cold");
  return text;
}

// CPU time of this thread, s: the paper's "CPU time", and far less disturbed than wall time
// by the other jobs of a shared machine.
double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

RunResult RunTrajectory(const TwoBodyModel& model, const RunConfig& config, const std::string& tag) {
  const SceneSpec& scene = model.scene();
  TwoBodySession session(model);
  session.solver = config.solver;
  session.parameters = config.parameters;
  RunResult run;
  Stopwatch wall;
  const int steps = scene.total_steps();
  run.steps.reserve(static_cast<std::size_t>(steps));
  for (int step = 1; step <= steps; ++step) {
    const double cpu_start = ThreadCpuSeconds();
    const auto& out = session.Step(scene.DeviceTranslationAtStep(step));
    const double cpu_s = ThreadCpuSeconds() - cpu_start;
    StepRecord record;
    record.step = step;
    record.phase = scene.PhaseOfStep(step);
    record.force_n = out.contact_force_n;
    record.contacts = out.num_contacts;
    record.outer = out.iterations;
    record.inner = out.inner_iterations;
    record.solve_s = out.solve_seconds;
    record.cpu_s = cpu_s;
    record.fc3d = out.fc3d_error;
    record.status = out.status;
    run.total_solve_s += out.solve_seconds;
    run.total_cpu_s += cpu_s;
    run.total_outer += out.iterations;
    run.total_inner += out.inner_iterations;
    run.max_outer = std::max(run.max_outer, out.iterations);
    if (out.status != SolverStatus::kConverged) ++run.not_converged;
    if (out.status == SolverStatus::kDiverged) ++run.diverged;
    if (!out.contact_force_n.allFinite()) ++run.nonfinite;
    if (out.num_contacts > 0) ++run.contact_steps;
    run.steps.push_back(record);
    if (step % 31 == 0 || step == steps) {
      std::fprintf(stderr, "\r  %-60s step %3d/%d  %6.1f s", tag.c_str(), step, steps,
                   wall.ElapsedSeconds());
    }
  }
  run.wall_s = wall.ElapsedSeconds();
  std::fprintf(stderr, "\r  %-60s %d steps %6.1f s: %ld outer, max %d, %d not converged\n",
               tag.c_str(), steps, run.wall_s, run.total_outer, run.max_outer, run.not_converged);
  return run;
}

// The reference run; falls back to the NSGS reference if local Uzawa missed ε₁ anywhere.
RunResult RunReference(const TwoBodyModel& model, const std::string& tag) {
  RunResult reference = RunTrajectory(model, ReferenceConfig(), tag + " reference");
  if (reference.not_converged > 0) {
    std::printf("note: %s: local-Uzawa reference missed 1e-12 m on %d steps; using NSGS at 1e-10 m\n",
                tag.c_str(), reference.not_converged);
    reference = RunTrajectory(model, NsgsReferenceConfig(), tag + " NSGS reference");
  }
  if (reference.not_converged > 0) {
    std::printf("WARNING: %s: the reference did not converge on %d steps\n", tag.c_str(),
                reference.not_converged);
  }
  return reference;
}

// ---------------------------------------------------------------------------------------
// Measures against a reference run of the same trajectory (docs/stability.md).

double TotalVariation(const RunResult& run) {
  double tv = 0.0;
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  for (const StepRecord& s : run.steps) {
    tv += (s.force_n - previous).norm();
    previous = s.force_n;
  }
  return tv;
}

double PeakForce(const RunResult& run) {
  double peak = 0.0;
  for (const StepRecord& s : run.steps) peak = std::max(peak, s.force_n.norm());
  return peak;
}

// Sign changes of the per-step force increment, summed over x, y, z. Increments smaller than
// `threshold_n` are ignored (no sign), so round-off on a flat force does not count.
int SignChanges(const RunResult& run, double threshold_n) {
  int changes = 0;
  for (int c = 0; c < 3; ++c) {
    int last_sign = 0;
    double previous = 0.0;
    for (const StepRecord& s : run.steps) {
      const double delta = s.force_n(c) - previous;
      previous = s.force_n(c);
      if (std::abs(delta) <= threshold_n) continue;
      const int sign = delta > 0 ? 1 : -1;
      if (last_sign != 0 && sign != last_sign) ++changes;
      last_sign = sign;
    }
  }
  return changes;
}

struct Measures {
  double oscillation = 1.0;      // TV(run) / TV(reference)
  int sign_changes = 0;
  int reference_sign_changes = 0;
  double max_error_n = 0.0;      // max_k ‖F_k − F_ref,k‖, N
  double max_error_rel = 0.0;    // the same / max_k ‖F_ref,k‖
  double peak_force_n = 0.0;
};

Measures Compare(const RunResult& run, const RunResult& reference) {
  Measures m;
  const double tv_ref = TotalVariation(reference);
  m.oscillation = tv_ref > 0 ? TotalVariation(run) / tv_ref : 0.0;
  const double peak_ref = PeakForce(reference);
  const double threshold_n = 1e-4 * peak_ref;
  m.sign_changes = SignChanges(run, threshold_n);
  m.reference_sign_changes = SignChanges(reference, threshold_n);
  const std::size_t n = std::min(run.steps.size(), reference.steps.size());
  for (std::size_t k = 0; k < n; ++k) {
    const double e = (run.steps[k].force_n - reference.steps[k].force_n).norm();
    m.max_error_n = std::max(m.max_error_n, std::isfinite(e) ? e : std::numeric_limits<double>::infinity());
  }
  m.max_error_rel = peak_ref > 0 ? m.max_error_n / peak_ref : 0.0;
  m.peak_force_n = PeakForce(run);
  return m;
}

// ---------------------------------------------------------------------------------------
// Scenes.

SceneSpec LoadBenchmark(const Options& o, int number) {
  SceneSpec scene = hapco::io::LoadSceneFile(o.scene_dir + "/benchmark" + std::to_string(number) + ".txtpb");
  // The documented figures and stability tables were measured with a Tet10 tool and local
  // Uzawa as the "default" configuration (the shipped defaults before docs/speed-accuracy.md
  // chose a Tet4 tool and, for benchmark 1, global Uzawa GS). Pinned so they reproduce.
  scene.tool.box.order = hapco::fem::ElementOrder::kTet10;
  scene.solver = hapco::contact::SolverKind::kLocalUzawa;
  if (o.quick) {
    // Smoke run: coarse meshes and a short trajectory.
    scene.obstacle.box.divisions = Eigen::Vector3i(10, 2, 2);
    scene.tool.box.divisions = Eigen::Vector3i(2, 2, 1);
    for (auto& phase : scene.trajectory) phase.steps = std::max(1, phase.steps / 10);
  }
  return scene;
}

// The stability sweeps' mesh: obstacle 10 x 2 x 2 and tool 2 x 2 x 1 Tet10 cells (25 contact
// candidates instead of 81), so ~200 runs fit in minutes. Unchanged under --quick.
SceneSpec CoarseScene(SceneSpec scene) {
  scene.obstacle.box.divisions = Eigen::Vector3i(10, 2, 2);
  scene.tool.box.divisions = Eigen::Vector3i(2, 2, 1);
  return scene;
}

// Fewer, larger device increments: each phase in ceil(steps / factor) steps.
SceneSpec ScaleIncrements(SceneSpec scene, int factor) {
  for (auto& phase : scene.trajectory) phase.steps = std::max(1, (phase.steps + factor - 1) / factor);
  return scene;
}

// The tool moved next to a clamped (or, on benchmark 2, the free) end of the obstacle. The
// slide along x goes away from the end first, so the tool never overhangs the obstacle.
SceneSpec NearEnd(SceneSpec scene, bool right_end) {
  const double length_m = scene.obstacle.box.size_m.x();
  const double tool_m = scene.tool.box.size_m.x();
  scene.tool.box.min_corner_m.x() = right_end ? scene.obstacle.box.min_corner_m.x() + length_m - tool_m
                                              : scene.obstacle.box.min_corner_m.x();
  if (right_end) {
    for (auto& phase : scene.trajectory) {
      phase.displacement_m.x() = -phase.displacement_m.x();
      if (phase.name == "slide+x") phase.name = "slide-x";
      else if (phase.name == "slide-x") phase.name = "slide+x";
    }
  }
  return scene;
}

// ---------------------------------------------------------------------------------------
// CSV helpers.

std::FILE* OpenCsv(const Options& o, const std::string& name, const char* header) {
  const std::string path = o.out_dir + "/" + name;
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw hapco::InputError("cannot write " + path);
  std::fprintf(f, "%s\n", header);
  std::printf("writing %s\n", path.c_str());
  return f;
}

const char* Name(SolverKind k) { return SolverName(k).data(); }

// ---------------------------------------------------------------------------------------
// Figures 6/7: outer iterations per step, benchmark 1, μ = 0.3, paper settings.

void StudyFig67(const Options& o) {
  std::printf("\n== Figures 6/7: iterations per step, benchmark 1, mu 0.3, cold start, paper rho ==\n");
  SceneSpec scene = LoadBenchmark(o, 1);
  scene.friction_coefficient = 0.3;
  const TwoBodyModel model(scene);
  std::FILE* f = OpenCsv(o, "paper_fig67_iterations.csv",
                         "tol_m,solver,step,phase,contacts,outer,inner,status,fz_n");
  std::FILE* s = OpenCsv(o, "paper_fig67_summary.csv",
                         "tol_m,solver,phase,steps,mean_outer,max_outer,total_inner,not_converged,cpu_s");
  std::printf("%-8s %-28s %s\n", "tol_m", "solver", "mean outer iterations per phase (press slide+x slide+y slide-x lift), not converged");
  for (double tol : {1e-6, 1e-7}) {
    for (const Method& method : kFig67Methods) {
      RunConfig config = PaperConfig(method.kind, tol, 5000);
      config.parameters.rho_scale = method.rho_scale;
      config.parameters.rho_rule = method.rho_rule;
      const char* name = method.label;
      const RunResult run = RunTrajectory(model, config, "fig67 " + Describe(config));
      for (const StepRecord& r : run.steps) {
        std::fprintf(f, "%.0e,%s,%d,%d,%d,%d,%d,%s,%.5g\n", tol, name, r.step, r.phase, r.contacts,
                     r.outer, r.inner, StatusName(r.status).data(), r.force_n.z());
      }
      std::printf("%-8.0e %-28s", tol, name);
      for (int p = 0; p < static_cast<int>(scene.trajectory.size()); ++p) {
        int count = 0, max_outer = 0, nc = 0;
        long outer = 0, inner = 0;
        double solve = 0;
        for (const StepRecord& r : run.steps) {
          if (r.phase != p) continue;
          ++count;
          outer += r.outer;
          inner += r.inner;
          max_outer = std::max(max_outer, r.outer);
          solve += r.cpu_s;
          if (r.status != SolverStatus::kConverged) ++nc;
        }
        const double mean = count > 0 ? static_cast<double>(outer) / count : 0.0;
        std::fprintf(s, "%.0e,%s,%s,%d,%.3f,%d,%ld,%d,%.6g\n", tol, name,
                     scene.trajectory[static_cast<std::size_t>(p)].name.c_str(), count, mean,
                     max_outer, inner, nc, solve);
        std::printf(" %8.1f", mean);
      }
      std::printf("   nc %d, total %ld outer, %.2f s CPU\n", run.not_converged, run.total_outer,
                  run.total_cpu_s);
    }
  }
  std::fclose(f);
  std::fclose(s);
}

// ---------------------------------------------------------------------------------------
// Figure 8: CPU time against the Uzawa error, benchmark 1, μ = 0.6, paper settings.

void StudyFig8(const Options& o) {
  std::printf("\n== Figure 8: CPU time vs Uzawa error, benchmark 1, mu 0.6, cold start, paper rho ==\n");
  SceneSpec scene = LoadBenchmark(o, 1);
  scene.friction_coefficient = 0.6;
  const TwoBodyModel model(scene);
  const RunResult reference = RunReference(model, "fig8");
  std::FILE* f = OpenCsv(o, "paper_fig8_cpu_per_step.csv", "tol_m,solver,step,phase,outer,cpu_us,status");
  std::FILE* s = OpenCsv(o, "paper_fig8_cpu_vs_tol.csv",
                         "tol_m,solver,total_cpu_s,median_step_cpu_us,max_step_cpu_us,total_solve_wall_s,total_outer,total_inner,"
                         "not_converged,max_force_error_rel");
  std::printf("%-8s %-22s %12s %12s %10s %8s %6s %10s\n", "tol_m", "solver", "total CPU s",
              "median us", "max us", "outer", "nc", "F err rel");
  const std::vector<double> tolerances = o.quick ? std::vector<double>{1e-5, 1e-7}
                                                 : std::vector<double>{1e-5, 1e-6, 1e-7, 1e-8, 1e-9};
  for (double tol : tolerances) {
    for (SolverKind k : kMethods) {
      const RunConfig config = PaperConfig(k, tol, 5000);
      const RunResult run = RunTrajectory(model, config, "fig8 " + Describe(config));
      std::vector<double> times;
      double max_us = 0;
      for (const StepRecord& r : run.steps) {
        times.push_back(r.cpu_s * 1e6);
        max_us = std::max(max_us, r.cpu_s * 1e6);
        // Per-step series for the paper's own setting only (Uzawa error 1e-4 cm = 1e-6 m).
        if (tol == 1e-6 || (o.quick && tol == 1e-5)) {
          std::fprintf(f, "%.0e,%s,%d,%d,%d,%.2f,%s\n", tol, Name(k), r.step, r.phase, r.outer,
                       r.cpu_s * 1e6, StatusName(r.status).data());
        }
      }
      std::sort(times.begin(), times.end());
      const double median = times.empty() ? 0.0 : times[times.size() / 2];
      const Measures m = Compare(run, reference);
      std::fprintf(s, "%.0e,%s,%.6g,%.2f,%.2f,%.6g,%ld,%ld,%d,%.3e\n", tol, Name(k), run.total_cpu_s,
                   median, max_us, run.total_solve_s, run.total_outer, run.total_inner, run.not_converged, m.max_error_rel);
      std::printf("%-8.0e %-22s %12.3f %12.1f %10.1f %8ld %6d %10.2e\n", tol, Name(k),
                  run.total_cpu_s, median, max_us, run.total_outer, run.not_converged, m.max_error_rel);
    }
  }
  std::fclose(f);
  std::fclose(s);
}

// ---------------------------------------------------------------------------------------
// Figure 9: benchmark 2 (left clamp only), μ = 0 .. 0.6, paper settings.

void StudyFig9(const Options& o) {
  std::printf("\n== Figure 9: benchmark 2 (left clamp), mu sweep, cold start, paper rho, tol 1e-6 m ==\n");
  std::FILE* s = OpenCsv(o, "paper_fig9_benchmark2.csv",
                         "mu,solver,total_outer,max_outer,not_converged,diverged,oscillation,"
                         "sign_changes,reference_sign_changes,max_force_error_n,max_force_error_rel,"
                         "peak_force_n,cpu_s");
  std::FILE* f = OpenCsv(o, "paper_fig9_forces.csv", "mu,solver,step,phase,outer,status,fx_n,fz_n");
  std::printf("%-5s %-22s %8s %6s %5s %5s %8s %6s %10s\n", "mu", "solver", "outer", "max", "nc",
              "div", "osc", "signs", "F err rel");
  const std::vector<double> mus = o.quick ? std::vector<double>{0.0, 0.6}
                                          : std::vector<double>{0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6};
  for (double mu : mus) {
    SceneSpec scene = LoadBenchmark(o, 2);
    scene.friction_coefficient = mu;
    const TwoBodyModel model(scene);
    char tag[64];
    std::snprintf(tag, sizeof(tag), "fig9 mu %.1f ", mu);
    const RunResult reference = RunReference(model, tag);
    auto write_forces = [&](const char* solver, const RunResult& run) {
      for (const StepRecord& r : run.steps) {
        std::fprintf(f, "%.1f,%s,%d,%d,%d,%s,%.5g,%.5g\n", mu, solver, r.step, r.phase, r.outer,
                     StatusName(r.status).data(), r.force_n.x(), r.force_n.z());
      }
    };
    const bool traced = std::abs(mu - 0.3) < 1e-9 || std::abs(mu - 0.6) < 1e-9;
    if (traced) write_forces("reference", reference);
    for (const Method& method : kFigureMethods) {
      RunConfig config = PaperConfig(method.kind, 1e-6, 5000);
      config.parameters.rho_scale = method.rho_scale;
      const char* name = method.label;
      const RunResult run = RunTrajectory(model, config, std::string(tag) + Describe(config));
      const Measures m = Compare(run, reference);
      std::fprintf(s, "%.1f,%s,%ld,%d,%d,%d,%.4f,%d,%d,%.4e,%.4e,%.5g,%.4g\n", mu, name,
                   run.total_outer, run.max_outer, run.not_converged, run.diverged, m.oscillation,
                   m.sign_changes, m.reference_sign_changes, m.max_error_n, m.max_error_rel,
                   m.peak_force_n, run.total_cpu_s);
      std::printf("%-5.1f %-22s %8ld %6d %5d %5d %8.3f %3d/%-3d %10.2e\n", mu, name, run.total_outer,
                  run.max_outer, run.not_converged, run.diverged, m.oscillation, m.sign_changes,
                  m.reference_sign_changes, m.max_error_rel);
      if (traced) write_forces(name, run);
    }
  }
  std::fclose(s);
  std::fclose(f);
}

// ---------------------------------------------------------------------------------------
// Stability study.

// Caps for the sweeps (the shipped scene's: 1000 outer, 100 inner per contact). A run whose
// inner loops cycle costs 1000 x 100 local updates per contact per step at these caps.
constexpr int kSweepMaxIterations = 1000;
constexpr int kSweepMaxInner = 100;

struct StabilityCase {
  std::string sweep;   // rho | mu | increment | end
  std::string label;   // the case, e.g. "benchmark1 mu=0.3"
  double value = 0.0;  // the swept value
  SceneSpec scene;
};

void StudyStability(const Options& o) {
  std::printf("\n== Stability study ==\n");
  std::FILE* s = OpenCsv(o, "stability_summary.csv",
                         "sweep,case,value,config,solver,rho_scale,steps,contact_steps,reference_contact_steps,total_outer,max_outer,"
                         "not_converged,diverged,nonfinite,oscillation,sign_changes,"
                         "reference_sign_changes,max_force_error_n,max_force_error_rel,cpu_s");
  std::FILE* t = OpenCsv(o, "stability_traces.csv", "config,solver,rho_scale,step,phase,outer,status,fz_n");
  std::printf("%-9s %-26s %-8s %-22s %5s %6s %5s %5s %8s %7s %10s\n", "sweep", "case", "config",
              "solver", "rho", "outer", "nc", "div", "osc", "signs", "F err rel");

  // Run one case: the reference, then every method in the shipped ("default") and the
  // paper's ("paper": cold start, ε₁ = ε₂ = 1e-6 m) settings at each ρ scale.
  auto run_case = [&](const StabilityCase& c, const std::vector<double>& rho_scales, bool trace) {
    const TwoBodyModel model(c.scene);
    const RunResult reference = RunReference(model, c.label);
    auto write_trace = [&](const char* config, const char* solver, double rho, const RunResult& run) {
      for (const StepRecord& r : run.steps) {
        std::fprintf(t, "%s,%s,%g,%d,%d,%d,%s,%.5g\n", config, solver, rho, r.step, r.phase, r.outer,
                     StatusName(r.status).data(), r.force_n.z());
      }
    };
    if (trace) write_trace("reference", "reference", 1.0, reference);
    for (const char* config_name : {"default", "paper"}) {
      for (SolverKind k : kMethods) {
        for (double rho : rho_scales) {
          RunConfig config = std::string(config_name) == "default"
                                 ? DefaultConfig(c.scene, k)
                                 : PaperConfig(k, 1e-6, kSweepMaxIterations, kSweepMaxInner);
          config.parameters.rho_scale = rho;
          const RunResult run = RunTrajectory(model, config, c.label + " " + config_name + " " + Describe(config));
          const Measures m = Compare(run, reference);
          std::fprintf(s, "%s,%s,%g,%s,%s,%g,%zu,%d,%d,%ld,%d,%d,%d,%d,%.4f,%d,%d,%.4e,%.4e,%.4g\n",
                       c.sweep.c_str(), c.label.c_str(), c.value, config_name, Name(k), rho,
                       run.steps.size(), run.contact_steps, reference.contact_steps, run.total_outer, run.max_outer, run.not_converged,
                       run.diverged, run.nonfinite, m.oscillation, m.sign_changes,
                       m.reference_sign_changes, m.max_error_n, m.max_error_rel, run.total_cpu_s);
          std::printf("%-9s %-26s %-8s %-22s %5g %6ld %5d %5d %8.3f %3d/%-3d %10.2e\n", c.sweep.c_str(),
                      c.label.c_str(), config_name, Name(k), rho, run.total_outer, run.not_converged,
                      run.diverged, m.oscillation, m.sign_changes, m.reference_sign_changes,
                      m.max_error_rel);
          // Traces (one case only, keeps the CSV small): the default config at ρ x1, x3, x10.
          if (trace && std::string(config_name) == "default" && rho >= 1.0) {
            write_trace(config_name, Name(k), rho, run);
          }
        }
      }
    }
    std::fflush(s);
  };

  const std::vector<double> rho_scales = {0.1, 0.3, 1.0, 3.0, 10.0};
  const std::vector<double> one_rho = {1.0};
  auto base = [&](int bench) { return o.quick ? LoadBenchmark(o, bench) : CoarseScene(LoadBenchmark(o, bench)); };
  char label[96];
  // 1. ρ scale, both benchmarks, μ = 0.3 (traced: the per-step forces for the chart).
  for (int bench : {1, 2}) {
    std::snprintf(label, sizeof(label), "benchmark%d mu=0.3", bench);
    run_case({"rho", label, 0.3, base(bench)}, rho_scales, bench == 2);
  }
  // 2. μ, benchmark 1 (benchmark 2 at the default mesh is figure 9).
  const std::vector<double> mus = o.quick ? std::vector<double>{0.0, 1.0}
                                          : std::vector<double>{0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0};
  for (double mu : mus) {
    SceneSpec scene = base(1);
    scene.friction_coefficient = mu;
    std::snprintf(label, sizeof(label), "benchmark1 mu=%.1f", mu);
    run_case({"mu", label, mu, scene}, one_rho, false);
  }
  // 3. Size of the device increment (the paper's "excessive free displacement").
  const std::vector<int> factors = o.quick ? std::vector<int>{1, 10} : std::vector<int>{1, 2, 5, 8, 10, 30};
  for (int bench : {1, 2}) {
    for (int factor : factors) {
      std::snprintf(label, sizeof(label), "benchmark%d increment x%d", bench, factor);
      run_case({"increment", label, static_cast<double>(factor), ScaleIncrements(base(bench), factor)},
               one_rho, false);
    }
  }
  // 4. Contact next to the obstacle's ends (clamped; benchmark 2's right end is free), with
  //    the normal and a 10x larger device increment.
  for (int bench : {1, 2}) {
    for (bool right : {false, true}) {
      for (int factor : {1, 10}) {
        std::snprintf(label, sizeof(label), "benchmark%d %s end%s", bench, right ? "right" : "left",
                      factor > 1 ? " increment x10" : "");
        run_case({"end", label, static_cast<double>(factor), ScaleIncrements(NearEnd(base(bench), right), factor)},
                 one_rho, false);
      }
    }
  }
  std::fclose(s);
  std::fclose(t);
}

// The accuracy reference against the exact-local-solve NSGS solver, on the coarse mesh
// (NSGS is 10-40x slower), benchmarks 1 and 2, μ = 0.3 and 0.6.
void StudyReferenceCheck(const Options& o) {
  std::printf("\n== Reference check: local Uzawa 1e-12 m (per-contact rho) vs NSGS exact 1e-10 m, coarse mesh ==\n");
  std::FILE* s = OpenCsv(o, "stability_reference_check.csv",
                         "benchmark,mu,max_force_difference_n,max_force_difference_rel,"
                         "reference_not_converged,nsgs_not_converged,reference_s,nsgs_s");
  for (int bench : {1, 2}) {
    for (double mu : {0.3, 0.6}) {
      SceneSpec scene = CoarseScene(LoadBenchmark(o, bench));
      scene.friction_coefficient = mu;
      const TwoBodyModel model(scene);
      char tag[64];
      std::snprintf(tag, sizeof(tag), "refcheck b%d mu %.1f", bench, mu);
      const RunResult local = RunTrajectory(model, ReferenceConfig(), std::string(tag) + " local");
      const RunResult nsgs = RunTrajectory(model, NsgsReferenceConfig(), std::string(tag) + " nsgs");
      const Measures m = Compare(local, nsgs);
      std::fprintf(s, "%d,%.1f,%.3e,%.3e,%d,%d,%.3g,%.3g\n", bench, mu, m.max_error_n, m.max_error_rel,
                   local.not_converged, nsgs.not_converged, local.wall_s, nsgs.wall_s);
      std::printf("benchmark %d mu %.1f: max |F_local - F_nsgs| = %.3e N (%.3e of peak); not converged %d / %d\n",
                  bench, mu, m.max_error_n, m.max_error_rel, local.not_converged, nsgs.not_converged);
    }
  }
  std::fclose(s);

  // How strongly the contacts are coupled: λ_max(W) against max W_ii at the 10th press step
  // (1 mm), on both meshes. The Jacobi order needs ρ λ_max(W) < 2; the one-contact steps need
  // ρ λ_max(W_αα) < 2 (docs/stability.md).
  std::FILE* w = OpenCsv(o, "stability_spectrum.csv",
                         "benchmark,mesh,contacts,max_w_ii_m_per_n,lambda_max_w_m_per_n,lambda_max_w_over_max_w_ii,"
                         "max_lambda_block_over_max_w_ii");
  for (int bench : {1, 2}) {
    for (bool coarse : {true, false}) {
      const SceneSpec scene = coarse ? CoarseScene(LoadBenchmark(o, bench)) : LoadBenchmark(o, bench);
      const TwoBodyModel model(scene);
      TwoBodySession session(model);
      for (int step = 1; step <= std::min(10, scene.total_steps()); ++step) {
        session.Step(scene.DeviceTranslationAtStep(step));
      }
      const Eigen::MatrixXd& flex = session.last_problem().flexibility_m_per_n;
      if (flex.rows() == 0) continue;
      const double max_wii = flex.diagonal().maxCoeff();
      const double lambda = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(flex, Eigen::EigenvaluesOnly)
                                .eigenvalues().maxCoeff();
      double block = 0.0;
      for (Eigen::Index a = 0; a < flex.rows() / 3; ++a) {
        const Eigen::Matrix3d b = flex.block<3, 3>(3 * a, 3 * a);
        block = std::max(block, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(b).eigenvalues().maxCoeff());
      }
      std::fprintf(w, "%d,%s,%ld,%.4e,%.4e,%.3f,%.3f\n", bench, coarse ? "coarse" : "default",
                   static_cast<long>(flex.rows() / 3), max_wii, lambda, lambda / max_wii, block / max_wii);
      std::printf("benchmark %d %s mesh: %ld contacts, lambda_max(W) = %.2f max W_ii, max lambda(W_aa) = %.2f max W_ii\n",
                  bench, coarse ? "coarse" : "default", static_cast<long>(flex.rows() / 3), lambda / max_wii,
                  block / max_wii);
    }
  }
  std::fclose(w);
}

constexpr const char* kDescription =
    R"(Reproduces the paper's figures 6-9 (section 3.3.3) with the two-body haptic pipeline and runs the stability study (docs/paper-comparison.md, docs/stability.md). Writes small CSVs into the --output directory; scripts/plot_paper_figures.py draws them (scripts/reproduce-paper-figures does both). Prints numbers, never asserts.)";

constexpr const char* kFooter = "Exit code: 0 when the studies ran, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("hapco_paper_study", "--output DIR [options]", kDescription, kFooter);
  command.AddChoice("--study", &o->study, {"all", "refcheck", "fig67", "fig8", "fig9", "stability"},
                    "which study to run (default all): refcheck (the accuracy reference against the exact-local-solve "
                    "NSGS solver), fig67, fig8, fig9 (the paper's figures), stability (docs/stability.md)",
                    "Run");
  command.AddFlag("--quick", &o->quick, "coarse meshes, short trajectories: a smoke run (ctest)", "Run");
  command.AddText("--scenes", &o->scene_dir, "DIR",
                  "directory holding benchmark1.txtpb and benchmark2.txtpb (default: proto/scenes of the "
                  "source tree)",
                  "Run");
  command.AddOutputDirectory("--output", &o->out_dir, "DIR", "directory for the CSVs, created if missing (required)",
                  hapco::cli::kGroupOutput);
  command.Deprecate("--out", "--output");
  if (!command.Parse(argc, argv)) return false;
  if (o->out_dir.empty()) throw hapco::InputError("--output DIR is required (see --help)");
  return true;
}

int Run(const Options& o) {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // line by line through `| tee`
  std::filesystem::create_directories(o.out_dir);
  Stopwatch total;
  const bool all = o.study == "all";
  if (all || o.study == "refcheck") StudyReferenceCheck(o);
  if (all || o.study == "fig67") StudyFig67(o);
  if (all || o.study == "fig8") StudyFig8(o);
  if (all || o.study == "fig9") StudyFig9(o);
  if (all || o.study == "stability") StudyStability(o);
  std::printf("\nhapco_paper_study: %s done in %.1f s\n", o.study.c_str(), total.ElapsedSeconds());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco_paper_study", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
