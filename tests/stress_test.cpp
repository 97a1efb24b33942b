// The stress for display (core/stress.h): per-particle Cauchy stress and von Mises of the
// MLS solid for every law, and the hex FEM's element stresses averaged to its nodes, against
// the analytic stress of homogeneous deformations. Independent truths: the uniaxial stress
// state of each law (the lateral stretch that makes the lateral stress vanish, from the law's
// own formula, docs/physics.md (A-4)-(A-5), (1.6), (1.8), (1.14)), where von Mises is |sigma_xx|;
// any pressure (F = s I), where it is zero; a rotated body, which rotates the stress of an
// objective law and leaves von Mises unchanged.
#include <cmath>
#include <string>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/model.h"
#include "core/stress.h"
#include "test_util.h"

namespace palpate {
namespace {

constexpr double kYoung = 1000.0, kPoisson = 0.3;

std::string mls_scene(const std::string& law, const std::string& material_extra = "") {
  return R"({"body": {"box": {"min": [0,0,0], "max": [1,1,1]}, "distribution": {"type": "grid", "per_edge": 6}},
            "fixed": [], "mls": {"neighbors": 16, "support_factor": 1.5},
            "material": {"young_modulus": 1000, "poisson_ratio": 0.3, "law": ")" +
         law + "\"" + material_extra + "}}";
}

std::string hex_scene(const std::string& formulation) {
  return R"({"model": "hex_fem", "body": {"box": {"min": [0,0,0], "max": [1,1,2]}, "distribution": {"type": "grid", "per_edge": 4}},
            "fixed": [], "material": {"young_modulus": 1000, "poisson_ratio": 0.3},
            "hex_fem": {"formulation": ")" +
         formulation + R"("}})";
}

// The uniaxial stress state of a law at axial stretch s: lateral stretch t (sigma_yy =
// sigma_zz = 0) and the axial Cauchy stress sigma_xx, Pa (the small-strain stress for the
// linear law and the linear/corotational bricks).
struct Uniaxial {
  double t = 1, sigma_xx = 0;
};

Uniaxial uniaxial(const std::string& law, double s) {
  const double E = kYoung, nu = kPoisson;
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
  Uniaxial u;
  if (law == "linear") {  // (1.8): eps_yy = -nu eps_xx, sigma_xx = E eps_xx
    u.t = 1 - nu * (s - 1);
    u.sigma_xx = E * (s - 1);
  } else if (law == "corotational") {  // (1.6) on a pure stretch (R = I): the linear law of F - I, pushed forward
    u.t = 1 - nu * (s - 1);
    u.sigma_xx = E * (s - 1) * s / (s * u.t * u.t);  // J^-1 P_xx F_xx
  } else if (law == "stvk") {  // (A-4), (A-5): S_yy = 0 gives E_yy = -nu E_xx and S_xx = E E_xx
    const double Exx = 0.5 * (s * s - 1);
    u.t = std::sqrt(1 - 2 * nu * Exx);
    u.sigma_xx = s * s * E * Exx / (s * u.t * u.t);  // J^-1 F S F^T
  } else if (law == "neo_hookean") {
    // (1.14): P_yy = mu (t - 1/t) + lambda ln(s t^2) / t = 0, solved by bisection (it grows with t).
    auto lateral = [&](double t) { return mu * (t - 1 / t) + lambda * std::log(s * t * t) / t; };
    double lo = 0.2, hi = 2.0;
    for (int it = 0; it < 200; ++it) {
      const double mid = 0.5 * (lo + hi);
      (lateral(mid) > 0 ? hi : lo) = mid;
    }
    u.t = 0.5 * (lo + hi);
    const double J = s * u.t * u.t;
    const double Pxx = mu * (s - 1 / s) + lambda * std::log(J) / s;
    u.sigma_xx = Pxx * s / J;
  }
  return u;
}

// x = F X for every particle, the stresses at x.
std::vector<Mat3> stresses_at(const Model& m, const Mat3& F) {
  Points x(3, m.particle_count);
  for (int i = 0; i < m.particle_count; ++i) x.col(i) = F * m.rest_position.col(i) + Vec3(0.2, -0.1, 0.3);
  std::vector<Mat3> sigma;
  cauchy_stress(m, x, sigma);
  EXPECT_EQ(sigma.size(), static_cast<size_t>(m.particle_count));
  std::vector<double> vm;
  von_mises_stress(m, x, vm);
  EXPECT_EQ(vm.size(), sigma.size());
  for (size_t i = 0; i < vm.size(); ++i) EXPECT_DOUBLE_EQ(vm[i], von_mises(sigma[i]));
  return sigma;
}

void expect_uniaxial_and_hydrostatic(const Model& m, const std::string& law, bool objective) {
  for (double s : {0.8, 0.97, 1.05, 1.3}) {
    SCOPED_TRACE("axial stretch " + std::to_string(s));
    const Uniaxial u = uniaxial(law, s);
    const Mat3 F = Vec3(s, u.t, u.t).asDiagonal();
    const double tol = 1e-9 * kYoung;
    const std::vector<Mat3> sigma = stresses_at(m, F);
    for (int i = 0; i < m.particle_count; ++i) {
      EXPECT_NEAR(sigma[i](0, 0), u.sigma_xx, tol) << "particle " << i;
      EXPECT_NEAR(sigma[i](1, 1), 0.0, tol) << "particle " << i;
      EXPECT_NEAR(sigma[i](2, 2), 0.0, tol) << "particle " << i;
      EXPECT_NEAR(sigma[i](0, 1), 0.0, tol) << "particle " << i;
      EXPECT_NEAR(von_mises(sigma[i]), std::abs(u.sigma_xx), tol) << "particle " << i;
    }
    if (objective) {  // the body turned: sigma -> Q sigma Q^T, von Mises unchanged
      const Mat3 Q = Eigen::AngleAxisd(0.9, Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
      const std::vector<Mat3> turned = stresses_at(m, Q * F);
      for (int i = 0; i < m.particle_count; ++i) {
        EXPECT_LT((turned[i] - Q * sigma[i] * Q.transpose()).norm(), 1e-8 * kYoung) << "particle " << i;
        EXPECT_NEAR(von_mises(turned[i]), std::abs(u.sigma_xx), 1e-8 * kYoung) << "particle " << i;
      }
    }
  }
  for (double s : {0.9, 1.1}) {  // a pressure: no deviatoric stress
    const std::vector<Mat3> sigma = stresses_at(m, s * Mat3::Identity());
    for (int i = 0; i < m.particle_count; ++i) {
      EXPECT_NEAR(von_mises(sigma[i]), 0.0, 1e-9 * kYoung) << "particle " << i;
      EXPECT_GT(std::abs(sigma[i].trace()), 1.0) << "particle " << i << ": a pressure, not nothing";
    }
  }
}

TEST(VonMises, UniaxialShearAndPressure) {
  Mat3 s = Mat3::Zero();
  s(0, 0) = -7.0;
  EXPECT_DOUBLE_EQ(von_mises(s), 7.0);
  s.setZero();
  s(0, 1) = s(1, 0) = 2.0;  // pure shear tau: sqrt(3) tau
  EXPECT_NEAR(von_mises(s), std::sqrt(3.0) * 2.0, 1e-12);
  EXPECT_NEAR(von_mises(-5.0 * Mat3::Identity()), 0.0, 1e-12);
  s = Vec3(3.0, 1.0, -2.0).asDiagonal();  // sqrt(1/2 (4 + 9 + 25))
  EXPECT_NEAR(von_mises(s), std::sqrt(19.0), 1e-12);
}

TEST(MlsStress, EveryLawAgainstHomogeneousDeformations) {
  for (const std::string law : {"stvk", "corotational", "linear", "neo_hookean"}) {
    SCOPED_TRACE("law " + law);
    const Model m = test::model_from_json(mls_scene(law));
    ASSERT_EQ(m.regularized_count, 0);  // F_i (A-9) is exact for x = F X at every particle
    expect_uniaxial_and_hydrostatic(m, law, law != "linear");
  }
}

TEST(MlsStress, TheVolumeTermIsAPressure) {
  // (A-12) adds k_v (J - 1) I to sigma: von Mises as without it.
  const Model plain = test::model_from_json(mls_scene("corotational"));
  const Model with = test::model_from_json(mls_scene("corotational", R"(, "volume_stiffness": 700)"));
  const Uniaxial u = uniaxial("corotational", 1.1);
  const Mat3 F = Vec3(1.1, u.t, u.t).asDiagonal();
  const double J = F.determinant();
  const std::vector<Mat3> a = stresses_at(plain, F), b = stresses_at(with, F);
  for (int i = 0; i < plain.particle_count; ++i) {
    EXPECT_LT((b[i] - a[i] - 700.0 * (J - 1) * Mat3::Identity()).norm(), 1e-9 * kYoung);
    EXPECT_NEAR(von_mises(b[i]), von_mises(a[i]), 1e-9 * kYoung);
  }
}

TEST(MlsStress, EachParticleTakesItsOwnLameParameters) {
  // A stiffer inclusion (1.16): a particle inside it carries 5x the stress of the matrix.
  const Model m = test::model_from_json(mls_scene(
      "linear", R"(, "inclusions": [{"sphere": {"center": [0.5, 0.5, 0.5], "radius": 0.3}, "young_modulus": 5000, "poisson_ratio": 0.3}])"));
  const Mat3 F = Vec3(1.01, 1 - 0.003, 1 - 0.003).asDiagonal();
  const std::vector<Mat3> sigma = stresses_at(m, F);
  int inside = 0, outside = 0;
  for (int i = 0; i < m.particle_count; ++i) {
    const double lambda = m.particle_lambda[i], mu = m.particle_mu[i];
    const double e1 = 0.01, e2 = -0.003;
    EXPECT_NEAR(sigma[i](0, 0), (lambda + 2 * mu) * e1 + 2 * lambda * e2, 1e-9) << "particle " << i;
    if (mu > 1.01 * m.lame_mu) ++inside;
    else ++outside;
  }
  EXPECT_GT(inside, 0);
  EXPECT_GT(outside, 0);
}

TEST(HexStress, EveryFormulationAgainstHomogeneousDeformations) {
  // The bricks' element stresses at their centres, averaged to the nodes: linear and
  // corotational are the small-strain law (1.8) (corotational in the element's frame),
  // neo-Hookean the Cauchy stress of (1.14).
  for (const auto& [formulation, law] : {std::pair<std::string, std::string>{"linear", "linear"},
                                         {"corotational", "linear"},
                                         {"neo_hookean", "neo_hookean"}}) {
    SCOPED_TRACE("formulation " + formulation);
    const Model m = test::model_from_json(hex_scene(formulation));
    ASSERT_EQ(m.solid, SolidKind::hex_fem);
    expect_uniaxial_and_hydrostatic(m, law, formulation != "linear");
  }
}

TEST(HexStress, ABentBlockAveragesTheElementsAroundANode) {
  // Not homogeneous: a node's stress is the volume-weighted mean of its elements' (a corner
  // node has one element, an interior node eight), so it is bounded by them and not zero.
  const Model m = test::model_from_json(hex_scene("linear"));
  Points x = m.rest_position;
  for (int i = 0; i < m.particle_count; ++i) x(0, i) += 0.01 * x(2, i) * x(2, i);  // bending u_x = 0.01 z^2
  std::vector<double> vm;
  von_mises_stress(m, x, vm);
  double lowest = 1e300, highest = 0;
  for (double v : vm) {
    lowest = std::min(lowest, v);
    highest = std::max(highest, v);
  }
  // Shear strain eps_xz = 0.01 z, von Mises sqrt(3) mu 2 eps_xz = sqrt(3) 2 mu 0.01 z, z in [0, 2].
  const double mu = kYoung / (2 * (1 + kPoisson));
  EXPECT_GT(lowest, 0.0);
  EXPECT_LT(highest, std::sqrt(3.0) * 2 * mu * 0.01 * 2.0 * (1 + 1e-9));
  EXPECT_GT(highest, 0.5 * std::sqrt(3.0) * 2 * mu * 0.01 * 2.0);
}

}  // namespace
}  // namespace palpate
