#pragma once
// The MLS weight kernel: w(q) = (1 - q^2)^3 for q = r/h <= 1, else 0.
// Normalised, it is the poly6 kernel W(r, h) = 315 / (64 pi h^3) (1 - q^2)^3,
// whose integral over the ball of radius h is 1. The constant cancels in the
// MLS gradient (d_j) but not in densities and volumes.
#include <numbers>

namespace palpate {

// Unnormalised weight (1 - q^2)^3 from the squared distance and squared radius.
inline double kernel_weight(double dist2, double support_radius2) {
  if (dist2 >= support_radius2) return 0.0;
  const double s = 1.0 - dist2 / support_radius2;
  return s * s * s;
}

// Normalised poly6 kernel W(r, h), 1/m^3.
inline double kernel_density(double dist2, double support_radius) {
  const double h = support_radius;
  return 315.0 / (64.0 * std::numbers::pi * h * h * h) * kernel_weight(dist2, h * h);
}

}  // namespace palpate
