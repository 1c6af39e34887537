// fclib_collection_bench [--tol 1e-6,1e-8] [--max-cpu-s S] --csv OUT.csv FILE.hdf5...
//
// Time to tolerance of HapCo's contact solvers and Siconos Numerics' NSGS and nonsmooth Newton
// (Alart–Curnier, NSN_AC) on FCLIB files written by other tools (local problems as stored;
// global problems reduced by the flexibility method, delassus/delassus.h, whose time is
// reported apart and not counted). One judge for every solver: Siconos' fc3d_compute_error on
// the file's own W (norm ‖q‖, as Siconos' drivers pass it). A solver whose own stop test passes
// before the judge does is continued, warm-started, at a tenth of its tolerance, with the time
// added, until the judge passes or --max-cpu-s is spent: a problem is solved when the
// judge says so. Prints one line per run and writes the CSV that
// scripts/plot_performance_profile.py reads (problem,solver,tolerance,seconds,converged,
// iterations,error). Times are process CPU seconds. Never asserts on time.
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "contact/solver.h"
#include "delassus/delassus.h"
#include "fclib/fclib_io.h"

extern "C" {
#include <FrictionContactProblem.h>
#include <Friction_cst.h>
#include <NonSmoothDrivers.h>
#include <NumericsMatrix.h>
#include <NumericsVerbose.h>
#include <SolverOptions.h>
#include <fc3d_compute_error.h>
}

namespace {

double CpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// The file's problem as Siconos sees it (dense W, column-major), and the judge.
class SiconosView {
 public:
  explicit SiconosView(const hapco::contact::ContactProblem& p)
      : q_(p.free_displacement_m), mu_(p.friction_coefficient) {
    const int n = static_cast<int>(q_.size());
    m_ = NM_create(NM_DENSE, n, n);
    std::memcpy(m_->matrix0, p.flexibility_m_per_n.data(), sizeof(double) * static_cast<std::size_t>(n) * n);
    problem_.dimension = 3;
    problem_.numberOfContacts = n / 3;
    problem_.M = m_;
    problem_.q = q_.data();
    problem_.mu = mu_.data();
  }
  ~SiconosView() { NM_free(m_); }
  SiconosView(const SiconosView&) = delete;
  SiconosView& operator=(const SiconosView&) = delete;

  double Judge(const Eigen::VectorXd& r) {
    Eigen::VectorXd rr = r, u = Eigen::VectorXd::Zero(q_.size());
    SolverOptions* options = solver_options_create(SICONOS_FRICTION_3D_NSGS);
    double error = 0.0;
    fc3d_compute_error(&problem_, rr.data(), u.data(), 0.0, options, q_.norm(), &error);
    solver_options_delete(options);
    return error;
  }
  // Siconos from r (warm) to `tol` on its own error, within `seconds` of CPU: Siconos has no
  // time budget, so it runs in chunks of iterations (1, 2, 4, ...), each warm-started from the
  // last (r is all the state NSGS and the Newton iteration keep), and stops after the chunk
  // that crosses `seconds` (so it may overshoot by up to the last chunk); returns iterations.
  int Run(int solver_id, double tol, double seconds, Eigen::VectorXd* r) {
    const double start = CpuSeconds();
    int done = 0;
    for (int chunk = 1; CpuSeconds() - start < seconds; chunk = std::min(2 * chunk, 1 << 20)) {
      SolverOptions* options = solver_options_create(solver_id);
      options->iparam[SICONOS_IPARAM_MAX_ITER] = chunk;
      options->dparam[SICONOS_DPARAM_TOL] = tol;
      Eigen::VectorXd u = Eigen::VectorXd::Zero(q_.size());
      const Eigen::VectorXd before = *r;
      const int info = fc3d_driver(&problem_, r->data(), u.data(), options);
      done += options->iparam[SICONOS_IPARAM_ITER_DONE];
      solver_options_delete(options);
      if (!r->allFinite()) {
        *r = before;  // keep the last finite iterate, as HapCo's solvers do
        break;
      }
      if (info == 0) break;
    }
    return done;
  }

 private:
  Eigen::VectorXd q_, mu_;
  NumericsMatrix* m_ = nullptr;
  FrictionContactProblem problem_{};
};

struct Row {
  std::string problem, solver;
  double tolerance = 0, seconds = 0, error = 0;
  bool converged = false;
  int iterations = 0;
};

struct Options {
  std::vector<double> tolerances = {1e-6, 1e-8};
  double max_cpu_s = 20.0;
  std::string csv_path;
  std::vector<std::string> files;
};

// "1e-6,1e-8" -> {1e-6, 1e-8}: every item a finite number > 0, else an error naming --tol.
std::vector<double> ParseTolerances(const std::string& text) {
  std::vector<double> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    char* end = nullptr;
    const double value = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(value) || !(value > 0)) {
      throw hapco::InputError("--tol expects comma-separated numbers > 0, got '" + text + "'");
    }
    out.push_back(value);
  }
  if (out.empty()) throw hapco::InputError("--tol expects comma-separated numbers > 0, got '" + text + "'");
  return out;
}

constexpr const char* kDescription =
    R"(Time to tolerance of HapCo's contact solvers (local-uzawa, global-uzawa-gs, reference; the last two also with Anderson acceleration, "+anderson") and Siconos Numerics' NSGS and nonsmooth Newton (Alart-Curnier, NSN_AC) on FCLIB files written by other tools; global problems are reduced by the flexibility method (its time reported apart, not counted). One judge for every solver: Siconos' fc3d_compute_error on the file's own W. A solver whose own stop test passes before the judge does is continued, warm-started, at a tenth of its tolerance, until the judge passes or --max-cpu-s is spent. Times are process CPU seconds. Prints one line per run and writes the CSV that scripts/plot_performance_profile.py reads; scripts/contact-collection runs the whole collection. Never asserts on time.)";

constexpr const char* kFooter = "Exit code: 0 when the benchmark ran, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("fclib_collection_bench", "--csv OUT.csv [options] FILE.hdf5...", kDescription,
                                  kFooter);
  command.app()
      .add_option("FILE", o->files, "FCLIB files (.hdf5) of local or global problems, at least one; a file that cannot be read is "
                  "reported and skipped (give -- before names that start with '-')")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->group("Arguments");
  std::string tolerances;
  command.AddText("--tol", &tolerances, "X[,X...]",
                  "fc3d tolerances of the judge, dimensionless, comma-separated (default 1e-6,1e-8)", "Solver");
  command.AddNumber("--max-cpu-s", &o->max_cpu_s, "S",
                    "CPU seconds per solver, problem and tolerance, continuations included (default 20)", "Solver",
                    0, HUGE_VAL, true);
  command.AddCsv(&o->csv_path,
                 "one row per run (problem, solver, tolerance, seconds, converged, iterations, error), "
                 "written row by row (required)");
  command.Deprecate("--max-seconds", "--max-cpu-s");
  if (!command.Parse(argc, argv)) return false;
  if (!tolerances.empty()) o->tolerances = ParseTolerances(tolerances);
  if (o->csv_path.empty()) throw hapco::InputError("--csv FILE is required (see --help)");
  if (o->files.empty()) throw hapco::InputError("missing FILE argument (see --help)");
  return true;
}

int Run(const Options& options) {
  const std::vector<double>& tolerances = options.tolerances;
  const double max_seconds = options.max_cpu_s;
  const std::string& csv_path = options.csv_path;
  const std::vector<std::string>& files = options.files;
  namespace contact = hapco::contact;
  namespace fclib = hapco::fclib;
  numerics_set_verbose(0);
  std::vector<Row> rows;
  std::ofstream csv(csv_path);  // written row by row: a long run keeps what it measured
  csv << "problem,solver,tolerance,seconds,converged,iterations,error\n";
  // "+anderson": the same sweeps with the shipped scenes' Anderson acceleration (depth 5,
  // docs/stability.md), judged like the others.
  const char* solvers[] = {"local-uzawa", "global-uzawa-gs", "global-uzawa-gs+anderson", "reference",
                           "reference+anderson", "siconos-nsgs", "siconos-nsn-ac"};
  std::printf("%-44s %5s %6s %-24s %8s %10s %7s %10s\n", "problem", "m", "tol", "solver", "solved", "cpu_s",
              "iters", "judge");
  for (const std::string& file : files) {
    const std::string name = std::filesystem::path(file).stem().string();
    contact::ContactProblem problem, stored;
    try {
      if (fclib::ReadFclibKind(file) == fclib::FclibKind::kGlobal) {
        const contact::GlobalContactProblem global = fclib::ReadFclibGlobalProblem(file);
        const hapco::delassus::GlobalToLocal reduction(global);
        problem = reduction.local();
        std::printf("%-44s delassus: factor %.4f s, W %.4f s\n", name.c_str(),
                    reduction.stats().factorization_seconds, reduction.stats().operator_seconds);
      } else {
        fclib::FclibFileDetails details;
        problem = fclib::ReadFclibLocalProblem(file, &details);
        if (details.stored_problem.num_contacts() > 0) stored = details.stored_problem;
      }
    } catch (const std::exception& error) {
      std::printf("%-44s skipped: %s\n", name.c_str(), error.what());
      continue;
    }
    const contact::ContactProblem& judged = stored.num_contacts() > 0 ? stored : problem;
    SiconosView siconos(judged);
    const int m = problem.num_contacts();
    for (const double tol : tolerances) {
      for (const char* solver : solvers) {
        Row row{name, solver, tol};
        Eigen::VectorXd r = Eigen::VectorXd::Zero(3 * m);
        double run_tol = tol;
        const bool is_siconos = std::strncmp(solver, "siconos", 7) == 0;
        contact::SolverWorkspace workspace;
        contact::SolverResult result;
        for (int attempt = 0; attempt < 6; ++attempt) {
          const double start = CpuSeconds();
          if (is_siconos) {
            const int id = std::strcmp(solver, "siconos-nsgs") == 0 ? SICONOS_FRICTION_3D_NSGS : SICONOS_FRICTION_3D_NSN_AC;
            row.iterations += siconos.Run(id, run_tol, std::max(0.0, max_seconds - row.seconds), &r);
          } else {
            contact::SolverParameters params;
            params.fc3d_tolerance = run_tol;
            params.global_tolerance_m = 1e-300;  // the fc3d test only
            params.max_iterations = 100000;
            params.time_budget_s = std::max(0.0, max_seconds - row.seconds);
            params.warm_start = attempt > 0;
            if (attempt > 0) result.force_n = r;
            std::string kind = solver;
            if (const auto plus = kind.find("+anderson"); plus != std::string::npos) {
              kind.erase(plus);
              params.anderson_depth = 5;
            }
            contact::Solve(contact::ParseSolverKind(kind), stored.num_contacts() > 0 ? stored : problem, params,
                           &workspace, &result);
            r = result.force_n;
            row.iterations += result.stats.iterations;
          }
          row.seconds += CpuSeconds() - start;
          row.error = r.allFinite() ? siconos.Judge(r) : 1e300;
          row.converged = row.error <= tol;
          if (row.converged || row.seconds >= max_seconds || !r.allFinite()) break;
          run_tol /= 10.0;
        }
        std::printf("%-44s %5d %6.0e %-24s %8s %10.4g %7d %10.3e\n", name.c_str(), m, tol, solver,
                    row.converged ? "yes" : "no", row.seconds, row.iterations, row.error);
        std::fflush(stdout);
        rows.push_back(row);
        csv << row.problem << ',' << row.solver << ',' << row.tolerance << ',' << row.seconds << ','
            << (row.converged ? 1 : 0) << ',' << row.iterations << ',' << row.error << '\n' << std::flush;
      }
    }
  }
  std::printf("wrote %zu runs to %s\n", rows.size(), csv_path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("fclib_collection_bench", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
