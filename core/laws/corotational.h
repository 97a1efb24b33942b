#pragma once
// The corotational linear law (the linear isotropic energy of the Biot strain; docs/physics.md
// (1.4)-(1.6), (1.17)): one material law of the MLS solid (core/mls_law.h says what a law
// provides). Its stress needs the rotation of the polar decomposition F = R U: Higham's scaled
// Newton iteration one particle at a time, and on the blocked loop's lanes the polynomial
// iteration (1.17), falling back to the packed Newton iteration, then to one lane at a time.
#include "core/mls_law.h"

#include <Eigen/Geometry>
#include <Eigen/LU>

namespace palpate::mls {

struct Corotational;  // below: its lane formulas fall back to its scalar one

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

// Always inlined, as before the refactor: GCC then fuses its products as it did (bit-identical).
PALPATE_INLINE Mat3 corotational_differential(const CorotationalTangent& t, const Mat3& R, const Mat3& dF,
                                              double lambda, double mu) {
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

// v_i P_i of the corotational law, P = 2 mu (F - R) + lambda (tr(R^T F) - 3) R, on all
// lanes of G blocks together (the volume term added when volume_term).
template <bool volume_term, int G>
PALPATE_INLINE void weighted_corotational_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                                 const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
  Mat3Lanes R[G];
  if (schulz_rotation_lanes<G>(F, R) == 0 && polar_rotation_lanes<G>(F, R) == 0) {
    for (int g = 0; g < G; ++g) weighted_stress_per_lane<Corotational>(m, F[g], v[g], lambda[g], mu[g], vP[g]);
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
    if constexpr (volume_term) add_volume_term_differential<true>(m, F, dF[q], dP);
    PALPATE_UNROLL
    for (int k = 0; k < 9; ++k) vdP[q].m[k] = v * dP.m[k];
  }
}

struct Corotational {
  static constexpr MaterialLaw id = MaterialLaw::corotational;
  static constexpr const char* name = "corotational";
  static constexpr int group = 2;  // two blocks' polar iterations interleave
  static constexpr int block_cost = 12;
  static constexpr bool small_strain = false;
  // After the polar decomposition: tr(R^T F) - 3 (1 mul + 8 fma + 1) = 18, 2 mu v 2,
  // lambda v tr 2, P = 2 mu v (F - R) + lambda v tr R 9 x (sub + mul + fma) = 36: 58.
  static constexpr double flops_per_particle = 58.0;

  // factor: R.
  static double stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3& factor) {
    return corotational_stress(F, lambda, mu, P, factor);
  }
  static Mat3 differential(const Mat3& F, const Mat3& R, const Mat3& dF, double lambda, double mu) {
    return corotational_differential(F, R, dF, lambda, mu);
  }
  template <bool volume_term, int G>
  PALPATE_INLINE static void weighted_stress(const Model& m, const Mat3Lanes (&F)[G], const Lanes (&v)[G],
                                             const Lanes (&lambda)[G], const Lanes (&mu)[G], Mat3Lanes (&vP)[G]) {
    weighted_corotational_stress<volume_term, G>(m, F, v, lambda, mu, vP);
  }
  template <bool volume_term, int K>
  PALPATE_INLINE static void weighted_differentials(const Model& m, const Mat3Lanes& F, const Mat3Lanes& R,
                                                    const Mat3Lanes (&dF)[K], const Lanes v, const Lanes lambda,
                                                    const Lanes mu, Mat3Lanes (&vdP)[K]) {
    weighted_corotational_differentials<volume_term, K>(m, F, R, dF, v, lambda, mu, vdP);
  }
  // The iterations of the blocked loop's rotations at the positions of `gradients` (it fills
  // F for block b and returns its real lanes), over the loop's pairs of blocks, each counted
  // once per real (not padding) lane: the polynomial iterations (1.17) spent (also by pairs
  // that then fall back), the scaled Newton iterations of the pairs that fall back to them,
  // and those of the latter that took the scaling; pairs that fall back to polar_rotation are
  // not counted further. Each iteration (1.17) of schulz_rotation_lanes: A = X^T X 6 x (mul
  // + 2 fma) = 30, its defect |A - I|^2 3 sub + 2 x (mul + 2 fma) + mul + add = 15, A^2 6 x
  // (mul + 2 fma) = 30, M = (15 I - 10 A + 3 A^2) / 8 6 x 2 fma = 24, X M 9 x (mul + 2 fma) =
  // 45: 144 (the first also checks the basin, not counted). Each Newton iteration of
  // polar_rotation_lanes (the fallback): cof R 27, det R 5, 1 / det 1, the update a R + b cof
  // R 9 x (mul + fma) = 27, its squared change 9 x (sub + fma) = 27: 87; a scaled one also
  // |R|^2, |cof R|^2 2 x (1 mul + 8 fma) = 34, g (2 mul, 1 div, 2 sqrt, 3 for the lanes'
  // choice) 8, a 1, g det 1: 131. Data dependent: counted at the positions.
  template <class Gradients>
  static double iteration_flops(const Model& m, const Gradients& gradients) {
    double schulz_iterations = 0, newton_iterations = 0, scaled_iterations = 0;
    const int blocks = static_cast<int>(m.blocks.size());
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
    for (; b + 2 <= blocks; b += 2) {  // the pairs of the blocked force loop
      Mat3Lanes F[2], R[2];
      const int lanes = gradients(b, F[0]) + gradients(b + 1, F[1]);
      count(F, R, lanes);
    }
    for (; b < blocks; ++b) {
      Mat3Lanes F[1], R[1];
      const int lanes = gradients(b, F[0]);
      count(F, R, lanes);
    }
    return 144.0 * schulz_iterations + 87.0 * newton_iterations + 44.0 * scaled_iterations;
  }
};

}  // namespace palpate::mls
