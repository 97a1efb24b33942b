#pragma once
// A material law of the MLS solid is one unit: a struct in core/laws/ (one file per law)
// listed once in core/laws/laws.h, from which the scene reader, the stress for display, the
// blocked loops and the tests take the list. A law L provides (docs/physics.md §1):
//
//   static constexpr MaterialLaw id;   const char* name;      the scene's material.law
//   static constexpr int group;        blocks whose stresses are formed together (1 or 2)
//   static constexpr int block_cost;   a block's stress in neighbour-slot units (threads' split)
//   static constexpr bool small_strain;  its P is the (Cauchy) stress itself (core/stress.h)
//   static constexpr double flops_per_particle;  the stress's flops in the blocked loop
//   static double stress(F, lambda, mu, P, factor)       psi(F) and P = dpsi/dF, one particle;
//                                                         `factor` what the tangent needs
//   static Mat3 differential(F, factor, dF, lambda, mu)   dP along dF at (F, factor)
//   template <bool volume_term, int G> static void weighted_stress(m, F[G], v[G], lambda[G],
//       mu[G], vP[G])                                    v_i P_i on G blocks' lanes (+ (A-12))
//   template <bool volume_term, int K> static void weighted_differentials(m, F, factor, dF[K],
//       v, lambda, mu, vdP[K])                           v_i dP_i for K directions (+ (A-12))
//   template <class Gradients> static double iteration_flops(m, gradients)  flops the blocked
//       stress spends in data-dependent iterations at the positions `gradients` gives (0: none)
//
// The generic formulas here add the volume term to the law's own and give the
// per-lane fallback a law's lane formula may take.
#include "core/mls_lanes.h"
#include "core/neo_hookean.h"
#include "core/scene.h"

namespace palpate::mls {

using hyperelastic::cofactor;

// Differential of the volume term's stress k_v (J - 1) cof F along dF:
// k_v [(cof F : dF) cof F + (J - 1) d cof F], d cof F from the columns crossed pairwise.
// Always inlined, as before the refactor: GCC then fuses its products as it did (bit-identical).
PALPATE_INLINE Mat3 volume_term_differential(const Mat3& F, const Mat3& dF, double volume_stiffness) {
  const Mat3 C = cofactor(F);
  const double J = F.col(0).dot(C.col(0));
  Mat3 dC;
  dC.col(0) = dF.col(1).cross(F.col(2)) + F.col(1).cross(dF.col(2));
  dC.col(1) = dF.col(2).cross(F.col(0)) + F.col(2).cross(dF.col(0));
  dC.col(2) = dF.col(0).cross(F.col(1)) + F.col(0).cross(dF.col(1));
  return volume_stiffness * ((C.array() * dF.array()).sum() * C + (J - 1) * dC);
}

// First Piola stress P of a particle with Lame parameters lambda, mu (its own:
// Model::particle_lambda, particle_mu) (elastic + volume term) and its energy density.
// law_factor_out receives what the tangent needs: S (St Venant-Kirchhoff), R (corotational) or
// F^-T (neo-Hookean); the linear law needs nothing (I).
template <class Law>
inline double piola_stress(const Model& m, const Mat3& F, double lambda, double mu, Mat3& P,
                           Mat3* law_factor_out = nullptr) {
  Mat3 S = Mat3::Identity();
  double psi = Law::stress(F, lambda, mu, P, S);
  fence(psi);
  fence(P);
  fence(S);
  if (m.volume_stiffness > 0) {  // U = 1/2 k_v (det F - 1)^2, P += k_v (J - 1) cof(F)
    const Mat3 C = cofactor(F);
    const double J = F.col(0).dot(C.col(0));
    psi += 0.5 * m.volume_stiffness * (J - 1) * (J - 1);
    P += m.volume_stiffness * (J - 1) * C;
  }
  if (law_factor_out) *law_factor_out = S;
  return psi;
}

// dP of piola_stress at (F, S) along dF, S what piola_stress returned in law_factor_out. Not
// inlined, as before the refactor: GCC then fuses its products as it did, whichever loop calls
// it (bit-identical; the blocked loops call it only for a block with a lane at det F <= 0).
template <class Law>
[[gnu::noinline]] Mat3 piola_differential(const Model& m, const Mat3& F, const Mat3& S, const Mat3& dF,
                                          double lambda, double mu) {
  Mat3 dP = Law::differential(F, S, dF, lambda, mu);
  fence(dP);
  if (m.volume_stiffness > 0) dP += volume_term_differential(F, dF, m.volume_stiffness);
  return dP;
}

// v_i P_i of a law one lane at a time (a law's lane formula falls back to it where the lanes
// cannot go together: an iteration that has not converged, a lane with det F <= 0); the
// gather and scatter stay blocked.
template <class Law>
PALPATE_INLINE void weighted_stress_per_lane(const Model& m, const Mat3Lanes& F, const Lanes v, const Lanes lambda,
                                             const Lanes mu, Mat3Lanes& vP) {
  for (int l = 0; l < kLanes; ++l) {
    Mat3 Fl, P;
    for (int k = 0; k < 9; ++k) Fl(k % 3, k / 3) = F.m[k][l];
    piola_stress<Law>(m, Fl, lambda[l], mu[l], P);
    for (int k = 0; k < 9; ++k) vP.m[k][l] = v[l] * P(k % 3, k / 3);
  }
}

// v_i dP_i of a law at (F_i, S_i) along dF_i, one lane at a time.
template <class Law>
PALPATE_INLINE void weighted_differential_per_lane(const Model& m, const Mat3Lanes& F, const Mat3Lanes& S,
                                                   const Mat3Lanes& dF, const Lanes v, const Lanes lambda,
                                                   const Lanes mu, Mat3Lanes& vdP) {
  for (int l = 0; l < kLanes; ++l) {
    Mat3 Fl, Sl, dFl;
    for (int k = 0; k < 9; ++k) {
      Fl(k % 3, k / 3) = F.m[k][l];
      Sl(k % 3, k / 3) = S.m[k][l];
      dFl(k % 3, k / 3) = dF.m[k][l];
    }
    const Mat3 dP = piola_differential<Law>(m, Fl, Sl, dFl, lambda[l], mu[l]);
    for (int k = 0; k < 9; ++k) vdP.m[k][l] = v[l] * dP(k % 3, k / 3);
  }
}

}  // namespace palpate::mls
