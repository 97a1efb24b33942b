#pragma once
// The St Venant-Kirchhoff law (the paper's; docs/physics.md, (A-5)): one material law
// of the MLS solid (core/mls_law.h says what a law provides).
#include "core/mls_law.h"

namespace palpate::mls {

// Green strain E = 1/2 (F^T F - I) and the St Venant-Kirchhoff second Piola
// stress S = lambda tr(E) I + 2 mu E, returning the energy density 1/2 E:S.
inline double stvk_stress(const Mat3& F, double lambda, double mu, Mat3& S) {
  const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
  S = (2 * mu) * E;
  S.diagonal().array() += lambda * E.trace();
  return 0.5 * (E.array() * S.array()).sum();
}

// v_i P_i for the four particles of a block, from F_i: Green strain E = 1/2 (F^T F - I)
// St Venant-Kirchhoff S = lambda tr(E) I + 2 mu E, P = F S, plus the volume
// term k_v (J - 1) cof F when volume_term. The volume v_i is folded into S.
template <bool volume_term>
PALPATE_INLINE void weighted_stvk_stress(const Model& m, const Mat3Lanes& F, const Lanes v, const Lanes lambda,
                                          const Lanes mu, Mat3Lanes& vP) {
  auto FtF = [&](int a, int b) { return F(0, a) * F(0, b) + F(1, a) * F(1, b) + F(2, a) * F(2, b); };
  const Lanes E00 = 0.5 * FtF(0, 0) - 0.5, E11 = 0.5 * FtF(1, 1) - 0.5, E22 = 0.5 * FtF(2, 2) - 0.5;
  const Lanes E01 = 0.5 * FtF(0, 1), E02 = 0.5 * FtF(0, 2), E12 = 0.5 * FtF(1, 2);
  const Lanes v_lambda_trE = (lambda * v) * (E00 + E11 + E22);
  const Lanes v_2mu = (2 * mu) * v;
  Mat3Lanes vS;  // v S (symmetric)
  vS(0, 0) = v_lambda_trE + v_2mu * E00;
  vS(1, 1) = v_lambda_trE + v_2mu * E11;
  vS(2, 2) = v_lambda_trE + v_2mu * E22;
  vS(0, 1) = vS(1, 0) = v_2mu * E01;
  vS(0, 2) = vS(2, 0) = v_2mu * E02;
  vS(1, 2) = vS(2, 1) = v_2mu * E12;
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c) vP(r, c) = F(r, 0) * vS(0, c) + F(r, 1) * vS(1, c) + F(r, 2) * vS(2, c);
  if constexpr (volume_term) add_weighted_volume_term_rounded(m, F, v, vP);
}

// v_i dP_i, the differential of weighted_stvk_stress at (F_i, S_i) along dF_i:
// dE = sym(F^T dF), dS = lambda tr(dE) I + 2 mu dE, dP = dF S + F dS, and for the
// volume term k_v [(cof F : dF) cof F + (J - 1) d cof F].
template <bool volume_term>
PALPATE_INLINE void weighted_stvk_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& S, const Mat3Lanes& dF,
                                        const Lanes v, const Lanes lambda, const Lanes mu, Mat3Lanes& vdP) {
  auto FtdF = [&](int a, int b) { return F(0, a) * dF(0, b) + F(1, a) * dF(1, b) + F(2, a) * dF(2, b); };
  const Lanes dE00 = FtdF(0, 0), dE11 = FtdF(1, 1), dE22 = FtdF(2, 2);
  const Lanes dE01 = 0.5 * (FtdF(0, 1) + FtdF(1, 0)), dE02 = 0.5 * (FtdF(0, 2) + FtdF(2, 0)),
              dE12 = 0.5 * (FtdF(1, 2) + FtdF(2, 1));
  const Lanes lambda_trdE = lambda * (dE00 + dE11 + dE22);
  const Lanes two_mu = 2 * mu;
  Mat3Lanes dS;  // symmetric
  dS(0, 0) = lambda_trdE + two_mu * dE00;
  dS(1, 1) = lambda_trdE + two_mu * dE11;
  dS(2, 2) = lambda_trdE + two_mu * dE22;
  dS(0, 1) = dS(1, 0) = two_mu * dE01;
  dS(0, 2) = dS(2, 0) = two_mu * dE02;
  dS(1, 2) = dS(2, 1) = two_mu * dE12;
  Mat3Lanes dP;
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c)
      dP(r, c) = dF(r, 0) * S(0, c) + dF(r, 1) * S(1, c) + dF(r, 2) * S(2, c) + F(r, 0) * dS(0, c) +
                 F(r, 1) * dS(1, c) + F(r, 2) * dS(2, c);
  if constexpr (volume_term) add_volume_term_differential<true>(m, F, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

struct StVenantKirchhoff {
  static constexpr MaterialLaw id = MaterialLaw::stvk;
  static constexpr const char* name = "stvk";
  static constexpr int group = 1;
  static constexpr int block_cost = 3;
  static constexpr bool small_strain = false;
  // F^T F 6 x (mul + 2 fma) = 30; E 3 fma + 3 mul = 9; lambda v tr E 4, 2 mu v 1;
  // v S 3 fma + 3 mul = 9; P = F (v S) 9 x (mul + 2 fma) = 45: 98.
  static constexpr double flops_per_particle = 98.0;

  // factor: S.
  static double stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3& factor) {
    const double psi = stvk_stress(F, lambda, mu, factor);
    P = F * factor;
    return psi;
  }
  // dE = sym(F^T dF), dS = lambda tr(dE) I + 2 mu dE, dP = dF S + F dS.
  static Mat3 differential(const Mat3& F, const Mat3& S, const Mat3& dF, double lambda, double mu) {
    const Mat3 FtdF = F.transpose() * dF;
    const Mat3 dE = 0.5 * (FtdF + FtdF.transpose());
    Mat3 dS = (2 * mu) * dE;
    dS.diagonal().array() += lambda * dE.trace();
    return dF * S + F * dS;
  }
  template <bool volume_term, int G>
  PALPATE_INLINE static void weighted_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                             const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) weighted_stvk_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
  }
  template <bool volume_term, int K>
  PALPATE_INLINE static void weighted_differentials(const Model& m, const Mat3Lanes& F, const Mat3Lanes& S,
                                                    const Mat3Lanes (&dF)[K], const Lanes v, const Lanes lambda,
                                                    const Lanes mu, Mat3Lanes (&vdP)[K]) {
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q) weighted_stvk_differential<volume_term>(m, F, S, dF[q], v, lambda, mu, vdP[q]);
  }
  template <class Gradients>
  static double iteration_flops(const Model&, const Gradients&) { return 0.0; }
};

}  // namespace palpate::mls
