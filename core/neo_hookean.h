#pragma once
// The compressible neo-Hookean law, pointwise (docs/physics.md (1.13)-(1.15)): shared by
// the MLS solid (core/laws/neo_hookean.h) and the neo-Hookean hex FEM
// (core/hex_neo_hookean.cpp, one Gauss point at a time).
#include <Eigen/Geometry>
#include <cmath>

#include "core/types.h"

namespace palpate::hyperelastic {

// cof F = det(F) F^-T, column by column (F's other two columns crossed).
inline Mat3 cofactor(const Mat3& F) {
  Mat3 C;
  C.col(0) = F.col(1).cross(F.col(2));
  C.col(1) = F.col(2).cross(F.col(0));
  C.col(2) = F.col(0).cross(F.col(1));
  return C;
}

// (1.13), (1.14): psi = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2, I1 = tr(F^T F),
// J = det F; P = mu (F - F^-T) + lambda ln J F^-T, F^-T = cof F / J. The energy grows
// without bound as J -> 0+ and is +infinity for J <= 0 (inverted or flat); no finite stress
// is right there, and the law exerts none (P = 0 and a zero tangent), so nothing is NaN and
// no energy is released that the health checks never saw put in. inverse_transpose receives
// F^-T for the tangent (0 at J <= 0).
inline double neo_hookean_stress(const Mat3& F, double lambda, double mu, Mat3& P, Mat3& inverse_transpose) {
  const Mat3 C = cofactor(F);
  const double J = F.col(0).dot(C.col(0));
  if (!(J > 0)) {
    inverse_transpose.setZero();
    P.setZero();
    return HUGE_VAL;
  }
  const double log_J = std::log(J);
  inverse_transpose = C / J;
  P = mu * F + (lambda * log_J - mu) * inverse_transpose;
  return 0.5 * mu * (F.squaredNorm() - 3.0) - mu * log_J + 0.5 * lambda * log_J * log_J;
}

// (1.15), G = F^-T: dP = mu dF + (mu - lambda ln J) G dF^T G + lambda (G : dF) G. At J <= 0
// the law exerts no stress and has no tangent.
inline Mat3 neo_hookean_differential(const Mat3& F, const Mat3& G, const Mat3& dF, double lambda, double mu) {
  const double J = F.col(0).dot(cofactor(F).col(0));  // as neo_hookean_stress computes it
  if (!(J > 0)) return Mat3::Zero();
  const double log_J = std::log(J);
  return mu * dF + (mu - lambda * log_J) * (G * dF.transpose() * G) + (lambda * (G.array() * dF.array()).sum()) * G;
}

}  // namespace palpate::hyperelastic
