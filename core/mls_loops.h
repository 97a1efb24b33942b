#pragma once
// The MLS solid's force loops (core/mls_forces.h is their API), templated on the material law
// (core/mls_law.h; the laws: core/laws/laws.h): the per-particle reference loops (one
// particle at a time, the formulas as written), and the blocked loops, four particles at a
// time on the Model's blocked layout (Model::blocks, Model::block_slots), each quantity held
// as Lanes (one particle of the block per lane), so the compiler emits packed AVX2/FMA (or
// SSE pairs) arithmetic. Gathering x_j and scattering f_j stay scalar per lane, in lane order,
// so a particle shared by two lanes is updated correctly. A header so that a law defined
// elsewhere (a test's) runs on the same loops.
#include <algorithm>
#include <cassert>
#include <cstdint>
#include <vector>

#include "core/laws/laws.h"
#include "core/mls_law.h"
#include "core/thread_pool.h"

namespace palpate::mls {

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

// mls_internal_forces one particle at a time (with hourglass control).
template <class Law>
void internal_forces_per_particle(const Model& m, const double* x, double* f) {
  const double* D = m.gradient_weight.data();
  const int* idx = m.neighbor_index.data();
  const bool hourglass = !m.hourglass_weight.empty();
  for (int i = 0; i < m.particle_count; ++i) {
    const Mat3 F = gradient_at(m, x, i);
    Mat3 P;
    piola_stress<Law>(m, F, m.particle_lambda[i], m.particle_mu[i], P);
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
template <class Law>
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
    Mat3 vdP = m.volume[i] * piola_differential<Law>(m, F, S, dF, m.particle_lambda[i], m.particle_mu[i]);
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
inline void to_rows(const double* __restrict x, int n, double* __restrict rows) {
  for (int i = 0; i < n; ++i) {
    rows[kRow * i] = x[3 * i];
    rows[kRow * i + 1] = x[3 * i + 1];
    rows[kRow * i + 2] = x[3 * i + 2];
    rows[kRow * i + 3] = 0.0;
  }
}

// f (3 x n, column-major) = rows (n padded rows).
inline void from_rows(const double* __restrict rows, int n, double* __restrict f) {
  for (int i = 0; i < n; ++i) {
    f[3 * i] = rows[kRow * i];
    f[3 * i + 1] = rows[kRow * i + 1];
    f[3 * i + 2] = rows[kRow * i + 2];
  }
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

// The force loop over G blocks at a time, block_of[0 .. G-1]: F of each, their stresses
// v_i P_i, the forces, with hourglass control's terms (1.9a) when hourglass.
// G = Law::group (2 for the corotational law: its polar iterations interleave).
template <class Law, class Layout, bool volume_term, bool hourglass, int G>
PALPATE_INLINE void internal_forces_of_blocks(const Model& m, const int* block_of, const double* __restrict x,
                                              double* __restrict f) {
  int i[G][kLanes];
  Mat3Lanes F[G], vP[G];
  Lanes v[G], lambda[G], mu[G];
  [[maybe_unused]] HourglassSums sums[G];
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    const Block& block = m.blocks[block_of[g]];
    block_particles(block, i[g]);
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) F[g].m[k] = load(block.rest_correction[k]);  // F_i = C_i + sum_j (x_j - x_i) d_j^T
    add_gradient<Layout, hourglass>(m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end, x, i[g],
                            F[g], hourglass ? m.block_hourglass_slots.data() + block.slot_begin : nullptr, &sums[g]);
    v[g] = load(block.volume);
    lambda[g] = load(block.lame_lambda);
    mu[g] = load(block.lame_mu);
  }
  Law::template weighted_stress<volume_term, G>(m, F, v, lambda, mu, vP);
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) fence(vP[g]);
  PALPATE_UNROLL
  for (int g = 0; g < G; ++g) {
    const Block& block = m.blocks[block_of[g]];
    [[maybe_unused]] HourglassScatter h{};
    if constexpr (hourglass) {
      subtract_hourglass_stress(m.block_hourglass[block_of[g]], F[g], sums[g], vP[g]);
      h = {m.block_hourglass_slots.data() + block.slot_begin, &m.block_hourglass[block_of[g]], &F[g], x, &sums[g]};
    }
    scatter_forces<Layout, hourglass>(block, m.block_slots.data() + block.slot_begin, m.block_slots.data() + block.slot_end,
                              vP[g], i[g], block.lanes, f, h);
  }
}

// Blocks [b_begin, b_end) (b_begin even: the pairs of a law of group 2 are those of the whole loop).
template <class Law, class Layout, bool volume_term, bool hourglass>
void internal_forces_blocked(const Model& m, int b_begin, int b_end, const double* __restrict x,
                             double* __restrict f) {
  static_assert(Law::group == 1 || Law::group == 2, "the blocked loop groups one or two blocks");
  // Blocks without hourglass control (a refined cloud's far part) take the loop without its terms.
  [[maybe_unused]] auto active = [&](int b) { return m.block_hourglass[b].active; };
  int b = b_begin;
  if constexpr (Law::group == 2)
    for (; b + 2 <= b_end; b += 2) {
      const int pair[2] = {b, b + 1};
      if constexpr (hourglass)
        if (!active(b) && !active(b + 1)) {
          internal_forces_of_blocks<Law, Layout, volume_term, false, 2>(m, pair, x, f);
          continue;
        }
      internal_forces_of_blocks<Law, Layout, volume_term, hourglass, 2>(m, pair, x, f);
    }
  for (; b < b_end; ++b) {
    if constexpr (hourglass)
      if (!active(b)) {
        internal_forces_of_blocks<Law, Layout, volume_term, false, 1>(m, &b, x, f);
        continue;
      }
    internal_forces_of_blocks<Law, Layout, volume_term, hourglass, 1>(m, &b, x, f);
  }
}

// The force loop over the listed blocks (ascending, count of them): internal_forces_blocked's
// per block, a law of group 2 taking the listed blocks two at a time in their order. All blocks
// listed, the pairs are internal_forces_blocked's, and so are the forces, bit for bit.
template <class Law, class Layout, bool volume_term, bool hourglass>
void internal_forces_listed(const Model& m, const int* list, int count, const double* __restrict x,
                            double* __restrict f) {
  [[maybe_unused]] auto active = [&](int b) { return m.block_hourglass[b].active; };
  int k = 0;
  if constexpr (Law::group == 2)
    for (; k + 2 <= count; k += 2) {
      const int* pair = list + k;
      if (hourglass && (active(pair[0]) || active(pair[1])))
        internal_forces_of_blocks<Law, Layout, volume_term, hourglass, 2>(m, pair, x, f);
      else
        internal_forces_of_blocks<Law, Layout, volume_term, false, 2>(m, pair, x, f);
    }
  for (; k < count; ++k) {
    if (hourglass && active(list[k]))
      internal_forces_of_blocks<Law, Layout, volume_term, hourglass, 1>(m, list + k, x, f);
    else
      internal_forces_of_blocks<Law, Layout, volume_term, false, 1>(m, list + k, x, f);
  }
}

// The force differentials df_q = (df/dx) dx_q for K directions in one sweep over blocks
// [b_begin, b_end): per block the tangent's F, S (R, F^-T) and the Lame parameters
// gathered once, the K gradients dF and scatters over the same slots, the laws' per-lane
// work shared where it can be (the corotational rotation's linear system). Hourglass
// control's energy is quadratic: its terms (1.9a) are those of the forces with (dx, dF).
template <class Law, class Layout, bool volume_term, bool hourglass, int K>
void force_differentials_blocked(const Model& m, int b_begin, int b_end, const double* tangent_F,
                                 const double* tangent_law_factor, const double* const* dx, double* const* df) {
  for (int b = b_begin; b < b_end; ++b) {
    if constexpr (hourglass)
      if (!m.block_hourglass[b].active) {  // a block without hourglass control: the loop without its terms
        force_differentials_blocked<Law, Layout, volume_term, false, K>(m, b, b + 1, tangent_F, tangent_law_factor, dx, df);
        continue;
      }
    const Block& block = m.blocks[b];
    const Slot* begin = m.block_slots.data() + block.slot_begin;
    const Slot* end = m.block_slots.data() + block.slot_end;
    [[maybe_unused]] const HourglassSlot* hg = hourglass ? m.block_hourglass_slots.data() + block.slot_begin : nullptr;
    int i[kLanes];
    block_particles(block, i);
    Mat3Lanes dF[K] = {};
    [[maybe_unused]] HourglassSums sums[K];
    PALPATE_UNROLL
    for (int q = 0; q < K; ++q) add_gradient<Layout, hourglass>(begin, end, dx[q], i, dF[q], hg, &sums[q]);
    Mat3Lanes F, S, vdP[K];
    gather_matrices(tangent_F, i, F);
    gather_matrices(tangent_law_factor, i, S);
    const Lanes v = load(block.volume), lambda = load(block.lame_lambda), mu = load(block.lame_mu);
    Law::template weighted_differentials<volume_term, K>(m, F, S, dF, v, lambda, mu, vdP);
    // v dP not fused with the hourglass term, as before the refactor (bit-identical); without
    // hourglass control the fence changes nothing but GCC's schedule (5 % faster corotational
    // K dx with it), except for the neo-Hookean law, whose K dx it moves off the old one by an ulp.
    if constexpr (hourglass || Law::id != MaterialLaw::neo_hookean) {
      PALPATE_UNROLL
      for (int q = 0; q < K; ++q) fence(vdP[q]);
    }
    const int lanes = block.lanes;
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

// Calls body.template operator()<Law, volume_term, hourglass>() with the model's law and
// flags: the blocked loops' variants.
template <class Body>
void with_blocked_variant(const Model& m, const Body& body) {
  with_law(m.law, [&]<class Law>() {
    const bool volume_term = m.volume_stiffness > 0, hourglass = !m.hourglass_weight.empty();
    if (volume_term && hourglass)
      body.template operator()<Law, true, true>();
    else if (volume_term)
      body.template operator()<Law, true, false>();
    else if (hourglass)
      body.template operator()<Law, false, true>();
    else
      body.template operator()<Law, false, false>();
  });
}

// The blocked layout is built by build_model; a Model put together otherwise (or whose
// blocks lack hourglass control's terms) takes the per-particle loops.
inline bool use_blocks(const Model& m) {
  return !m.blocks.empty() && static_cast<int>(m.blocks.size()) * kLanes >= m.particle_count &&
         (m.hourglass_weight.empty() || (m.block_hourglass.size() == m.blocks.size() &&
                                         m.block_hourglass_slots.size() == m.block_slots.size()));
}

// The ranges of a split of the blocked loops over T threads: thread t takes the blocks at
// positions [bounds[t], bounds[t + 1]) of the list (list[k]; all blocks in order, k itself,
// when list is null), the ranges of about equal work (neighbour slots + a per-block cost of
// the law's stress, in slot units), every bound but the last even (the corotational loop's
// pairs stay whole). Depends on the model, the list and T only.
inline void split_blocks(const Model& m, const int* list, int count, int T, int* bounds) {
  const int64_t per_block = with_law(m.law, []<class Law>() { return int64_t{Law::block_cost}; });
  auto cost = [&](int k) {
    const Block& block = m.blocks[list ? list[k] : k];
    return block.slot_end - block.slot_begin + per_block;
  };
  int64_t total = 0;
  for (int k = 0; k < count; ++k) total += cost(k);
  bounds[0] = 0;
  int k = 0;
  int64_t done = 0;
  for (int t = 1; t < T; ++t) {
    const int64_t target = total * t / T;
    while (k + 2 <= count && done + cost(k) + cost(k + 1) <= target) {
      done += cost(k) + cost(k + 1);
      k += 2;
    }
    bounds[t] = k;
  }
  bounds[T] = count;
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

// Runs loop(k_begin, k_end, out) -- a blocked loop on Columns that adds the forces of the
// blocks at positions [k_begin, k_end) of the list (list[k], or all blocks when list is null:
// block k) into out (3 x n) -- on the pool's threads over split_blocks' ranges,
// thread 0 into f, thread t > 0 into its own zeroed buffer of the scratch; then adds the
// buffers into f in the order t = 1, 2, ..., each thread over its share of the coordinates.
template <class Loop>
void scatter_in_parallel(const Model& m, double* f, WorkerThreads& threads, const Loop& loop, const int* list = nullptr,
                         int count = -1) {
  const int T = threads.count(), n = m.particle_count;
  const size_t stride = kRow * static_cast<size_t>(n);  // the scratch's buffers (3 n used)
  double* partial = threads.row_buffers(T - 1, n);
  int bounds[kMaxThreads + 1];
  split_blocks(m, list, list ? count : static_cast<int>(m.blocks.size()), T, bounds);
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

// The tangent's linearisation point of particles [i_begin, i_end): F_i and the law's factor.
template <class Law>
void linearize_particles(const Model& m, const Points& x, int i_begin, int i_end, std::vector<double>& tangent_F,
                         std::vector<double>& tangent_law_factor) {
  for (int i = i_begin; i < i_end; ++i) {
    Mat3 F = gradient_at(m, x.data(), i);
    fence_in_memory(F);  // the law reads F from memory, as before the refactor: keeps the old rounding
    Mat3 P, S;
    piola_stress<Law>(m, F, m.particle_lambda[i], m.particle_mu[i], P, &S);  // S, or R (corotational), or F^-T (neo-Hookean)
    Eigen::Map<Mat3> F_out(&tangent_F[9 * static_cast<size_t>(i)]), law_factor_out(&tangent_law_factor[9 * static_cast<size_t>(i)]);
    F_out = F;
    law_factor_out = S;
  }
}

}  // namespace palpate::mls
