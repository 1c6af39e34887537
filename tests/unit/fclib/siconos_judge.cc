// siconos-judge FILE.hdf5 TOL: judges the solution stored in an FCLIB file with Siconos
// Numerics' own error functions, an implementation independent of HapCo's:
//   local problem:  fc3d_compute_error(W as stored, r, u) with norm ‖q‖ (what Siconos' NSGS
//                   driver passes), u recomputed by Siconos;
//   global problem: gfc3d_compute_error(M, H, q = f, b = w as Siconos reads FCLIB files, r, u,
//                   v) with norms ‖f‖ and ‖w‖.
// Prints the error and exits 0 when it is <= TOL, 2 otherwise (1 on bad input). The problem
// and solution are read with HapCo's FCLIB reader (Siconos' own FCLIB interface is compiled
// out in Debian's package); the matrices are handed to Siconos dense, as stored.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "fclib/fclib_io.h"

extern "C" {
#include <FrictionContactProblem.h>
#include <Friction_cst.h>
#include <GlobalFrictionContactProblem.h>
#include <NumericsMatrix.h>
#include <SolverOptions.h>
#include <fc3d_compute_error.h>
#include <gfc3d_compute_error.h>
}

namespace {

NumericsMatrix* DenseCopy(const Eigen::MatrixXd& a) {
  NumericsMatrix* m = NM_create(NM_DENSE, static_cast<int>(a.rows()), static_cast<int>(a.cols()));
  std::memcpy(m->matrix0, a.data(), sizeof(double) * static_cast<std::size_t>(a.size()));
  return m;
}

double JudgeLocal(const std::string& path) {
  namespace fclib = hapco::fclib;
  fclib::FclibFileDetails details;
  const hapco::contact::ContactProblem symmetric = fclib::ReadFclibLocalProblem(path, &details);
  const hapco::contact::ContactProblem& stored =
      details.stored_problem.num_contacts() > 0 ? details.stored_problem : symmetric;
  const auto solution = fclib::ReadFclibSolution(path);
  if (!solution) throw hapco::InputError(path + " holds no /solution");
  Eigen::VectorXd q = stored.free_displacement_m, mu = stored.friction_coefficient;
  Eigen::VectorXd r = solution->force_n, u = Eigen::VectorXd::Zero(q.size());
  FrictionContactProblem problem{};
  problem.dimension = 3;
  problem.numberOfContacts = stored.num_contacts();
  problem.M = DenseCopy(stored.flexibility_m_per_n);
  problem.q = q.data();
  problem.mu = mu.data();
  SolverOptions* options = solver_options_create(SICONOS_FRICTION_3D_NSGS);
  double error = 0.0;
  fc3d_compute_error(&problem, r.data(), u.data(), 0.0, options, q.norm(), &error);
  solver_options_delete(options);
  NM_free(problem.M);
  std::printf("siconos fc3d_compute_error %.3e (local, %d contacts, W as stored: max|W - W^T| / max|W| = %.2e)\n",
              error, problem.numberOfContacts, details.w_relative_asymmetry);
  return error;
}

double JudgeGlobal(const std::string& path) {
  namespace fclib = hapco::fclib;
  const hapco::contact::GlobalContactProblem global = fclib::ReadFclibGlobalProblem(path);
  const auto solution = fclib::ReadFclibGlobalSolution(path);
  if (!solution) throw hapco::InputError(path + " holds no /solution");
  Eigen::VectorXd f = global.f, w = global.w, mu = global.mu;
  Eigen::VectorXd r = solution->force, v = solution->velocity, u = solution->local_velocity;
  GlobalFrictionContactProblem* problem = globalFrictionContactProblem_new();
  problem->dimension = 3;
  problem->numberOfContacts = global.num_contacts();
  problem->M = DenseCopy(Eigen::MatrixXd(global.m));
  problem->H = DenseCopy(Eigen::MatrixXd(global.h));
  problem->q = f.data();  // Siconos: M v = q + H r, u = H^T v + b (from_fclib_global: q = f, b = w)
  problem->b = w.data();
  problem->mu = mu.data();
  SolverOptions* options = solver_options_create(SICONOS_GLOBAL_FRICTION_3D_NSGS_WR);
  double error = 0.0;
  gfc3d_compute_error(problem, r.data(), u.data(), v.data(), 0.0, options, f.norm(), w.norm(), &error);
  solver_options_delete(options);
  std::printf("siconos gfc3d_compute_error %.3e (global, %d dofs, %d contacts)\n", error, global.num_dofs(),
              global.num_contacts());
  // The problem struct borrows q, b, mu: detach them before Siconos frees it.
  problem->q = nullptr;
  problem->b = nullptr;
  problem->mu = nullptr;
  globalFrictionContact_free(problem);
  return error;
}

struct Options {
  std::string path;
  double tolerance = 0;
};

constexpr const char* kDescription =
    R"(Judges the solution stored in an FCLIB file with Siconos Numerics' own error functions, an implementation independent of HapCo's: a local problem with fc3d_compute_error (W as stored, norm |q|), a global one with gfc3d_compute_error (M, H, f, w; norms |f| and |w|). Prints the error and whether it is within TOL.)";

constexpr const char* kFooter = "Exit code: 0 when the error is <= TOL, 2 when it is not, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* o) {
  hapco::cli::CommandLine command("siconos-judge", "FILE.hdf5 TOL", kDescription, kFooter);
  command.AddText("FILE", &o->path, "", "FCLIB file with a /solution (hapco-solve --output)", "Arguments")
      ->required();
  command.AddNumber("TOL", &o->tolerance, "", "largest accepted Siconos error, dimensionless", "Arguments", 0,
                    HUGE_VAL)
      ->required();
  return command.Parse(argc, argv);
}

int Run(const Options& o) {
  const double error = hapco::fclib::ReadFclibKind(o.path) == hapco::fclib::FclibKind::kGlobal ? JudgeGlobal(o.path)
                                                                                                : JudgeLocal(o.path);
  const bool ok = error <= o.tolerance;
  std::printf("%s: error %.3e %s tolerance %.1e\n", ok ? "solved" : "NOT solved", error, ok ? "<=" : ">",
              o.tolerance);
  return ok ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("siconos-judge", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
