#include "core/mls_forces.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <bit>
#include <cmath>
#include <cassert>
#include <cstring>
#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "core/neo_hookean.h"

namespace palpate {

namespace {

// ---------------------------------------------------------------------------
// One particle at a time: the reference formulas. They serve the energy, the
// linearisation, single-particle queries, and models without the blocked layout;
// the vectorised loops below compute the same forces.
// ---------------------------------------------------------------------------

// Green strain E = 1/2 (F^T F - I) and the St Venant-Kirchhoff second Piola
// stress S = lambda tr(E) I + 2 mu E, returning the energy density 1/2 E:S.
inline double stvk_stress(const Mat3& F, double lambda, double mu, Mat3& S) {
  const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
  S = (2 * mu) * E;
  S.diagonal().array() += lambda * E.trace();
  return 0.5 * (E.array() * S.array()).sum();
}

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

// cof F and the neo-Hookean law (1.13)-(1.15), shared with the neo-Hookean hex FEM.
using hyperelastic::cofactor;
using hyperelastic::neo_hookean_differential;
using hyperelastic::neo_hookean_stress;

inline Mat3 gradient_at(const Model& m, const double* x, int i) {
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  Mat3 F = Eigen::Map<const Mat3>(&m.rest_correction[9 * static_cast<size_t>(i)]);
  const double xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
  for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
    const double* xj = x + 3 * idx[a];
    const double* d = D + 3 * a;
    const double u0 = xj[0] - xi0, u1 = xj[1] - xi1, u2 = xj[2] - xi2;
    F(0, 0) += u0 * d[0]; F(0, 1) += u0 * d[1]; F(0, 2) += u0 * d[2];
    F(1, 0) += u1 * d[0]; F(1, 1) += u1 * d[1]; F(1, 2) += u1 * d[2];
    F(2, 0) += u2 * d[0]; F(2, 1) += u2 * d[1]; F(2, 2) += u2 * d[2];
  }
  return F;
}

// Hourglass control: residuals r_ij = x_ij - F X_ij of the MLS fit, energy
// 1/2 sum_j kappa w_ij |r_ij|^2 (zero for every affine motion). Its gradient has a
// direct part on each neighbour and a part through F, G = sum_j kappa w_ij r_ij X_ij^T,
// which the caller folds into the stress term (f_j = -(v_i P - G) d_j).
// With f != nullptr the direct forces -kappa w_ij r_ij (and their reaction on i) are
// added to f. Works for positions (x, F) and for differentials (dx, dF) alike.
inline double hourglass_forces(const Model& m, const double* x, int i, const Mat3& F, Mat3& G, double* f) {
  const int* idx = m.neighbor_index.data();
  G.setZero();
  double energy = 0;
  const Vec3 xi(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
  Vec3 fi = Vec3::Zero();
  for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
    const Vec3 X_ij = m.neighbor_rest_offset.col(a);
    const Vec3 r = Eigen::Map<const Vec3>(x + 3 * idx[a]) - xi - F * X_ij;
    const double kw = m.hourglass_weight[a];
    energy += 0.5 * kw * r.squaredNorm();
    G += kw * r * X_ij.transpose();
    if (f) {
      Eigen::Map<Vec3>(f + 3 * idx[a]) -= kw * r;
      fi += kw * r;
    }
  }
  if (f) Eigen::Map<Vec3>(f + 3 * i) += fi;
  return energy;
}

// The rotation R of the polar decomposition F = R U, by Higham's scaled Newton
// iteration R <- 1/2 (g R + R^-T / g), g = |det R|^(-1/3) (R^-T = cof R / det R);
// quadratic convergence, 4-6 iterations at the strains of a contact problem. An
// inverted F (det F < 0) gives the nearest reflection; det F = 0 gives I.
inline Mat3 polar_rotation(const Mat3& F) {
  Mat3 R = F;
  bool scaled = true;  // scaling pays only far from convergence
  for (int it = 0; it < 30; ++it) {
    const Mat3 C = cofactor(R);
    const double det = R.col(0).dot(C.col(0));
    if (!(std::abs(det) > 1e-300)) return Mat3::Identity();
    const double g = scaled ? 1.0 / std::cbrt(std::abs(det)) : 1.0;
    const Mat3 next = 0.5 * (g * R + C / (g * det));
    const double change = (next - R).squaredNorm();
    R = next;
    if (change < 1e-24) break;
    scaled = change > 1e-4;
  }
  return R;
}

// Corotational linear law: psi = mu |F - R|^2 + lambda/2 (tr(R^T F) - 3)^2, F = R U, the
// linear isotropic energy of the Biot strain U - I. Its gradient is exactly
// P = 2 mu (F - R) + lambda (tr(R^T F) - 3) R (the terms through dR vanish: R^T dR is
// skew and U symmetric). Returns psi; R is returned for the tangent.
inline double corotational_stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3& R) {
  R = polar_rotation(F);
  const double trace_strain = (R.transpose() * F).trace() - 3.0;
  P = (2 * mu) * (F - R) + (lambda * trace_strain) * R;
  return mu * (F - R).squaredNorm() + 0.5 * lambda * trace_strain * trace_strain;
}

// Its differential along dF: with A = R^T dF and U = R^T F, dR = R [w]x where
// (tr U I - U) w = (A32 - A23, A13 - A31, A21 - A12); then
// dP = 2 mu (dF - dR) + lambda tr(A) R + lambda (tr U - 3) dR.
// The parts of it that depend on (F, R) only, shared by several dF (the multi-right-hand-side
// product): tr U and (tr U I - U)^-1.
struct CorotationalTangent {
  double trace_U;
  Mat3 K_inverse;
};
inline CorotationalTangent corotational_tangent(const Mat3& F, const Mat3& R) {
  const Mat3 U = R.transpose() * F;
  Mat3 K = -U;
  K.diagonal().array() += U.trace();
  return {U.trace(), K.inverse()};
}
inline Mat3 corotational_differential(const CorotationalTangent& t, const Mat3& R, const Mat3& dF, double lambda,
                                      double mu) {
  const Mat3 A = R.transpose() * dF;
  const Vec3 w = t.K_inverse * Vec3(A(2, 1) - A(1, 2), A(0, 2) - A(2, 0), A(1, 0) - A(0, 1));
  Mat3 W;
  W << 0, -w[2], w[1], w[2], 0, -w[0], -w[1], w[0], 0;
  const Mat3 dR = R * W;
  return (2 * mu) * (dF - dR) + (lambda * A.trace()) * R + (lambda * (t.trace_U - 3.0)) * dR;
}
inline Mat3 corotational_differential(const Mat3& F, const Mat3& R, const Mat3& dF, double lambda, double mu) {
  return corotational_differential(corotational_tangent(F, R), R, dF, lambda, mu);
}

// Differential of the volume term's stress k_v (J - 1) cof F along dF:
// k_v [(cof F : dF) cof F + (J - 1) d cof F], d cof F from the columns crossed pairwise.
inline Mat3 volume_term_differential(const Mat3& F, const Mat3& dF, double volume_stiffness) {
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
inline double piola_stress(const Model& m, const Mat3& F, double lambda, double mu, Mat3& P, Mat3* law_factor_out = nullptr) {
  Mat3 S = Mat3::Identity();
  double psi = 0;
  switch (m.law) {
    case MaterialLaw::corotational:
      psi = corotational_stress(F, lambda, mu, P, S);
      break;
    case MaterialLaw::linear:
      psi = linear_stress(F, lambda, mu, P);
      break;
    case MaterialLaw::neo_hookean:
      psi = neo_hookean_stress(F, lambda, mu, P, S);
      break;
    case MaterialLaw::stvk:
      psi = stvk_stress(F, lambda, mu, S);
      P = F * S;
      break;
  }
  if (m.volume_stiffness > 0) {  // U = 1/2 k_v (det F - 1)^2, P += k_v (J - 1) cof(F)
    const Mat3 C = cofactor(F);
    const double J = F.col(0).dot(C.col(0));
    psi += 0.5 * m.volume_stiffness * (J - 1) * (J - 1);
    P += m.volume_stiffness * (J - 1) * C;
  }
  if (law_factor_out) *law_factor_out = S;
  return psi;
}

// dP of piola_stress at (F, S) along dF, S what piola_stress returned in law_factor_out.
inline Mat3 piola_differential(const Model& m, const Mat3& F, const Mat3& S, const Mat3& dF, double lambda,
                               double mu) {
  Mat3 dP;
  switch (m.law) {
    case MaterialLaw::corotational:  // S holds R
      dP = corotational_differential(F, S, dF, lambda, mu);
      break;
    case MaterialLaw::neo_hookean:  // S holds F^-T
      dP = neo_hookean_differential(F, S, dF, lambda, mu);
      break;
    case MaterialLaw::linear:  // dP = 2 mu sym(dF) + lambda tr(dF) I
      dP = mu * (dF + dF.transpose());
      dP.diagonal().array() += lambda * dF.trace();
      break;
    case MaterialLaw::stvk: {  // dE = sym(F^T dF), dS = lambda tr(dE) I + 2 mu dE, dP = dF S + F dS.
      const Mat3 FtdF = F.transpose() * dF;
      const Mat3 dE = 0.5 * (FtdF + FtdF.transpose());
      Mat3 dS = (2 * mu) * dE;
      dS.diagonal().array() += lambda * dE.trace();
      dP = dF * S + F * dS;
      break;
    }
  }
  if (m.volume_stiffness > 0) dP += volume_term_differential(F, dF, m.volume_stiffness);
  return dP;
}

// mls_internal_forces one particle at a time (with hourglass control).
void internal_forces_per_particle(const Model& m, const double* x, double* f) {
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  const bool hourglass = !m.hourglass_weight.empty();
  for (int i = 0; i < m.particle_count; ++i) {
    const Mat3 F = gradient_at(m, x, i);
    Mat3 P;
    piola_stress(m, F, m.particle_lambda[i], m.particle_mu[i], P);
    // Forces: f_j = -v_i P d_j on every neighbour, f_i = -v_i P d_i = v_i P sum_j d_j.
    Mat3 vP = m.volume[i] * P;
    if (hourglass) {
      Mat3 G;
      hourglass_forces(m, x, i, F, G, f);
      vP -= G;
    }
    double fi0 = 0, fi1 = 0, fi2 = 0;
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const double* d = D + 3 * a;
      double* fj = f + 3 * idx[a];
      const double g0 = vP(0, 0) * d[0] + vP(0, 1) * d[1] + vP(0, 2) * d[2];
      const double g1 = vP(1, 0) * d[0] + vP(1, 1) * d[1] + vP(1, 2) * d[2];
      const double g2 = vP(2, 0) * d[0] + vP(2, 1) * d[1] + vP(2, 2) * d[2];
      fj[0] -= g0; fj[1] -= g1; fj[2] -= g2;
      fi0 += g0; fi1 += g1; fi2 += g2;
    }
    f[3 * i] += fi0;
    f[3 * i + 1] += fi1;
    f[3 * i + 2] += fi2;
  }
}

// mls_force_differential one particle at a time (with hourglass control).
void force_differential_per_particle(const Model& m, const double* tangent_F, const double* tangent_law_factor,
                                     const double* dx, double* df) {
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  for (int i = 0; i < m.particle_count; ++i) {
    const Eigen::Map<const Mat3> F(tangent_F + 9 * static_cast<size_t>(i));
    const Eigen::Map<const Mat3> S(tangent_law_factor + 9 * static_cast<size_t>(i));
    // dF = sum_j (dx_j - dx_i) d_j^T (the rest correction is constant).
    Mat3 dF = Mat3::Zero();
    const Vec3 dxi = Eigen::Map<const Vec3>(dx + 3 * i);
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a)
      dF += (Eigen::Map<const Vec3>(dx + 3 * idx[a]) - dxi) * Eigen::Map<const Vec3>(D + 3 * a).transpose();
    Mat3 vdP = m.volume[i] * piola_differential(m, F, S, dF, m.particle_lambda[i], m.particle_mu[i]);
    if (!m.hourglass_weight.empty()) {  // the hourglass energy is quadratic: same form with (dx, dF)
      Mat3 G;
      hourglass_forces(m, dx, i, dF, G, df);
      vdP -= G;
    }
    Vec3 fi = Vec3::Zero();
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 g = vdP * Eigen::Map<const Vec3>(D + 3 * a);
      Eigen::Map<Vec3>(df + 3 * idx[a]) -= g;
      fi += g;
    }
    Eigen::Map<Vec3>(df + 3 * i) += fi;
  }
}

// ---------------------------------------------------------------------------
// Four particles at a time: the same formulas on the blocked layout of the
// Model (Model::blocks, Model::block_slots), each quantity held as Lanes (one
// particle of the block per lane), so the compiler emits packed AVX2/FMA (or
// SSE pairs) arithmetic. Gathering x_j and scattering f_j stay scalar per lane,
// in lane order, so a particle shared by two lanes is updated correctly.
// ---------------------------------------------------------------------------

// Loops over lanes and matrix entries have fixed, small trip counts; unrolled, every
// Lanes value is a register (GCC does not unroll all of them at -O2 by itself).
#define PALPATE_UNROLL _Pragma("GCC unroll 16")
// The helpers of one block are inlined into its loop, so that its matrices stay in registers.
#define PALPATE_INLINE [[gnu::always_inline]] inline

constexpr int kLanes = Model::block_width;
using Lanes = double __attribute__((vector_size(kLanes * sizeof(double))));
using Slot = Model::NeighborSlot;
using Block = Model::ParticleBlock;
using HourglassSlot = Model::HourglassSlot;
using HourglassBlock = Model::HourglassBlock;

PALPATE_INLINE Lanes load(const double* p) {  // kLanes consecutive doubles (any alignment)
  Lanes v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// 3x3 matrices of the four particles of a block; entry (r, c) at m[r + 3 c] (column-major, as Mat3).
struct Mat3Lanes {
  Lanes m[9];
  Lanes& operator()(int r, int c) { return m[r + 3 * c]; }
  const Lanes& operator()(int r, int c) const { return m[r + 3 * c]; }
};

// The blocked loops read positions (x, or dx for a differential) and write forces in one
// of two layouts, their template parameter Layout:
// - Rows: padded rows, particle i's x, y, z at rows[4 i ... 4 i + 2] and rows[4 i + 3] = 0,
//   the buffer 32-byte aligned: one 256-bit load or store per particle and a 4 x 4
//   transpose instead of three scalar accesses per lane (4-12 % off the single-thread
//   loops, docs/verification.md); to_rows / from_rows convert at the loops' edges;
// - Columns: the 3 x n column-major Points themselves (the threaded loops: on two threads
//   the rows' conversions cost more than they save, docs/verification.md).
// gather(x, i, c): c[r] lane l = entry r of particle i_l. subtract(f, i, g, lanes): f_{i_l}
// -= g_l for the first `lanes` lanes, one particle after the other (two lanes may name the
// same particle); each component gets the same subtractions in the same order in both
// layouts, so their forces are bit-identical.
constexpr int kRow = 4;

struct Rows {
  PALPATE_INLINE static void gather(const double* __restrict rows, const int (&i)[kLanes], Lanes (&c)[3]) {
#if defined(__AVX__)
    const __m256d r0 = _mm256_load_pd(rows + kRow * static_cast<ptrdiff_t>(i[0])),
                  r1 = _mm256_load_pd(rows + kRow * static_cast<ptrdiff_t>(i[1])),
                  r2 = _mm256_load_pd(rows + kRow * static_cast<ptrdiff_t>(i[2])),
                  r3 = _mm256_load_pd(rows + kRow * static_cast<ptrdiff_t>(i[3]));
    const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1), t2 = _mm256_unpacklo_pd(r2, r3),
                  t3 = _mm256_unpackhi_pd(r2, r3);
    c[0] = _mm256_permute2f128_pd(t0, t2, 0x20);
    c[1] = _mm256_permute2f128_pd(t1, t3, 0x20);
    c[2] = _mm256_permute2f128_pd(t0, t2, 0x31);
#else
    const double *x0 = rows + kRow * static_cast<ptrdiff_t>(i[0]), *x1 = rows + kRow * static_cast<ptrdiff_t>(i[1]),
                 *x2 = rows + kRow * static_cast<ptrdiff_t>(i[2]), *x3 = rows + kRow * static_cast<ptrdiff_t>(i[3]);
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) c[r] = Lanes{x0[r], x1[r], x2[r], x3[r]};
#endif
  }
  PALPATE_INLINE static void subtract(double* __restrict rows, const int (&i)[kLanes], const Lanes (&g)[3],
                                      int lanes = kLanes) {
#if defined(__AVX__)
    const __m256d zero = _mm256_setzero_pd();
    const __m256d t0 = _mm256_unpacklo_pd(g[0], g[1]), t1 = _mm256_unpackhi_pd(g[0], g[1]),
                  t2 = _mm256_unpacklo_pd(g[2], zero), t3 = _mm256_unpackhi_pd(g[2], zero);
    const __m256d v[kLanes] = {_mm256_permute2f128_pd(t0, t2, 0x20), _mm256_permute2f128_pd(t1, t3, 0x20),
                               _mm256_permute2f128_pd(t0, t2, 0x31), _mm256_permute2f128_pd(t1, t3, 0x31)};
    PALPATE_UNROLL
    for (int l = 0; l < lanes; ++l) {
      double* p = rows + kRow * static_cast<ptrdiff_t>(i[l]);
      _mm256_store_pd(p, _mm256_sub_pd(_mm256_load_pd(p), v[l]));
    }
#else
    PALPATE_UNROLL
    for (int l = 0; l < lanes; ++l) {
      double* p = rows + kRow * static_cast<ptrdiff_t>(i[l]);
      p[0] -= g[0][l];
      p[1] -= g[1][l];
      p[2] -= g[2][l];
    }
#endif
  }
};

struct Columns {
  PALPATE_INLINE static void gather(const double* __restrict x, const int (&i)[kLanes], Lanes (&c)[3]) {
    const double *x0 = x + 3 * static_cast<ptrdiff_t>(i[0]), *x1 = x + 3 * static_cast<ptrdiff_t>(i[1]),
                 *x2 = x + 3 * static_cast<ptrdiff_t>(i[2]), *x3 = x + 3 * static_cast<ptrdiff_t>(i[3]);
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) c[r] = Lanes{x0[r], x1[r], x2[r], x3[r]};
  }
  PALPATE_INLINE static void subtract(double* __restrict f, const int (&i)[kLanes], const Lanes (&g)[3],
                                      int lanes = kLanes) {
    PALPATE_UNROLL
    for (int l = 0; l < lanes; ++l) {
      double* fi = f + 3 * static_cast<ptrdiff_t>(i[l]);
      fi[0] -= g[0][l];
      fi[1] -= g[1][l];
      fi[2] -= g[2][l];
    }
  }
};

// rows (n padded rows) = x (3 x n, column-major).
void to_rows(const double* __restrict x, int n, double* __restrict rows) {
  for (int i = 0; i < n; ++i) {
    rows[kRow * i] = x[3 * i];
    rows[kRow * i + 1] = x[3 * i + 1];
    rows[kRow * i + 2] = x[3 * i + 2];
    rows[kRow * i + 3] = 0.0;
  }
}

// f (3 x n, column-major) = rows (n padded rows).
void from_rows(const double* __restrict rows, int n, double* __restrict f) {
  for (int i = 0; i < n; ++i) {
    f[3 * i] = rows[kRow * i];
    f[3 * i + 1] = rows[kRow * i + 1];
    f[3 * i + 2] = rows[kRow * i + 2];
  }
}

// The particles of block b (padding lanes repeat the last particle).
PALPATE_INLINE void block_particles(int b, int n, int (&i)[kLanes]) {
  PALPATE_UNROLL
  for (int l = 0; l < kLanes; ++l) i[l] = std::min(kLanes * b + l, n - 1);
}

// Entries of a per-particle 3x3 cache (9 x n, column-major per particle) as Lanes.
PALPATE_INLINE void gather_matrices(const double* cache, const int (&i)[kLanes], Mat3Lanes& M) {
  const double *M0 = cache + 9 * static_cast<ptrdiff_t>(i[0]), *M1 = cache + 9 * static_cast<ptrdiff_t>(i[1]),
               *M2 = cache + 9 * static_cast<ptrdiff_t>(i[2]), *M3 = cache + 9 * static_cast<ptrdiff_t>(i[3]);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) M.m[k] = Lanes{M0[k], M1[k], M2[k], M3[k]};
}

// The sums over a block's neighbours that hourglass control needs besides F (1.9a):
// B = sum_j x_ij e_ij^T and s = sum_j k_ij x_ij (dx_ij for a differential).
struct HourglassSums {
  Mat3Lanes B = {};
  Lanes s[3] = {};
};

// Adds sum_j (x_j - x_i) d_j^T over the block's slots to F (A-9; also dF from dx); with
// hourglass control, also the block's HourglassSums, from its slots hg (parallel to slot).
template <class Layout, bool hourglass = false>
PALPATE_INLINE void add_gradient(const Slot* slot, const Slot* end, const double* __restrict x, const int (&i)[kLanes],
                                 Mat3Lanes& F, const HourglassSlot* hg = nullptr, HourglassSums* sums = nullptr) {
  Lanes xi[3], xj[3];
  Layout::gather(x, i, xi);
  for (; slot != end; ++slot) {
    const Lanes d0 = load(slot->d[0]), d1 = load(slot->d[1]), d2 = load(slot->d[2]);
    Layout::gather(x, slot->j, xj);
    Lanes e0, e1, e2, k;
    if constexpr (hourglass) {
      e0 = load(hg->e[0]), e1 = load(hg->e[1]), e2 = load(hg->e[2]), k = load(hg->k);
      ++hg;
    }
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) {
      const Lanes x_ij = xj[r] - xi[r];
      F(r, 0) += x_ij * d0;
      F(r, 1) += x_ij * d1;
      F(r, 2) += x_ij * d2;
      if constexpr (hourglass) {
        sums->B(r, 0) += x_ij * e0;
        sums->B(r, 1) += x_ij * e1;
        sums->B(r, 2) += x_ij * e2;
        sums->s[r] += k * x_ij;
      }
    }
  }
}

// T -= G_i, G_i = B - F H_i (1.9a): the hourglass part of the stress the scatter distributes
// (F the block's gradient, dF for a differential).
PALPATE_INLINE void subtract_hourglass_stress(const HourglassBlock& hg, const Mat3Lanes& F, const HourglassSums& sums,
                                              Mat3Lanes& T) {
  const Lanes h00 = load(hg.H[0]), h11 = load(hg.H[1]), h22 = load(hg.H[2]), h01 = load(hg.H[3]),
              h02 = load(hg.H[4]), h12 = load(hg.H[5]);
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r) {
    T(r, 0) += F(r, 0) * h00 + F(r, 1) * h01 + F(r, 2) * h02 - sums.B(r, 0);
    T(r, 1) += F(r, 0) * h01 + F(r, 1) * h11 + F(r, 2) * h12 - sums.B(r, 1);
    T(r, 2) += F(r, 0) * h02 + F(r, 1) * h12 + F(r, 2) * h22 - sums.B(r, 2);
  }
}

// What scatter_forces needs for the direct hourglass forces (1.9a): the block's hourglass
// slots and terms, its gradient F (or dF), the positions x (or dx) and the sums.
struct HourglassScatter {
  const HourglassSlot* slot;
  const HourglassBlock* block;
  const Mat3Lanes* F;
  const double* x;
  const HourglassSums* sums;
};

// g = T d for the block's stresses T and weights d (d[c] = component c of the four lanes).
PALPATE_INLINE void stress_times_weight(const Mat3Lanes& T, const double (&d)[3][kLanes], Lanes (&g)[3]) {
  const Lanes d0 = load(d[0]), d1 = load(d[1]), d2 = load(d[2]);
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r) g[r] = T(r, 0) * d0 + T(r, 1) * d1 + T(r, 2) * d2;
}

// Forces of the block's stresses T = v_i P_i: f_j -= T d_j on every
// neighbour and f_i -= T d_i on the particle itself. Padding slots have d = 0 and
// add nothing; padding lanes (i >= n) are not written. With hourglass control (T then
// v_i P_i - G_i) also the direct forces (1.9a): f_j -= k_ij x_ij - F e_ij, f_i += s - F e_i.
template <class Layout, bool hourglass = false>
PALPATE_INLINE void scatter_forces(const Block& block, const Slot* slot, const Slot* end, const Mat3Lanes& T,
                                   const int (&i)[kLanes], int lanes, double* __restrict f,
                                   const HourglassScatter& h = {}) {
  Lanes g[3];
  [[maybe_unused]] Lanes xi[3], xj[3];
  [[maybe_unused]] const HourglassSlot* hg = h.slot;
  if constexpr (hourglass) Layout::gather(h.x, i, xi);
  for (; slot != end; ++slot) {
    stress_times_weight(T, slot->d, g);
    if constexpr (hourglass) {
      const Mat3Lanes& F = *h.F;
      const Lanes e0 = load(hg->e[0]), e1 = load(hg->e[1]), e2 = load(hg->e[2]), k = load(hg->k);
      ++hg;
      Layout::gather(h.x, slot->j, xj);
      PALPATE_UNROLL
      for (int r = 0; r < 3; ++r) g[r] += k * (xj[r] - xi[r]) - (F(r, 0) * e0 + F(r, 1) * e1 + F(r, 2) * e2);
    }
    Layout::subtract(f, slot->j, g);
  }
  stress_times_weight(T, block.self_weight, g);
  if constexpr (hourglass) {
    const Mat3Lanes& F = *h.F;
    const Lanes e0 = load(h.block->e_sum[0]), e1 = load(h.block->e_sum[1]), e2 = load(h.block->e_sum[2]);
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) g[r] -= h.sums->s[r] - (F(r, 0) * e0 + F(r, 1) * e1 + F(r, 2) * e2);
  }
  Layout::subtract(f, i, g, lanes);
}

// C += the columns of A and B crossed pairwise: column c of C gains A_a x B_b, (a, b) =
// (c + 1, c + 2) mod 3. With A = B = F that is cof F; d cof F = cross(dF, F) + cross(F, dF).
PALPATE_INLINE void add_crossed_columns(const Mat3Lanes& A, const Mat3Lanes& B, Mat3Lanes& C) {
  PALPATE_UNROLL
  for (int c = 0; c < 3; ++c) {
    const int a = (c + 1) % 3, b = (c + 2) % 3;
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) {
      const int r1 = (r + 1) % 3, r2 = (r + 2) % 3;
      C(r, c) += A(r1, a) * B(r2, b) - A(r2, a) * B(r1, b);
    }
  }
}

// cof F of the four lanes.
PALPATE_INLINE void cofactor_lanes(const Mat3Lanes& F, Mat3Lanes& C) {
  C = {};
  add_crossed_columns(F, F, C);
}

// vP += v k_v (J - 1) cof F, the volume term's stress.
PALPATE_INLINE void add_weighted_volume_term(const Model& m, const Mat3Lanes& F, const Lanes v, Mat3Lanes& vP) {
  Mat3Lanes C;
  cofactor_lanes(F, C);
  const Lanes J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
  const Lanes scale = (m.volume_stiffness * v) * (J - 1.0);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vP.m[k] += scale * C.m[k];
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
  if constexpr (volume_term) add_weighted_volume_term(m, F, v, vP);
}

// dP += the volume term's differential k_v [(cof F : dF) cof F + (J - 1) d cof F].
PALPATE_INLINE void add_volume_term_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& dF, Mat3Lanes& dP) {
  Mat3Lanes C, dC = {};  // cof F and its differential
  cofactor_lanes(F, C);
  add_crossed_columns(dF, F, dC);
  add_crossed_columns(F, dF, dC);
  const Lanes J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
  Lanes C_dF = C.m[0] * dF.m[0];
  PALPATE_UNROLL
  for (int k = 1; k < 9; ++k) C_dF += C.m[k] * dF.m[k];
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) dP.m[k] += m.volume_stiffness * (C_dF * C.m[k] + (J - 1.0) * dC.m[k]);
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
  if constexpr (volume_term) add_volume_term_differential(m, F, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

// sqrt of each lane (packed; std::sqrt, which may set errno, would stay scalar).
PALPATE_INLINE Lanes sqrt_lanes(Lanes a) {
#if defined(__AVX__)
  static_assert(kLanes == 4, "the packed square root takes four doubles");
  return _mm256_sqrt_pd(a);
#else
  PALPATE_UNROLL
  for (int l = 0; l < kLanes; ++l) a[l] = std::sqrt(a[l]);
  return a;
#endif
}

// Squared Frobenius change of a Newton step below which a lane has converged. Newton's
// polar iteration converges quadratically: the distance of the next iterate from the
// rotation is about half the squared change of this step (in the spectral norm, for a
// change d: |R_next - Q| <= d^2 / 2 once the singular values are near 1), so a squared
// change below 1e-16 leaves an error below 1e-16, the rounding of the iterate itself.
// (polar_rotation asks for 1e-24, which costs one more iteration and gains nothing.)
constexpr double kPolarChangeTolerance = 1e-16;
constexpr int kPolarMaxIterations = 30;

// The rotations R[g] of the polar decompositions of G blocks' F[g] (4 G particles):
// polar_rotation's Newton iteration R <- 1/2 (g R + cof R / (g det R)) on all lanes
// together, every operation packed, the G blocks' operations interleaved (one iteration
// is a chain of dependent operations, a division among them; alone it leaves the FMA
// units idle most of the time). While some lane is far from convergence (its last
// squared change above 1e-4) the lanes that are take the Frobenius-norm scaling
// g = (|R^-1| / |R|)^(1/2) (no cube root; packed square roots and division), the others
// g = 1; near convergence the norms and roots are skipped. Converged lanes stay put (an
// orthogonal R is a fixed point). Returns the number of iterations, or 0, leaving the
// lanes to polar_rotation, if a lane of F is (nearly) singular (the iteration keeps the
// sign of det and, after one step, lifts every singular value to >= 1, so one check of
// det F suffices) or a lane does not converge in 30 iterations. scaled_iterations, if
// given, receives the number of iterations that took the scaling.
template <int G>
PALPATE_INLINE int polar_rotation_lanes(const Mat3Lanes (&F)[G], Mat3Lanes (&R)[G], int* scaled_iterations = nullptr) {
  Lanes scaled[G];  // 1 while the lane's last squared change exceeded 1e-4
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    R[g] = F[g];
    scaled[g] = Lanes{1, 1, 1, 1};
  }
  bool any_scaled = true;
  int scaled_count = 0;
  for (int it = 0; it < kPolarMaxIterations; ++it) {
    Mat3Lanes C[G];
    Lanes det[G], a[G], b[G];
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) {
      cofactor_lanes(R[g], C[g]);
      det[g] = R[g](0, 0) * C[g](0, 0) + R[g](1, 0) * C[g](1, 0) + R[g](2, 0) * C[g](2, 0);
    }
    if (it == 0) {
      PALPATE_UNROLL
      for (int g = 0; g < G; ++g)
        PALPATE_UNROLL
        for (int l = 0; l < kLanes; ++l)
          if (!(std::abs(det[g][l]) > 1e-300)) return 0;
    }
    if (!any_scaled) {
      PALPATE_UNROLL
      for (int g = 0; g < G; ++g) {
        a[g] = Lanes{0.5, 0.5, 0.5, 0.5};
        b[g] = 0.5 / det[g];
      }
    } else {
      PALPATE_UNROLL
      for (int g = 0; g < G; ++g) {
        Lanes norm_R = R[g].m[0] * R[g].m[0], norm_C = C[g].m[0] * C[g].m[0];
        PALPATE_UNROLL
        for (int k = 1; k < 9; ++k) {
          norm_R += R[g].m[k] * R[g].m[k];
          norm_C += C[g].m[k] * C[g].m[k];
        }
        // (|cof R| / (|det R| |R|))^(1/2) in the scaled lanes, 1 in the others.
        const Lanes scale =
            1.0 + scaled[g] * (sqrt_lanes(sqrt_lanes(norm_C / (det[g] * det[g] * norm_R))) - 1.0);
        a[g] = 0.5 * scale;
        b[g] = 0.5 / (scale * det[g]);
      }
      ++scaled_count;
    }
    Lanes change[G];
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) {
      change[g] = Lanes{0, 0, 0, 0};
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) {
        const Lanes next = a[g] * R[g].m[k] + b[g] * C[g].m[k];
        const Lanes d = next - R[g].m[k];
        change[g] += d * d;
        R[g].m[k] = next;
      }
    }
    bool converged = true;
    any_scaled = false;
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g)
      PALPATE_UNROLL
      for (int l = 0; l < kLanes; ++l) {
        converged = converged && change[g][l] < kPolarChangeTolerance;
        if (!(change[g][l] > 1e-4)) scaled[g][l] = 0;
        any_scaled = any_scaled || scaled[g][l] != 0;
      }
    if (converged) {
      if (scaled_iterations) *scaled_iterations = scaled_count;
      return it + 1;
    }
  }
  return 0;
}

// The blocked loop's rotation, first choice: the polynomial (Newton-Schulz type) iteration
//
//     X <- X (15 I - 10 A + 3 A^2) / 8,   A = X^T X,   X_0 = F             (1.17)
//
// (B in docs/physics.md, where A is the moment matrix)
// on all lanes of G blocks (Kenney and Laub's third-order polynomial iteration for the
// polar factor). It keeps the singular vectors of F and maps each singular value s to
// f(s) = s (15 - 10 s^2 + 3 s^4) / 8, increasing, with 1 - f(s) = (1 - s)^3 (8 + 9 s + 3 s^2) / 8:
// for s in (0, (7/3)^(1/2)) it converges monotonically to 1, cubically near 1
// (1 + e -> 1 + e^3 (20 + 15 e + 3 e^2) / 8), so X converges to the polar rotation R (the
// nearest reflection for det F < 0, as polar_rotation). It needs neither a division nor a
// square root -- only FMAs in short dependency chains -- where the scaled Newton iteration
// waits on a division and two square roots per step. Its basin is checked on A_0 = F^T F:
// with m = tr A_0 / 3 and the deviator D = A_0 - m I, the largest eigenvalue of A_0 (the
// largest squared singular value) is at most m + (2/3)^(1/2) |D|, required <= 2, i.e. every
// singular value <= 2^(1/2) (the bound is exact for a uniaxial deviator and above the
// largest eigenvalue by up to 0.155 (it - m) otherwise; tissue strains stay far inside).
// The defect E = A - I, computed for the update anyway, measures the distance to R
// exactly: its eigenvalues are s_k^2 - 1 = 2 e_k + e_k^2. When its squared Frobenius norm
// is below 4e-11 (every |e_k| < 3.2e-6) the step taken with it leaves |e_k| < 8e-17, a
// third of the rounding unit of R's entries, and the iteration stops. Returns the number
// of iterations; 0 when a lane is outside the basin or has not converged after
// kSchulzMaxIterations (a small singular value grows only by 15/8 per step): the caller
// then takes the scaled Newton iteration. `attempted` receives the iterations spent.
constexpr double kSchulzDefectTolerance = 4e-11;
constexpr double kSchulzEigenvalueBound = 2.0;
constexpr int kSchulzMaxIterations = 9;

template <int G>
PALPATE_INLINE int schulz_rotation_lanes(const Mat3Lanes (&F)[G], Mat3Lanes (&R)[G], int* attempted = nullptr) {
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) R[g] = F[g];
  for (int it = 0; it < kSchulzMaxIterations; ++it) {
    Lanes A[G][6];  // X^T X: (0,0), (1,1), (2,2), (0,1), (0,2), (1,2)
    Lanes defect[G];
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) {
      const Mat3Lanes& X = R[g];
      auto XtX = [&](int a, int b) { return X(0, a) * X(0, b) + X(1, a) * X(1, b) + X(2, a) * X(2, b); };
      A[g][0] = XtX(0, 0);
      A[g][1] = XtX(1, 1);
      A[g][2] = XtX(2, 2);
      A[g][3] = XtX(0, 1);
      A[g][4] = XtX(0, 2);
      A[g][5] = XtX(1, 2);
      const Lanes e0 = A[g][0] - 1.0, e1 = A[g][1] - 1.0, e2 = A[g][2] - 1.0;
      defect[g] = e0 * e0 + e1 * e1 + e2 * e2 + 2.0 * (A[g][3] * A[g][3] + A[g][4] * A[g][4] + A[g][5] * A[g][5]);
    }
    if (it == 0) {  // the basin: m + (2/3)^(1/2) |D| <= bound, squared (no root)
      bool inside = true;
      PALPATE_UNROLL
      for (int g = 0; g < G; ++g) {
        const Lanes m = (A[g][0] + A[g][1] + A[g][2]) * (1.0 / 3.0);
        const Lanes d0 = A[g][0] - m, d1 = A[g][1] - m, d2 = A[g][2] - m;
        const Lanes deviator =
            d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * (A[g][3] * A[g][3] + A[g][4] * A[g][4] + A[g][5] * A[g][5]);
        const Lanes margin = kSchulzEigenvalueBound - m;
        PALPATE_UNROLL
        for (int l = 0; l < kLanes; ++l)
          inside = inside && margin[l] >= 0 && (2.0 / 3.0) * deviator[l] <= margin[l] * margin[l];
      }
      if (!inside) {
        if (attempted) *attempted = 0;
        return 0;
      }
    }
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) {  // X <- X M, M = (15 I - 10 A + 3 A^2) / 8 (symmetric)
      const Lanes* a = A[g];
      const Lanes B[6] = {a[0] * a[0] + a[3] * a[3] + a[4] * a[4], a[3] * a[3] + a[1] * a[1] + a[5] * a[5],
                          a[4] * a[4] + a[5] * a[5] + a[2] * a[2], a[0] * a[3] + a[3] * a[1] + a[4] * a[5],
                          a[0] * a[4] + a[3] * a[5] + a[4] * a[2], a[3] * a[4] + a[1] * a[5] + a[5] * a[2]};  // A^2
      Mat3Lanes M;
      M(0, 0) = (15.0 / 8) - (10.0 / 8) * a[0] + (3.0 / 8) * B[0];
      M(1, 1) = (15.0 / 8) - (10.0 / 8) * a[1] + (3.0 / 8) * B[1];
      M(2, 2) = (15.0 / 8) - (10.0 / 8) * a[2] + (3.0 / 8) * B[2];
      M(0, 1) = M(1, 0) = (3.0 / 8) * B[3] - (10.0 / 8) * a[3];
      M(0, 2) = M(2, 0) = (3.0 / 8) * B[4] - (10.0 / 8) * a[4];
      M(1, 2) = M(2, 1) = (3.0 / 8) * B[5] - (10.0 / 8) * a[5];
      const Mat3Lanes X = R[g];
      PALPATE_UNROLL
      for (int r = 0; r < 3; ++r)
        PALPATE_UNROLL
        for (int c = 0; c < 3; ++c) R[g](r, c) = X(r, 0) * M(0, c) + X(r, 1) * M(1, c) + X(r, 2) * M(2, c);
    }
    bool converged = true;
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g)
      PALPATE_UNROLL
      for (int l = 0; l < kLanes; ++l) converged = converged && defect[g][l] < kSchulzDefectTolerance;
    if (converged) {
      if (attempted) *attempted = it + 1;
      return it + 1;
    }
  }
  if (attempted) *attempted = kSchulzMaxIterations;
  return 0;
}

// v_i P_i of the laws other than St Venant-Kirchhoff, one lane at a time (the polar
// decomposition iterates a data-dependent number of times); the gather and scatter stay blocked.
PALPATE_INLINE void weighted_stress_per_lane(const Model& m, const Mat3Lanes& F, const Lanes v, const Lanes lambda,
                                             const Lanes mu, Mat3Lanes& vP) {
  for (int l = 0; l < kLanes; ++l) {
    Mat3 Fl, P;
    for (int k = 0; k < 9; ++k) Fl(k % 3, k / 3) = F.m[k][l];
    piola_stress(m, Fl, lambda[l], mu[l], P);
    for (int k = 0; k < 9; ++k) vP.m[k][l] = v[l] * P(k % 3, k / 3);
  }
}

// v_i P_i of the corotational law, P = 2 mu (F - R) + lambda (tr(R^T F) - 3) R, on all
// lanes of G blocks together (the volume term added when volume_term).
template <bool volume_term, int G>
PALPATE_INLINE void weighted_corotational_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                                 const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
  Mat3Lanes R[G];
  if (schulz_rotation_lanes<G>(F, R) == 0 && polar_rotation_lanes<G>(F, R) == 0) {
    for (int g = 0; g < G; ++g) weighted_stress_per_lane(m, F[g], v[g], lambda[g], mu[g], vP[g]);
    return;
  }
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    Lanes trace_strain = R[g].m[0] * F[g].m[0];
    PALPATE_UNROLL
    for (int k = 1; k < 9; ++k) trace_strain += R[g].m[k] * F[g].m[k];
    trace_strain -= 3.0;
    const Lanes v_2mu = (2 * mu[g]) * v[g], v_lambda_tr = (lambda[g] * v[g]) * trace_strain;
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) vP[g].m[k] = v_2mu * (F[g].m[k] - R[g].m[k]) + v_lambda_tr * R[g].m[k];
    if constexpr (volume_term) add_weighted_volume_term(m, F[g], v[g], vP[g]);
  }
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
  if constexpr (volume_term) add_weighted_volume_term(m, F, v, vP);
}

// v_i dP_i of the laws other than St Venant-Kirchhoff at (F_i, S_i) along dF_i, one lane at a time.
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
    const Mat3 dP = piola_differential(m, Fl, Sl, dFl, lambda[l], mu[l]);
    for (int k = 0; k < 9; ++k) vdP.m[k][l] = v[l] * dP(k % 3, k / 3);
  }
}

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
// the block). ln J packed (log_lanes), or lane by lane outside [1e-300, 1e300].
PALPATE_INLINE bool log_det_lanes(const Mat3Lanes& F, Mat3Lanes& C, Lanes& J, Lanes& log_J) {
  cofactor_lanes(F, C);
  J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
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
  if (!log_det_lanes(F, C, J, log_J)) return weighted_stress_per_lane(m, F, v, lambda, mu, vP);
  const Lanes v_mu = mu * v, scale = v * (lambda * log_J - mu) / J;
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vP.m[k] = v_mu * F.m[k] + scale * C.m[k];
  if constexpr (volume_term) add_weighted_volume_term(m, F, v, vP);
}

// v_i dP_i of the neo-Hookean law (1.15) at (F_i, G_i = F_i^-T) along dF_i, on all four lanes:
// dP = mu dF + (mu - lambda ln J) G dF^T G + lambda (G : dF) G (+ the volume term's).
template <bool volume_term>
PALPATE_INLINE void weighted_neo_hookean_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& G,
                                                      const Mat3Lanes& dF, const Lanes v, const Lanes lambda,
                                                      const Lanes mu, Mat3Lanes& vdP) {
  Mat3Lanes C;
  Lanes J, log_J;
  if (!log_det_lanes(F, C, J, log_J)) return weighted_differential_per_lane(m, F, G, dF, v, lambda, mu, vdP);
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
  if constexpr (volume_term) add_volume_term_differential(m, F, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

// The corotational law's tangent at (F_i, R_i), packed, for K directions dF[0..K) at once:
// tr U and (tr U I - U)^-1 (U = R^T F; the inverse as cof^T / det) formed once per block,
// then per direction A = R^T dF, (tr U I - U) w = (A32 - A23, A13 - A31, A21 - A12),
// dR = R [w]x, dP = 2 mu (dF - dR) + lambda tr(A) R + lambda (tr U - 3) dR (+ the volume
// term's), as corotational_differential one lane at a time (the same to round-off).
template <bool volume_term, int K>
PALPATE_INLINE void weighted_corotational_differentials(const Model& m, const Mat3Lanes& F, const Mat3Lanes& R,
                                                        const Mat3Lanes (&dF)[K], const Lanes v, const Lanes lambda,
                                                        const Lanes mu, Mat3Lanes (&vdP)[K]) {
  Mat3Lanes T;  // tr U I - U
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c) T(r, c) = -(R(0, r) * F(0, c) + R(1, r) * F(1, c) + R(2, r) * F(2, c));
  const Lanes trace_U = -(T(0, 0) + T(1, 1) + T(2, 2));
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r) T(r, r) += trace_U;
  Mat3Lanes C;  // cof T; T^-1 = C^T / det T
  cofactor_lanes(T, C);
  const Lanes inverse_det = 1.0 / (T(0, 0) * C(0, 0) + T(1, 0) * C(1, 0) + T(2, 0) * C(2, 0));
  Mat3Lanes T_inverse;
  PALPATE_UNROLL
  for (int r = 0; r < 3; ++r)
    PALPATE_UNROLL
    for (int c = 0; c < 3; ++c) T_inverse(r, c) = C(c, r) * inverse_det;
  const Lanes two_mu = 2 * mu, lambda_rotation = lambda * (trace_U - 3.0);
  PALPATE_UNROLL
  for (int q = 0; q < K; ++q) {
    Mat3Lanes A;  // R^T dF
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r)
      PALPATE_UNROLL
      for (int c = 0; c < 3; ++c) A(r, c) = R(0, r) * dF[q](0, c) + R(1, r) * dF[q](1, c) + R(2, r) * dF[q](2, c);
    const Lanes a0 = A(2, 1) - A(1, 2), a1 = A(0, 2) - A(2, 0), a2 = A(1, 0) - A(0, 1);
    Lanes w[3];
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) w[r] = T_inverse(r, 0) * a0 + T_inverse(r, 1) * a1 + T_inverse(r, 2) * a2;
    const Lanes lambda_trace_A = lambda * (A(0, 0) + A(1, 1) + A(2, 2));
    Mat3Lanes dP;
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) {
      const Lanes dR0 = R(r, 1) * w[2] - R(r, 2) * w[1];
      const Lanes dR1 = R(r, 2) * w[0] - R(r, 0) * w[2];
      const Lanes dR2 = R(r, 0) * w[1] - R(r, 1) * w[0];
      dP(r, 0) = two_mu * (dF[q](r, 0) - dR0) + lambda_trace_A * R(r, 0) + lambda_rotation * dR0;
      dP(r, 1) = two_mu * (dF[q](r, 1) - dR1) + lambda_trace_A * R(r, 1) + lambda_rotation * dR1;
      dP(r, 2) = two_mu * (dF[q](r, 2) - dR2) + lambda_trace_A * R(r, 2) + lambda_rotation * dR2;
    }
    if constexpr (volume_term) add_volume_term_differential(m, F, dF[q], dP);
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) vdP[q].m[k] = v * dP.m[k];
  }
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
  if constexpr (volume_term) add_volume_term_differential(m, F, dF, dP);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vdP.m[k] = v * dP.m[k];
}

// The force loop over G blocks at a time: F of each, their stresses v_i P_i, the
// forces, with hourglass control's terms (1.9a) when hourglass. G = 2 for the
// corotational law (its polar iterations interleave).
template <class Layout, bool volume_term, bool hourglass, int G>
PALPATE_INLINE void internal_forces_of_blocks(const Model& m, int b0, const double* __restrict x,
                                              double* __restrict f) {
  const int n = m.particle_count;
  int i[G][kLanes];
  Mat3Lanes F[G], vP[G];
  Lanes v[G], lambda[G], mu[G];
  [[maybe_unused]] HourglassSums sums[G];
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    const Block& block = m.blocks[b0 + g];
    block_particles(b0 + g, n, i[g]);
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) F[g].m[k] = load(block.rest_correction[k]);  // F_i = C_i + sum_j (x_j - x_i) d_j^T
    add_gradient<Layout, hourglass>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x, i[g],
                            F[g], hourglass ? m.block_hourglass_slots.data() + block.slot_begin : nullptr, &sums[g]);
    v[g] = load(block.volume);
    lambda[g] = load(block.lame_lambda);
    mu[g] = load(block.lame_mu);
  }
  if (m.law == MaterialLaw::corotational) {
    weighted_corotational_stress<volume_term, G>(m, F, v, lambda, mu, vP);
  } else {
    PALPATE_UNROLL
    for (int g = 0; g < G; ++g) {
      if (m.law == MaterialLaw::neo_hookean)
        weighted_neo_hookean_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
      else if (m.law == MaterialLaw::linear)
        weighted_linear_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
      else
        weighted_stvk_stress<volume_term>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
    }
  }
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    const Block& block = m.blocks[b0 + g];
    [[maybe_unused]] HourglassScatter h{};
    if constexpr (hourglass) {
      subtract_hourglass_stress(m.block_hourglass[b0 + g], F[g], sums[g], vP[g]);
      h = {m.block_hourglass_slots.data() + block.slot_begin, &m.block_hourglass[b0 + g], &F[g], x, &sums[g]};
    }
    scatter_forces<Layout, hourglass>(block, m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end,
                              vP[g], i[g], std::min(kLanes, n - kLanes * (b0 + g)), f, h);
  }
}

// Blocks [b_begin, b_end) (b_begin even: the corotational pairs are those of the whole loop).
template <class Layout, bool volume_term, bool hourglass>
void internal_forces_blocked(const Model& m, int b_begin, int b_end, const double* __restrict x,
                             double* __restrict f) {
  int b = b_begin;
  if (m.law == MaterialLaw::corotational)
    for (; b + 2 <= b_end; b += 2) internal_forces_of_blocks<Layout, volume_term, hourglass, 2>(m, b, x, f);
  for (; b < b_end; ++b) internal_forces_of_blocks<Layout, volume_term, hourglass, 1>(m, b, x, f);
}

// The force differentials df_q = (df/dx) dx_q for K directions in one sweep over blocks
// [b_begin, b_end): per block the tangent's F, S (R, F^-T) and the Lame parameters
// gathered once, the K gradients dF and scatters over the same slots, the laws' per-lane
// work shared where it can be (the corotational rotation's linear system). Hourglass
// control's energy is quadratic: its terms (1.9a) are those of the forces with (dx, dF).
template <class Layout, bool volume_term, bool hourglass, int K>
void force_differentials_blocked(const Model& m, int b_begin, int b_end, const double* tangent_F,
                                 const double* tangent_law_factor, const double* const* dx, double* const* df) {
  const int n = m.particle_count;
  for (int b = b_begin; b < b_end; ++b) {
    const Block& block = m.blocks[b];
    const Slot* begin = m.block_slots.data() + block.slot_begin;
    const Slot* end = m.block_slots.data() + block.slot_end;
    [[maybe_unused]] const HourglassSlot* hg = hourglass ? m.block_hourglass_slots.data() + block.slot_begin : nullptr;
    int i[kLanes];
    block_particles(b, n, i);
    Mat3Lanes dF[K] = {};
    [[maybe_unused]] HourglassSums sums[K];
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q) add_gradient<Layout, hourglass>(begin, end, dx[q], i, dF[q], hg, &sums[q]);
    Mat3Lanes F, S, vdP[K];
    gather_matrices(tangent_F, i, F);
    gather_matrices(tangent_law_factor, i, S);
    const Lanes v = load(block.volume), lambda = load(block.lame_lambda), mu = load(block.lame_mu);
    if (m.law == MaterialLaw::neo_hookean) {
      PALPATE_UNROLL
      for (int q = 0; q < K; ++q) weighted_neo_hookean_differential<volume_term>(m, F, S, dF[q], v, lambda, mu, vdP[q]);
    } else if (m.law == MaterialLaw::corotational) {  // S holds R
      weighted_corotational_differentials<volume_term, K>(m, F, S, dF, v, lambda, mu, vdP);
    } else if (m.law == MaterialLaw::linear) {
      PALPATE_UNROLL
      for (int q = 0; q < K; ++q) weighted_linear_differential<volume_term>(m, F, dF[q], v, lambda, mu, vdP[q]);
    } else {
      PALPATE_UNROLL
      for (int q = 0; q < K; ++q) weighted_stvk_differential<volume_term>(m, F, S, dF[q], v, lambda, mu, vdP[q]);
    }
    const int lanes = std::min(kLanes, n - kLanes * b);
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q) {
      [[maybe_unused]] HourglassScatter h{};
      if constexpr (hourglass) {
        subtract_hourglass_stress(m.block_hourglass[b], dF[q], sums[q], vdP[q]);
        h = {hg, &m.block_hourglass[b], &dF[q], dx[q], &sums[q]};
      }
      scatter_forces<Layout, hourglass>(block, begin, end, vdP[q], i, lanes, df[q], h);
    }
  }
}

// Calls body.template operator()<volume_term, hourglass>() with the model's flags: the
// blocked loops' variants.
template <class Body>
void with_blocked_variant(const Model& m, const Body& body) {
  const bool volume_term = m.volume_stiffness > 0, hourglass = !m.hourglass_weight.empty();
  if (volume_term && hourglass)
    body.template operator()<true, true>();
  else if (volume_term)
    body.template operator()<true, false>();
  else if (hourglass)
    body.template operator()<false, true>();
  else
    body.template operator()<false, false>();
}

// The blocked layout is built by build_model; a Model put together otherwise (or whose
// blocks lack hourglass control's terms) takes the per-particle loops.
bool use_blocks(const Model& m) {
  return !m.blocks.empty() && static_cast<int>(m.blocks.size()) * kLanes >= m.particle_count &&
         (m.hourglass_weight.empty() || (m.block_hourglass.size() == m.blocks.size() &&
                                         m.block_hourglass_slots.size() == m.block_slots.size()));
}

// Iterations of the blocked loop's rotations at positions x (corotational law), over the
// loop's pairs of blocks, each counted once per real (not padding) lane: the polynomial
// iterations (1.17) spent (also by pairs that then fall back), the scaled Newton
// iterations of the pairs that fall back to them, and those of the latter that took the
// scaling. Pairs that fall back to polar_rotation are not counted further.
void count_polar_iterations(const Model& m, const double* x, double& schulz_iterations, double& newton_iterations,
                            double& scaled_iterations) {
  schulz_iterations = newton_iterations = scaled_iterations = 0;
  const int n = m.particle_count, blocks = static_cast<int>(m.blocks.size());
  auto gradients = [&](int b, Mat3Lanes& F) {
    const Block& block = m.blocks[b];
    int i[kLanes];
    block_particles(b, n, i);
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) F.m[k] = load(block.rest_correction[k]);
    add_gradient<Columns>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x, i, F);
    return std::min(kLanes, n - kLanes * b);
  };
  auto count = [&](auto& F, auto& R, int lanes) {
    int spent = 0, scaled = 0;
    const int converged_after = schulz_rotation_lanes(F, R, &spent);
    schulz_iterations += lanes * spent;
    if (converged_after == 0) {
      newton_iterations += lanes * polar_rotation_lanes(F, R, &scaled);
      scaled_iterations += lanes * scaled;
    }
  };
  int b = 0;
  for (; b + 2 <= blocks; b += 2) {  // the pairs of internal_forces_blocked
    Mat3Lanes F[2], R[2];
    const int lanes = gradients(b, F[0]) + gradients(b + 1, F[1]);
    count(F, R, lanes);
  }
  for (; b < blocks; ++b) {
    Mat3Lanes F[1], R[1];
    const int lanes = gradients(b, F[0]);
    count(F, R, lanes);
  }
}

// The block ranges of a split of the blocked loops over T threads: thread t takes blocks
// [bounds[t], bounds[t + 1]), the ranges of about equal work (neighbour slots + a per-block
// cost of the law's stress, in slot units), every bound but the last even (the corotational
// loop's pairs stay whole). Depends on the model and T only.
void split_blocks(const Model& m, int T, int* bounds) {
  const int blocks = static_cast<int>(m.blocks.size());
  const int64_t per_block = m.law == MaterialLaw::corotational ? 12 : 3;
  auto cost = [&](int b) { return m.blocks[b].slot_end - m.blocks[b].slot_begin + per_block; };
  int64_t total = 0;
  for (int b = 0; b < blocks; ++b) total += cost(b);
  bounds[0] = 0;
  int b = 0;
  int64_t done = 0;
  for (int t = 1; t < T; ++t) {
    const int64_t target = total * t / T;
    while (b + 2 <= blocks && done + cost(b) + cost(b + 1) <= target) {
      done += cost(b) + cost(b + 1);
      b += 2;
    }
    bounds[t] = b;
  }
  bounds[T] = blocks;
}

// One thread: x (3 x n) to padded rows in the scratch, loop(0, blocks, x_rows, f_rows) -- a
// blocked loop on Rows that adds the forces of the blocks into f_rows (zeroed first) --
// and f (3 x n) from f_rows.
template <class Loop>
void loop_on_rows(const Model& m, WorkerThreads& scratch, const double* x, double* f, const Loop& loop) {
  const int n = m.particle_count;
  const size_t stride = kRow * static_cast<size_t>(n);
  double* x_rows = scratch.row_buffers(2, n);
  double* f_rows = x_rows + stride;
  to_rows(x, n, x_rows);
  std::fill(f_rows, f_rows + stride, 0.0);
  loop(0, static_cast<int>(m.blocks.size()), x_rows, f_rows);
  from_rows(f_rows, n, f);
}

// Runs loop(b_begin, b_end, out) -- a blocked loop on Columns that adds the forces of blocks
// [b_begin, b_end) into out (3 x n) -- on the pool's threads over split_blocks' ranges,
// thread 0 into f, thread t > 0 into its own zeroed buffer of the scratch; then adds the
// buffers into f in the order t = 1, 2, ..., each thread over its share of the coordinates.
template <class Loop>
void scatter_in_parallel(const Model& m, double* f, WorkerThreads& threads, const Loop& loop) {
  const int T = threads.count(), n = m.particle_count;
  const size_t stride = kRow * static_cast<size_t>(n);  // the scratch's buffers (3 n used)
  double* partial = threads.row_buffers(T - 1, n);
  int bounds[kMaxThreads + 1];
  split_blocks(m, T, bounds);
  threads.pool->run([&](int t) {
    double* out = t == 0 ? f : partial + (t - 1) * stride;
    std::fill(out, out + 3 * static_cast<ptrdiff_t>(n), 0.0);
    loop(bounds[t], bounds[t + 1], out);
  });
  const int64_t coordinates = 3 * int64_t{n};
  threads.pool->run([&](int t) {
    const int64_t k_begin = coordinates * t / T, k_end = coordinates * (t + 1) / T;
    for (int u = 1; u < T; ++u) {
      const double* in = partial + (u - 1) * stride;
      for (int64_t k = k_begin; k < k_end; ++k) f[k] += in[k];
    }
  });
}

void linearize_particles(const Model& m, const Points& x, int i_begin, int i_end, std::vector<double>& tangent_F,
                         std::vector<double>& tangent_law_factor);

}  // namespace

bool detail::uses_blocked_loops(const Model& model) { return use_blocks(model); }

Mat3 detail::polar_rotation(const Mat3& F) { return palpate::polar_rotation(F); }

namespace {
void to_lanes(const Mat3 (&F)[Model::block_width], Mat3Lanes (&F_lanes)[1]) {
  for (int l = 0; l < kLanes; ++l)
    for (int k = 0; k < 9; ++k) F_lanes[0].m[k][l] = F[l](k % 3, k / 3);
}
void from_lanes(const Mat3Lanes (&R_lanes)[1], Mat3 (&R)[Model::block_width]) {
  for (int l = 0; l < kLanes; ++l)
    for (int k = 0; k < 9; ++k) R[l](k % 3, k / 3) = R_lanes[0].m[k][l];
}
}  // namespace

int detail::polar_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]) {
  Mat3Lanes F_lanes[1], R_lanes[1];
  to_lanes(F, F_lanes);
  int iterations = schulz_rotation_lanes<1>(F_lanes, R_lanes);
  if (iterations == 0) iterations = polar_rotation_lanes<1>(F_lanes, R_lanes);
  from_lanes(R_lanes, R);
  return iterations;
}

int detail::schulz_rotation_blocked(const Mat3 (&F)[Model::block_width], Mat3 (&R)[Model::block_width]) {
  Mat3Lanes F_lanes[1], R_lanes[1];
  to_lanes(F, F_lanes);
  const int iterations = schulz_rotation_lanes<1>(F_lanes, R_lanes);
  from_lanes(R_lanes, R);
  return iterations;
}

double detail::pair_loop_floor(const Model& m, const Points& x, Points& f, WorkerThreads& scratch) {
  assert(use_blocks(m) && "pair_loop_floor needs the blocked layout");
  const int n = m.particle_count;
  loop_on_rows(m, scratch, x.data(), f.data(), [&](int b_begin, int b_end, const double* x_rows, double* f_rows) {
    for (int b = b_begin; b < b_end; ++b) {
      const Block& block = m.blocks[b];
      int i[kLanes];
      block_particles(b, n, i);
      Mat3Lanes F, vP;
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) F.m[k] = load(block.rest_correction[k]);
      add_gradient<Rows>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x_rows, i, F);
      const Lanes v = load(block.volume);
      PALPATE_UNROLL
      for (int k = 0; k < 9; ++k) vP.m[k] = v * F.m[k];
      scatter_forces<Rows>(block, m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, vP, i,
                           std::min(kLanes, n - kLanes * b), f_rows);
    }
  });
  return m.neighbor_offset.back() * 39.0 + n * (18.0 + 9.0);
}

void detail::log_blocked(const double (&a)[Model::block_width], double (&log_a)[Model::block_width]) {
  Lanes v;
  std::memcpy(&v, a, sizeof v);
  const Lanes r = log_lanes(v);
  std::memcpy(log_a, &r, sizeof r);
}

Mat3 deformation_gradient(const Model& model, const Points& x, int i) { return gradient_at(model, x.data(), i); }

double first_piola_stress(const Model& model, const Mat3& F, Mat3& P) {
  return piola_stress(model, F, model.lame_lambda, model.lame_mu, P);
}

double particle_first_piola_stress(const Model& model, const Mat3& F, int i, Mat3& P) {
  return piola_stress(model, F, model.particle_lambda[i], model.particle_mu[i], P);
}

void mls_internal_forces(const Model& m, const Points& x, Points& f) {
  WorkerThreads scratch;  // allocates the loop's rows: the stepping code passes its own
  mls_internal_forces(m, x, f, scratch);
}

void mls_internal_forces(const Model& m, const Points& x, Points& f, WorkerThreads& threads) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  if (!use_blocks(m)) {
    f.setZero();
    return internal_forces_per_particle(m, x.data(), f.data());
  }
  with_blocked_variant(m, [&]<bool volume_term, bool hourglass>() {
    if (threads.count() == 1)
      return loop_on_rows(m, threads, x.data(), f.data(), [&](int b_begin, int b_end, const double* x_rows, double* out) {
        internal_forces_blocked<Rows, volume_term, hourglass>(m, b_begin, b_end, x_rows, out);
      });
    scatter_in_parallel(m, f.data(), threads, [&](int b_begin, int b_end, double* out) {
      internal_forces_blocked<Columns, volume_term, hourglass>(m, b_begin, b_end, x.data(), out);
    });
  });
}

double mls_strain_energy(const Model& m, const Points& x) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  double U = 0;
  for (int i = 0; i < m.particle_count; ++i) {
    const Mat3 F = gradient_at(m, x.data(), i);
    Mat3 P;
    U += m.volume[i] * piola_stress(m, F, m.particle_lambda[i], m.particle_mu[i], P);
    if (!m.hourglass_weight.empty()) {
      Mat3 G;
      U += hourglass_forces(m, x.data(), i, F, G, nullptr);
    }
  }
  return U;
}

void mls_linearize(const Model& m, const Points& x, std::vector<double>& tangent_F,
                      std::vector<double>& tangent_law_factor) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  tangent_F.resize(9 * static_cast<size_t>(m.particle_count));
  tangent_law_factor.resize(9 * static_cast<size_t>(m.particle_count));
  linearize_particles(m, x, 0, m.particle_count, tangent_F, tangent_law_factor);
}

void mls_linearize(const Model& m, const Points& x, std::vector<double>& tangent_F,
                   std::vector<double>& tangent_law_factor, WorkerThreads& threads) {
  if (threads.count() == 1) return mls_linearize(m, x, tangent_F, tangent_law_factor);
  tangent_F.resize(9 * static_cast<size_t>(m.particle_count));
  tangent_law_factor.resize(9 * static_cast<size_t>(m.particle_count));
  const int T = threads.count(), n = m.particle_count;
  threads.pool->run([&](int t) {
    linearize_particles(m, x, static_cast<int>(int64_t{n} * t / T), static_cast<int>(int64_t{n} * (t + 1) / T),
                        tangent_F, tangent_law_factor);
  });
}

namespace {
void linearize_particles(const Model& m, const Points& x, int i_begin, int i_end, std::vector<double>& tangent_F,
                         std::vector<double>& tangent_law_factor) {
  for (int i = i_begin; i < i_end; ++i) {
    const Mat3 F = gradient_at(m, x.data(), i);
    Mat3 P, S;
    piola_stress(m, F, m.particle_lambda[i], m.particle_mu[i], P, &S);  // S, or R (corotational), or F^-T (neo-Hookean)
    Eigen::Map<Mat3> F_out(&tangent_F[9 * static_cast<size_t>(i)]), law_factor_out(&tangent_law_factor[9 * static_cast<size_t>(i)]);
    F_out = F;
    law_factor_out = S;
  }
}
}  // namespace

void mls_force_differential(const Model& m, const std::vector<double>& tangent_F,
                            const std::vector<double>& tangent_law_factor, const Points& dx, Points& df) {
  WorkerThreads scratch;  // allocates the loop's rows: the stepping code passes its own
  mls_force_differential(m, tangent_F, tangent_law_factor, dx, df, scratch);
}

void mls_force_differential(const Model& m, const std::vector<double>& tangent_F,
                            const std::vector<double>& tangent_law_factor, const Points& dx, Points& df,
                            WorkerThreads& threads) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  if (!use_blocks(m)) {
    df.setZero();
    return force_differential_per_particle(m, tangent_F.data(), tangent_law_factor.data(), dx.data(), df.data());
  }
  const double *F = tangent_F.data(), *S = tangent_law_factor.data();
  with_blocked_variant(m, [&]<bool volume_term, bool hourglass>() {
    if (threads.count() == 1)
      return loop_on_rows(m, threads, dx.data(), df.data(), [&](int b_begin, int b_end, const double* dx_rows, double* out) {
        const double* in[1] = {dx_rows};
        double* outs[1] = {out};
        force_differentials_blocked<Rows, volume_term, hourglass, 1>(m, b_begin, b_end, F, S, in, outs);
      });
    scatter_in_parallel(m, df.data(), threads, [&](int b_begin, int b_end, double* out) {
      const double* in[1] = {dx.data()};
      double* outs[1] = {out};
      force_differentials_blocked<Columns, volume_term, hourglass, 1>(m, b_begin, b_end, F, S, in, outs);
    });
  });
}

void mls_force_differentials(const Model& m, const std::vector<double>& tangent_F,
                             const std::vector<double>& tangent_law_factor, int count, const Points* const* dx,
                             Points* const* df, WorkerThreads& scratch) {
  assert(m.solid == SolidKind::mls && "an MLS function called on a hex-FEM model");
  assert(count >= 0 && count <= kMaxDifferentials);
  if (count == 0) return;
  if (!use_blocks(m)) {  // the per-particle reference loop: one product after the other
    for (int q = 0; q < count; ++q) mls_force_differential(m, tangent_F, tangent_law_factor, *dx[q], *df[q], scratch);
    return;
  }
  const int n = m.particle_count;
  const size_t stride = kRow * static_cast<size_t>(n);
  double* rows = scratch.row_buffers(2 * count, n);  // the directions' rows, then their forces'
  const double* in[kMaxDifferentials];
  double* out[kMaxDifferentials];
  for (int q = 0; q < count; ++q) {
    double* in_rows = rows + q * stride;
    to_rows(dx[q]->data(), n, in_rows);
    in[q] = in_rows;
    out[q] = rows + (count + q) * stride;
    std::fill(out[q], out[q] + stride, 0.0);
  }
  const int blocks = static_cast<int>(m.blocks.size());
  const double *F = tangent_F.data(), *S = tangent_law_factor.data();
  with_blocked_variant(m, [&]<bool volume_term, bool hourglass>() {
    switch (count) {
      case 1: force_differentials_blocked<Rows, volume_term, hourglass, 1>(m, 0, blocks, F, S, in, out); break;
      case 2: force_differentials_blocked<Rows, volume_term, hourglass, 2>(m, 0, blocks, F, S, in, out); break;
      default: force_differentials_blocked<Rows, volume_term, hourglass, 3>(m, 0, blocks, F, S, in, out); break;
    }
  });
  for (int q = 0; q < count; ++q) from_rows(out[q], n, df[q]->data());
}

double mls_internal_forces_flops(const Model& m, const Points& x) {
  // Floating-point operations (an FMA counts two; a division, square root or logarithm one)
  // of the arithmetic the force loop needs, as the code does it; padding slots and lanes of
  // the blocked loop are not counted.
  const double nnz = m.neighbor_offset.back(), n = m.particle_count;
  if (use_blocks(m)) {
    // Every law, per neighbour pair: F += (x_j - x_i) d_j^T 3 sub + 9 fma = 21;
    // g = v_i P_i d_j 3 x (mul + 2 fma) = 15; f_j -= g 3: 39. Per particle:
    // f_i -= v_i P_i d_i 15 + 3 = 18. Volume term per particle: cof F
    // 9 x (mul + fma) = 27, J 5, k_v v (J - 1) 3, P += 9 fma 18: 53.
    double per_particle = 18.0 + (m.volume_stiffness > 0 ? 53.0 : 0.0);
    double polar = 0;
    switch (m.law) {
      case MaterialLaw::stvk:
        // F^T F 6 x (mul + 2 fma) = 30; E 3 fma + 3 mul = 9; lambda v tr E 4, 2 mu v 1;
        // v S 3 fma + 3 mul = 9; P = F (v S) 9 x (mul + 2 fma) = 45: 98.
        per_particle += 98.0;
        break;
      case MaterialLaw::linear:
        // 2 mu v 2, mu v 1, lambda v (tr F - 3) 5; diagonal 3 x (sub + fma) = 9; off-diagonal
        // 3 x (add + mul) = 6: 23.
        per_particle += 23.0;
        break;
      case MaterialLaw::neo_hookean:
        // (1.14): cof F 27, J 5, ln J 30 (log_lanes: the reduction 2, s 3, s^2 1, the series
        // 8 fma 16, 2 s 1, 2 s s^2 p 2, + k ln 2 in two parts 5), mu v 1, v (lambda ln J - mu) / J
        // 4, P = mu v F + s cof F 9 x (mul + fma) = 27: 94.
        per_particle += 94.0;
        break;
      case MaterialLaw::corotational: {
        // After the polar decomposition: tr(R^T F) - 3 (1 mul + 8 fma + 1) = 18, 2 mu v 2,
        // lambda v tr 2, P = 2 mu v (F - R) + lambda v tr R 9 x (sub + mul + fma) = 36: 58.
        per_particle += 58.0;
        // Each iteration (1.17) of schulz_rotation_lanes: A = X^T X 6 x (mul + 2 fma) = 30, its
        // defect |A - I|^2 3 sub + 2 x (mul + 2 fma) + mul + add = 15, A^2 6 x (mul + 2 fma) = 30,
        // M = (15 I - 10 A + 3 A^2) / 8 6 x 2 fma = 24, X M 9 x (mul + 2 fma) = 45: 144 (the first
        // also checks the basin, not counted). Each Newton iteration of
        // polar_rotation_lanes (the fallback): cof R 27, det R 5, 1 / det 1, the update
        // a R + b cof R 9 x (mul + fma) = 27, its squared change 9 x (sub + fma) = 27: 87; a
        // scaled one also |R|^2, |cof R|^2 2 x (1 mul + 8 fma) = 34, g (2 mul, 1 div, 2 sqrt,
        // 3 for the lanes' choice) 8, a 1, g det 1: 131. Data dependent: counted at x.
        double schulz = 0, newton = 0, scaled = 0;
        count_polar_iterations(m, x.data(), schulz, newton, scaled);
        polar = 144.0 * schulz + 87.0 * newton + 44.0 * scaled;
        break;
      }
    }
    if (!m.hourglass_weight.empty()) {
      // Hourglass control (1.9a), per pair: B += x_ij e_ij^T 9 fma 18, s += k x_ij 3 fma 6; in
      // the scatter x_ij 3 sub, k x_ij - F e_ij 3 x (mul + 3 fma) = 21: 48. Per particle: F H
      // 9 x (mul + 2 fma) = 45, T += F H - B 18; s - F e_i 3 x (mul + 3 fma) = 21: 84.
      return nnz * (39.0 + 51.0) + n * (per_particle + 84.0) + polar;
    }
    return nnz * 39.0 + n * per_particle + polar;
  }
  // Per particle loop (a model without the blocked layout): per pair 21 (F) + 15 (T d_j) + 3 (f_j)
  // + 3 (f_i sum) = 42, per particle about 130 (E, S, P with Eigen 3x3 products; energy density)
  // plus the volume term, and the hourglass residuals r_ij = x_ij - F X_ij, G += kw r X^T and its
  // direct forces: about 60 per pair. (The St Venant-Kirchhoff law's count; the per-particle
  // loop is the reference, not timed.)
  return nnz * (42.0 + (m.hourglass_weight.empty() ? 0.0 : 60.0)) +
         n * (130.0 + (m.volume_stiffness > 0 ? 60.0 : 0.0));
}

}  // namespace palpate
