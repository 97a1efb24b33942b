#pragma once
// Lock-free histogram of durations in microseconds (the loop's step times and tick
// lateness): 1 us bins up to 5 ms, 1 ms bins up to 1 s, one bin for everything
// beyond, and the exact maximum. One writer thread, any number of readers.
#include <atomic>
#include <cstdint>

namespace palpate::server {

class Histogram {
 public:
  // Writer thread only. Negative and NaN durations count as 0.
  void add(double us);
  // Writer thread only (a reader may see a partly cleared histogram).
  void clear();

  // A quantile is the upper edge of the bin that holds it, capped by the exact
  // maximum (so one sample, or a quantile in the bin beyond 1 s, gives the maximum).
  struct Summary {
    double p50 = 0, p99 = 0, max = 0;
    uint64_t count = 0;
  };
  // Any thread. Allocates (a copy of the bins): not for the writer's hot path.
  Summary summary() const;

  static constexpr int kFine = 5000;   // [0, 5 ms) in 1 us bins
  static constexpr int kCoarse = 995;  // [5 ms, 1 s) in 1 ms bins
  static constexpr int kBins = kFine + kCoarse + 1;  // and [1 s, inf)

 private:
  std::atomic<uint64_t> bins_[kBins] = {};
  std::atomic<uint64_t> count_{0};
  std::atomic<double> max_{0.0};
};

}  // namespace palpate::server
