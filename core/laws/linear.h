#pragma once
// The small-strain linear law (a verification law, not objective: rigid rotations strain
// it; the continuum of the linear hex FEM and of the finite-cube reference): one material law
// of the MLS solid (core/mls_law.h says what a law provides).
#include "core/mls_law.h"

namespace palpate::mls {

// Small-strain linear law (a verification law, not objective: rigid rotations strain it):
// eps = sym(F) - I, psi = mu eps:eps + lambda/2 tr(eps)^2, P = 2 mu eps + lambda tr(eps) I,
// the continuum of the linear hex FEM and of the finite-cube reference.
inline double linear_stress(const Mat3& F, double lambda, double mu, Mat3& P) {
  Mat3 eps = 0.5 * (F + F.transpose());
  eps.diagonal().array() -= 1.0;
  const double tr = eps.trace();
  P = (2 * mu) * eps;
  P.diagonal().array() += lambda * tr;
  return mu * eps.squaredNorm() + 0.5 * lambda * tr * tr;
}

// v_i P_i of the small-strain linear law, P = 2 mu eps + lambda tr(eps) I, eps = sym(F) - I
// (linear_stress), on all four lanes together (the volume term added when volume_term).
template <bool volume_term>
PALPATE_INLINE void weighted_linear_stress(const Model& m, const Mat3Lanes& F, const Lanes v, const Lanes lambda,
                                           const Lanes mu, Mat3Lanes& vP) {
  const Lanes v_2mu = (2 * mu) * v, v_mu = mu * v;
  const Lanes v_lambda_tr = (lambda * v) * (F(0, 0) + F(1, 1) + F(2, 2) - 3.0);
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r) {
    vP(r, r) = v_2mu * (F(r, r) - 1.0) + v_lambda_tr;
    PALPATE_UNROLL
    for (int c = r + 1; c < 3; ++c) vP(r, c) = vP(c, r) = v_mu * (F(r, c) + F(c, r));
  }
  if constexpr (volume_term) add_weighted_volume_term_rounded(m, F, v, vP);
}

// The linear law's v_i dP_i = v_i [mu (dF + dF^T) + lambda tr(dF) I] (+ the volume term's), packed.
template <bool volume_term>
PALPATE_INLINE void weighted_linear_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& dF, const Lanes v,
                                                 const Lanes lambda, const Lanes mu, Mat3Lanes& vdP) {
  Mat3Lanes dP;
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c) dP(r, c) = mu * (dF(r, c) + dF(c, r));
  const Lanes lambda_trace = lambda * (dF(0, 0) + dF(1, 1) + dF(2, 2));
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r) dP(r, r) += lambda_trace;
  if constexpr (volume_term) add_volume_term_differential<true>(m, F, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

struct Linear {
  static constexpr MaterialLaw id = MaterialLaw::linear;
  static constexpr const char* name = "linear";
  static constexpr int group = 1;
  static constexpr int block_cost = 3;
  static constexpr bool small_strain = true;
  // 2 mu v 2, mu v 1, lambda v (tr F - 3) 5; diagonal 3 x (sub + fma) = 9; off-diagonal
  // 3 x (add + mul) = 6: 23.
  static constexpr double flops_per_particle = 23.0;

  // factor: I (the law needs none).
  static double stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3&) {
    return linear_stress(F, lambda, mu, P);
  }
  // dP = 2 mu sym(dF) + lambda tr(dF) I
  static Mat3 differential(const Mat3&, const Mat3&, const Mat3& dF, double lambda, double mu) {
    Mat3 dP = mu * (dF + dF.transpose());
    dP.diagonal().array() += lambda * dF.trace();
    return dP;
  }
  template <bool volume_term, int G>
  PALPATE_INLINE static void weighted_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                             const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) weighted_linear_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
  }
  template <bool volume_term, int K>
  PALPATE_INLINE static void weighted_differentials(const Model& m, const Mat3Lanes& F, const Mat3Lanes&,
                                                    const Mat3Lanes (&dF)[K], const Lanes v, const Lanes lambda,
                                                    const Lanes mu, Mat3Lanes (&vdP)[K]) {
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q) weighted_linear_differential<volume_term>(m, F, dF[q], v, lambda, mu, vdP[q]);
  }
  template <class Gradients>
  static double iteration_flops(const Model&, const Gradients&) { return 0.0; }
};

}  // namespace palpate::mls
