#include "server/histogram.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace palpate::server {

void Histogram::add(double us) {
  if (!(us >= 0.0)) us = 0.0;
  int bin;
  if (us < kFine) bin = static_cast<int>(us);
  else bin = static_cast<int>(std::min((us - kFine) / 1000.0, static_cast<double>(kCoarse))) + kFine;
  bins_[bin].fetch_add(1, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
  if (us > max_.load(std::memory_order_relaxed)) max_.store(us, std::memory_order_relaxed);  // one writer
}

void Histogram::clear() {
  for (auto& b : bins_) b.store(0, std::memory_order_relaxed);
  count_.store(0, std::memory_order_relaxed);
  max_.store(0.0, std::memory_order_relaxed);
}

Histogram::Summary Histogram::summary() const {
  Summary s;
  std::vector<uint64_t> copy(kBins);
  uint64_t total = 0;
  for (int i = 0; i < kBins; ++i) total += copy[i] = bins_[i].load(std::memory_order_relaxed);
  s.count = total;
  s.max = max_.load(std::memory_order_relaxed);
  if (total == 0) return s;
  // Upper edge of the bin holding the q-quantile (capped by the exact maximum; the
  // last bin has no upper edge but the maximum).
  auto quantile = [&](double q) {
    const uint64_t rank = std::max<uint64_t>(1, static_cast<uint64_t>(std::ceil(q * static_cast<double>(total))));
    uint64_t seen = 0;
    for (int i = 0; i < kBins - 1; ++i) {
      seen += copy[i];
      if (seen >= rank) {
        const double upper = i < kFine ? i + 1.0 : kFine + (i - kFine + 1) * 1000.0;
        return std::min(upper, s.max);
      }
    }
    return s.max;
  };
  s.p50 = quantile(0.50);
  s.p99 = quantile(0.99);
  return s;
}

}  // namespace palpate::server
