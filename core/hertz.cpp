#include "core/hertz.h"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace palpate::hertz {

double effective_modulus(double E, double nu) { return E / (1.0 - nu * nu); }

double force(double d, double R, double E_star) {
  return d <= 0 ? 0.0 : 4.0 / 3.0 * E_star * std::sqrt(R) * std::pow(d, 1.5);
}

double depth(double F, double R, double E_star) {
  return F <= 0 ? 0.0 : std::pow(3.0 * F / (4.0 * E_star * std::sqrt(R)), 2.0 / 3.0);
}

double contact_radius(double d, double R) { return d <= 0 ? 0.0 : std::sqrt(R * d); }

double finite_layer_factor(double chi, double nu) {
  constexpr double pi = std::numbers::pi;
  const double a0 = -(1.2876 - 1.4678 * nu + 1.3442 * nu * nu) / (1.0 - nu);
  const double b0 = (0.6387 - 1.0277 * nu + 1.5164 * nu * nu) / (1.0 - nu);
  return 1.0 - 2.0 * a0 / pi * chi + 4.0 * a0 * a0 / (pi * pi) * chi * chi -
         8.0 / (pi * pi * pi) * (a0 * a0 * a0 + 4.0 * pi * pi * b0 / 15.0) * chi * chi * chi +
         16.0 * a0 / (pi * pi * pi * pi) * (a0 * a0 * a0 + 3.0 * pi * pi * b0 / 5.0) * chi * chi * chi * chi;
}

double force_finite_layer(double d, double R, double E, double nu, double L) {
  return force(d, R, effective_modulus(E, nu)) * finite_layer_factor(contact_radius(d, R) / L, nu);
}

double depth_finite_layer(double F, double R, double E, double nu, double L) {
  if (F <= 0) return 0.0;
  // The layer is stiffer than the half-space, so the depth lies below Hertz's.
  double hi = depth(F, R, effective_modulus(E, nu));
  double lo = 0.0;
  const double d_max = 0.25 * L * L / R;  // a / L = 0.5: the series' range of use
  if (hi > d_max) throw std::domain_error("depth_finite_layer: a/L > 0.5, outside the series' range");
  for (int it = 0; it < 200 && hi - lo > 1e-15 * hi; ++it) {
    const double mid = 0.5 * (lo + hi);
    (force_finite_layer(mid, R, E, nu, L) < F ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace palpate::hertz
