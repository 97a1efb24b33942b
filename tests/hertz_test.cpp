// Hertz theory and the finite-layer correction (docs/physics.md §3).
#include <gtest/gtest.h>

#include <cmath>

#include "core/hertz.h"

namespace palpate {
namespace {

TEST(Hertz, ForceDepthAndContactRadius) {
  const double E = 1e4, nu = 0.3, R = 0.5;
  const double Es = hertz::effective_modulus(E, nu);
  EXPECT_NEAR(Es, 1e4 / 0.91, 1e-9);
  // F = 4/3 E* sqrt(R) d^1.5 at d = 0.01 m: 4/3 * 10989.01 * 0.70711 * 0.001 = 10.3605 N.
  EXPECT_NEAR(hertz::force(0.01, R, Es), 10.36050, 1e-4);
  for (double d : {1e-4, 0.01, 0.1, 0.3}) EXPECT_NEAR(hertz::depth(hertz::force(d, R, Es), R, Es), d, 1e-12 * d + 1e-15);
  EXPECT_NEAR(hertz::contact_radius(0.02, R), 0.1, 1e-15);
  EXPECT_EQ(hertz::force(-0.1, R, Es), 0.0);
  EXPECT_EQ(hertz::depth(0.0, R, Es), 0.0);
}

TEST(Hertz, FiniteLayerFactorMatchesDimitriadisFigures) {
  // docs/physics.md §3: about +5 % at a/L = 0.05, +10 % at 0.1, +21 % at 0.2 for nu = 0.3;
  // to first order 1 + 0.88 a/L.
  EXPECT_DOUBLE_EQ(hertz::finite_layer_factor(0.0, 0.3), 1.0);
  EXPECT_NEAR(hertz::finite_layer_factor(0.05, 0.3), 1.05, 0.006);
  EXPECT_NEAR(hertz::finite_layer_factor(0.1, 0.3), 1.10, 0.01);
  EXPECT_NEAR(hertz::finite_layer_factor(0.2, 0.3), 1.21, 0.01);
  const double slope = (hertz::finite_layer_factor(1e-4, 0.3) - 1.0) / 1e-4;
  EXPECT_NEAR(slope, 0.88, 0.01);
  // Stiffer for more nearly incompressible layers.
  EXPECT_GT(hertz::finite_layer_factor(0.1, 0.45), hertz::finite_layer_factor(0.1, 0.3));
}

TEST(Hertz, FiniteLayerDepthInvertsTheForce) {
  const double E = 1e4, nu = 0.3, R = 0.5, L = 2.0;
  for (double F : {10.36, 53.83, 327.6}) {
    const double d = hertz::depth_finite_layer(F, R, E, nu, L);
    EXPECT_NEAR(hertz::force_finite_layer(d, R, E, nu, L), F, 1e-9 * F);
    EXPECT_LT(d, hertz::depth(F, R, hertz::effective_modulus(E, nu)));  // the layer is stiffer
  }
  // In the default scene the correction is +3 ... +11 % in force (docs/physics.md §3).
  const double Es = hertz::effective_modulus(E, nu);
  EXPECT_NEAR(hertz::force_finite_layer(0.01, R, E, nu, L) / hertz::force(0.01, R, Es), 1.03, 0.01);
  EXPECT_NEAR(hertz::force_finite_layer(0.1, R, E, nu, L) / hertz::force(0.1, R, Es), 1.11, 0.015);
  EXPECT_THROW(hertz::depth_finite_layer(1e7, R, E, nu, L), std::domain_error);
}

}  // namespace
}  // namespace palpate
