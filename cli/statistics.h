#pragma once
// Small statistics of measured samples for the programs' reports (header only).
#include <algorithm>
#include <cmath>
#include <vector>

namespace palpate::cli {

// The median: the middle sample, or the mean of the two middle ones; NaN when there are none.
inline double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t k = v.size() / 2;
  return v.size() % 2 ? v[k] : 0.5 * (v[k - 1] + v[k]);
}

// The q-quantile by nearest rank (the smallest sample with at least q of them at or below
// it), q in [0, 1] (0: the smallest); NaN when there are none. The one percentile of the
// programs' reports (palpate-follow, the haptic client's Percentiles, the benches').
inline double quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double rank = std::ceil(q * static_cast<double>(v.size()));
  return v[static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(v.size()))) - 1];
}

}  // namespace palpate::cli
