#pragma once
// The vocabulary of the blocked MLS loops (core/mls_loops.h) and of the material laws' lane
// formulas (core/laws/): the four particles of a block as the lanes of one vector, 3x3
// matrices of them, and the terms every law shares (the volume term ).
#include <cmath>
#include <cstring>
#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "core/model.h"

// Loops over lanes and matrix entries have fixed, small trip counts; unrolled, every
// Lanes value is a register (GCC does not unroll all of them at -O2 by itself).
#define PALPATE_UNROLL _Pragma("GCC unroll 16")
// The helpers of one block are inlined into its loop, so that its matrices stay in registers.
// Not forced in the sanitized builds (scripts/test.sh --sanitize): there the forced inlining
// made core/mls_forces.cpp an 84 s compile under ASan + UBSan at -O1 (29 s without), and the
// loops ran no faster for it (MassFloor.* 45.5 / 43.6 s, Refocus.AnInlineRunIsDeterministic
// 27.2 / 27.1 s, forced / not; docs/robustness.md "CI time").
#ifdef PALPATE_SANITIZED
#define PALPATE_INLINE inline
#else
#define PALPATE_INLINE [[gnu::always_inline]] inline
#endif

namespace palpate::mls {

constexpr int kLanes = Model::block_width;
using Lanes = double __attribute__((vector_size(kLanes * sizeof(double))));
using Slot = Model::NeighborSlot;
using Block = Model::ParticleBlock;
using HourglassSlot = Model::HourglassSlot;
using HourglassBlock = Model::HourglassBlock;

// Passes values through an empty asm as registers: the compiler may not fuse an operation
// before it with one after it (no FMA across it). A law's outputs pass through one where the
// law's formulas end and the caller adds to them (mls_law.h, mls_loops.h), so that a law's
// results do not depend on what the caller does with them next: the same forces whether the
// law is chosen at run time or at compile time (as before the refactor, bit for bit).
PALPATE_INLINE void fence(Lanes& v) { asm("" : "+x"(v)); }
PALPATE_INLINE void fence(double& v) { asm("" : "+x"(v)); }
PALPATE_INLINE void fence(Mat3& M) {
  for (int k = 0; k < 9; ++k) fence(M.data()[k]);
}
// Passes M through memory (an empty asm that may read and write it there): what follows reads
// M from memory, and GCC vectorises (and so fuses) the scalar formulas that read it as it did
// when M was in memory anyway (the pre-refactor linearisation: the tangent stays bit-identical).
PALPATE_INLINE void fence_in_memory(Mat3& M) { asm("" : "+m"(M)); }

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

PALPATE_INLINE void fence(Mat3Lanes& M) {
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) fence(M.m[k]);
}

// The particles of a block (padding lanes repeat its last particle).
template <class Block>
PALPATE_INLINE void block_particles(const Block& block, int (&i)[kLanes]) {
  PALPATE_UNROLL
  for (int l = 0; l < kLanes; ++l) i[l] = block.particle[l];
}

// Entries of a per-particle 3x3 cache (9 x n, column-major per particle) as Lanes.
PALPATE_INLINE void gather_matrices(const double* cache, const int (&i)[kLanes], Mat3Lanes& M) {
  const double *M0 = cache + 9 * static_cast<ptrdiff_t>(i[0]), *M1 = cache + 9 * static_cast<ptrdiff_t>(i[1]),
               *M2 = cache + 9 * static_cast<ptrdiff_t>(i[2]), *M3 = cache + 9 * static_cast<ptrdiff_t>(i[3]);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) M.m[k] = Lanes{M0[k], M1[k], M2[k], M3[k]};
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

// Which product of each difference a b - c d of cof F (and of the first sum of J = det F) is
// fused with the subtraction (addition), the other rounded: GCC chose per loop before the refactor
// (by the order the products came in), the fences of cofactor_det_lanes fix the choice.
enum class Fused { first, second };

// cof F and J = det F of the four lanes with the products fused as `fused` says: the rounding of
// the pre-refactor loops next to the volume term (Fused::second: the forces of the laws of group 1,
// whose cof F GCC hoisted out of the law's branches; Fused::first: the neo-Hookean differential).
template <Fused fused>
PALPATE_INLINE void cofactor_det_lanes(const Mat3Lanes& F, Mat3Lanes& C, Lanes& J) {
  C = {};
  PALPATE_UNROLL
  for (int c = 0; c < 3; ++c) {
    const int a = (c + 1) % 3, b = (c + 2) % 3;
    PALPATE_UNROLL
    for (int r = 0; r < 3; ++r) {
      const int r1 = (r + 1) % 3, r2 = (r + 2) % 3;
      Lanes first = F(r1, a) * F(r2, b), second = F(r2, a) * F(r1, b);
      fence(fused == Fused::first ? second : first);  // the other one fused: keeps the old rounding (bit-identical)
      C(r, c) += first - second;
    }
  }
  Lanes first = F(0, 0) * C(0, 0), second = F(1, 0) * C(1, 0);
  fence(fused == Fused::first ? second : first);  // the other one fused: keeps the old rounding (bit-identical)
  J = first + second + F(2, 0) * C(2, 0);
}

// vP += v k_v (J - 1) cof F, the volume term's stress, from C = cof F and J = det F.
PALPATE_INLINE void add_weighted_volume_term(const Model& m, const Mat3Lanes& C, const Lanes J, const Lanes v,
                                             Mat3Lanes& vP) {
  const Lanes scale = (m.volume_stiffness * v) * (J - 1.0);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) vP.m[k] += scale * C.m[k];
}

// vP += v k_v (J - 1) cof F, the volume term's stress.
PALPATE_INLINE void add_weighted_volume_term(const Model& m, const Mat3Lanes& F, const Lanes v, Mat3Lanes& vP) {
  Mat3Lanes C;
  cofactor_lanes(F, C);
  const Lanes J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
  add_weighted_volume_term(m, C, J, v, vP);
}

// add_weighted_volume_term as the pre-refactor loop of the laws of group 1 rounded it (St
// Venant-Kirchhoff, linear; GCC formed the term before the law's branch there): cof F and J
// with Fused::second, the term's products rounded before the law's stress is added.
PALPATE_INLINE void add_weighted_volume_term_rounded(const Model& m, const Mat3Lanes& F, const Lanes v, Mat3Lanes& vP) {
  Mat3Lanes C;
  Lanes J;
  cofactor_det_lanes<Fused::second>(F, C, J);
  const Lanes scale = (m.volume_stiffness * v) * (J - 1.0);
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) {
    Lanes term = scale * C.m[k];
    fence(term);  // not fused with the law's stress: keeps the old rounding (bit-identical forces)
    vP.m[k] += term;
  }
}

// dP += the volume term's differential k_v [(cof F : dF) cof F + (J - 1) d cof F], from
// C = cof F and J = det F. rounded: the term rounded before it is added to the law's dP, as the
// pre-refactor loop of the St Venant-Kirchhoff, corotational and linear laws had it (GCC formed
// it before their branches).
template <bool rounded = false>
PALPATE_INLINE void add_volume_term_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& C, const Lanes J,
                                                 const Mat3Lanes& dF, Mat3Lanes& dP) {
  Mat3Lanes dC = {};  // d cof F
  add_crossed_columns(dF, F, dC);
  add_crossed_columns(F, dF, dC);
  Lanes C_dF = C.m[0] * dF.m[0];
  PALPATE_UNROLL
  for (int k = 1; k < 9; ++k) C_dF += C.m[k] * dF.m[k];
  PALPATE_UNROLL
  for (int k = 0; k < 9; ++k) {
    Lanes term = m.volume_stiffness * (C_dF * C.m[k] + (J - 1.0) * dC.m[k]);
    if constexpr (rounded) fence(term);  // not fused with the law's dP: keeps the old rounding (bit-identical)
    dP.m[k] += term;
  }
}

// dP += the volume term's differential k_v [(cof F : dF) cof F + (J - 1) d cof F].
template <bool rounded = false>
PALPATE_INLINE void add_volume_term_differential(const Model& m, const Mat3Lanes& F, const Mat3Lanes& dF, Mat3Lanes& dP) {
  Mat3Lanes C;  // cof F
  cofactor_lanes(F, C);
  const Lanes J = F(0, 0) * C(0, 0) + F(1, 0) * C(1, 0) + F(2, 0) * C(2, 0);
  add_volume_term_differential<rounded>(m, F, C, J, dF, dP);
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

}  // namespace palpate::mls
