// hapco-solve: solve a local friction-contact problem stored in an FCLIB file and report how
// it went. Thin: the work is in hapco::fclib and hapco::contact (design.md, example 14).
#include <algorithm>
#include <array>
#include <charconv>
#include <cstdio>
#include <exception>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

#include "common/error.h"
#include "contact/projection.h"
#include "contact/solver.h"
#include "fclib/fclib_io.h"

namespace {

constexpr int kExitConverged = 0;
constexpr int kExitBadInput = 1;
constexpr int kExitNotConverged = 2;

constexpr const char* kUsage = R"(usage: hapco-solve PROBLEM.hdf5 [options]

Reads a local friction-contact problem u = W r + q (FCLIB file, /fclib_local: W, q, mu;
spacedim 3; W in compressed columns, compressed rows or triplets, as Siconos or libfclib
write it), solves it and prints: the file, the number of contacts, the mu range, the solver,
its status, outer/inner iterations, time, the fc3d error, the paper error, libfclib's merit
and the number of contacts separating/sticking/sliding (r_n resp. the slip ||u_t|| compared
with 100 * tol * max(||q||, ||r||, ||u||)).

  --solver NAME     local-uzawa | global-uzawa-gs | global-uzawa-jacobi | reference
                    (default: reference, Gauss-Seidel with an exact local solve)
  --tol X           fc3d tolerance, dimensionless (default 1e-8): stop when
                    ||r - Proj_K(r - (u + mu||u_t||n))|| / max(||q||, ||r||, ||u||) < X
  --paper-tol X     also stop when the paper's test ||r(k+1) - r(k)|| / rho < X, in the
                    units of W*r (m for HapCo problems) (default: off)
  --local-tol X     inner tolerance of local-uzawa, ||dr_alpha|| / rho < X, same units
                    (default 1e-8)
  --max-iter N      cap on outer iterations (sweeps), N >= 1 (default 1000)
  --out FILE.hdf5   write a copy of the problem (W in compressed columns) with the solution
                    r, u in its FCLIB /solution group (also when not converged)
  --help            this text

If PROBLEM.hdf5 already holds a /solution, its fc3d error is printed too.

Exit code: 0 converged, 2 not converged (max-iterations, time-budget-exceeded or diverged;
the report is still printed), 1 bad input (one line on stderr says what to fix).
)";

struct Options {
  std::string problem_path;
  std::string out_path;
  hapco::contact::SolverKind solver = hapco::contact::SolverKind::kReferenceNsgs;
  double fc3d_tolerance = 1e-8;
  std::optional<double> paper_tolerance;
  double local_tolerance = 1e-8;
  int max_iterations = 1000;
  bool help = false;
};

double ParsePositive(std::string_view flag, std::string_view text) {
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || !(value > 0.0) ||
      value == std::numeric_limits<double>::infinity()) {
    throw hapco::InputError(std::string(flag) + " needs a positive number, got '" +
                            std::string(text) + "'");
  }
  return value;
}

int ParseCount(std::string_view flag, std::string_view text) {
  int value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || value < 1) {
    throw hapco::InputError(std::string(flag) + " needs an integer >= 1, got '" +
                            std::string(text) + "'");
  }
  return value;
}

Options ParseOptions(int argc, char** argv) {
  Options options;
  for (int k = 1; k < argc; ++k) {
    const std::string_view arg = argv[k];
    if (arg == "--help" || arg == "-h") {
      options.help = true;
      return options;
    }
    if (arg.starts_with("--")) {
      if (k + 1 >= argc) throw hapco::InputError(std::string(arg) + " needs a value");
      const std::string_view value = argv[++k];
      if (arg == "--solver") {
        options.solver = hapco::contact::ParseSolverKind(value);
      } else if (arg == "--tol") {
        options.fc3d_tolerance = ParsePositive(arg, value);
      } else if (arg == "--paper-tol") {
        options.paper_tolerance = ParsePositive(arg, value);
      } else if (arg == "--local-tol") {
        options.local_tolerance = ParsePositive(arg, value);
      } else if (arg == "--max-iter") {
        options.max_iterations = ParseCount(arg, value);
      } else if (arg == "--out") {
        options.out_path = std::string(value);
      } else {
        throw hapco::InputError("unknown option " + std::string(arg) + " (see --help)");
      }
    } else if (options.problem_path.empty()) {
      options.problem_path = std::string(arg);
    } else {
      throw hapco::InputError("one problem file only; unexpected '" + std::string(arg) + "'");
    }
  }
  if (options.problem_path.empty()) {
    throw hapco::InputError("no problem file given (usage: hapco-solve PROBLEM.hdf5, see --help)");
  }
  return options;
}

int Run(const Options& options) {
  namespace contact = hapco::contact;
  namespace fclib = hapco::fclib;
  fclib::FclibFileDetails details;
  const contact::ContactProblem problem =
      fclib::ReadFclibLocalProblem(options.problem_path, &details);
  const std::optional<fclib::FclibSolution> stored =
      fclib::ReadFclibSolution(options.problem_path);
  const int m = problem.num_contacts();

  std::printf("file          %s\n", options.problem_path.c_str());
  if (!details.info.title.empty()) std::printf("title         %s\n", details.info.title.c_str());
  std::printf("W             %d x %d, %s, %d stored entries\n", 3 * m, 3 * m,
              fclib::StorageName(details.w_storage), details.w_stored_entries);
  std::printf("contacts      %d, mu in [%g, %g]\n", m, problem.friction_coefficient.minCoeff(),
              problem.friction_coefficient.maxCoeff());
  if (stored) {
    std::printf("stored solution fc3d error %.3e\n", contact::Fc3dError(problem, stored->force_n));
  }

  contact::SolverParameters params;
  params.fc3d_tolerance = options.fc3d_tolerance;
  // The paper's test is off unless asked for: a tolerance no residual can pass but zero.
  params.global_tolerance_m = options.paper_tolerance.value_or(std::numeric_limits<double>::min());
  params.local_tolerance_m = options.local_tolerance;
  params.max_iterations = options.max_iterations;
  contact::SolverWorkspace workspace;
  workspace.Reserve(m, params.max_iterations);
  contact::SolverResult result;
  result.Reserve(m, params.max_iterations);
  const contact::SolverStatus status =
      contact::Solve(options.solver, problem, params, &workspace, &result);
  const contact::SolverStats& stats = result.stats;  // stats.state_counts: see below

  std::printf("solver        %s (fc3d tol %g, paper tol %s, max %d iterations)\n",
              std::string(contact::SolverName(options.solver)).c_str(), options.fc3d_tolerance,
              options.paper_tolerance ? std::to_string(*options.paper_tolerance).c_str() : "off",
              options.max_iterations);
  std::printf("status        %s\n", std::string(contact::StatusName(status)).c_str());
  std::printf("iterations    %d outer, %d inner\n", stats.iterations, stats.inner_iterations);
  std::printf("time          %.6f s\n", stats.seconds);
  std::printf("fc3d error    %.3e\n", stats.fc3d_error);
  std::printf("paper error   %.3e (units of W r, m for HapCo problems; rho %.4g)\n",
              stats.paper_error_m, stats.rho);
  std::printf("fclib merit   %.3e (libfclib MERIT_1)\n",
              fclib::FclibMeritLocal(problem, result.force_n));
  // States from tolerances relative to the fc3d scale: the solver's own counts use the
  // paper tolerance, which is off here (projection.h ClassifyContact).
  const double scale = std::max({problem.free_displacement_m.norm(), result.force_n.norm(),
                                 result.displacement_m.norm()});
  const double state_tolerance = std::max(100.0 * options.fc3d_tolerance, 1e-12) * scale;
  const std::array<int, 3> states = contact::CountContactStates(
      result.force_n, result.displacement_m, state_tolerance, state_tolerance);
  std::printf("states        separating %d, sticking %d, sliding %d (tolerance %.2e)\n",
              states[0], states[1], states[2], state_tolerance);
  if (!options.out_path.empty()) {
    fclib::FclibInfo info = details.info;
    if (info.title.empty()) info.title = "solved by hapco-solve";
    fclib::WriteFclibLocalProblem(options.out_path, problem, info);
    fclib::WriteFclibSolution(options.out_path, result.force_n, result.displacement_m);
    std::printf("solution      written to %s (FCLIB /solution)\n", options.out_path.c_str());
  }
  return status == contact::SolverStatus::kConverged ? kExitConverged : kExitNotConverged;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options options = ParseOptions(argc, argv);
    if (options.help) {
      std::fputs(kUsage, stdout);
      return kExitConverged;
    }
    return Run(options);
  } catch (const hapco::InputError& error) {
    std::fprintf(stderr, "hapco-solve: %s\n", error.what());
    return kExitBadInput;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "hapco-solve: unexpected error: %s\n", error.what());
    return kExitBadInput;
  }
}
