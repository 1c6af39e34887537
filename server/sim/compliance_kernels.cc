#include "sim/compliance_kernels.h"

#include <algorithm>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

namespace hapco::sim {
namespace {

void AddComplianceTimesForcesPortable(const BlockedCompliance& compliance, const SlotRunList& free_runs,
                                      const std::vector<int>& loaded, const SlotRunList& loaded_runs,
                                      const double* f, double* u) {
  // f_j stays in registers, no branch in the inner loops (column-major block: column r at 3r).
  for (int j : loaded) {
    const double* column = compliance.column_data(j);
    const double f0 = f[3 * j], f1 = f[3 * j + 1], f2 = f[3 * j + 2];
    for (const auto& [begin, end] : free_runs) {
      const double* b = column + 9 * static_cast<std::size_t>(begin);
      for (int i = begin; i < end; ++i, b += 9) {
        double* ui = u + 3 * i;
        ui[0] += b[0] * f0 + b[3] * f1 + b[6] * f2;
        ui[1] += b[1] * f0 + b[4] * f1 + b[7] * f2;
        ui[2] += b[2] * f0 + b[5] * f1 + b[8] * f2;
      }
    }
    // Loaded slots i > j: U_i += C(i, j) f_j and U_j += C(i, j)ᵀ f_i.
    double uj0 = 0.0, uj1 = 0.0, uj2 = 0.0;
    for (const auto& [run_begin, end] : loaded_runs) {
      if (end <= j) continue;
      const int begin = std::max(run_begin, j + 1);
      const double* b = column + 9 * static_cast<std::size_t>(begin);
      for (int i = begin; i < end; ++i, b += 9) {
        double* ui = u + 3 * i;
        const double* fi = f + 3 * i;
        ui[0] += b[0] * f0 + b[3] * f1 + b[6] * f2;
        ui[1] += b[1] * f0 + b[4] * f1 + b[7] * f2;
        ui[2] += b[2] * f0 + b[5] * f1 + b[8] * f2;
        uj0 += b[0] * fi[0] + b[1] * fi[1] + b[2] * fi[2];
        uj1 += b[3] * fi[0] + b[4] * fi[1] + b[5] * fi[2];
        uj2 += b[6] * fi[0] + b[7] * fi[1] + b[8] * fi[2];
      }
    }
    const double* d = column + 9 * static_cast<std::size_t>(j);
    u[3 * j] += uj0 + d[0] * f0 + d[3] * f1 + d[6] * f2;
    u[3 * j + 1] += uj1 + d[1] * f0 + d[4] * f1 + d[7] * f2;
    u[3 * j + 2] += uj2 + d[2] * f0 + d[5] * f1 + d[8] * f2;
  }
}

Eigen::Matrix3d WeightedBlockSumPortable(const BlockedCompliance& compliance, const std::array<int, 6>& p,
                                         const std::array<double, 6>& c, int np, const std::array<int, 6>& q,
                                         const std::array<double, 6>& d, int nq) {
  // The 9 sums stay in registers. (Reading the lower triangle only, C(max, min), and
  // transposing half of the blocks was 1.4x slower: the transposed half needed a second set
  // of sums.)
  double sum[9] = {};  // column-major
  for (int k = 0; k < np; ++k) {
    const int pk = p[static_cast<std::size_t>(k)];
    const double ck = c[static_cast<std::size_t>(k)];
    for (int l = 0; l < nq; ++l) {
      const double w = ck * d[static_cast<std::size_t>(l)];
      const double* block = compliance.column_data(q[static_cast<std::size_t>(l)]) + 9 * static_cast<std::size_t>(pk);
      for (int e = 0; e < 9; ++e) sum[e] += w * block[e];
    }
  }
  return Eigen::Map<const Eigen::Matrix3d>(sum);
}

#if defined(__x86_64__)
// Four-lane versions. A 3x3 column-major block b is three 3-vectors b[0..2], b[3..5], b[6..8];
// each is loaded as four lanes (b[a..a+3]) and lane 3 is ignored: C(i, j) f_j is
// f0·b[0..3] + f1·b[3..6] + f2·b[6..9] in lanes 0-2. The load of b[6..9] reads one double
// past the block, which BlockedCompliance's padding covers for its last block.
#define HAPCO_AVX2_FMA __attribute__((target("avx2,fma")))

HAPCO_AVX2_FMA inline void AddLanes012(__m256d v, double* p) {
  _mm_storeu_pd(p, _mm_add_pd(_mm_loadu_pd(p), _mm256_castpd256_pd128(v)));
  p[2] += _mm_cvtsd_f64(_mm256_extractf128_pd(v, 1));
}

HAPCO_AVX2_FMA inline double SumLanes012(__m256d v) {
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, v);
  return lanes[0] + lanes[1] + lanes[2];
}

HAPCO_AVX2_FMA inline __m256d BlockTimes(const double* b, __m256d f0, __m256d f1, __m256d f2) {
  return _mm256_fmadd_pd(_mm256_loadu_pd(b + 6), f2,
                         _mm256_fmadd_pd(_mm256_loadu_pd(b + 3), f1, _mm256_mul_pd(_mm256_loadu_pd(b), f0)));
}

HAPCO_AVX2_FMA void AddComplianceTimesForcesAvx2Fma(const BlockedCompliance& compliance, const SlotRunList& free_runs,
                                                    const std::vector<int>& loaded, const SlotRunList& loaded_runs,
                                                    const double* f, double* u) {
  // f_i is read as lanes 0-2 only: the slot after the last one has no force.
  const __m256i lanes012 = _mm256_setr_epi64x(-1, -1, -1, 0);
  for (int j : loaded) {
    const double* column = compliance.column_data(j);
    const __m256d f0 = _mm256_broadcast_sd(f + 3 * j);
    const __m256d f1 = _mm256_broadcast_sd(f + 3 * j + 1);
    const __m256d f2 = _mm256_broadcast_sd(f + 3 * j + 2);
    for (const auto& [begin, end] : free_runs) {
      const double* b = column + 9 * static_cast<std::size_t>(begin);
      for (int i = begin; i < end; ++i, b += 9) AddLanes012(BlockTimes(b, f0, f1, f2), u + 3 * i);
    }
    // Loaded slots i > j: U_i += C(i, j) f_j, and U_j(a) += Σ_i b[3a..3a+2]·f_i, summed lane
    // by lane in t_a and over the lanes once per column.
    __m256d t0 = _mm256_setzero_pd(), t1 = _mm256_setzero_pd(), t2 = _mm256_setzero_pd();
    for (const auto& [run_begin, end] : loaded_runs) {
      if (end <= j) continue;
      const int begin = std::max(run_begin, j + 1);
      const double* b = column + 9 * static_cast<std::size_t>(begin);
      for (int i = begin; i < end; ++i, b += 9) {
        const __m256d b0 = _mm256_loadu_pd(b), b1 = _mm256_loadu_pd(b + 3), b2 = _mm256_loadu_pd(b + 6);
        AddLanes012(_mm256_fmadd_pd(b2, f2, _mm256_fmadd_pd(b1, f1, _mm256_mul_pd(b0, f0))), u + 3 * i);
        const __m256d fi = _mm256_maskload_pd(f + 3 * i, lanes012);
        t0 = _mm256_fmadd_pd(b0, fi, t0);
        t1 = _mm256_fmadd_pd(b1, fi, t1);
        t2 = _mm256_fmadd_pd(b2, fi, t2);
      }
    }
    double* uj = u + 3 * j;
    AddLanes012(BlockTimes(column + 9 * static_cast<std::size_t>(j), f0, f1, f2), uj);
    uj[0] += SumLanes012(t0);
    uj[1] += SumLanes012(t1);
    uj[2] += SumLanes012(t2);
  }
}

HAPCO_AVX2_FMA Eigen::Matrix3d WeightedBlockSumAvx2Fma(const BlockedCompliance& compliance, const std::array<int, 6>& p,
                                                       const std::array<double, 6>& c, int np, const std::array<int, 6>& q,
                                                       const std::array<double, 6>& d, int nq) {
  __m256d sum03 = _mm256_setzero_pd(), sum47 = _mm256_setzero_pd();
  double sum8 = 0.0;
  for (int k = 0; k < np; ++k) {
    const int pk = p[static_cast<std::size_t>(k)];
    const double ck = c[static_cast<std::size_t>(k)];
    for (int l = 0; l < nq; ++l) {
      const double w = ck * d[static_cast<std::size_t>(l)];
      const double* block = compliance.column_data(q[static_cast<std::size_t>(l)]) + 9 * static_cast<std::size_t>(pk);
      const __m256d weight = _mm256_set1_pd(w);
      sum03 = _mm256_fmadd_pd(weight, _mm256_loadu_pd(block), sum03);
      sum47 = _mm256_fmadd_pd(weight, _mm256_loadu_pd(block + 4), sum47);
      sum8 += w * block[8];
    }
  }
  Eigen::Matrix3d sum;
  _mm256_storeu_pd(sum.data(), sum03);
  _mm256_storeu_pd(sum.data() + 4, sum47);
  sum.data()[8] = sum8;
  return sum;
}
#undef HAPCO_AVX2_FMA
#endif

}  // namespace

ComplianceKernel FastestComplianceKernel() {
#if defined(__x86_64__)
  static const bool has_avx2_fma = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  if (has_avx2_fma) return ComplianceKernel::kAvx2Fma;
#endif
  return ComplianceKernel::kPortable;
}

const char* ComplianceKernelName(ComplianceKernel kernel) {
  return kernel == ComplianceKernel::kAvx2Fma ? "avx2-fma" : "portable";
}

void AddComplianceTimesForces(ComplianceKernel kernel, const BlockedCompliance& compliance,
                              const SlotRunList& free_runs, const std::vector<int>& loaded,
                              const SlotRunList& loaded_runs, const double* force_n, double* displacement_m) {
#if defined(__x86_64__)
  // Never an illegal instruction: a kernel this CPU lacks runs as the portable one.
  if (kernel == ComplianceKernel::kAvx2Fma && FastestComplianceKernel() == ComplianceKernel::kAvx2Fma) {
    AddComplianceTimesForcesAvx2Fma(compliance, free_runs, loaded, loaded_runs, force_n, displacement_m);
    return;
  }
#endif
  (void)kernel;
  AddComplianceTimesForcesPortable(compliance, free_runs, loaded, loaded_runs, force_n, displacement_m);
}

Eigen::Matrix3d WeightedBlockSum(ComplianceKernel kernel, const BlockedCompliance& compliance,
                                 const std::array<int, 6>& p, const std::array<double, 6>& c, int np,
                                 const std::array<int, 6>& q, const std::array<double, 6>& d, int nq) {
#if defined(__x86_64__)
  if (kernel == ComplianceKernel::kAvx2Fma && FastestComplianceKernel() == ComplianceKernel::kAvx2Fma) {
    return WeightedBlockSumAvx2Fma(compliance, p, c, np, q, d, nq);
  }
#endif
  (void)kernel;
  return WeightedBlockSumPortable(compliance, p, c, np, q, d, nq);
}

}  // namespace hapco::sim
