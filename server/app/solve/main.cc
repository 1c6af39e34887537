// hapco-solve: solve a local or global friction-contact problem stored in an FCLIB file and
// report how it went. Thin: the work is in hapco::fclib, hapco::delassus and hapco::contact
// (design.md, example 14).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/memory.h"
#include "contact/global_problem.h"
#include "contact/projection.h"
#include "contact/solver.h"
#include "delassus/delassus.h"
#include "fclib/fclib_io.h"

namespace {

constexpr int kExitConverged = 0;
constexpr int kExitNotConverged = 2;

constexpr const char* kDescription =
    R"(Reads a local friction-contact problem u = W r + q (FCLIB file, /fclib_local: W, q, mu; spacedim 3; W in compressed columns, compressed rows or triplets, as Siconos or libfclib write it), solves it and prints: the file, the number of contacts, the mu range, the solver, its status, outer/inner iterations, time, the fc3d error, the paper error, libfclib's merit and the number of contacts separating/sticking/sliding (r_n compared with 100 * tol * ||r||, the slip ||u_t|| with 100 * tol * max(||q||, ||u||)).

A W symmetric only up to round-off (max|W - W^T| / max|W| <= 1e-4, printed) is solved with its symmetric part, then refined on the stored W, and every error is reported on the stored W.

A global problem (/fclib_global: M v = H r + f, u = H^T v + w, as fclib.h defines it; no equality constraints G, b) is reduced to the local one by the flexibility method: M factored once with CHOLMOD, W = H^T M^-1 H, q = H^T M^-1 f + w (time and memory printed); after the solve v = M^-1 (H r + f), and the global residual (momentum balance ||M v - H r - f|| and the cone complementarity of u = H^T v + w) is computed from M, H, f, w directly.

If PROBLEM.hdf5 already holds a /solution, its fc3d error is printed too.)";

constexpr const char* kFooter =
    "Exit code: 0 converged, 2 not converged (max-iterations, time-budget-exceeded or diverged; the report is "
    "still printed), 1 bad input (one line on stderr says what to fix).";

struct Options {
  std::string problem_path;
  std::string out_path;
  hapco::contact::SolverKind solver = hapco::contact::SolverKind::kReferenceNsgs;
  double fc3d_tolerance = 1e-8;
  std::optional<double> paper_tolerance;
  double local_tolerance = 1e-8;
  int max_iterations = 1000;
  int anderson_depth = 0;
  std::string triplet_rows = "auto";  // a triplet H's row indices: auto, i or p
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("hapco-solve", "PROBLEM.hdf5 [options]", kDescription, kFooter);
  command.app()
      .add_option("PROBLEM", options->problem_path, "FCLIB file with a local (/fclib_local) or global "
                                                    "(/fclib_global) friction-contact problem")
      ->group("Arguments");  // checked after parsing: an unknown option is reported first
  std::string solver = "reference";
  command.AddSolver(&solver, "reference, Gauss-Seidel with an exact local solve");
  command.AddNumber("--tol", &options->fc3d_tolerance, "X",
                    "fc3d tolerance, dimensionless (default 1e-8): stop when\n"
                    "  ||r - Proj_K(r - (u + mu||u_t||n))|| / max(||q||, ||r||, ||u||) < X",
                    "Solver", 0, HUGE_VAL, true);
  double paper_tolerance = 0;
  CLI::Option* paper = command.AddNumber(
      "--paper-tol-m", &paper_tolerance, "X",
      "also stop when the paper's test ||r(k+1) - r(k)|| / rho < X, in the units of W r (m for HapCo "
      "problems) (default: off)",
      "Solver", 0, HUGE_VAL, true);
  command.AddNumber("--local-tol-m", &options->local_tolerance, "X",
                    "inner tolerance of local-uzawa, ||dr_alpha|| / rho < X, same units (default 1e-8)", "Solver", 0,
                    HUGE_VAL, true);
  command.AddMaxIterations(&options->max_iterations, "1000");
  command.AddAndersonDepth(&options->anderson_depth, "0; the shipped scenes use 5",
                           hapco::contact::SolverParameters::kMaxAndersonDepth);
  command.AddChoice("--triplet-rows", &options->triplet_rows, {"auto", "i", "p"},
                    "where a global problem's triplet-stored H keeps its row indices: i (CSparse, as Siconos "
                    "writes), p (as fclib.h's comment documents), or auto: the reading whose indices fit, i "
                    "when both do (default auto; when both fit and give different matrices, e.g. a square H, "
                    "a warning says so)",
                    "Solver");
  command.AddOutput(&options->out_path,
                    "write a copy of the problem (matrices in compressed columns) with the solution in its FCLIB "
                    "/solution group: r, u (and v for a global problem); also when not converged");
  command.Deprecate("--out", "--output");
  command.Deprecate("--paper-tol", "--paper-tol-m");
  command.Deprecate("--local-tol", "--local-tol-m");
  if (!command.Parse(argc, argv)) return false;

  if (options->problem_path.empty()) {
    throw hapco::InputError("no problem file given (usage: hapco-solve PROBLEM.hdf5, see --help)");
  }
  options->solver = hapco::contact::ParseSolverKind(solver);
  if (paper->count() > 0) options->paper_tolerance = paper_tolerance;
  return true;
}

namespace contact = hapco::contact;
namespace fclib = hapco::fclib;

contact::SolverParameters ParametersOf(const Options& options) {
  contact::SolverParameters params;
  params.fc3d_tolerance = options.fc3d_tolerance;
  // The paper's test is off unless asked for: a tolerance no residual can pass but zero.
  params.global_tolerance_m = options.paper_tolerance.value_or(std::numeric_limits<double>::min());
  params.local_tolerance_m = options.local_tolerance;
  params.max_iterations = options.max_iterations;
  params.anderson_depth = options.anderson_depth;
  return params;
}

struct LocalSolve {
  contact::SolverStatus status = contact::SolverStatus::kMaxIterations;
  contact::SolverResult result;
  int refine_iterations = -1;  // outer iterations of the refinement on the stored W (-1: none)
};

// Solves `problem`; when the file's W was only symmetric up to round-off (`stored` has
// contacts), the solution of the symmetric part is refined on the stored W, warm-started, until
// the tolerance holds there too: the solvers do not need W symmetric (they update u = W r + q
// by columns), so the answer is a solution of the problem as written.
LocalSolve SolveLocal(const Options& options, const contact::ContactProblem& problem,
                      const contact::ContactProblem& stored) {
  const contact::SolverParameters params = ParametersOf(options);
  const int m = problem.num_contacts();
  contact::SolverWorkspace workspace;
  workspace.Reserve(m, params.max_iterations);
  LocalSolve out;
  out.result.Reserve(m, params.max_iterations);
  out.status = contact::Solve(options.solver, problem, params, &workspace, &out.result);
  if (stored.num_contacts() > 0 && !(contact::Fc3dError(stored, out.result.force_n) < options.fc3d_tolerance)) {
    // The refinement shares --max-iter with the first solve: the user's cap is on the total
    // (a helper saw 24 outer iterations reported under --max-iter 20).
    const contact::SolverStats first = out.result.stats;
    const int left = params.max_iterations - first.iterations;
    if (left <= 0) {
      out.status = contact::SolverStatus::kMaxIterations;
      out.refine_iterations = 0;
      return out;
    }
    contact::SolverParameters refine = params;
    refine.warm_start = true;
    refine.max_iterations = left;
    out.status = contact::Solve(options.solver, stored, refine, &workspace, &out.result);
    out.refine_iterations = out.result.stats.iterations;
    out.result.stats.iterations += first.iterations;
    out.result.stats.inner_iterations += first.inner_iterations;
    out.result.stats.seconds += first.seconds;
  }
  return out;
}

void PrintSolve(const Options& options, const contact::ContactProblem& judged, const LocalSolve& solve) {
  const contact::SolverStats& stats = solve.result.stats;
  std::printf("solver        %s (fc3d tol %g, paper tol %s, max %d iterations)\n",
              std::string(contact::SolverName(options.solver)).c_str(), options.fc3d_tolerance,
              options.paper_tolerance ? std::to_string(*options.paper_tolerance).c_str() : "off",
              options.max_iterations);
  std::printf("status        %s\n", std::string(contact::StatusName(solve.status)).c_str());
  if (solve.refine_iterations >= 0) {
    std::printf("iterations    %d outer (%d of them refining on the stored W), %d inner\n", stats.iterations,
                solve.refine_iterations, stats.inner_iterations);
  } else {
    std::printf("iterations    %d outer, %d inner\n", stats.iterations, stats.inner_iterations);
  }
  if (options.anderson_depth > 0) {
    std::printf("acceleration  Anderson depth %d: %d extrapolated sweeps, %d restarts%s\n", options.anderson_depth,
                stats.accelerated_iterations, stats.acceleration_restarts,
                stats.acceleration_stalled ? ", stalled (then plain sweeps)" : "");
  }
  std::printf("time          %.6f s\n", stats.seconds);
  std::printf("fc3d error    %.3e\n", contact::Fc3dError(judged, solve.result.force_n));
  std::printf("paper error   %.3e (units of W r, m for HapCo problems; rho %.4g)\n", stats.paper_error_m,
              stats.rho);
  std::printf("fclib merit   %.3e (libfclib MERIT_1)\n", fclib::FclibMeritLocal(judged, solve.result.force_n));
  // States from tolerances relative to each quantity's own scale (projection.h ClassifyContact;
  // the solver's own counts use the paper tolerance, which is off here): r_n against the forces,
  // the slip against the displacements. One scale for both mixed units: a problem scaled by
  // 1e12 called a pressed, sliding contact "separating", by 1e-12 a sliding one "sticking" (a
  // helper session).
  const Eigen::VectorXd u = judged.flexibility_m_per_n * solve.result.force_n + judged.free_displacement_m;
  const double relative = std::max(100.0 * options.fc3d_tolerance, 1e-12);
  const double force_tolerance = relative * std::max(solve.result.force_n.norm(), std::numeric_limits<double>::min());
  const double slip_tolerance =
      relative * std::max({judged.free_displacement_m.norm(), u.norm(), std::numeric_limits<double>::min()});
  const std::array<int, 3> states =
      contact::CountContactStates(solve.result.force_n, u, force_tolerance, slip_tolerance);
  std::printf("states        separating %d, sticking %d, sliding %d (r_n above %.2e, slip above %.2e)\n", states[0],
              states[1], states[2], force_tolerance, slip_tolerance);
}

int ExitCodeOf(contact::SolverStatus status) {
  return status == contact::SolverStatus::kConverged ? kExitConverged : kExitNotConverged;
}

// Magnitudes of W's and q's entries the solvers handle: their errors and steps square and
// multiply these, and beyond ~1e140 they overflow or underflow (a helper session scaled a
// problem by 1e±160: "diverged" with a NaN merit, or "converged" with an error of 0). 1e±100
// solves like the unscaled file. Beyond it the file is refused with what to do.
constexpr double kLargestSolvableEntry = 1e100;

void CheckSolvableScale(const std::string& path, const char* name, const Eigen::Ref<const Eigen::MatrixXd>& values) {
  const double largest = values.size() > 0 ? values.cwiseAbs().maxCoeff() : 0.0;
  if (largest > kLargestSolvableEntry || (largest > 0.0 && largest < 1.0 / kLargestSolvableEntry)) {
    char text[320];
    std::snprintf(text, sizeof(text),
                  "FCLIB file '%s': the largest |%s| entry is %.3g, outside [1e-100, 1e100], where the solvers' "
                  "norms overflow or underflow in double precision: rescale the problem (other units for "
                  "forces or lengths) and solve it again",
                  path.c_str(), name, largest);
    throw hapco::InputError(text);
  }
}

int RunLocal(const Options& options) {
  fclib::FclibFileDetails details;
  const contact::ContactProblem problem = fclib::ReadFclibLocalProblem(options.problem_path, &details);
  CheckSolvableScale(options.problem_path, "W", problem.flexibility_m_per_n);
  CheckSolvableScale(options.problem_path, "q", problem.free_displacement_m);
  const std::optional<fclib::FclibSolution> stored_solution = fclib::ReadFclibSolution(options.problem_path);
  const int m = problem.num_contacts();
  const bool asymmetric = details.stored_problem.num_contacts() > 0;
  const contact::ContactProblem& judged = asymmetric ? details.stored_problem : problem;

  std::printf("file          %s\n", options.problem_path.c_str());
  if (!details.info.title.empty()) std::printf("title         %s\n", details.info.title.c_str());
  std::printf("W             %d x %d, %s, %d stored entries\n", 3 * m, 3 * m,
              fclib::StorageName(details.w_storage), details.w_stored_entries);
  if (asymmetric) {
    std::printf("W symmetry    max|W - W^T| / max|W| = %.2e (round-off, accepted up to %.0e): solved with "
                "(W + W^T)/2, judged on the stored W\n",
                details.w_relative_asymmetry, fclib::kMaxRelativeAsymmetry);
  }
  std::printf("contacts      %d, mu in [%g, %g]\n", m, problem.friction_coefficient.minCoeff(),
              problem.friction_coefficient.maxCoeff());
  if (stored_solution) {
    std::printf("stored solution fc3d error %.3e\n", contact::Fc3dError(judged, stored_solution->force_n));
  }
  const LocalSolve solve = SolveLocal(options, problem, asymmetric ? details.stored_problem : contact::ContactProblem{});
  PrintSolve(options, judged, solve);
  if (!options.out_path.empty()) {
    fclib::FclibInfo info = details.info;
    if (info.title.empty()) info.title = "solved by hapco-solve";
    fclib::WriteFclibLocalProblem(options.out_path, judged, info);
    const Eigen::VectorXd u = judged.flexibility_m_per_n * solve.result.force_n + judged.free_displacement_m;
    fclib::WriteFclibSolution(options.out_path, solve.result.force_n, u);
    std::printf("solution      written to %s (FCLIB /solution)\n", options.out_path.c_str());
  }
  return ExitCodeOf(solve.status);
}

const char* ReadingName(fclib::TripletReading reading) {
  switch (reading) {
    case fclib::TripletReading::kNotTriplet:
      return "";
    case fclib::TripletReading::kRowsInI:
      return ", rows in i (CSparse, as Siconos writes)";
    case fclib::TripletReading::kRowsInP:
      return ", rows in p (as fclib.h documents)";
  }
  return "";
}

// Applies --triplet-rows to a triplet-stored H that both readings fit (fclib_io.h).
void ChooseTripletReading(const Options& options, fclib::FclibGlobalDetails* details,
                          contact::GlobalContactProblem* global) {
  using fclib::TripletReading;
  if (details->h_triplet_reading == TripletReading::kNotTriplet || options.triplet_rows == "auto") {
    if (details->h_other_reading.size() > 0) {
      std::fprintf(stderr,
                   "hapco-solve: warning: H's triplet indices fit both with rows in i (CSparse, as Siconos writes) "
                   "and with rows in p (as fclib.h documents), and the two give different matrices: read with "
                   "rows in i. If the file was written to fclib.h's comment, give --triplet-rows p.\n");
    }
    return;
  }
  const TripletReading wanted = options.triplet_rows == "i" ? TripletReading::kRowsInI : TripletReading::kRowsInP;
  if (details->h_triplet_reading == wanted) {
    details->h_other_reading = {};
    return;
  }
  if (details->h_other_reading.size() == 0) {
    throw hapco::InputError("--triplet-rows " + options.triplet_rows + ": H's triplet indices do not fit that " +
                            "reading (they fit only with rows in " +
                            (wanted == TripletReading::kRowsInI ? "p" : "i") + ")");
  }
  global->h = std::move(details->h_other_reading);
  details->h_other_reading = {};
  details->h_triplet_reading = wanted;
  contact::ValidateGlobalProblem(*global);
}

int RunGlobal(const Options& options) {
  fclib::FclibGlobalDetails details;
  contact::GlobalContactProblem global = fclib::ReadFclibGlobalProblem(options.problem_path, &details);
  ChooseTripletReading(options, &details, &global);
  const std::optional<fclib::FclibGlobalSolution> stored_solution =
      fclib::ReadFclibGlobalSolution(options.problem_path);
  const int n = global.num_dofs(), m = global.num_contacts();
  std::printf("file          %s\n", options.problem_path.c_str());
  if (!details.info.title.empty()) std::printf("title         %s\n", details.info.title.c_str());
  std::printf("problem       global (M v = H r + f, u = H^T v + w): %d dofs, %d contacts\n", n, m);
  std::printf("M             %d x %d, %s, %d stored entries, max|M - M^T| / max|M| = %.2e\n", n, n,
              fclib::StorageName(details.m_storage), details.m_stored_entries, details.m_relative_asymmetry);
  std::printf("H             %d x %d, %s%s%s, %d stored entries\n", n, 3 * m, fclib::StorageName(details.h_storage),
              ReadingName(details.h_triplet_reading),
              details.h_other_reading.size() > 0 ? " (ambiguous: see the warning; --triplet-rows)" : "",
              details.h_stored_entries);
  std::printf("contacts      %d, mu in [%g, %g]\n", m, global.mu.minCoeff(), global.mu.maxCoeff());
  if (stored_solution) {
    const contact::GlobalResidual residual =
        contact::ComputeGlobalResidual(global, stored_solution->velocity, stored_solution->force);
    std::printf("stored solution global residual: momentum %.3e, complementarity %.3e\n", residual.momentum,
                residual.complementarity);
  }
  const hapco::delassus::GlobalToLocal reduction(global);
  const hapco::delassus::DelassusStats& d = reduction.stats();
  std::printf("delassus      W = H^T M^-1 H %d x %d: factor %.4f s (L %ld nonzeros, %.2f MiB), W %.4f s "
              "(%d batched solves of <= %d columns), W %.2f MiB, peak memory %.1f MiB\n",
              3 * m, 3 * m, d.factorization_seconds, d.factor_nonzeros, d.factor_bytes / 1048576.0,
              d.operator_seconds, d.solve_batches, d.rhs_per_batch, d.operator_bytes / 1048576.0,
              hapco::PeakResidentBytes() / 1048576.0);
  const contact::ContactProblem& local = reduction.local();
  const LocalSolve solve = SolveLocal(options, local, contact::ContactProblem{});
  PrintSolve(options, local, solve);
  const Eigen::VectorXd v = reduction.GlobalVelocity(solve.result.force_n);
  const contact::GlobalResidual residual = contact::ComputeGlobalResidual(global, v, solve.result.force_n);
  std::printf("global        v = M^-1 (H r + f); residual from M, H, f, w: momentum %.3e, complementarity "
              "%.3e\n",
              residual.momentum, residual.complementarity);
  if (!options.out_path.empty()) {
    fclib::FclibInfo info = details.info;
    if (info.title.empty()) info.title = "solved by hapco-solve";
    fclib::WriteFclibGlobalProblem(options.out_path, global, info);
    fclib::WriteFclibGlobalSolution(options.out_path, {v, solve.result.force_n, residual.u});
    std::printf("solution      written to %s (FCLIB /solution: v, r, u)\n", options.out_path.c_str());
  }
  return ExitCodeOf(solve.status);
}

int Run(const Options& options) {
  return fclib::ReadFclibKind(options.problem_path) == fclib::FclibKind::kGlobal ? RunGlobal(options)
                                                                                  : RunLocal(options);
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-solve", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : kExitConverged;
  });
}
