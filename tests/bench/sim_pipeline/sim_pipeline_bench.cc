// Per-step cost of the haptic step pipeline (sim/step_pipeline.h) on a shipped scene:
//   - precomputed mode over the whole trajectory, repeated: median / p99 / max of the step
//     and of each stage (detect, assemble ũ and W, solve, update);
//   - the paper's per-step full solves (kFullSolve) on the first --full-steps steps only
//     (about 1 s per step on the default scene), and the precomputed mode on the same steps
//     in the same run: the ratio of medians;
//   - the W gather and displacement update as they were before the optimisation (the 6 × 6
//     double loop over the obstacle weights of every contact pair, then dense compliance ×
//     nodal force products), timed on the same contact sets and checked to give the same W:
//     the before/after of the hot spot in the same run;
//   - the per-scene precomputation: TwoBodyModelStats, operator bytes, peak RSS;
//   - heap allocations per step (global operator new counted).
// The machine is shared: the load average is printed at start and end. Prints numbers only.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "common/error.h"
#include "common/memory.h"
#include "common/timer.h"
#include "io/scene_file.h"
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
};

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())) - 1));
  return v[q <= 0 ? 0 : i];
}

std::string LoadAverage() {
  std::ifstream file("/proc/loadavg");
  std::string a, b, c;
  file >> a >> b >> c;
  return a + " " + b + " " + c;
}

// The W gather before the optimisation (git 2a83258): for every pair β ≥ α, the 6 × 6 double
// sum over the obstacle weights of both contacts, world axes, then rotated. Kept here as the
// "before" of the hot spot.
void NaiveFlexibility(const sim::TwoBodyModel& model, const std::vector<sim::ContactPoint>& contacts,
                      Eigen::MatrixXd* w) {
  const int m = static_cast<int>(contacts.size());
  w->resize(3 * m, 3 * m);
  const Eigen::MatrixXd& tool_c = model.tool_compliance_m_per_n();
  const Eigen::MatrixXd& obstacle_c = model.obstacle_compliance_m_per_n();
  const auto& tool_map = model.tool_candidate_index();
  const auto& obstacle_map = model.obstacle_candidate_index();
  for (int alpha = 0; alpha < m; ++alpha) {
    const sim::ContactPoint& a = contacts[static_cast<std::size_t>(alpha)];
    const int ta = tool_map[static_cast<std::size_t>(a.tool_node)];
    for (int beta = alpha; beta < m; ++beta) {
      const sim::ContactPoint& b = contacts[static_cast<std::size_t>(beta)];
      const int tb = tool_map[static_cast<std::size_t>(b.tool_node)];
      Eigen::Matrix3d world = tool_c.block<3, 3>(3 * ta, 3 * tb);
      for (int k = 0; k < a.num_obstacle_nodes; ++k) {
        const int ok = obstacle_map[static_cast<std::size_t>(a.obstacle_nodes[static_cast<std::size_t>(k)])];
        Eigen::Matrix3d row_sum = Eigen::Matrix3d::Zero();
        for (int l = 0; l < b.num_obstacle_nodes; ++l) {
          const int ol = obstacle_map[static_cast<std::size_t>(b.obstacle_nodes[static_cast<std::size_t>(l)])];
          row_sum += b.weights[static_cast<std::size_t>(l)] * obstacle_c.block<3, 3>(3 * ok, 3 * ol);
        }
        world += a.weights[static_cast<std::size_t>(k)] * row_sum;
      }
      const Eigen::Matrix3d local = a.frame * world * b.frame.transpose();
      w->block<3, 3>(3 * alpha, 3 * beta) = local;
      if (beta != alpha) w->block<3, 3>(3 * beta, 3 * alpha) = local.transpose();
    }
  }
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

void PrintRow(const char* name, const std::vector<double>& v) {
  std::printf("  %-9s median %9.1f us   p99 %9.1f us   max %9.1f us\n", name, 1e6 * Percentile(v, 0.5),
              1e6 * Percentile(v, 0.99), 1e6 * Percentile(v, 1.0));
}

Options Parse(int argc, char** argv) {
  Options options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw InputError(arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--scene") {
      options.scene = value();
    } else if (arg == "--repeats") {
      options.repeats = std::max(1, std::atoi(value().c_str()));
    } else if (arg == "--full-steps") {
      options.full_steps = std::max(0, std::atoi(value().c_str()));
    } else if (arg == "--steps") {
      options.steps = std::max(0, std::atoi(value().c_str()));
    } else if (arg == "--csv") {
      options.csv = value();
    } else if (arg == "--help") {
      std::printf("usage: sim_pipeline_bench [--scene FILE] [--repeats N] [--full-steps N] [--steps N] [--csv FILE]\n"
                  "  --repeats N     whole-trajectory runs of the precomputed mode (default 3)\n"
                  "  --full-steps N  steps timed in full-solve mode, from step 1 (default 12; 0 = skip)\n"
                  "  --steps N       trajectory steps per run (default: all)\n"
                  "  --csv FILE      per-step rows of the last precomputed run\n");
      std::exit(0);
    } else {
      throw InputError("unknown option " + arg + " (see --help)");
    }
  }
  return options;
}

int Run(const Options& options) {
  std::printf("load average at start: %s (2 cores, shared)\n", LoadAverage().c_str());
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
  const int steps = options.steps > 0 ? std::min(options.steps, scene.total_steps()) : scene.total_steps();

  // Precomputed mode over the whole trajectory, `repeats` times (a fresh session each time).
  Series all;
  std::vector<double> alloc_per_step;
  std::vector<double> naive_assemble, spread_assemble;
  double worst_w_difference = 0.0;
  long outer_iterations = 0;
  std::FILE* csv = options.csv.empty() ? nullptr : std::fopen(options.csv.c_str(), "w");
  if (!options.csv.empty() && csv == nullptr) throw InputError("cannot write " + options.csv);
  if (csv != nullptr) {
    std::fprintf(csv, "step,contacts,outer_iterations,detect_s,assemble_s,solve_s,update_s,step_s,naive_assemble_s,allocations\n");
  }
  for (int repeat = 0; repeat < options.repeats; ++repeat) {
    sim::TwoBodySession session(model, sim::SolveMode::kPrecomputed);
    Eigen::MatrixXd naive_w;
    const Eigen::Index obstacle_rows = model.obstacle_compliance_m_per_n().rows();
    const Eigen::Index tool_rows = model.tool_compliance_m_per_n().rows();
    Eigen::VectorXd obstacle_f = Eigen::VectorXd::Ones(obstacle_rows), obstacle_u(obstacle_rows);
    Eigen::VectorXd tool_f = Eigen::VectorXd::Ones(tool_rows), tool_u(tool_rows);
    naive_w.resize(3 * static_cast<Eigen::Index>(model.tool_candidates().size()),
                   3 * static_cast<Eigen::Index>(model.tool_candidates().size()));
    for (int step = 1; step <= steps; ++step) {
      const Eigen::Vector3d d = scene.DeviceTranslationAtStep(step);
      const long before = g_allocations.load();
      const sim::StepOutput& out = session.Step(d);
      const long allocations = g_allocations.load() - before;
      all.Add(out);
      alloc_per_step.push_back(static_cast<double>(allocations));
      outer_iterations += out.iterations;
      double naive_s = 0.0;
      if (out.num_contacts > 0) {
        Stopwatch naive;
        NaiveFlexibility(model, session.contacts(), &naive_w);
        // The old update: dense compliance × nodal force vector for both bodies.
        obstacle_u.noalias() = model.obstacle_compliance_m_per_n() * obstacle_f;
        tool_u.noalias() = model.tool_compliance_m_per_n() * tool_f;
        naive_s = naive.ElapsedSeconds();
        naive_assemble.push_back(naive_s);
        spread_assemble.push_back(out.assemble_seconds + out.update_seconds);
        const Eigen::MatrixXd& w = session.last_problem().flexibility_m_per_n;
        worst_w_difference = std::max(worst_w_difference, (w - naive_w).cwiseAbs().maxCoeff() / w.cwiseAbs().maxCoeff());
      }
      if (csv != nullptr && repeat == options.repeats - 1) {
        std::fprintf(csv, "%d,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%ld\n", step, out.num_contacts, out.iterations,
                     out.detect_seconds, out.assemble_seconds, out.solve_seconds, out.update_seconds,
                     out.total_seconds, naive_s, allocations);
      }
    }
    std::fprintf(stderr, "precomputed run %d/%d done\n", repeat + 1, options.repeats);
  }
  if (csv != nullptr) std::fclose(csv);
  std::printf("\nprecomputed mode, %d steps x %d runs (%ld outer iterations per run):\n", steps, options.repeats,
              outer_iterations / options.repeats);
  PrintRow("step", all.step);
  PrintRow("detect", all.detect);
  PrintRow("assemble", all.assemble);
  PrintRow("solve", all.solve);
  PrintRow("update", all.update);
  std::printf("  heap allocations per step: median %.0f, max %.0f (W, ũ, μ are resized when the contact count changes)\n",
              Percentile(alloc_per_step, 0.5), Percentile(alloc_per_step, 1.0));
  std::printf("\nassemble + update on the same contact sets: before (6x6 double loop per pair, dense C f) "
              "median %.1f us, after (incl. ũ) median %.1f us, ratio %.2f; max |W_after - W_before| / max|W| = %.2e\n",
              1e6 * Percentile(naive_assemble, 0.5), 1e6 * Percentile(spread_assemble, 0.5),
              Percentile(naive_assemble, 0.5) / Percentile(spread_assemble, 0.5), worst_w_difference);

  if (options.full_steps > 0) {
    const int n = std::min(options.full_steps, steps);
    sim::TwoBodySession full(model, sim::SolveMode::kFullSolve);
    sim::TwoBodySession fast(model, sim::SolveMode::kPrecomputed);
    Series full_series, fast_series;
    double worst_force_difference = 0.0, peak_force = 0.0;
    for (int step = 1; step <= n; ++step) {
      const Eigen::Vector3d d = scene.DeviceTranslationAtStep(step);
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
  std::printf("\nload average at end: %s\n", LoadAverage().c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(Parse(argc, argv));
  } catch (const std::exception& error) {
    std::fprintf(stderr, "sim_pipeline_bench: %s\n", error.what());
    return 1;
  }
}
