// Per-step cost of the haptic step pipeline (sim/step_pipeline.h) on a shipped scene:
//   - precomputed mode over the whole trajectory, repeated: median / p99 / max of the step
//     and of each stage (detect, assemble ũ and W, solve, update);
//   - the paper's per-step full solves (kFullSolve) on the first --full-steps steps only
//     (about 1 s per step on the default scene), and the precomputed mode on the same steps
//     in the same run: the ratio of medians;
//   - --path top-face: instead of the scene's trajectory, a 3 mm press and a 0.1 mm-step sweep
//     over the whole top face (tool from x = 5 mm to 95 mm): the cost anywhere on the bar;
//   - the per-scene precomputation: TwoBodyModelStats, operator bytes, peak RSS;
//   - heap allocations per step (global operator new counted);
//   - --cold-mib M: M MiB of other data are read between steps, as in the server, where DDS,
//     the clients and other sessions run between two 1 kHz ticks: the step with cold caches.
// The machine is shared: the load average is printed at start and end. Prints numbers only.
#include <algorithm>
#include <chrono>
#include <thread>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "common/load_average.h"
#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/memory.h"
#include "common/timer.h"
#include "io/scene_file.h"
#include "sim/device_path.h"
#include "sim/local_model.h"
#include "sim/surface_ahead.h"
#include "sim/step_pipeline.h"

namespace {

std::atomic<long> g_allocations{0};

}  // namespace

// Counting allocator: Eigen allocates with malloc, the standard library with operator new
// (which calls malloc in glibc), so counting malloc/calloc/realloc sees every heap allocation.
// glibc lets the executable interpose malloc and exposes the real one as __libc_malloc.
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* malloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(count, size);
}
void* realloc(void* p, std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, size);
}
}

namespace {

using namespace hapco;  // NOLINT: a short benchmark

struct Options {
  std::string scene = std::string(HAPCO_SOURCE_DIR) + "/proto/scenes/benchmark1.txtpb";
  int repeats = 3;
  int full_steps = 12;
  int steps = 0;  // 0: the whole trajectory
  std::string csv;
  std::string path = "scene";  // or "top-face"
  int cold_mib = 0;  // MiB read between steps (0: warm caches)
  int pace_us = 0;   // steps start every pace_us, sleeping in between, as the server's tick (0: back to back)
  std::string kernel = "fastest";  // compliance kernels of the step (sim/compliance_kernels.h)
  int kernel_repeats = 3;          // interleaved runs per kernel in the kernel comparison (0: skip)
};

sim::ComplianceKernel KernelByName(const std::string& name) {
  if (name == "portable") return sim::ComplianceKernel::kPortable;
  if (name == "avx2-fma") return sim::ComplianceKernel::kAvx2Fma;
  return sim::FastestComplianceKernel();
}

// The device path of the run: the scene's trajectory, or the top-face sweep.
std::vector<Eigen::Vector3d> DevicePath(const sim::SceneSpec& scene, const std::string& name) {
  if (name == "scene") return scene.DeviceTrajectory();
  if (name != "top-face") throw InputError("--path must be scene or top-face, got " + name);
  const Eigen::Vector3d home = scene.tool.box.min_corner_m;
  const double x_low = 0.005 - home.x(), x_high = 0.095 - scene.tool.box.size_m.x() - home.x();
  return sim::PolylinePath({{0, 0, 0}, {0, 0, -0.003}, {x_low, 0, -0.003}, {x_high, 0, -0.003},
                            {0, 0, -0.003}, {0, 0, 0}},
                           1e-4);
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())) - 1));
  return v[q <= 0 ? 0 : i];
}

struct Series {
  std::vector<double> step, detect, assemble, solve, update;
  void Add(const sim::StepOutput& out) {
    step.push_back(out.total_seconds);
    detect.push_back(out.detect_seconds);
    assemble.push_back(out.assemble_seconds);
    solve.push_back(out.solve_seconds);
    update.push_back(out.update_seconds);
  }
};

// Reads and writes every cache line of *data: evicts the step's working set (a cache line is 8
// doubles). Returns a sum so the reads are not optimised away.
double EvictCaches(std::vector<double>* data) {
  double sum = 0.0;
  for (std::size_t i = 0; i < data->size(); i += 8) {
    sum += (*data)[i];
    (*data)[i] = sum * 1e-300;
  }
  return sum;
}

// Sleeps until the next tick, pace_us after the last one, as the server's tick loop does; a tick
// already past (a slow step, or other work since) starts now instead of a burst of catch-up
// steps back to back. No-op for pace_us = 0.
void WaitForTick(int pace_us, std::chrono::steady_clock::time_point* next) {
  if (pace_us <= 0) return;
  *next += std::chrono::microseconds(pace_us);
  const auto now = std::chrono::steady_clock::now();
  if (*next < now) *next = now;
  std::this_thread::sleep_until(*next);
}

void PrintRow(const char* name, const std::vector<double>& v) {
  std::printf("  %-11s median %9.1f us   p99 %9.1f us   max %9.1f us\n", name, 1e6 * Percentile(v, 0.5),
              1e6 * Percentile(v, 0.99), 1e6 * Percentile(v, 1.0));
}

constexpr const char* kDescription =
    R"(Per-step cost of the haptic step pipeline (detect, assemble, solve, update) on a scene: the precomputed mode over the whole trajectory, repeated (median, p99, max of the step and of each stage); the paper's per-step full solves on the first --full-steps steps against the precomputed mode on the same steps in the same run; the per-scene precomputation (time, operator bytes, peak RSS); heap allocations per step. The machine is shared: the load average is printed at start and end. Prints numbers only (docs/performance.md).)";

constexpr const char* kFooter = "Exit code: 0 when the benchmark ran, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("sim_pipeline_bench", "[SCENE.txtpb] [options]", kDescription, kFooter);
  command.app()
      .add_option("SCENE", options->scene,
                  "scene file (proto/scene.proto); default: proto/scenes/benchmark1.txtpb of the source tree")
      ->group("Arguments");
  command.AddInteger("--repeats", &options->repeats, "N",
                     "whole-trajectory runs of the precomputed mode (default 3)", "Run", 1, 1000000);
  command.AddInteger("--full-steps", &options->full_steps, "N",
                     "steps timed in full-solve mode, from step 1 (about 1 s each on the default scene; default "
                     "12; 0 = skip)",
                     "Run", 0, 100000000);
  command.AddInteger("--steps", &options->steps, "N", "trajectory steps per run (default 0 = all)", "Run", 0,
                     100000000);
  command.AddChoice("--path", &options->path, {"scene", "top-face"},
                    "scene: the scene's trajectory (default); top-face: a 3 mm press and a 0.1 mm-step sweep over "
                    "the whole top face (tool from x = 5 mm to 95 mm)",
                    "Run");
  command.AddInteger("--pace-us", &options->pace_us, "T",
                     "start a step every T us and sleep in between, as a server's 1 kHz tick does (T = 1000); "
                     "the core idles between steps (default 0: back to back)",
                     "Run", 0, 1000000);
  command.AddInteger("--cold-mib", &options->cold_mib, "M",
                     "read M MiB of other data between steps (cold caches, as in the server, where DDS, the "
                     "clients and other sessions run between two 1 kHz ticks; default 0)",
                     "Run", 0, 65536);
  command.AddChoice("--kernel", &options->kernel, {"fastest", "portable", "avx2-fma"},
                    "compliance kernels of the timed runs (sim/compliance_kernels.h; default fastest: avx2-fma "
                    "where the CPU has it)",
                    "Run");
  command.AddInteger("--kernel-repeats", &options->kernel_repeats, "N",
                     "runs per kernel, interleaved, in the portable vs avx2-fma comparison (default 3; 0 = skip; "
                     "skipped where the CPU lacks AVX2/FMA)",
                     "Run", 0, 1000);
  command.AddCsv(&options->csv, "per-step rows of the last precomputed run");
  command.Deprecate("--scene", "");
  return command.Parse(argc, argv);
}

int Run(const Options& options) {
  std::printf("load average at start: %s (2 cores, shared)\n", hapco::LoadAverageText().c_str());
  const sim::SceneSpec scene = io::LoadSceneFile(options.scene);
  const std::size_t rss_before = PeakResidentBytes();
  Stopwatch setup;
  const sim::TwoBodyModel model(scene);
  const double setup_s = setup.ElapsedSeconds();
  const std::size_t rss_after = PeakResidentBytes();
  const sim::TwoBodyModelStats& stats = model.stats();
  std::printf("scene %s: obstacle %s %dx%dx%d (%d dofs), tool %s %dx%dx%d (%d dofs); %zu obstacle + %zu tool candidate nodes\n",
              scene.name.c_str(), std::string(fem::ToString(scene.obstacle.box.order)).c_str(),
              scene.obstacle.box.divisions.x(), scene.obstacle.box.divisions.y(), scene.obstacle.box.divisions.z(),
              model.obstacle().num_dofs(), std::string(fem::ToString(scene.tool.box.order)).c_str(),
              scene.tool.box.divisions.x(), scene.tool.box.divisions.y(), scene.tool.box.divisions.z(),
              model.tool().num_dofs(), model.obstacle_candidates().size(), model.tool_candidates().size());
  std::printf("solver %s, tolerance %.3g m, %s start\n", std::string(contact::SolverName(scene.solver)).c_str(),
              scene.solver_parameters.global_tolerance_m, scene.solver_parameters.warm_start ? "warm" : "cold");
  std::printf("precomputation: %.3f s wall (build+factor %.3f s, compliance blocks %.3f s, model total %.3f s), "
              "operators %.2f MiB, peak RSS %.1f MiB before -> %.1f MiB after\n",
              setup_s, stats.build_seconds, stats.compliance_seconds, stats.total_seconds,
              static_cast<double>(stats.operator_bytes) / (1 << 20), static_cast<double>(rss_before) / (1 << 20),
              static_cast<double>(rss_after) / (1 << 20));
  const std::vector<Eigen::Vector3d> path = DevicePath(scene, options.path);
  const int path_steps = static_cast<int>(path.size()) - 1;
  const int steps = options.steps > 0 ? std::min(options.steps, path_steps) : path_steps;
  std::printf("path %s: %d steps\n", options.path.c_str(), steps);

  std::vector<double> cold(static_cast<std::size_t>(options.cold_mib) << 17);  // doubles
  double cold_sum = 0.0;
  // Precomputed mode over the whole trajectory, `repeats` times (a fresh session each time).
  Series all;
  std::vector<double> alloc_per_step;
  std::vector<double> region_nodes, contacts;
  long outer_iterations = 0;
  std::FILE* csv = options.csv.empty() ? nullptr : std::fopen(options.csv.c_str(), "w");
  if (!options.csv.empty() && csv == nullptr) throw InputError("cannot write " + options.csv);
  if (csv != nullptr) {
    std::fprintf(csv, "step,contacts,edge_contacts,region_nodes,outer_iterations,detect_s,assemble_s,solve_s,update_s,step_s,force_n,allocations\n");
  }
  // The local contact model the server sends with each force (issue 12): timed after each
  // step, apart from it, with its allocations.
  std::vector<double> local_model_s, local_model_alloc, local_model_unknowns;
  auto tick = std::chrono::steady_clock::now();
  long beyond_range = 0;  // steps that needed a pair beyond a banded compliance
  for (int repeat = 0; repeat < options.repeats; ++repeat) {
    sim::TwoBodySession session(model, sim::SolveMode::kPrecomputed);
    session.compliance_kernel = KernelByName(options.kernel);
    sim::LocalModelBuilder local_model;
    for (int step = 1; step <= steps; ++step) {
      const Eigen::Vector3d& d = path[static_cast<std::size_t>(step)];
      if (!cold.empty()) cold_sum += EvictCaches(&cold);
      WaitForTick(options.pace_us, &tick);
      const long before = g_allocations.load();
      const sim::StepOutput& out = session.Step(d);
      const long allocations = g_allocations.load() - before;
      all.Add(out);
      alloc_per_step.push_back(static_cast<double>(allocations));
      outer_iterations += out.iterations;
      beyond_range += out.compliance_out_of_range;
      {
        const long model_before = g_allocations.load();
        Stopwatch model_watch;
        const sim::LocalContactModel& m = local_model.Linearize(session);
        local_model_s.push_back(model_watch.ElapsedSeconds());
        local_model_alloc.push_back(static_cast<double>(g_allocations.load() - model_before));
        local_model_unknowns.push_back(3 * m.sticking + m.sliding);
      }
      region_nodes.push_back(out.region_nodes);
      contacts.push_back(out.num_contacts);
      if (csv != nullptr && repeat == options.repeats - 1) {
        std::fprintf(csv, "%d,%d,%d,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%ld\n", step, out.num_contacts,
                     out.num_edge_contacts, out.region_nodes, out.iterations, out.detect_seconds,
                     out.assemble_seconds, out.solve_seconds, out.update_seconds, out.total_seconds,
                     out.contact_force_n.norm(), allocations);
      }
    }
    std::fprintf(stderr, "precomputed run %d/%d done\n", repeat + 1, options.repeats);
  }
  if (csv != nullptr) std::fclose(csv);
  std::printf("\nprecomputed mode, %d steps x %d runs (%ld outer iterations per run, %s kernels)%s:\n", steps,
              options.repeats, outer_iterations / options.repeats,
              sim::ComplianceKernelName(KernelByName(options.kernel)),
              (std::string(cold.empty() ? "" : ", " + std::to_string(options.cold_mib) + " MiB read between steps") +
               (options.pace_us > 0 ? ", one step every " + std::to_string(options.pace_us) + " us" : ""))
                  .c_str());
  if (model.obstacle_surface().range_axis >= 0) {
    std::printf("  banded obstacle compliance, range %.3g m: %ld of %d steps needed a pair beyond it\n",
                model.obstacle_surface().range_m, beyond_range / options.repeats, steps);
  }
  volatile double keep_eviction_reads = cold_sum;  // the reads must not be optimised away
  (void)keep_eviction_reads;
  PrintRow("step", all.step);
  PrintRow("detect", all.detect);
  PrintRow("assemble", all.assemble);
  PrintRow("solve", all.solve);
  PrintRow("update", all.update);
  PrintRow("local model", local_model_s);
  std::printf("  local model (not in the step above): unknowns median %.0f, max %.0f (3 per sticking, 1 per sliding "
              "contact); heap allocations median %.0f, max %.0f\n",
              Percentile(local_model_unknowns, 0.5), Percentile(local_model_unknowns, 1.0),
              Percentile(local_model_alloc, 0.5), Percentile(local_model_alloc, 1.0));
  std::printf("  heap allocations per step: median %.0f, max %.0f (W, ũ, μ are resized when the contact count changes)\n",
              Percentile(alloc_per_step, 0.5), Percentile(alloc_per_step, 1.0));
  std::printf("  contacts per step: median %.0f, max %.0f; broad-phase region: median %.0f, max %.0f of %zu "
              "obstacle surface nodes\n",
              Percentile(contacts, 0.5), Percentile(contacts, 1.0), Percentile(region_nodes, 0.5),
              Percentile(region_nodes, 1.0), model.obstacle_candidates().size());

  {
    // Apart, the server's local model carries the surface ahead (sim/surface_ahead.h): what
    // that search costs a step without contact, the tool hovering 0..10 mm above the path's
    // poses (the step itself then costs a few us).
    sim::SurfaceAheadProbe probe(model, sim::LocalModelBuilder::kDefaultSurfaceReachM);
    std::vector<double> probe_s;
    int found = 0;
    for (int step = 1; step <= steps; ++step) {
      Eigen::Vector3d d = path[static_cast<std::size_t>(step)];
      d.z() = 0.01 * (step % 11) / 10.0;
      Stopwatch watch;
      found += probe.Probe(d).found ? 1 : 0;
      probe_s.push_back(watch.ElapsedSeconds());
    }
    PrintRow("surface ahead", probe_s);
    std::printf("  surface ahead (not in the step above: steps without contact only): %d of %d poses 0..10 mm "
                "above the path found it\n", found, steps);
  }

  if (options.kernel_repeats > 0 && sim::FastestComplianceKernel() == sim::ComplianceKernel::kAvx2Fma) {
    // The same path with each build of the compliance sums, runs interleaved (portable,
    // avx2-fma, portable, ...) so a drift of the machine hits both: step and stage medians, the
    // ratio, and how far their forces are apart (rounding only: the order of additions).
    const std::array<sim::ComplianceKernel, 2> kernels = {sim::ComplianceKernel::kPortable,
                                                         sim::ComplianceKernel::kAvx2Fma};
    std::array<Series, 2> series;
    std::array<std::vector<Eigen::Vector3d>, 2> forces;
    for (int repeat = 0; repeat < options.kernel_repeats; ++repeat) {
      for (std::size_t k = 0; k < kernels.size(); ++k) {
        sim::TwoBodySession session(model, sim::SolveMode::kPrecomputed);
        session.compliance_kernel = kernels[k];
        forces[k].clear();
        for (int step = 1; step <= steps; ++step) {
          if (!cold.empty()) cold_sum += EvictCaches(&cold);
          WaitForTick(options.pace_us, &tick);
          const sim::StepOutput& out = session.Step(path[static_cast<std::size_t>(step)]);
          series[k].Add(out);
          forces[k].push_back(out.contact_force_n);
        }
      }
    }
    double worst_difference_n = 0.0, peak_n = 0.0;
    for (std::size_t i = 0; i < forces[0].size(); ++i) {
      worst_difference_n = std::max(worst_difference_n, (forces[0][i] - forces[1][i]).norm());
      peak_n = std::max(peak_n, forces[0][i].norm());
    }
    std::printf("\ncompliance kernels, %d interleaved runs each (same path):\n", options.kernel_repeats);
    for (std::size_t k = 0; k < kernels.size(); ++k) {
      std::printf(" %s:\n", sim::ComplianceKernelName(kernels[k]));
      PrintRow("step", series[k].step);
      PrintRow("detect", series[k].detect);
      PrintRow("assemble", series[k].assemble);
    }
    std::printf("  ratio portable / avx2-fma: step median %.2f, p99 %.2f; detect median %.2f; assemble median %.2f\n",
                Percentile(series[0].step, 0.5) / Percentile(series[1].step, 0.5),
                Percentile(series[0].step, 0.99) / Percentile(series[1].step, 0.99),
                Percentile(series[0].detect, 0.5) / Percentile(series[1].detect, 0.5),
                Percentile(series[0].assemble, 0.5) / Percentile(series[1].assemble, 0.5));
    std::printf("  max |F_portable - F_avx2-fma| = %.2e N over the path (peak %.3f N)\n", worst_difference_n, peak_n);
  }

  if (options.full_steps > 0) {
    const int n = std::min(options.full_steps, steps);
    sim::TwoBodySession full(model, sim::SolveMode::kFullSolve);
    sim::TwoBodySession fast(model, sim::SolveMode::kPrecomputed);
    Series full_series, fast_series;
    double worst_force_difference = 0.0, peak_force = 0.0;
    for (int step = 1; step <= n; ++step) {
      const Eigen::Vector3d& d = path[static_cast<std::size_t>(step)];
      const sim::StepOutput& a = fast.Step(d);
      fast_series.Add(a);
      const Eigen::Vector3d fast_force = a.contact_force_n;
      const sim::StepOutput& b = full.Step(d);
      full_series.Add(b);
      worst_force_difference = std::max(worst_force_difference, (fast_force - b.contact_force_n).norm());
      peak_force = std::max(peak_force, b.contact_force_n.norm());
      std::fprintf(stderr, "full-solve step %d/%d: %.3f s\n", step, n, b.total_seconds);
    }
    std::printf("\nfull-solve mode on steps 1..%d only (press phase; ~1 s per step), precomputed on the same steps:\n", n);
    PrintRow("full", full_series.step);
    PrintRow("  assem.", full_series.assemble);
    PrintRow("  update", full_series.update);
    PrintRow("precomp.", fast_series.step);
    std::printf("  ratio of medians full / precomputed: %.0f x; max |F_full - F_precomputed| = %.2e N (peak %.3f N)\n",
                Percentile(full_series.step, 0.5) / Percentile(fast_series.step, 0.5), worst_force_difference, peak_force);
  }
  std::printf("\nload average at end: %s\n", hapco::LoadAverageText().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("sim_pipeline_bench", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
