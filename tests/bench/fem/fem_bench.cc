// fem_bench: cost of the FEM pipeline on the red bar (0.10 x 0.02 x 0.02 m) meshed at about 1k,
// 10k and 50k dofs with Tet4 and Tet10, and of the compliance block that benchmark 1 needs
// (algorithms.md section 6) at about 10k, 50k and 100k dofs, against the batched-solve baseline.
// Times are medians of repeated runs; memory is resident-set growth.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Core>

#include "common/memory.h"
#include "common/timer.h"
#include "fem/box_mesh.h"
#include "fem/elastic_body.h"

namespace {

using namespace hapco::fem;

constexpr double kMiB = 1024.0 * 1024.0;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Median wall time of `repeats` calls of fn, s.
template <typename Fn>
double MedianSeconds(int repeats, Fn fn) {
  std::vector<double> times;
  for (int i = 0; i < repeats; ++i) {
    hapco::Stopwatch watch;
    fn();
    times.push_back(watch.ElapsedSeconds());
  }
  return Median(times);
}

BoxMeshSpec RedBar(ElementOrder order, int nx, int nyz) {
  BoxMeshSpec spec;
  spec.size_m = Eigen::Vector3d(0.10, 0.02, 0.02);
  spec.divisions = Eigen::Vector3i(nx, nyz, nyz);
  spec.order = order;
  return spec;
}

void BenchBody(ElementOrder order, int nx, int nyz) {
  const BoxMeshSpec spec = RedBar(order, nx, nyz);
  const std::size_t rss_before = hapco::CurrentResidentBytes();
  const std::size_t peak_before = hapco::PeakResidentBytes();
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = {3e6, 0.3};
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  const ElasticBody body(std::move(s));
  const std::size_t rss_after = hapco::CurrentResidentBytes();
  const std::size_t peak_after = hapco::PeakResidentBytes();

  Eigen::VectorXd f = Eigen::VectorXd::Zero(body.num_dofs());
  for (int n : NodesOnBoxFace(body.mesh(), spec, BoxFace::kXMax)) f[3 * n + 2] = -1e-3;
  std::vector<double> solve_s;
  for (int i = 0; i < 7; ++i) {
    hapco::Stopwatch watch;
    const Eigen::VectorXd u = body.SolveDisplacement(f, Eigen::Vector3d::Zero());
    solve_s.push_back(watch.ElapsedSeconds());
    if (!u.allFinite()) std::printf("non-finite solution!\n");
  }
  const std::string div =
      std::to_string(nx) + "x" + std::to_string(nyz) + "x" + std::to_string(nyz);
  std::printf("%-6s %-9s %8d %8d %10ld %11ld %10.4f %10.4f %10.5f %9.1f %9.1f\n", ToString(order),
              div.c_str(), body.num_dofs(), body.mesh().num_elements(), body.stats().stiffness_nonzeros,
              body.stats().factor_nonzeros, body.stats().assembly_seconds,
              body.stats().factorization_seconds, Median(solve_s),
              static_cast<double>(rss_after - std::min(rss_after, rss_before)) / kMiB,
              static_cast<double>(peak_after - std::min(peak_after, peak_before)) / kMiB);
  std::fflush(stdout);
}

// Compliance block of the red bar clamped at x = 0 and x = L, candidate contact nodes = every node
// of its top face (benchmark 1's obstacle at 20x4x4). Times both the Schur-complement method the
// server uses (ComplianceBlock) and the batched-solve baseline (ComplianceBlockBySolves, the method
// before it) when `with_baseline`, and checks that they agree.
void BenchComplianceBlock(int nx, int nyz, bool with_baseline) {
  const BoxMeshSpec spec = RedBar(ElementOrder::kTet10, nx, nyz);
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = {3e6, 0.3};
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  const auto far_end = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMax);
  s.clamped_nodes.insert(s.clamped_nodes.end(), far_end.begin(), far_end.end());
  const std::size_t peak_before = hapco::PeakResidentBytes();
  hapco::Stopwatch build;
  const ElasticBody body(std::move(s));
  const double build_s = build.ElapsedSeconds();
  const std::vector<int> top = NodesOnBoxFace(body.mesh(), spec, BoxFace::kZMax);
  const int repeats = body.num_dofs() < 20000 ? 3 : 1;
  Eigen::MatrixXd c;
  const double schur_s = MedianSeconds(repeats, [&] { c = body.ComplianceBlock(top); });
  const std::size_t peak_after = hapco::PeakResidentBytes();
  // The server's way: the candidates are known when the body is built, so its one factor
  // orders them last and the block is read off it (Spec::compliance_nodes).
  ElasticBody::Spec ordered_spec;
  ordered_spec.mesh = body.mesh();
  ordered_spec.material = body.material();
  ordered_spec.clamped_nodes = body.clamped_nodes();
  ordered_spec.compliance_nodes = top;
  hapco::Stopwatch ordered_watch;
  const ElasticBody ordered(std::move(ordered_spec));
  const double ordered_build_s = ordered_watch.ElapsedSeconds();
  const Eigen::MatrixXd c_ordered = ordered.ComplianceBlock(top);
  const double ordered_total_s = ordered_watch.ElapsedSeconds();
  const double ordered_diff = (c_ordered - c).cwiseAbs().maxCoeff() / c.cwiseAbs().maxCoeff();
  double baseline_s = 0.0;
  double rel_diff = 0.0;
  if (with_baseline) {
    Eigen::MatrixXd b;
    baseline_s = MedianSeconds(repeats, [&] { b = body.ComplianceBlockBySolves(top); });
    rel_diff = (c - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
  }
  const std::string div =
      std::to_string(nx) + "x" + std::to_string(nyz) + "x" + std::to_string(nyz);
  std::printf("%-9s %8d %6zu %7ld %8.3f %9.3f %9.1f %9.3f %9.3f %9.1e", div.c_str(), body.num_dofs(), top.size(),
              static_cast<long>(c.rows()), build_s, schur_s,
              static_cast<double>(peak_after - std::min(peak_after, peak_before)) / kMiB, ordered_build_s,
              ordered_total_s, ordered_diff);
  if (with_baseline) {
    std::printf(" %10.3f %7.1f %9.1e\n", baseline_s, baseline_s / schur_s, rel_diff);
  } else {
    std::printf(" %10s %7s %9s\n", "-", "-", "-");
  }
  std::fflush(stdout);
}

// Runs one case in a child process so that its peak RSS is its own, not the largest case's so far.
template <typename Fn>
void InChild(Fn fn) {
  std::fflush(stdout);
  const pid_t pid = fork();
  if (pid == 0) {
    fn();
    std::fflush(stdout);
    _exit(0);
  }
  if (pid < 0) {
    fn();  // no fork: run here (peak RSS column then reflects the largest case so far)
    return;
  }
  int status = 0;
  waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) std::printf("case failed (status %d)\n", status);
}

}  // namespace

int main() {
  std::printf("fem_bench: red bar 0.10 x 0.02 x 0.02 m clamped at x=0, E=3 MPa, nu=0.3\n");
  std::printf("times in s (solve = median of 7), dRSS = resident-set growth while the body is alive,\n"
              "dPeak = growth of the peak RSS while building it (each case in its own process)\n\n");
  std::printf("%-6s %-9s %8s %8s %10s %11s %10s %10s %10s %9s %9s\n", "order", "divisions", "dofs",
              "elements", "K_nnz", "L_nnz", "assembly", "factor", "solve", "dRSS_MiB", "dPeak_MiB");
  // Same dof counts for both orders (Tet10 n cells = Tet4 2n cells per axis).
  InChild([] { BenchBody(ElementOrder::kTet4, 20, 4); });
  InChild([] { BenchBody(ElementOrder::kTet10, 10, 2); });
  InChild([] { BenchBody(ElementOrder::kTet4, 40, 8); });
  InChild([] { BenchBody(ElementOrder::kTet10, 20, 4); });
  InChild([] { BenchBody(ElementOrder::kTet4, 70, 14); });
  InChild([] { BenchBody(ElementOrder::kTet10, 35, 7); });
  std::printf("\nCompliance block (algorithms.md section 6): red bar Tet10 clamped at x=0 and x=L,\n"
              "candidates = top-face nodes; build = assembly + factor + 3 unit solves; schur =\n"
              "ComplianceBlock (median of 3 below 20k dofs, else 1 run); dPeak = peak-RSS growth over\n"
              "build + block (a second factorization, the candidates last); one_build_s / one_total_s =\n"
              "building with the candidates ordered last in the body's one factor, then + the block read\n"
              "off it (as the server does), one_diff its max difference / max |schur|; solves =\n"
              "ComplianceBlockBySolves baseline; rel_diff = max |schur - solves| / max |solves|\n");
  std::printf("%-9s %8s %6s %7s %8s %9s %9s %9s %9s %9s %10s %7s %9s\n", "divisions", "dofs", "cand", "block",
              "build_s", "schur_s", "dPeak_MiB", "one_build", "one_total", "one_diff", "solves_s", "ratio", "rel_diff");
  InChild([] { BenchComplianceBlock(20, 4, true); });   // benchmark 1's obstacle, ~10k dofs
  InChild([] { BenchComplianceBlock(35, 7, true); });   // ~50k dofs
  InChild([] { BenchComplianceBlock(45, 9, false); });  // ~100k dofs; the baseline takes minutes
  return 0;
}
