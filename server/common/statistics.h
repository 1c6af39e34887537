#pragma once
// Percentiles of latency and step-time samples, one definition for every tool (phantom,
// load test, server status, report), so their p50/p99 agree on the same data.
#include <vector>

namespace hapco {

// p-quantile (p in [0, 1], clamped) by nearest rank: the smallest sample with at least
// p * n samples <= it (p = 0: the minimum, p = 1: the maximum); 0 for no samples.
// Reorders `values` (nth_element, O(n)).
double Quantile(std::vector<double>* values, double p);

// The same on a copy, for callers that keep their samples in order.
inline double QuantileOf(std::vector<double> values, double p) { return Quantile(&values, p); }

}  // namespace hapco
