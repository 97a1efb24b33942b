#pragma once
// The machine's fused multiply-add peak on one core, measured: independent chains of
// packed AVX2 FMAs (4 doubles or 8 floats per instruction), more chains than the FMA
// latency times the FMA ports (4-5 cycles x 2 ports on current x86), so the loop issues
// an FMA on every port every cycle. An FMA counts two flops, as the force loops' counts
// do (core/mls_forces.cpp, mls_internal_forces_flops). Built without AVX2/FMA (option
// PALPATE_ARCH none) the peak is not measured (0).
#include <algorithm>
#include <chrono>

#if defined(__FMA__) && defined(__AVX__)
#include <immintrin.h>
#endif

namespace palpate::bench {

struct FmaPeak {
  double double_gflops = 0;  // GFLOP/s, 4-wide double FMAs
  double single_gflops = 0;  // GFLOP/s, 8-wide float FMAs
};

namespace fma_peak_detail {

constexpr int kChains = 12;          // independent accumulators (>= latency x ports = 10)
constexpr long kInnerRounds = 4096;  // rounds of kChains FMAs between clock reads

#if defined(__FMA__) && defined(__AVX__)
// flops per second of `rounds` x kChains FMAs of width `lanes` (V: __m256d or __m256).
template <class V, class Fma, class Set1>
double chain_rate(Fma fma, Set1 set1, int lanes, double seconds) {
  V acc[kChains];
  for (int c = 0; c < kChains; ++c) acc[c] = set1(1.0 + 1e-3 * c);
  const V a = set1(0.999999), b = set1(1e-6);  // acc -> a acc + b stays near 1
  using Clock = std::chrono::steady_clock;
  long rounds = 0;
  const auto t0 = Clock::now();
  double elapsed = 0;
  do {
    for (long r = 0; r < kInnerRounds; ++r)
      for (int c = 0; c < kChains; ++c) acc[c] = fma(acc[c], a, b);
    rounds += kInnerRounds;
    elapsed = std::chrono::duration<double>(Clock::now() - t0).count();
  } while (elapsed < seconds);
  // Keep the chains alive: their sum goes to memory the compiler cannot see through.
  V sum = acc[0];
  for (int c = 1; c < kChains; ++c) sum = fma(sum, a, acc[c]);
  volatile V sink = sum;
  (void)sink;
  return 2.0 * lanes * kChains * static_cast<double>(rounds) / elapsed;
}
#endif

}  // namespace fma_peak_detail

// The best of `trials` runs of `seconds` each per precision (the peak: a disturbed run
// is only slower).
inline FmaPeak measure_fma_peak(int trials = 5, double seconds = 0.04) {
  FmaPeak peak;
#if defined(__FMA__) && defined(__AVX__)
  using namespace fma_peak_detail;
  for (int t = 0; t < trials; ++t) {
    peak.double_gflops = std::max(
        peak.double_gflops,
        1e-9 * chain_rate<__m256d>([](__m256d x, __m256d y, __m256d z) { return _mm256_fmadd_pd(x, y, z); },
                                   [](double v) { return _mm256_set1_pd(v); }, 4, seconds));
    peak.single_gflops = std::max(
        peak.single_gflops,
        1e-9 * chain_rate<__m256>([](__m256 x, __m256 y, __m256 z) { return _mm256_fmadd_ps(x, y, z); },
                                  [](double v) { return _mm256_set1_ps(static_cast<float>(v)); }, 8, seconds));
  }
#else
  (void)trials;
  (void)seconds;
#endif
  return peak;
}

}  // namespace palpate::bench
