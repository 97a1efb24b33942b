#pragma once
// Hertz theory for a rigid sphere on an elastic half-space (docs/physics.md §3) and
// the finite bonded-layer correction of Dimitriadis et al. (2002).
namespace palpate::hertz {

// E* = E / (1 - nu^2) for a rigid indenter, Pa.
double effective_modulus(double young_modulus, double poisson_ratio);
// F = 4/3 E* sqrt(R) d^(3/2), N.
double force(double depth, double radius, double effective_modulus);
// d = (3 F / (4 E* sqrt(R)))^(2/3), m.
double depth(double force, double radius, double effective_modulus);
// a = sqrt(R d), m.
double contact_radius(double depth, double radius);

// F / F_Hertz for a layer of thickness L bonded to a rigid base, chi = a / L:
// 1 - (2 a0/pi) chi + (4 a0^2/pi^2) chi^2 - (8/pi^3)(a0^3 + 4 pi^2 b0/15) chi^3
//   + (16 a0/pi^4)(a0^3 + 3 pi^2 b0/5) chi^4,
// a0 = -(1.2876 - 1.4678 nu + 1.3442 nu^2)/(1 - nu), b0 = (0.6387 - 1.0277 nu + 1.5164 nu^2)/(1 - nu).
double finite_layer_factor(double chi, double poisson_ratio);
// Force at depth d on a layer of thickness L (Hertz times the factor), N.
double force_finite_layer(double depth, double radius, double young_modulus, double poisson_ratio,
                          double thickness);
// Its inverse by bisection on the monotone branch (d with a/L <= 0.5), m.
double depth_finite_layer(double force, double radius, double young_modulus, double poisson_ratio,
                          double thickness);

}  // namespace palpate::hertz
