// contact_bench: the contact-solver benchmark of docs/contact-benchmark.md (issue "Contact
// solvers", item 4). Prints tables, optionally writes CSV; never asserts on time.
//
// Problems (a real elastic model, not random matrices):
//   Obstacle: an elastic slab like the paper's red bar (algorithms.md §1), widened so that its
//   top face has enough nodes: L × W × H = 0.10 × 0.05 × 0.02 m, Tet4 50 × 24 × 4 hex cells,
//   E = 3e6 Pa, ν = 0.3, clamped at both end faces x = 0 and x = L. Its free top-face nodes
//   (49 × 25 = 1225) are the candidate contact points.
//   Contacts: the m free top-face nodes nearest the face centre (ties by node id), i.e. the
//   footprint of a rigid punch; patches are nested, so W for m is the leading 3m × 3m block
//   of W for m_max.
//   W: the compliance block C of those nodes (ElasticBody::ComplianceBlock) in local frames
//   n = +z, t1 = +x, t2 = +y, i.e. rows/columns reordered [z, x, y] per node. The punch is
//   rigid, so the relative displacement of the punch w.r.t. the slab is u = C r + ũ (the
//   reaction −r on the slab moves its surface by −C r).
//   ũ: a curved punch pressed by δ and slid by one haptic-step increment:
//       ũ_n = g(d) − δ,  g(d) = 1.25 δ (d / d_max)²  (d = distance of the node to the face
//       centre, d_max the largest d in the patch), so the outer ring starts with a gap;
//       ũ_t = (0.1 mm, 0.05 mm) (the slide increment of one step, algorithms.md §2 incremental
//       friction), μ = 0.3. δ = 0.5 mm (step 5 of the paper-like press series of 0.1 mm steps).
//   This gives a mix of separating (rim), sticking (centre) and sliding (ring) contacts; the
//   state counts are printed.
// Warm start: from the solution of the previous haptic step, i.e. the same problem with
//   δ − 0.1 mm (same gap profile and slide), solved to fc3d 1e-10 by global-uzawa-gs.
// Time to tolerance: SolverParameters::fc3d_tolerance = 1e-4 / 1e-6 / 1e-8 with a tiny
//   global_tolerance_m (never triggers first); median of several runs; wall time of Solve.
// Sweep: (T(max_iterations = K + 1) − T(max_iterations = 1)) / K from a cold start, which
//   cancels the per-call set-up and exit work (exit W·r, fc3d, state counts), against one
//   dense Eigen product W·r of the same size, timed in the same run.
// Siconos (HAPCO_HAVE_SICONOS): fc3d_driver with SICONOS_FRICTION_3D_NSGS (default local
//   solver) and SICONOS_FRICTION_3D_DSFP (De Saxcé fixed point, ρ = 1 / max W_ii like ours), M
//   dense column-major, q = ũ. Siconos stops on its own error measure, so its result is
//   re-measured with our Fc3dError; if that is above the target, the run is repeated with a
//   10× tighter Siconos tolerance (up to 3 times) and the time of the first run that meets the
//   target on our measure is reported.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <cstdlib>
#include <string>
#include <vector>

#include <time.h>

#include <Eigen/Dense>

#include "common/load_average.h"
#include "cli/command_line.h"
#include "cli/run_main.h"
#include "common/timer.h"
#include "contact/problem.h"
#include "contact/projection.h"
#include "contact/solver.h"
#include "fem/box_mesh.h"
#include "fem/elastic_body.h"

#ifdef HAPCO_HAVE_SICONOS
#include <FrictionContactProblem.h>
#include <Friction_cst.h>
#include <NonSmoothDrivers.h>
#include <NumericsMatrix.h>
#include <NumericsVerbose.h>
#include <SolverOptions.h>
#endif

namespace {

// Process CPU time (all threads), s: on this shared, loaded machine wall time mostly measures
// the other users; CPU time measures the solver (it still sees memory-bandwidth contention).
class Stopwatch {
 public:
  Stopwatch() : start_(Now()) {}
  double ElapsedSeconds() const { return Now() - start_; }

 private:
  static double Now() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  double start_;
};
using hapco::contact::ContactProblem;
using hapco::contact::SolverKind;

constexpr double kDeltaM = 0.5e-3;       // press depth δ, m
constexpr double kStepM = 0.1e-3;        // press increment of one haptic step, m
constexpr double kSlideXM = 0.03e-3;      // tangential slide increment, m
constexpr double kSlideYM = 0.015e-3;     // tangential slide increment, m
constexpr double kFriction = 0.3;        // μ
double g_gap_shape = 0.3;                // g(d_max) = g_gap_shape δ (--gap-shape)
constexpr double kTolerances[] = {1e-4, 1e-6, 1e-8};

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The slab, its candidate nodes (sorted by distance to the top-face centre) and W for m_max.
struct Scene {
  Eigen::MatrixXd w_full;           // 3 m_max × 3 m_max, m/N, local frames [z, x, y]
  std::vector<double> distance_m;   // distance of contact i to the top-face centre, m
  double build_seconds = 0.0;
  int mesh_nodes = 0;
};

Scene BuildScene(int m_max) {
  using namespace hapco::fem;
  Stopwatch clock;
  BoxMeshSpec spec;
  spec.size_m = Eigen::Vector3d(0.10, 0.05, 0.02);
  spec.divisions = Eigen::Vector3i(50, 24, 4);
  spec.order = ElementOrder::kTet4;
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = {3e6, 0.3};
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  const auto far_end = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMax);
  s.clamped_nodes.insert(s.clamped_nodes.end(), far_end.begin(), far_end.end());
  const ElasticBody body(std::move(s));

  const Eigen::Vector2d centre(0.5 * spec.size_m.x(), 0.5 * spec.size_m.y());
  std::vector<int> top;
  for (int node : NodesOnBoxFace(body.mesh(), spec, BoxFace::kZMax)) {
    if (!body.is_dirichlet_node(node)) top.push_back(node);
  }
  auto dist = [&](int node) {
    return (body.mesh().nodes_m.row(node).head<2>().transpose() - centre).norm();
  };
  std::stable_sort(top.begin(), top.end(), [&](int a, int b) { return dist(a) < dist(b); });
  if (static_cast<int>(top.size()) < m_max) {
    std::fprintf(stderr, "slab top face has only %zu free nodes\n", top.size());
    std::exit(1);
  }
  top.resize(static_cast<std::size_t>(m_max));
  const Eigen::MatrixXd c = body.ComplianceBlock(top);
  Scene scene;
  const int n = 3 * m_max;
  scene.w_full.resize(n, n);
  constexpr int kAxis[3] = {2, 0, 1};  // local [n, t1, t2] = world [z, x, y]
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      scene.w_full(i, j) = c(3 * (i / 3) + kAxis[i % 3], 3 * (j / 3) + kAxis[j % 3]);
    }
  }
  for (int node : top) scene.distance_m.push_back(dist(node));
  scene.mesh_nodes = body.mesh().num_nodes();
  scene.build_seconds = clock.ElapsedSeconds();
  return scene;
}

// The curved punch pressed by `delta_m` (gap profile fixed by kDeltaM so that the previous
// step differs from the current one only by the press increment), in SI units.
ContactProblem MakeProblemSi(const Scene& scene, int m, double delta_m) {
  ContactProblem p;
  p.flexibility_m_per_n = scene.w_full.topLeftCorner(3 * m, 3 * m);
  p.free_displacement_m.resize(3 * m);
  p.friction_coefficient = Eigen::VectorXd::Constant(m, kFriction);
  const double d_max =
      *std::max_element(scene.distance_m.begin(), scene.distance_m.begin() + m);
  for (int i = 0; i < m; ++i) {
    const double x = d_max > 0.0 ? scene.distance_m[static_cast<std::size_t>(i)] / d_max : 0.0;
    p.free_displacement_m(3 * i) = g_gap_shape * kDeltaM * x * x - delta_m;
    p.free_displacement_m(3 * i + 1) = kSlideXM;
    p.free_displacement_m(3 * i + 2) = kSlideYM;
  }
  return p;
}

// The fc3d error (algorithms.md §4) adds forces (N) to displacements (m) with ρ = 1, so in SI
// units, where W ~ 1e-4 m/N, ‖r‖ dominates its denominator and r − Proj(r − u) is tiny after
// one sweep: 1e-4 is "reached" by r⁽¹⁾. The benchmark therefore solves the problem in units
// where W and ũ are O(1), as FCLIB/Siconos problems are:
//     length L₀ = δ,  force F₀ = δ / w̄  (w̄ = mean W_nn of the patch),
//     W' = W / w̄,  ũ' = ũ / δ,  r = F₀ r'.
// Every solver here is equivariant under this change of units when its tolerances are scaled
// with it (ρ = 1/max W_ii scales too); only the fc3d measure changes meaning.
struct ScaledProblem {
  ContactProblem problem;   // dimensionless
  double force_scale_n;     // F₀, N
};

ScaledProblem Scale(const ContactProblem& si, double length_scale_m) {
  const int m = si.num_contacts();
  double w_mean = 0.0;
  for (int i = 0; i < m; ++i) w_mean += si.flexibility_m_per_n(3 * i, 3 * i) / m;
  ScaledProblem out;
  out.problem.flexibility_m_per_n = si.flexibility_m_per_n / w_mean;
  out.problem.free_displacement_m = si.free_displacement_m / length_scale_m;
  out.problem.friction_coefficient = si.friction_coefficient;
  out.force_scale_n = length_scale_m / w_mean;
  return out;
}

// SI local Uzawa default ε₂ = 1e-8 m, in units of L₀ = δ.
constexpr double kLocalToleranceScaled = 1e-8 / kDeltaM;

struct Row {
  std::string kind;    // "solve" or "sweep"
  int m = 0;
  std::string start;   // cold / warm
  std::string solver;
  double tolerance = 0.0;
  double seconds = 0.0;  // median time to tolerance, or sweep time
  int iterations = 0;
  double fc3d = 0.0;     // our Fc3dError of the returned force
  bool converged = false;
  std::string note;      // status, or Siconos tolerance used
  double wr_seconds = 0.0;
  double ratio = 0.0;
};

struct Config {
  bool quick = false;
  std::string csv;
  bool states_only = false;  // --states
  bool sweeps_only = false;  // --sweeps
};

int Reps(int m) { return m <= 50 ? 7 : m <= 100 ? 5 : 3; }
double CapSeconds(int m) { return m <= 100 ? 2.0 : m <= 300 ? 4.0 : 10.0; }

// One timed solve of a HapCo solver.
Row RunHapco(SolverKind kind, const ContactProblem& p, double tol, const Eigen::VectorXd* warm,
             double cap_s, hapco::contact::SolverWorkspace* ws, hapco::contact::SolverResult* res) {
  hapco::contact::SolverParameters par;
  par.global_tolerance_m = 1e-300;  // never first: fc3d_tolerance decides
  par.fc3d_tolerance = tol;
  par.max_iterations = 1000000;
  par.time_budget_s = cap_s;
  par.warm_start = warm != nullptr;
  par.divergence_factor = 1e300;  // the paper test is off; do not stop on its growth
  par.local_tolerance_m = kLocalToleranceScaled;
  if (warm != nullptr) res->force_n = *warm;
  Stopwatch clock;
  hapco::contact::Solve(kind, p, par, ws, res);
  Row row;
  row.seconds = clock.ElapsedSeconds();
  row.iterations = res->stats.iterations;
  row.fc3d = res->stats.fc3d_error;
  row.converged = res->stats.status == hapco::contact::SolverStatus::kConverged;
  row.note = std::string(hapco::contact::StatusName(res->stats.status));
  return row;
}

// Sweep time of a HapCo solver: (T(K+1) − T(1)) / K, cold start, no stop test.
double SweepSeconds(SolverKind kind, const ContactProblem& p, int k,
                    hapco::contact::SolverWorkspace* ws, hapco::contact::SolverResult* res) {
  hapco::contact::SolverParameters par;
  par.global_tolerance_m = 1e-300;
  par.divergence_factor = 1e300;
  par.local_tolerance_m = kLocalToleranceScaled;
  auto time_it = [&](int iters) {
    par.max_iterations = iters;
    Stopwatch clock;
    hapco::contact::Solve(kind, p, par, ws, res);
    return clock.ElapsedSeconds();
  };
  std::vector<double> diffs;
  Stopwatch total;
  for (int rep = 0; rep < 51 && (rep < 3 || total.ElapsedSeconds() < 0.4); ++rep) {
    const double t1 = time_it(1);
    const double tk = time_it(k + 1);
    diffs.push_back((tk - t1) / k);
  }
  return Median(diffs);
}

// One dense y = W r (Eigen), s: median over batches of products (a batch lasts >= ~0.2 ms so
// that the clock's own cost does not count).
double ProductSeconds(const Eigen::MatrixXd& w) {
  Eigen::VectorXd r = Eigen::VectorXd::LinSpaced(w.cols(), 1.0, 2.0);
  Eigen::VectorXd y(w.rows());
  const double flops = 2.0 * static_cast<double>(w.rows()) * static_cast<double>(w.cols());
  const int batch = static_cast<int>(std::max(1.0, 2e5 / flops));
  std::vector<double> t;
  Stopwatch total;
  double sink = 0.0;
  for (int rep = 0; rep < 2001 && (rep < 11 || total.ElapsedSeconds() < 0.3); ++rep) {
    Stopwatch clock;
    for (int b = 0; b < batch; ++b) {
      y.noalias() = w * r;
      sink += y(0);
      r(0) += 1e-30 * sink;  // keep the products live
    }
    t.push_back(clock.ElapsedSeconds() / batch);
  }
  return Median(t);
}

#ifdef HAPCO_HAVE_SICONOS
// Siconos Numerics on the same problem. M is dense column-major (Eigen's layout).
class SiconosProblem {
 public:
  explicit SiconosProblem(const ContactProblem& p)
      : n_(static_cast<int>(p.free_displacement_m.size())),
        q_(p.free_displacement_m),
        mu_(p.friction_coefficient) {
    m_ = NM_create(NM_DENSE, n_, n_);
    std::memcpy(m_->matrix0, p.flexibility_m_per_n.data(),
                sizeof(double) * static_cast<std::size_t>(n_) * static_cast<std::size_t>(n_));
    problem_.dimension = 3;
    problem_.numberOfContacts = n_ / 3;
    problem_.M = m_;
    problem_.q = q_.data();
    problem_.mu = mu_.data();
  }
  ~SiconosProblem() { m_ = NM_free(m_); }
  SiconosProblem(const SiconosProblem&) = delete;
  SiconosProblem& operator=(const SiconosProblem&) = delete;

  struct Out {
    double seconds = 0.0;
    int iterations = 0;
    int info = 0;
    double siconos_error = 0.0;
    Eigen::VectorXd r;
  };
  // solver_id: SICONOS_FRICTION_3D_NSGS or SICONOS_FRICTION_3D_DSFP.
  Out Run(int solver_id, double tol, int max_iter, const Eigen::VectorXd* warm, double rho) {
    SolverOptions* options = solver_options_create(solver_id);
    options->iparam[SICONOS_IPARAM_MAX_ITER] = max_iter;
    options->dparam[SICONOS_DPARAM_TOL] = tol;
    // DSFP: rho > 0 fixes ρ; 0 keeps Siconos' own variable step (its default).
    if (solver_id == SICONOS_FRICTION_3D_DSFP) options->dparam[SICONOS_FRICTION_3D_NSN_RHO] = rho;
    Out out;
    out.r = warm != nullptr ? *warm : Eigen::VectorXd::Zero(n_);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(n_);
    Stopwatch clock;
    out.info = fc3d_driver(&problem_, out.r.data(), v.data(), options);
    out.seconds = clock.ElapsedSeconds();
    out.iterations = options->iparam[SICONOS_IPARAM_ITER_DONE];
    out.siconos_error = options->dparam[SICONOS_DPARAM_RESIDU];
    solver_options_delete(options);
    return out;
  }

 private:
  int n_;
  Eigen::VectorXd q_, mu_;
  NumericsMatrix* m_ = nullptr;
  FrictionContactProblem problem_{};
};
#endif

void PrintTime(double s, bool ok) {
  if (!ok) {
    std::printf("  >%8.4g", s);
  } else {
    std::printf("  %9.4g", s);
  }
}

constexpr const char* kDescription =
    R"(The contact-solver benchmark of docs/contact-benchmark.md: time to fc3d tolerance (1e-4, 1e-6, 1e-8; cold and warm start) and the cost of one sweep against a dense W*r product, for every HapCo contact solver (and Siconos NSGS and DSFP when built with Siconos Numerics), on problems of m = 10 to 1000 contacts built from an elastic slab under a curved rigid punch. Prints tables (process CPU time), never asserts on time; the problem construction is described at the top of tests/bench/contact/contact_bench.cc.)";

constexpr const char* kFooter = "Exit code: 0 when the benchmark ran, 1 on bad input.";

// Defines the command line (docs/cli.md) and parses it; false: --help/--version answered.
bool Parse(int argc, char** argv, Config* cfg) {
  hapco::cli::CommandLine command("contact_bench", "[options]", kDescription, kFooter);
  command.AddFlag("--quick", &cfg->quick, "m = 10, 50, 100 only (about 1 min)", "Run");
  command.AddFlag("--states", &cfg->states_only, "print the contact-state mix per m only, no timings", "Run");
  command.AddFlag("--sweeps", &cfg->sweeps_only, "sweep / W*r ratios only, no time to tolerance", "Run");
  command.AddNumber("--gap-shape", &g_gap_shape, "G",
                    "punch profile: the initial gap at the patch rim is g(d_max) = G delta, dimensionless "
                    "(default 0.3)",
                    "Problem", -HUGE_VAL, HUGE_VAL);
  command.AddCsv(&cfg->csv, "also write every number as CSV (scripts/plot_contact_benchmark.py)");
  return command.Parse(argc, argv);
}

int Run(const Config& cfg) {
#ifdef HAPCO_HAVE_SICONOS
  numerics_set_verbose(0);
#endif
  const std::vector<int> sizes =
      cfg.quick ? std::vector<int>{10, 50, 100} : std::vector<int>{10, 50, 100, 300, 1000};
  const int m_max = sizes.back();
  const std::string load_start = hapco::LoadAverageText();
  const hapco::Stopwatch wall;
  const Scene scene = BuildScene(m_max);
  std::printf("contact_bench: slab 0.10x0.05x0.02 m Tet4 50x24x4 (%d nodes), E=3e6 Pa nu=0.3,\n"
              "clamped x=0,L; curved punch delta=%.2g m, g(d_max)=%.2g delta, slide (%.2g, %.2g)"
              " m, mu=%.2g\nscene build incl. compliance of %d nodes: %.2f s; load average at "
              "start: %s\nProblems solved in units L0 = delta, F0 = delta/mean(W_nn) (see "
              "source); times are medians, '>' = not reached within the cap.\n\n",
              scene.mesh_nodes, kDeltaM, g_gap_shape, kSlideXM, kSlideYM, kFriction, m_max,
              scene.build_seconds, load_start.c_str());

  const std::vector<SolverKind> kinds = {SolverKind::kLocalUzawa,
                                         SolverKind::kGlobalUzawaGaussSeidel,
                                         SolverKind::kGlobalUzawaJacobi,
                                         SolverKind::kReferenceNsgs};
  std::vector<Row> rows;
  std::vector<std::string> solver_names;
  for (SolverKind k : kinds) solver_names.emplace_back(hapco::contact::SolverName(k));
#ifdef HAPCO_HAVE_SICONOS
  solver_names.emplace_back("siconos-nsgs");
  solver_names.emplace_back("siconos-dsfp");
#endif
  auto is_siconos = [](const std::string& name) { return name.rfind("siconos", 0) == 0; };

  for (int m : sizes) {
    // Two consecutive haptic steps (algorithms.md §2, incremental friction): the previous step
    // k−1 presses by δ − 0.1 mm and slides by s; the current step k presses by δ and slides by
    // s more, so its tangential free displacement is the slide increment minus the tangential
    // displacement already reached at k−1: ũ_t,k = s − (W r_{k−1})_t.
    const ContactProblem si_prev = MakeProblemSi(scene, m, kDeltaM - kStepM);
    const ScaledProblem scaled_prev = Scale(si_prev, kDeltaM);
    const ContactProblem& prev = scaled_prev.problem;
    hapco::contact::SolverWorkspace ws;
    ws.Reserve(m, 0);
    hapco::contact::SolverResult res;
    res.Reserve(m, 0);
    hapco::contact::SolverParameters tight;
    tight.global_tolerance_m = 1e-300;
    tight.fc3d_tolerance = 1e-10;
    tight.max_iterations = 200000;
    tight.divergence_factor = 1e300;
    hapco::contact::Solve(SolverKind::kGlobalUzawaGaussSeidel, prev, tight, &ws, &res);
    const Eigen::VectorXd warm = res.force_n;  // warm start = the previous step's force
    ContactProblem p = prev;                    // same W and scale
    {
      const ContactProblem si_now = MakeProblemSi(scene, m, kDeltaM);
      p.free_displacement_m = si_now.free_displacement_m / kDeltaM;
      for (int i = 0; i < m; ++i) {
        p.free_displacement_m.segment<2>(3 * i + 1) -= res.displacement_m.segment<2>(3 * i + 1) -
                                                       prev.free_displacement_m.segment<2>(3 * i + 1);
      }
    }
    {
      // State mix of the current problem (tight solve), with tolerances in the scaled units
      // (1e-6 F0 and 1e-6 δ); stats.state_counts uses ε₁, which is ~0 here.
      hapco::contact::Solve(SolverKind::kGlobalUzawaGaussSeidel, p, tight, &ws, &res);
      const auto sc = hapco::contact::CountContactStates(res.force_n, res.displacement_m, 1e-6,
                                                         1e-6);
      std::printf("m = %d: states at the solution (separating/sticking/sliding) = %d/%d/%d "
                  "(fc3d %.0e, %d GS sweeps); total normal force %.3g N; F0 = %.3g N; "
                  "warm start (previous step) fc3d %.2e\n",
                  m, sc[0], sc[1], sc[2], res.stats.fc3d_error, res.stats.iterations,
                  scaled_prev.force_scale_n * res.force_n(Eigen::seqN(0, m, 3)).sum(),
                  scaled_prev.force_scale_n, hapco::contact::Fc3dError(p, warm));
      std::fflush(stdout);
    }
    if (cfg.states_only) continue;
    const double cap = CapSeconds(m);
#ifdef HAPCO_HAVE_SICONOS
    SiconosProblem sp(p);
    // DSFP with ρ = 1/max W_ii, like global-uzawa-jacobi. Its default variable step
    // (dparam[3] = 0) aborts in Siconos 4.4 on these problems, so it is not used.
    const double rho_paper = 1.0 / p.flexibility_m_per_n.diagonal().maxCoeff();
#endif

    // Sweep cost against one dense product of the same size, same run.
    const double wr = ProductSeconds(p.flexibility_m_per_n);
    std::printf("sweep  m=%-5d W*r %.3g s |", m, wr);
    std::vector<double> sweep_s;
    double inner_per_contact = 0.0;
    for (const std::string& name : solver_names) {
      double sweep = 0.0;
      if (!is_siconos(name)) {
        const SolverKind kind = hapco::contact::ParseSolverKind(name);
        const int k = (kind == SolverKind::kReferenceNsgs && m >= 300) ? 3 : 10;
        sweep = SweepSeconds(kind, p, k, &ws, &res);
        if (kind == SolverKind::kLocalUzawa) {
          // Count: inner Uzawa steps per contact per sweep over the first k sweeps.
          inner_per_contact = static_cast<double>(res.stats.inner_iterations) /
                              (static_cast<double>(res.stats.iterations) * m);
        }
      } else {
#ifdef HAPCO_HAVE_SICONOS
        const int id = name == "siconos-nsgs" ? SICONOS_FRICTION_3D_NSGS
                                              : SICONOS_FRICTION_3D_DSFP;
        const int k = 10;
        std::vector<double> d;
        Stopwatch total;
        for (int rep = 0; rep < 51 && (rep < 3 || total.ElapsedSeconds() < 0.4); ++rep) {
          const double t1 = sp.Run(id, 1e-300, 1, nullptr, rho_paper).seconds;
          const double tk = sp.Run(id, 1e-300, k + 1, nullptr, rho_paper).seconds;
          d.push_back((tk - t1) / k);
        }
        sweep = Median(d);
#endif
      }
      sweep_s.push_back(sweep);
      Row row;
      row.kind = "sweep";
      row.m = m;
      row.solver = name;
      row.seconds = sweep;
      row.wr_seconds = wr;
      row.ratio = sweep / wr;
      rows.push_back(row);
      std::printf(" %s %.2f", name.c_str(), row.ratio);
    }
    std::printf("  (sweep / W*r); local-uzawa inner steps per contact-sweep %.1f\n",
                inner_per_contact);
    std::fflush(stdout);
    if (cfg.sweeps_only) continue;

    std::printf("%-6s %-5s %-20s |%s\n", "m", "start", "solver",
                "  t(1e-4) s  iters   t(1e-6) s  iters   t(1e-8) s  iters");
    for (const char* start : {"cold", "warm"}) {
      const bool is_warm = std::strcmp(start, "warm") == 0;
      const Eigen::VectorXd* w0 = is_warm ? &warm : nullptr;
      for (std::size_t s = 0; s < solver_names.size(); ++s) {
        const std::string& name = solver_names[s];
        std::printf("%-6d %-5s %-20s |", m, start, name.c_str());
        bool capped = false;
        for (double tol : kTolerances) {
          Row row;
          if (capped) {
            row.seconds = cap;
            row.note = "skipped (looser tolerance not reached within the cap)";
          } else if (!is_siconos(name)) {
            const SolverKind kind = hapco::contact::ParseSolverKind(name);
            std::vector<double> t;
            for (int rep = 0; rep < Reps(m); ++rep) {
              row = RunHapco(kind, p, tol, w0, cap, &ws, &res);
              t.push_back(row.seconds);
              if (!row.converged) break;
            }
            row.seconds = Median(t);
          } else {
#ifdef HAPCO_HAVE_SICONOS
            const int id = name == "siconos-nsgs" ? SICONOS_FRICTION_3D_NSGS
                                                  : SICONOS_FRICTION_3D_DSFP;
            // Siconos has no time budget: cap its iterations by the time cap / sweep cost.
            const int max_iter = static_cast<int>(
                std::clamp(cap / std::max(sweep_s[s], 1e-9), 10.0, 1e6));
            double stol = tol;
            for (int attempt = 0; attempt < 4; ++attempt, stol *= 0.1) {
              std::vector<double> t;
              SiconosProblem::Out out;
              for (int rep = 0; rep < Reps(m); ++rep) {
                out = sp.Run(id, stol, max_iter, w0, rho_paper);
                t.push_back(out.seconds);
                if (out.info != 0) break;
              }
              row.seconds = Median(t);
              row.iterations = out.iterations;
              row.fc3d = hapco::contact::Fc3dError(p, out.r);
              row.converged = row.fc3d < tol;
              char note[96];
              std::snprintf(note, sizeof note, "siconos tol %.0e info %d err %.1e", stol,
                            out.info, out.siconos_error);
              row.note = note;
              if (row.converged || out.info != 0) break;
            }
#endif
          }
          if (!row.converged) capped = true;
          row.kind = "solve";
          row.m = m;
          row.start = start;
          row.solver = name;
          row.tolerance = tol;
          PrintTime(row.seconds, row.converged);
          std::printf(" %6d ", row.iterations);
          rows.push_back(row);
        }
        std::printf("\n");
        std::fflush(stdout);
      }
#ifdef HAPCO_HAVE_SICONOS
      std::printf("%-6d %-5s %-20s |", m, start, "uzawa/siconos-nsgs");
      for (double tol : kTolerances) {
        double a = 0.0, b = 0.0;
        for (const Row& r : rows) {
          if (r.kind == "solve" && r.m == m && r.start == start && r.tolerance == tol) {
            if (r.solver == "local-uzawa") a = r.seconds;
            if (r.solver == "siconos-nsgs") b = r.seconds;
          }
        }
        std::printf("  %9.3f        ", b > 0.0 ? a / b : 0.0);
      }
      std::printf("\n");
#endif
    }
    std::printf("\n");
  }
  const std::string load_end = hapco::LoadAverageText();
  std::printf("total %.1f s; load average at end: %s\n", wall.ElapsedSeconds(), load_end.c_str());

  if (!cfg.csv.empty()) {
    std::ofstream f(cfg.csv);
    f << "kind,m,start,solver,tolerance,seconds,iterations,fc3d_error,converged,note,"
         "wr_seconds,ratio,load_start,load_end\n";
    for (const Row& r : rows) {
      f << r.kind << ',' << r.m << ',' << r.start << ',' << r.solver << ',' << r.tolerance << ','
        << r.seconds << ',' << r.iterations << ',' << r.fc3d << ',' << (r.converged ? 1 : 0)
        << ",\"" << r.note << "\"," << r.wr_seconds << ',' << r.ratio << ",\"" << load_start
        << "\",\"" << load_end << "\"\n";
    }
    std::printf("wrote %s\n", cfg.csv.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return hapco::cli::RunMain("contact_bench", [&] {
    Config cfg;
    return Parse(argc, argv, &cfg) ? Run(cfg) : 0;
  });
}
