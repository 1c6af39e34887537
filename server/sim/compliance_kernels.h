#pragma once

#include <array>
#include <utility>
#include <vector>

#include <Eigen/Dense>

#include "sim/blocked_compliance.h"

namespace hapco::sim {

// The two compliance sums of the 1 kHz step (algorithms.md §5), on a BlockedCompliance:
// U = C f on the broad phase's region, and the W gather Σ c_k d_l C(p_k, q_l). Together
// they were over half of a benchmark-1 step, and they are arithmetic on blocks that are
// already in cache (docs/performance.md "Compliance kernels"), so they come in two builds of
// the same sums:
//   kPortable  plain C++, what the compiler makes of it for the build's target (SSE2, two
//              lanes, on a generic x86-64 Debian build);
//   kAvx2Fma   four-lane fused multiply-add (x86-64-v3), compiled for that target alone and
//              chosen at run time when the CPU has it, so one binary runs everywhere.
// Both give the same sums up to rounding (the order of additions differs).
enum class ComplianceKernel { kPortable, kAvx2Fma };

// The fastest kernel this CPU runs (kAvx2Fma when it has AVX2 and FMA).
ComplianceKernel FastestComplianceKernel();
const char* ComplianceKernelName(ComplianceKernel kernel);

// Runs [begin, end) of consecutive slots.
using SlotRunList = std::vector<std::pair<int, int>>;

// displacement_m[3i..3i+2] += Σ_j C(i, j) f_j (m; C in m/N, f in N, 3 doubles per slot) for
//   every slot i in free_runs (slots that carry no load) and every loaded slot i,
// over the loaded slots j: loaded (ascending) and the same slots as runs in loaded_runs.
// C = Cᵀ: a block between two loaded slots is read once, in the column of the smaller slot,
// and serves both. The blocks of one column j are read in runs of consecutive slots (one
// memory stream each).
void AddComplianceTimesForces(ComplianceKernel kernel, const BlockedCompliance& compliance,
                              const SlotRunList& free_runs, const std::vector<int>& loaded,
                              const SlotRunList& loaded_runs, const double* force_n, double* displacement_m);

// Σ_k Σ_l c_k d_l C(p_k, q_l) (m/N; k < np, l < nq), each block read where it is stored
// (column q_l).
Eigen::Matrix3d WeightedBlockSum(ComplianceKernel kernel, const BlockedCompliance& compliance,
                                 const std::array<int, 6>& p, const std::array<double, 6>& c, int np,
                                 const std::array<int, 6>& q, const std::array<double, 6>& d, int nq);

}  // namespace hapco::sim
