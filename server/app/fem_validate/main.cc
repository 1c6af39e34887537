// hapco-fem-validate: mesh convergence of the red bar (benchmark 2, clamped at x = 0) under a
// tip shear load, for Tet4 and Tet10, against Timoshenko beam theory. Prints a table and
// optionally writes CSV for scripts/plot_validation.py (docs/validation.md).
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/error.h"
#include "common/timer.h"
#include "fem/assembly.h"
#include "fem/box_mesh.h"
#include "fem/elastic_body.h"

namespace {

using namespace hapco::fem;

constexpr double kLength = 0.10, kWidth = 0.02, kHeight = 0.02;  // m (algorithms.md section 1)
constexpr double kYoungs = 3e6, kPoisson = 0.3;                  // Pa, -
constexpr double kLoad = 0.1;                                    // N, tip shear, downward

constexpr const char* kDescription =
    R"(Clamps the red bar (0.10 x 0.02 x 0.02 m, E = 3 MPa, nu = 0.3) at x = 0, applies a uniform downward shear traction on the x = L face (total 0.1 N, consistent nodal loads) and compares the mean vertical displacement of the tip face with Timoshenko beam theory
  delta = P L^3 / (3 E I) + P L / (kappa G A),  kappa = 10 (1 + nu) / (12 + 11 nu) (Cowper),
for Tet4 and Tet10 over a sequence of nested box meshes. Prints a table (docs/validation.md).)";

constexpr const char* kFooter = "Exit code: 0 on success, 1 on bad flags or an unwritable CSV file.";

double BeamTheoryDeflection() {
  const double area = kWidth * kHeight;
  const double inertia = kWidth * kHeight * kHeight * kHeight / 12.0;
  const double shear_modulus = kYoungs / (2.0 * (1.0 + kPoisson));
  const double kappa = 10.0 * (1.0 + kPoisson) / (12.0 + 11.0 * kPoisson);
  return kLoad * kLength * kLength * kLength / (3.0 * kYoungs * inertia) +
         kLoad * kLength / (kappa * shear_modulus * area);
}

struct Row {
  ElementOrder order;
  Eigen::Vector3i divisions;
  int dofs = 0, free_dofs = 0;
  long factor_nonzeros = 0;
  double deflection_m = 0.0, beam_m = 0.0, relative_error = 0.0;
  double assembly_s = 0.0, factorization_s = 0.0, solve_s = 0.0;
};

Row RunCantilever(ElementOrder order, int nx, int ny, int nz) {
  BoxMeshSpec spec;
  spec.size_m = Eigen::Vector3d(kLength, kWidth, kHeight);
  spec.divisions = Eigen::Vector3i(nx, ny, nz);
  spec.order = order;
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = {kYoungs, kPoisson};
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  std::vector<SurfaceTriangle> tip;
  for (const auto& f : BoundaryTriangles(s.mesh)) {
    bool on_tip = true;
    for (int c : f.corners) on_tip = on_tip && s.mesh.nodes_m(c, 0) >= kLength * (1.0 - 1e-9);
    if (on_tip) tip.push_back(f);
  }
  const Eigen::VectorXd f =
      UniformTractionLoads(s.mesh, tip, Eigen::Vector3d(0.0, 0.0, -kLoad / (kWidth * kHeight)));
  const ElasticBody body(std::move(s));

  // Median of 5 solves (the factor is reused; this is the per-step cost of a full solve).
  std::vector<double> times;
  Eigen::VectorXd u;
  for (int i = 0; i < 5; ++i) {
    hapco::Stopwatch watch;
    u = body.SolveDisplacement(f, Eigen::Vector3d::Zero());
    times.push_back(watch.ElapsedSeconds());
  }
  std::nth_element(times.begin(), times.begin() + 2, times.end());

  Row row;
  row.order = order;
  row.divisions = spec.divisions;
  row.dofs = body.num_dofs();
  row.free_dofs = body.num_free_dofs();
  row.factor_nonzeros = body.stats().factor_nonzeros;
  // Area-mean tip deflection = f.u / P (work-conjugate to the uniform traction).
  row.deflection_m = f.dot(u) / kLoad;
  row.beam_m = BeamTheoryDeflection();
  row.relative_error = (row.deflection_m - row.beam_m) / row.beam_m;
  row.assembly_s = body.stats().assembly_seconds;
  row.factorization_s = body.stats().factorization_seconds;
  row.solve_s = times[2];
  return row;
}

struct Case {
  ElementOrder order;
  int nx, ny, nz;
  bool large;
};

Case ParseCase(const std::string& text) {
  const auto colon = text.find(':');
  Case c{ElementOrder::kTet10, 0, 0, 0, false};
  const std::string order = text.substr(0, colon);
  if (order == "Tet4") {
    c.order = ElementOrder::kTet4;
  } else if (order != "Tet10" || colon == std::string::npos) {
    throw hapco::InputError("--case '" + text + "': expected Tet4:NXxNYxNZ or Tet10:NXxNYxNZ");
  }
  if (std::sscanf(text.c_str() + colon + 1, "%dx%dx%d", &c.nx, &c.ny, &c.nz) != 3 || c.nx < 1 ||
      c.ny < 1 || c.nz < 1) {
    throw hapco::InputError("--case '" + text + "': divisions must look like 20x4x4");
  }
  return c;
}

struct Options {
  std::string csv_path;
  bool quick = false;
  std::vector<Case> custom;  // --case, in the order given
};

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Options* options) {
  hapco::cli::CommandLine command("hapco-fem-validate", "[options]", kDescription, kFooter);
  command.AddFlag("--quick", &options->quick, "skip the two largest meshes of each order (for a fast check)",
                  "Meshes");
  // Repeatable: every value is parsed into options->custom as it is validated (the string
  // itself only gives the help its metavar).
  std::string case_text;
  command.AddText("--case", &case_text, "ORDER:NXxNYxNZ",
                  "run this mesh instead of the default sequence (repeatable), e.g. Tet10:12x3x3", "Meshes")
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)
      ->each([options](const std::string& text) { options->custom.push_back(ParseCase(text)); });
  command.AddCsv(&options->csv_path, "also write the table as CSV (input of scripts/plot_validation.py)");
  return command.Parse(argc, argv);
}

int Run(const Options& options) {
  const bool quick = options.quick;
  const std::string& csv_path = options.csv_path;
  const std::vector<Case>& custom = options.custom;
  // Refinements of the bar with cubic cells (cells 5 mm down to 1.25 mm / 0.625 mm).
  std::vector<Case> cases = {
      {ElementOrder::kTet10, 5, 1, 1, false},   {ElementOrder::kTet10, 10, 2, 2, false},
      {ElementOrder::kTet10, 15, 3, 3, false},  {ElementOrder::kTet10, 20, 4, 4, false},
      {ElementOrder::kTet10, 30, 6, 6, true},   {ElementOrder::kTet10, 40, 8, 8, true},
      {ElementOrder::kTet4, 10, 2, 2, false},   {ElementOrder::kTet4, 20, 4, 4, false},
      {ElementOrder::kTet4, 40, 8, 8, false},   {ElementOrder::kTet4, 60, 12, 12, true},
      {ElementOrder::kTet4, 80, 16, 16, true}};
  if (!custom.empty()) cases = custom;

  std::printf("Cantilever: red bar %.2f x %.2f x %.2f m, E = %.3g Pa, nu = %.2f, tip load %.2f N\n",
              kLength, kWidth, kHeight, kYoungs, kPoisson, kLoad);
  std::printf("Timoshenko beam theory tip deflection: %.6e m\n\n", BeamTheoryDeflection());
  std::printf("%-6s %-9s %8s %14s %14s %10s %10s %10s %10s %10s\n", "order", "divisions", "dofs",
              "tip_defl_m", "beam_m", "rel_err_%", "assemb_s", "factor_s", "solve_s", "L_nnz");
  std::vector<Row> rows;
  for (const Case& c : cases) {
    if (quick && c.large) continue;
    const Row r = RunCantilever(c.order, c.nx, c.ny, c.nz);
    const std::string div = std::to_string(r.divisions.x()) + "x" + std::to_string(r.divisions.y()) +
                            "x" + std::to_string(r.divisions.z());
    std::printf("%-6s %-9s %8d %14.6e %14.6e %10.3f %10.4f %10.4f %10.5f %10ld\n", ToString(r.order),
                div.c_str(), r.dofs, r.deflection_m, r.beam_m, 100.0 * r.relative_error,
                r.assembly_s, r.factorization_s, r.solve_s, r.factor_nonzeros);
    std::fflush(stdout);
    rows.push_back(r);
  }
  if (!csv_path.empty()) {
    std::ofstream out(csv_path);
    if (!out) throw hapco::InputError("cannot write CSV file '" + csv_path + "'");
    out << "order,nx,ny,nz,dofs,free_dofs,tip_deflection_m,beam_theory_m,relative_error,"
           "assembly_s,factorization_s,solve_s,factor_nonzeros\n";
    out.precision(10);
    for (const Row& r : rows) {
      out << ToString(r.order) << ',' << r.divisions.x() << ',' << r.divisions.y() << ','
          << r.divisions.z() << ',' << r.dofs << ',' << r.free_dofs << ',' << r.deflection_m << ','
          << r.beam_m << ',' << r.relative_error << ',' << r.assembly_s << ',' << r.factorization_s
          << ',' << r.solve_s << ',' << r.factor_nonzeros << '\n';
    }
    std::printf("\nwrote %s\n", csv_path.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("hapco-fem-validate", [&] {
    Options options;
    return Parse(argc, argv, &options) ? Run(options) : 0;
  });
}
