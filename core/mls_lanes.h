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
#define PALPATE_INLINE [[gnu::always_inline]] inline

namespace palpate::mls {

constexpr int kLanes = Model::block_width;
using Lanes = double __attribute__((vector_size(kLanes * sizeof(double))));
using Slot = Model::NeighborSlot;
using Block = Model::ParticleBlock;
using HourglassSlot = Model::HourglassSlot;
using HourglassBlock = Model::HourglassBlock;

// Passes values through an empty asm as registers: the compiler may not fuse an operation
// before it with one after it (no FMA across it). A law's outputs pass through one where the
// law's formulas end (mls_law.h, mls_loops.h), so that a law's results do not depend on what
// the caller does with them next: the same forces whether the law is chosen at run time or
// at compile time.
PALPATE_INLINE void fence(Lanes& v) { asm("" : "+x"(v)); }
PALPATE_INLINE void fence(double& v) { asm("" : "+x"(v)); }
PALPATE_INLINE void fence(Mat3& M) {
  for (int k = 0; k < 9; ++k) fence(M.data()[k]);
}

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
