// Hexahedral FEM reference: element stiffness properties, patch test,
// corotational objectivity, energy and tangent consistency.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "core/hex_fem.h"
#include "core/node_cloud.h"

namespace palpate {
namespace {

const double kLambda = 5769.23, kMu = 3846.15;  // E = 10 kPa, nu = 0.3

constexpr HexVolumetricIntegration kIntegrations[] = {HexVolumetricIntegration::full,
                                                      HexVolumetricIntegration::reduced};

TEST(HexElement, SymmetricPositiveSemiDefiniteWithSixRigidModes) {
  // Both volumetric integrations: the reduced one adds no zero-energy (hourglass) mode,
  // because the mu part stays fully integrated.
  for (const HexVolumetricIntegration integration : kIntegrations)
  for (const Vec3& size : {Vec3(1, 1, 1), Vec3(0.1, 0.25, 0.05)}) {
    const ElementMatrix K = hex_element_stiffness(size, kLambda, kMu, integration);
    EXPECT_LT((K - K.transpose()).norm(), 1e-12 * K.norm());
    Eigen::SelfAdjointEigenSolver<ElementMatrix> eig(K);
    const auto ev = eig.eigenvalues();
    const double largest = ev.maxCoeff();
    int zero = 0;
    for (int k = 0; k < 24; ++k) {
      EXPECT_GT(ev[k], -1e-10 * largest);
      if (std::abs(ev[k]) < 1e-10 * largest) ++zero;
    }
    EXPECT_EQ(zero, 6) << "size " << size.transpose();
  }
}

TEST(HexElement, UniaxialStrainEnergyIsExact) {
  // u = eps x on a brick: energy 1/2 (lambda + 2 mu) eps^2 V, independent of the element.
  const Vec3 size(0.3, 0.2, 0.5);
  for (const HexVolumetricIntegration integration : kIntegrations) {
  const ElementMatrix K = hex_element_stiffness(size, kLambda, kMu, integration);
  const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  const double eps = 0.01, gamma = 0.02;
  Eigen::Matrix<double, 24, 1> u_axial, u_shear;
  for (int a = 0; a < 8; ++a) {
    const Vec3 X(corner[a][0] * size[0], corner[a][1] * size[1], corner[a][2] * size[2]);
    u_axial.segment<3>(3 * a) = Vec3(eps * X[0], 0, 0);
    u_shear.segment<3>(3 * a) = Vec3(gamma * X[1], 0, 0);  // simple shear: gamma_xy = gamma
  }
  const double V = size.prod();
  EXPECT_NEAR(0.5 * u_axial.dot(K * u_axial), 0.5 * (kLambda + 2 * kMu) * eps * eps * V, 1e-12 * kMu * V);
  EXPECT_NEAR(0.5 * u_shear.dot(K * u_shear), 0.5 * kMu * gamma * gamma * V, 1e-12 * kMu * V);
  }
}

// A 4 x 4 x 4 node lattice (27 elements) on a skewed box.
struct SmallMesh {
  NodeCloud cloud;
  HexMesh mesh;
  explicit SmallMesh(HexFormulation formulation,
                     HexVolumetricIntegration integration = HexVolumetricIntegration::full,
                     double lambda = kLambda) {
    BoxSpec box;
    box.min = Vec3(0, 0, 0);
    box.max = Vec3(1.0, 0.6, 0.8);
    cloud = grid_nodes(box, Eigen::Vector3i(4, 4, 4));
    mesh = hex_mesh(cloud.positions, cloud.lattice_size, lambda, kMu, formulation, integration);
  }
  int n() const { return static_cast<int>(cloud.positions.cols()); }
};

Eigen::MatrixXd assembled_stiffness(const SmallMesh& s) {
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(3 * s.n(), 3 * s.n());
  for (int e = 0; e < s.mesh.element_count; ++e) {
    const ElementMatrix& Ke = s.mesh.element_stiffness[s.mesh.element_type[e]];
    for (int a = 0; a < 8; ++a)
      for (int b = 0; b < 8; ++b)
        K.block<3, 3>(3 * s.mesh.element_nodes[e][a], 3 * s.mesh.element_nodes[e][b]) += Ke.block<3, 3>(3 * a, 3 * b);
  }
  return K;
}

TEST(HexFem, PatchTestReproducesALinearFieldInside) {
  for (const HexVolumetricIntegration integration : kIntegrations) {
  const SmallMesh s(HexFormulation::linear, integration);
  const Eigen::MatrixXd K = assembled_stiffness(s);
  Mat3 G;
  G << 0.01, 0.02, -0.01, 0.005, -0.02, 0.015, 0.01, 0.0, 0.03;
  const Vec3 t(0.1, -0.05, 0.2);
  // Interior nodes unknown, boundary nodes prescribed: K_ii u_i = -K_ib u_b.
  std::vector<int> interior, boundary;
  for (int i = 0; i < s.n(); ++i) {
    const Vec3 X = s.cloud.positions.col(i);
    const bool on_boundary = (X.array() < 1e-12).any() || (X - Vec3(1.0, 0.6, 0.8)).cwiseAbs().minCoeff() < 1e-12;
    (on_boundary ? boundary : interior).push_back(i);
  }
  ASSERT_EQ(interior.size(), 8u);
  const int ni = static_cast<int>(interior.size()), nb = static_cast<int>(boundary.size());
  Eigen::MatrixXd Kii(3 * ni, 3 * ni), Kib(3 * ni, 3 * nb);
  Eigen::VectorXd ub(3 * nb), exact(3 * ni);
  for (int r = 0; r < ni; ++r) {
    for (int c = 0; c < ni; ++c) Kii.block<3, 3>(3 * r, 3 * c) = K.block<3, 3>(3 * interior[r], 3 * interior[c]);
    for (int c = 0; c < nb; ++c) Kib.block<3, 3>(3 * r, 3 * c) = K.block<3, 3>(3 * interior[r], 3 * boundary[c]);
    exact.segment<3>(3 * r) = G * s.cloud.positions.col(interior[r]) + t;
  }
  for (int c = 0; c < nb; ++c) ub.segment<3>(3 * c) = G * s.cloud.positions.col(boundary[c]) + t;
  const Eigen::VectorXd ui = Kii.ldlt().solve(-Kib * ub);
  EXPECT_LT((ui - exact).cwiseAbs().maxCoeff(), 1e-12);
  }
}

// Volumetric locking (Hughes 1980, constraint counting): with the bottom fixed, the
// 27 bricks of SmallMesh have 48 free nodal dofs. Full integration imposes 8
// incompressibility constraints per brick (216 > 48), so as nu -> 1/2 the mesh locks:
// its compliance under a load that an incompressible continuum accommodates by an
// isochoric flow (a point load on the free top) goes to zero. The reduced integration
// imposes one per brick (27 < 48) and keeps a finite compliance.
double top_load_compliance(HexVolumetricIntegration integration, double nu) {
  const double E = 2 * kMu * (1 + nu);
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
  const SmallMesh s(HexFormulation::linear, integration, lambda);
  const Eigen::MatrixXd K = assembled_stiffness(s);
  std::vector<int> free_dof;
  for (int i = 0; i < s.n(); ++i)
    if (s.cloud.positions(2, i) > 1e-12)
      for (int c = 0; c < 3; ++c) free_dof.push_back(3 * i + c);
  const int nf = static_cast<int>(free_dof.size());
  Eigen::MatrixXd Kff(nf, nf);
  for (int r = 0; r < nf; ++r)
    for (int c = 0; c < nf; ++c) Kff(r, c) = K(free_dof[r], free_dof[c]);
  // A downward unit force on the top node nearest the centre of the top face.
  Eigen::VectorXd load = Eigen::VectorXd::Zero(nf);
  int loaded = -1;
  double nearest = 1e9;
  for (int i = 0; i < s.n(); ++i) {
    const double dist = (s.cloud.positions.col(i) - Vec3(0.5, 0.3, 0.8)).norm();
    if (dist < nearest) nearest = dist, loaded = i;
  }
  for (int r = 0; r < nf; ++r)
    if (free_dof[r] == 3 * loaded + 2) load[r] = -1.0;
  const Eigen::VectorXd u = Kff.ldlt().solve(load);
  return load.dot(u);
}

TEST(HexFem, ReducedVolumetricIntegrationDoesNotLock) {
  const double full_ratio = top_load_compliance(HexVolumetricIntegration::full, 0.49999) /
                            top_load_compliance(HexVolumetricIntegration::full, 0.3);
  const double reduced_ratio = top_load_compliance(HexVolumetricIntegration::reduced, 0.49999) /
                               top_load_compliance(HexVolumetricIntegration::reduced, 0.3);
  RecordProperty("full_ratio", std::to_string(full_ratio));
  RecordProperty("reduced_ratio", std::to_string(reduced_ratio));
  EXPECT_LT(full_ratio, 0.05) << "full integration should lock";
  EXPECT_GT(reduced_ratio, 0.3) << "reduced integration locks";
}

TEST(HexFem, CorotationalForceVanishesUnderRigidRotation) {
  const SmallMesh co(HexFormulation::corotational), lin(HexFormulation::linear);
  const Mat3 Q = Eigen::AngleAxisd(0.8, Vec3(1, -2, 0.5).normalized()).toRotationMatrix();
  Points x(3, co.n());
  for (int i = 0; i < co.n(); ++i) x.col(i) = Q * co.cloud.positions.col(i) + Vec3(0.3, 0.1, -0.4);
  Points f(3, co.n());
  hex_internal_forces(co.mesh, co.cloud.positions, x, f);
  EXPECT_LT(f.cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(hex_strain_energy(co.mesh, co.cloud.positions, x), 0.0, 1e-10);  // 1 % strain stores ~0.3 J
  // The linear formulation is not objective: the same motion strains it.
  hex_internal_forces(lin.mesh, lin.cloud.positions, x, f);
  EXPECT_GT(f.cwiseAbs().maxCoeff(), 100.0);
}

TEST(HexFem, LinearForcesAreMinusKuAndTheEnergyGradient) {
  const SmallMesh s(HexFormulation::linear);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-0.01, 0.01);
  Points x = s.cloud.positions;
  for (int i = 0; i < s.n(); ++i) x.col(i) += Vec3(u(rng), u(rng), u(rng));
  Points f(3, s.n());
  hex_internal_forces(s.mesh, s.cloud.positions, x, f);
  const Eigen::MatrixXd K = assembled_stiffness(s);
  const Points disp = x - s.cloud.positions;
  const Eigen::VectorXd Ku = K * Eigen::Map<const Eigen::VectorXd>(disp.data(), 3 * s.n());
  EXPECT_LT((Eigen::Map<const Eigen::VectorXd>(f.data(), 3 * s.n()) + Ku).norm(), 1e-10 * Ku.norm());
  // Sum of forces is zero (translation invariance).
  EXPECT_LT(f.rowwise().sum().norm(), 1e-10 * f.norm());
  // Energy gradient by central differences.
  const double h = 1e-7;
  for (int i = 0; i < s.n(); i += 5)
    for (int c = 0; c < 3; ++c) {
      Points xp = x, xm = x;
      xp(c, i) += h;
      xm(c, i) -= h;
      const double dU = (hex_strain_energy(s.mesh, s.cloud.positions, xp) - hex_strain_energy(s.mesh, s.cloud.positions, xm)) / (2 * h);
      EXPECT_NEAR(-dU, f(c, i), 1e-6 * f.cwiseAbs().maxCoeff());
    }
}

TEST(HexFem, CorotationalTangentMatchesForcesForSmallIncrements) {
  // About a rigidly rotated configuration the corotational tangent R K R^T is exact.
  const SmallMesh s(HexFormulation::corotational);
  const Mat3 Q = Eigen::AngleAxisd(0.5, Vec3(0.2, 1, 0.3).normalized()).toRotationMatrix();
  Points x(3, s.n());
  for (int i = 0; i < s.n(); ++i) x.col(i) = Q * s.cloud.positions.col(i);
  std::mt19937 rng(8);
  std::uniform_real_distribution<double> u(-1, 1);
  Points dx(3, s.n());
  for (int i = 0; i < s.n(); ++i) dx.col(i) = Vec3(u(rng), u(rng), u(rng));
  std::vector<double> R;
  hex_linearize(s.mesh, x, R);
  Points df(3, s.n()), fp(3, s.n()), fm(3, s.n());
  hex_force_differential(s.mesh, R, dx, df);
  const double h = 1e-7;
  hex_internal_forces(s.mesh, s.cloud.positions, x + h * dx, fp);
  hex_internal_forces(s.mesh, s.cloud.positions, x - h * dx, fm);
  // At a stress-free state the rotation's own variation contributes nothing.
  EXPECT_LT(((fp - fm) / (2 * h) - df).norm(), 1e-5 * df.norm());
}

}  // namespace
}  // namespace palpate
