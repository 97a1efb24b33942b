#pragma once
// The compressible neo-Hookean law (docs/physics.md (1.13)-(1.15); its scalar formulas,
// core/neo_hookean.h, are shared with the neo-Hookean hex FEM): one material law of the MLS
// solid (core/mls_law.h says what a law provides).
#include "core/mls_law.h"

#include <bit>

namespace palpate::mls {

struct NeoHookean;  // below: its lane formulas fall back to its scalar one

using hyperelastic::neo_hookean_differential;
using hyperelastic::neo_hookean_stress;

using LaneBits = long long __attribute__((vector_size(kLanes * sizeof(long long))));

// ln a of each lane, packed, for a in [1e-300, 1e300]: a = 2^k m with m in [2^-1/2, 2^1/2),
// ln a = k ln 2 + 2 atanh(s), s = (m - 1) / (m + 1) (m - 1 exact), |s| <= 0.1716, by the
// series 2 (s + s^3/3 + ... + s^19/19), whose next term is below 1e-17 |2 s|; k ln 2 in a
// high part exact for any k and a low part. Within a few units of rounding of std::log
// (tests/mls_forces_test.cpp); four calls of std::log per block took 5-7 % of the
// neo-Hookean loop's time on the haptic scene's cloud.
PALPATE_INLINE Lanes log_lanes(const Lanes a) {
  constexpr double kLn2High = 6.93147180369123816490e-01, kLn2Low = 1.90821492927058770002e-10;
  const LaneBits bits = std::bit_cast<LaneBits>(a);
  Lanes m = std::bit_cast<Lanes>((bits & 0x000fffffffffffffLL) | 0x3ff0000000000000LL);  // [1, 2)
  const LaneBits high = m > M_SQRT2;  // -1 where m >= 2^1/2: m / 2, k + 1
  m = high ? 0.5 * m : m;
  const LaneBits biased_k = ((bits >> 52) & 0x7ff) - high;
  // k as a double: the biased exponent in the mantissa of 2^52, minus 2^52 + 1023 (exact).
  const Lanes k = std::bit_cast<Lanes>(biased_k | 0x4330000000000000LL) - (4503599627370496.0 + 1023.0);
  const Lanes s = (m - 1.0) / (m + 1.0), s2 = s * s;
  Lanes series = Lanes{} + 1.0 / 19;
  PALPATE_UNROLL
  for (int d = 17; d >= 3; d -= 2) series = series * s2 + 1.0 / d;  // (s^-1 atanh s - 1) / s^2
  const Lanes two_s = 2.0 * s;
  return k * kLn2High + (two_s + (two_s * s2 * series + k * kLn2Low));
}

// J = det F (through its cofactor C, written) and ln J on the four lanes; false when a
// lane has J <= 0, where the neo-Hookean law exerts nothing (the per-lane formula handles
// the block). ln J packed (log_lanes), or lane by lane outside [1e-300, 1e300]. volume_term:
// C and J rounded as cofactor_det_lanes<fused> (the pre-refactor loops' rounding next to the
// volume term, which takes the same C and J).
template <bool volume_term = false, Fused fused = Fused::first>
PALPATE_INLINE bool log_det_lanes(const Mat3Lanes& F, Mat3Lanes& C, Lanes& J, Lanes& log_J) {
  if constexpr (volume_term) {
    cofactor_det_lanes<fused>(F, C, J);
  } else {
    cofactor_lanes(F, C);
    J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
  }
  bool packed = true;
  PALPATE_UNROLL
  for (int l = 0; l < kLanes; ++l) {
    if (!(J[l] > 0)) return false;
    packed = packed && J[l] >= 1e-300 && J[l] <= 1e300;
  }
  if (packed) {
    log_J = log_lanes(J);
  } else {
    PALPATE_UNROLL
    for (int l = 0; l < kLanes; ++l) log_J[l] = std::log(J[l]);
  }
  return true;
}

// v_i P_i of the neo-Hookean law (1.14), P = mu F + (lambda ln J - mu) cof F / J, on all four
// lanes together (ln J one lane at a time); a lane with J <= 0 sends the block to the
// per-lane formula (no stress from the law at J <= 0).
template <bool volume_term>
PALPATE_INLINE void weighted_neo_hookean_stress(const Model& m, const Mat3Lanes& F, const Lanes v, const Lanes lambda,
                                                const Lanes mu, Mat3Lanes& vP) {
  Mat3Lanes C;
  Lanes J, log_J;
  if (!log_det_lanes<volume_term, Fused::second>(F, C, J, log_J))
    return weighted_stress_per_lane<NeoHookean>(m, F, v, lambda, mu, vP);
  const Lanes v_mu = mu * v, scale = v * (lambda * log_J - mu) / J;
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vP.m[k] = v_mu * F.m[k] + scale * C.m[k];
  if constexpr (volume_term) add_weighted_volume_term(m, C, J, v, vP);
}

// v_i dP_i of the neo-Hookean law (1.15) at (F_i, G_i = F_i^-T) along dF_i, on all four lanes:
// dP = mu dF + (mu - lambda ln J) G dF^T G + lambda (G : dF) G (+ the volume term's).
// one_direction: the loop's only direction (K = 1); with the volume term, cof F and J then
// rounded as cofactor_det_lanes<Fused::first> (the pre-refactor K = 1 loop's rounding; with
// K > 1 GCC's own choice already is the old one).
template <bool volume_term, bool one_direction = true>
PALPATE_INLINE void weighted_neo_hookean_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& G,
                                                      const Mat3Lanes& dF, const Lanes v, const Lanes lambda,
                                                      const Lanes mu, Mat3Lanes& vdP) {
  Mat3Lanes C;
  Lanes J, log_J;
  if (!log_det_lanes<volume_term && one_direction, Fused::first>(F, C, J, log_J))
    return weighted_differential_per_lane<NeoHookean>(m, F, G, dF, v, lambda, mu, vdP);
  Mat3Lanes T;  // dF^T G
  PALPATE_UNROLL
  for (int a = 0; a < 3; ++a)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c) T(a, c) = dF(0, a) * G(0, c) + dF(1, a) * G(1, c) + dF(2, a) * G(2, c);
  Lanes G_dF = G.m[0] * dF.m[0];
  PALPATE_UNROLL
  for (int k = 1; k < 9; ++k) G_dF += G.m[k] * dF.m[k];
  const Lanes a = mu - lambda * log_J, b = lambda * G_dF;
  Mat3Lanes dP;
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c)
      dP(r, c) = mu * dF(r, c) + a * (G(r, 0) * T(0, c) + G(r, 1) * T(1, c) + G(r, 2) * T(2, c)) + b * G(r, c);
  if constexpr (volume_term) add_volume_term_differential(m, F, C, J, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

struct NeoHookean {
  static constexpr MaterialLaw id = MaterialLaw::neo_hookean;
  static constexpr const char* name = "neo_hookean";
  static constexpr int group = 1;
  static constexpr int block_cost = 3;
  static constexpr bool small_strain = false;
  // (1.14): cof F 27, J 5, ln J 30 (log_lanes: the reduction 2, s 3, s^2 1, the series
  // 8 fma 16, 2 s 1, 2 s s^2 p 2, + k ln 2 in two parts 5), mu v 1, v (lambda ln J - mu) / J
  // 4, P = mu v F + s cof F 9 x (mul + fma) = 27: 94.
  static constexpr double flops_per_particle = 94.0;

  // factor: F^-T.
  static double stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3& factor) {
    return neo_hookean_stress(F, lambda, mu, P, factor);
  }
  static Mat3 differential(const Mat3& F, const Mat3& G, const Mat3& dF, double lambda, double mu) {
    return neo_hookean_differential(F, G, dF, lambda, mu);
  }
  template <bool volume_term, int G>
  PALPATE_INLINE static void weighted_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                             const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) weighted_neo_hookean_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
  }
  template <bool volume_term, int K>
  PALPATE_INLINE static void weighted_differentials(const Model& m, const Mat3Lanes& F, const Mat3Lanes& G,
                                                    const Mat3Lanes (&dF)[K], const Lanes v, const Lanes lambda,
                                                    const Lanes mu, Mat3Lanes (&vdP)[K]) {
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q)
      weighted_neo_hookean_differential<volume_term, K == 1>(m, F, G, dF[q], v, lambda, mu, vdP[q]);
  }
  template <class Gradients>
  static double iteration_flops(const Model&, const Gradients&) { return 0.0; }
};

}  // namespace palpate::mls
