// fem_bench: cost of the FEM pipeline on the red bar (0.10 x 0.02 x 0.02 m) meshed at about 1k,
// 10k and 50k dofs with Tet4 and Tet10, and of the compliance block that benchmark 1 needs
// (algorithms.md section 6). Times are medians of repeated runs; memory is resident-set growth.
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

void BenchComplianceBlock() {
  // Benchmark 1's obstacle: the red bar clamped at x = 0 and x = L, Tet10 20x4x4; candidate
  // contact nodes = every node of its top face.
  const BoxMeshSpec spec = RedBar(ElementOrder::kTet10, 20, 4);
  ElasticBody::Spec s;
  s.mesh = MakeBoxMesh(spec);
  s.material = {3e6, 0.3};
  s.clamped_nodes = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMin);
  const auto far_end = NodesOnBoxFace(s.mesh, spec, BoxFace::kXMax);
  s.clamped_nodes.insert(s.clamped_nodes.end(), far_end.begin(), far_end.end());
  hapco::Stopwatch build;
  const ElasticBody body(std::move(s));
  const double build_s = build.ElapsedSeconds();
  const std::vector<int> top = NodesOnBoxFace(body.mesh(), spec, BoxFace::kZMax);
  std::vector<double> times;
  Eigen::MatrixXd c;
  for (int i = 0; i < 3; ++i) {
    hapco::Stopwatch watch;
    c = body.ComplianceBlock(top);
    times.push_back(watch.ElapsedSeconds());
  }
  int free_nodes = 0;
  for (int n : top) free_nodes += body.is_dirichlet_node(n) ? 0 : 1;
  std::printf("\nComplianceBlock, benchmark 1 obstacle (Tet10 20x4x4, clamped at x=0 and x=L, %d dofs):\n",
              body.num_dofs());
  std::printf("  candidate nodes (top face) %zu (%d free) -> block %ld x %ld, %.1f MiB\n", top.size(),
              free_nodes, static_cast<long>(c.rows()), static_cast<long>(c.cols()),
              static_cast<double>(c.size()) * 8.0 / kMiB);
  std::printf("  body construction (assembly + factor + 3 unit solves) %.3f s\n", build_s);
  std::printf("  ComplianceBlock median of 3: %.3f s (%.3f ms per free column)\n", Median(times),
              1e3 * Median(times) / (3.0 * free_nodes));
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
  InChild([] { BenchComplianceBlock(); });
  return 0;
}
