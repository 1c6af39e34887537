// Solve allocates nothing once the workspace and the result are reserved (design.md example 4).
// This executable replaces the global allocation functions with counting ones. Eigen takes its
// dynamic memory from std::malloc rather than operator new, so malloc/calloc/realloc are
// counted too (glibc lets the executable interpose them; __libc_* are the real ones).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <functional>
#include <new>

#include "contact/solver.h"
#include "test_problems.h"

extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* ptr, std::size_t size);
void __libc_free(void* ptr);
}

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
void Count() {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
}
}  // namespace

extern "C" {
void* malloc(std::size_t size) {
  Count();
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) {
  Count();
  return __libc_calloc(count, size);
}
void* realloc(void* ptr, std::size_t size) {
  Count();
  return __libc_realloc(ptr, size);
}
void free(void* ptr) { __libc_free(ptr); }
}

void* operator new(std::size_t size) {
  Count();
  if (void* p = __libc_malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) { return operator new(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  Count();
  return __libc_malloc(size == 0 ? 1 : size);
}
void* operator new[](std::size_t size, const std::nothrow_t& tag) noexcept {
  return operator new(size, tag);
}
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }

namespace hapco::contact {
namespace {

long CountAllocations(const std::function<void()>& body) {
  g_allocations = 0;
  g_counting = true;
  body();
  g_counting = false;
  return g_allocations.load();
}

TEST(AllocationTest, CounterSeesEigenAndNewAllocations) {
  // The counter must be able to fail the real test: it sees both kinds of allocation.
  EXPECT_GT(CountAllocations([] {
              Eigen::VectorXd v(100);
              v.setZero();
              EXPECT_EQ(v.size(), 100);
            }),
            0);
  EXPECT_GT(CountAllocations([] { delete new int(3); }), 0);
}

class AllocationFreeSolveTest : public ::testing::TestWithParam<SolverKind> {};

TEST_P(AllocationFreeSolveTest, NoAllocationAfterReserve) {
  const SolverKind kind = GetParam();
  const int m = 30;
  const ContactProblem p = testing::RandomSpdProblem(m, 5u);
  SolverParameters params;
  params.global_tolerance_m = 1e-12;
  params.max_iterations = 500;
  params.fc3d_tolerance = 1e-14;   // exercise the per-iteration fc3d path too
  SolverWorkspace ws;
  SolverResult res;
  ws.Reserve(m, params.max_iterations);
  res.Reserve(m, params.max_iterations);

  SolverStatus status = SolverStatus::kDiverged;
  EXPECT_EQ(CountAllocations([&] { status = Solve(kind, p, params, &ws, &res); }), 0)
      << SolverName(kind);
  EXPECT_EQ(status, SolverStatus::kConverged);
  EXPECT_GT(res.stats.iterations, 1);

  // Warm start with per-contact ρ, then the time-budget exit: still nothing.
  params.warm_start = true;
  params.rho_rule = RhoRule::kPerContact;
  EXPECT_EQ(CountAllocations([&] { Solve(kind, p, params, &ws, &res); }), 0);
  params.warm_start = false;
  params.time_budget_s = 1e-9;
  EXPECT_EQ(CountAllocations([&] { Solve(kind, p, params, &ws, &res); }), 0);
  EXPECT_EQ(res.stats.status, SolverStatus::kTimeBudgetExceeded);

  // Anderson acceleration at its largest depth: its history lives in the workspace.
  params.time_budget_s = 0.0;
  params.anderson_depth = SolverParameters::kMaxAndersonDepth;
  params.anderson_start = 1;
  EXPECT_EQ(CountAllocations([&] { status = Solve(kind, p, params, &ws, &res); }), 0) << SolverName(kind);
  EXPECT_EQ(status, SolverStatus::kConverged);
  if (kind != SolverKind::kGlobalUzawaJacobi) {
    EXPECT_GT(res.stats.accelerated_iterations, 0);
  }
}

INSTANTIATE_TEST_SUITE_P(AllSolvers, AllocationFreeSolveTest,
                         ::testing::Values(SolverKind::kLocalUzawa,
                                           SolverKind::kGlobalUzawaGaussSeidel,
                                           SolverKind::kGlobalUzawaJacobi,
                                           SolverKind::kReferenceNsgs));

}  // namespace
}  // namespace hapco::contact
