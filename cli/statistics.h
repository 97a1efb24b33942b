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

}  // namespace palpate::cli
