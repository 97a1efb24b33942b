// The neo-Hookean hex FEM (core/hex_neo_hookean.h, docs/physics.md (5.4)-(5.6)):
// homogeneous deformations against the analytic neo-Hookean stress, the small-strain
// limit against the linear brick (5.1), forces against finite differences of the energy
// and the tangent against finite differences of the forces.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <random>

#include "core/hex_fem.h"
#include "core/node_cloud.h"
#include "core/scene.h"

namespace palpate {
namespace {

const double kLambda = 5769.23, kMu = 3846.15;  // E = 10 kPa, nu = 0.3

// 3 x 3 x 3 nodes (8 bricks) on the box [0, 0.4] x [0, 0.3] x [0, 0.5] (unequal sides).
struct Block {
  BoxSpec box{Vec3(0, 0, 0), Vec3(0.4, 0.3, 0.5)};
  NodeCloud cloud = grid_nodes(box, Eigen::Vector3i(3, 3, 3));
  HexMesh mesh = hex_mesh(cloud.positions, cloud.lattice_size, kLambda, kMu, HexFormulation::neo_hookean);
  HexMesh linear = hex_mesh(cloud.positions, cloud.lattice_size, kLambda, kMu, HexFormulation::linear);
  const Points& X() const { return cloud.positions; }
  int n() const { return static_cast<int>(cloud.positions.cols()); }
  double volume() const { return (box.max - box.min).prod(); }
};

// The analytic neo-Hookean law for a homogeneous F, written out from (1.13), (1.14).
double psi_exact(const Mat3& F) {
  const double J = F.determinant();
  return 0.5 * kMu * ((F.transpose() * F).trace() - 3) - kMu * std::log(J) + 0.5 * kLambda * std::log(J) * std::log(J);
}
Mat3 piola_exact(const Mat3& F) {
  const Mat3 G = F.inverse().transpose();
  return kMu * (F - G) + kLambda * std::log(F.determinant()) * G;
}

Mat3 uniaxial(double s) { return Vec3(s, 1, 1).asDiagonal(); }
Mat3 simple_shear(double g) {
  Mat3 F = Mat3::Identity();
  F(0, 1) = g;
  return F;
}

TEST(HexNeoHookean, HomogeneousDeformationsGiveTheAnalyticEnergyAndStress) {
  const Block b;
  const std::vector<Mat3> cases = {uniaxial(1.3), uniaxial(0.6), simple_shear(0.5),
                                   Mat3(0.8 * Mat3::Identity()), Mat3(1.1 * Mat3::Identity())};
  for (const Mat3& F0 : cases) {
    const Points x = F0 * b.X();
    EXPECT_NEAR(hex_strain_energy(b.mesh, b.X(), x), b.volume() * psi_exact(F0),
                1e-12 * b.volume() * (kLambda + kMu));
    Points f(3, b.n());
    hex_internal_forces(b.mesh, b.X(), x, f);
    // Homogeneous stress is divergence free: the centre node feels nothing; a corner node
    // carries -P times its share of the three faces it touches, f = -P sum (A_face / 4) n.
    const int centre = 1 + 3 * (1 + 3 * 1), corner = 2 + 3 * (2 + 3 * 2);  // (0.2,0.15,0.25), (0.4,0.3,0.5)
    const double scale = (kLambda + kMu) * 0.04;
    EXPECT_LT(f.col(centre).norm(), 1e-12 * scale);
    const Vec3 h(0.2, 0.15, 0.25);
    const Vec3 share(h[1] * h[2] / 4, h[0] * h[2] / 4, h[0] * h[1] / 4);  // face areas / 4 times n = e_x, e_y, e_z
    const Vec3 expected = -piola_exact(F0) * share;
    EXPECT_LT((f.col(corner) - expected).norm(), 1e-10 * expected.norm()) << F0;
    // Net force zero (equilibrium of a free body).
    EXPECT_LT(f.rowwise().sum().norm(), 1e-10 * scale);
  }
}

TEST(HexNeoHookean, SmallStrainIsTheLinearBrick) {
  const Block b;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> U(-1, 1);
  Points u(3, b.n());
  for (int i = 0; i < b.n(); ++i) u.col(i) = Vec3(U(rng), U(rng), U(rng));
  for (const double eps : {1e-4, 1e-5}) {
    Points f_neo(3, b.n()), f_lin(3, b.n());
    hex_internal_forces(b.mesh, b.X(), b.X() + eps * u, f_neo);
    hex_internal_forces(b.linear, b.X(), b.X() + eps * u, f_lin);
    // The difference is second order in the strain.
    EXPECT_LT((f_neo - f_lin).norm(), 10 * eps * f_lin.norm()) << eps;
  }
}

TEST(HexNeoHookean, ForcesAreMinusTheEnergyGradientAndTheTangentIsExact) {
  const Block b;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  Points x = b.X();
  for (int i = 0; i < b.n(); ++i) x.col(i) += 0.04 * Vec3(U(rng), U(rng), U(rng));  // ~20 % strains
  Points f(3, b.n());
  hex_internal_forces(b.mesh, b.X(), x, f);
  const double h = 1e-6;
  for (int i = 0; i < b.n(); i += 5)
    for (int c = 0; c < 3; ++c) {
      Points xp = x, xm = x;
      xp(c, i) += h;
      xm(c, i) -= h;
      const double fd = -(hex_strain_energy(b.mesh, b.X(), xp) - hex_strain_energy(b.mesh, b.X(), xm)) / (2 * h);
      EXPECT_NEAR(f(c, i), fd, 1e-6 * f.norm()) << i << " " << c;
    }
  Points dx(3, b.n());
  for (int i = 0; i < b.n(); ++i) dx.col(i) = Vec3(U(rng), U(rng), U(rng));
  std::vector<double> cache;
  hex_linearize(b.mesh, x, cache);
  Points df(3, b.n()), fp(3, b.n()), fm(3, b.n());
  hex_force_differential(b.mesh, cache, dx, df);
  hex_internal_forces(b.mesh, b.X(), x + h * dx, fp);
  hex_internal_forces(b.mesh, b.X(), x - h * dx, fm);
  const Points fd = (fp - fm) / (2 * h);
  EXPECT_LT((df - fd).norm(), 1e-6 * fd.norm());
}

TEST(HexNeoHookean, ItsSceneFormulationIsFullyIntegratedOnly) {
  const std::string json = R"({"model": "hex_fem", "hex_fem": {"formulation": "neo_hookean"}})";
  EXPECT_EQ(parse_scene(json, "t.json", ".").hex_fem.formulation, HexFormulation::neo_hookean);
  try {
    parse_scene(json, "t.json", ".", {{"hex_fem.volumetric_integration", "reduced"}});
    FAIL() << "reduced integration accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/hex_fem/volumetric_integration") << e.what();
  }
}

}  // namespace
}  // namespace palpate
