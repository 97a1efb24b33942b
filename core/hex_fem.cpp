#include "core/hex_fem.h"

#include <Eigen/Geometry>
#include <bit>
#include <cmath>
#include <map>
#include <stdexcept>
#include <tuple>

#include "core/hex_neo_hookean.h"
#include "core/material_field.h"

namespace palpate {

namespace {

// Natural coordinates of the 8 nodes in the local order.
constexpr int kCorner[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                               {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

using ElementVector = Eigen::Matrix<double, 24, 1>;

// Gathers the element's node positions minus their rest positions, in the frame R
// (u'_a = R^T x_a - X_a).
inline ElementVector element_displacement(const Points& rest, const Points& x, const std::array<int, 8>& nodes,
                                          const Mat3* R) {
  ElementVector u;
  for (int a = 0; a < 8; ++a) {
    const Vec3 xa = x.col(nodes[a]);
    u.segment<3>(3 * a) = (R ? Vec3(R->transpose() * xa) : xa) - rest.col(nodes[a]);
  }
  return u;
}

}  // namespace

BrickGradients brick_shape_gradients(const Eigen::Vector3d& size, const double xi[3]) {
  BrickGradients G;
  for (int a = 0; a < 8; ++a)
    for (int c = 0; c < 3; ++c) {  // dN_a/dx_c = dN_a/dxi_c * 2 / h_c, N_a = 1/8 prod (1 + xi_o s_o)
      double v = 0.125 * kCorner[a][c];
      for (int o = 0; o < 3; ++o)
        if (o != c) v *= 1.0 + xi[o] * kCorner[a][o];
      G(c, a) = v * 2.0 / size[c];
    }
  return G;
}

ElementMatrix hex_element_stiffness(const Eigen::Vector3d& size, double lambda, double mu,
                                    HexVolumetricIntegration volumetric) {
  // Isotropic elasticity in Voigt form (engineering shear strains): the shear
  // entries are mu, not 2 mu. C = C_mu + C_lambda, C_lambda = lambda m m^T (m = [1 1 1 0 0 0]).
  Eigen::Matrix<double, 6, 6> C_mu = Eigen::Matrix<double, 6, 6>::Zero();
  C_mu.topLeftCorner<3, 3>().diagonal().setConstant(2 * mu);
  C_mu.bottomRightCorner<3, 3>().diagonal().setConstant(mu);
  Eigen::Matrix<double, 6, 6> C_lambda = Eigen::Matrix<double, 6, 6>::Zero();
  C_lambda.topLeftCorner<3, 3>().setConstant(lambda);
  const double detJ = size.prod() / 8.0;  // the map from [-1, 1]^3
  // B(xi): strain-displacement matrix at natural coordinates xi.
  auto strain_matrix = [&](const double xi[3]) {
    const BrickGradients G = brick_shape_gradients(size, xi);
    Eigen::Matrix<double, 6, 24> B = Eigen::Matrix<double, 6, 24>::Zero();
    for (int a = 0; a < 8; ++a) {
      const auto dN = G.col(a);
      B(0, 3 * a + 0) = dN[0];
      B(1, 3 * a + 1) = dN[1];
      B(2, 3 * a + 2) = dN[2];
      B(3, 3 * a + 0) = dN[1];  // gamma_xy
      B(3, 3 * a + 1) = dN[0];
      B(4, 3 * a + 1) = dN[2];  // gamma_yz
      B(4, 3 * a + 2) = dN[1];
      B(5, 3 * a + 0) = dN[2];  // gamma_zx
      B(5, 3 * a + 2) = dN[0];
    }
    return B;
  };
  const bool reduced = volumetric == HexVolumetricIntegration::reduced;
  const Eigen::Matrix<double, 6, 6> C_gauss = reduced ? C_mu : Eigen::Matrix<double, 6, 6>(C_mu + C_lambda);
  const double g = 1.0 / std::sqrt(3.0);
  ElementMatrix K = ElementMatrix::Zero();
  for (int q = 0; q < 8; ++q) {  // Gauss points (+-g)^3, weights 1
    const double xi[3] = {g * kCorner[q][0], g * kCorner[q][1], g * kCorner[q][2]};
    const Eigen::Matrix<double, 6, 24> B = strain_matrix(xi);
    K += B.transpose() * C_gauss * B * detJ;
  }
  if (reduced) {
    // Selective reduced integration (Hughes 1980): the lambda (volumetric) part at the
    // centre with weight 8, the mean dilatation of the brick; no volumetric locking as
    // nu -> 1/2, and the mu part keeps full rank (no hourglass modes).
    const double centre[3] = {0.0, 0.0, 0.0};
    const Eigen::Matrix<double, 6, 24> B0 = strain_matrix(centre);
    K += B0.transpose() * C_lambda * B0 * (8.0 * detJ);
  }
  return 0.5 * (K + K.transpose());
}

HexMesh hex_mesh(const Points& rest, const Eigen::Vector3i& per_axis, double lambda, double mu,
                 HexFormulation formulation, HexVolumetricIntegration volumetric,
                 const MaterialSpec* heterogeneous) {
  const int nx = per_axis[0], ny = per_axis[1], nz = per_axis[2];
  if (static_cast<long>(nx) * ny * nz != rest.cols())
    throw std::invalid_argument("hex_mesh: node count does not match the lattice size");
  HexMesh mesh;
  mesh.formulation = formulation;
  // Distinct (element size, lambda, mu) share one stiffness matrix (a regular homogeneous grid has one).
  std::map<std::tuple<long long, long long, long long, uint64_t, uint64_t>, int> type_of_size;
  // Sizes are keyed in units of 1e-12 of the lattice's extent: one absolute unit, so only
  // equal bricks share a type (a unit relative to each brick would merge bricks of the same
  // shape and different sizes, as the cubes along a graded lattice's diagonal).
  const double unit = 1e-12 * (rest.rowwise().maxCoeff() - rest.rowwise().minCoeff()).maxCoeff();
  auto node = [&](int a, int b, int c) { return a + nx * (b + ny * c); };
  for (int c = 0; c + 1 < nz; ++c)
    for (int b = 0; b + 1 < ny; ++b)
      for (int a = 0; a + 1 < nx; ++a) {
        const std::array<int, 8> nodes = {node(a, b, c),         node(a + 1, b, c),     node(a + 1, b + 1, c),
                                          node(a, b + 1, c),     node(a, b, c + 1),     node(a + 1, b, c + 1),
                                          node(a + 1, b + 1, c + 1), node(a, b + 1, c + 1)};
        const Vec3 size(rest(0, nodes[1]) - rest(0, nodes[0]), rest(1, nodes[3]) - rest(1, nodes[0]),
                        rest(2, nodes[4]) - rest(2, nodes[0]));
        double element_lambda = lambda, element_mu = mu;
        if (heterogeneous) {
          const CellMaterial c = cell_material(*heterogeneous, rest.col(nodes[0]), rest.col(nodes[6]));
          element_lambda = c.lambda;
          element_mu = c.mu;
        }
        const auto key = std::make_tuple(std::llround(size[0] / unit), std::llround(size[1] / unit),
                                         std::llround(size[2] / unit), std::bit_cast<uint64_t>(element_lambda),
                                         std::bit_cast<uint64_t>(element_mu));
        auto [it, inserted] = type_of_size.emplace(key, static_cast<int>(mesh.element_size.size()));
        if (inserted) {
          mesh.element_size.push_back(size);
          mesh.element_lambda.push_back(element_lambda);
          mesh.element_mu.push_back(element_mu);
          mesh.element_stiffness.push_back(hex_element_stiffness(size, element_lambda, element_mu, volumetric));
          std::array<BrickGradients, 8> gauss;
          const double g = 1.0 / std::sqrt(3.0);
          for (int q = 0; q < 8; ++q) {
            const double xi[3] = {g * kCorner[q][0], g * kCorner[q][1], g * kCorner[q][2]};
            gauss[q] = brick_shape_gradients(size, xi);
          }
          mesh.gauss_gradients.push_back(gauss);
          mesh.gauss_weight.push_back(size.prod() / 8.0);
        }
        mesh.element_nodes.push_back(nodes);
        mesh.element_type.push_back(it->second);
      }
  mesh.element_count = static_cast<int>(mesh.element_nodes.size());
  return mesh;
}

Mat3 hex_element_rotation(const Points& x, const std::array<int, 8>& nodes, const Eigen::Vector3d&) {
  // Mean edge vectors along the lattice x and y directions (columns of F at the
  // centre up to the edge length), orthonormalised.
  const Vec3 ex = (x.col(nodes[1]) - x.col(nodes[0])) + (x.col(nodes[2]) - x.col(nodes[3])) +
                  (x.col(nodes[5]) - x.col(nodes[4])) + (x.col(nodes[6]) - x.col(nodes[7]));
  const Vec3 ey = (x.col(nodes[3]) - x.col(nodes[0])) + (x.col(nodes[2]) - x.col(nodes[1])) +
                  (x.col(nodes[7]) - x.col(nodes[4])) + (x.col(nodes[6]) - x.col(nodes[5]));
  Mat3 R;
  R.col(0) = ex.normalized();
  R.col(2) = R.col(0).cross(ey).normalized();
  R.col(1) = R.col(2).cross(R.col(0));
  return R;
}

void hex_internal_forces(const HexMesh& mesh, const Points& rest, const Points& x, Points& f) {
  f.setZero();
  if (mesh.formulation == HexFormulation::neo_hookean) return hex_neo_hookean_add_forces(mesh, x, f);
  const bool corotational = mesh.formulation == HexFormulation::corotational;
  for (int e = 0; e < mesh.element_count; ++e) {
    const auto& nodes = mesh.element_nodes[e];
    const int type = mesh.element_type[e];
    Mat3 R;
    if (corotational) R = hex_element_rotation(x, nodes, mesh.element_size[type]);
    const ElementVector u = element_displacement(rest, x, nodes, corotational ? &R : nullptr);
    const ElementVector fe = -(mesh.element_stiffness[type] * u);
    for (int a = 0; a < 8; ++a)
      f.col(nodes[a]) += corotational ? Vec3(R * fe.segment<3>(3 * a)) : Vec3(fe.segment<3>(3 * a));
  }
}

double hex_strain_energy(const HexMesh& mesh, const Points& rest, const Points& x) {
  if (mesh.formulation == HexFormulation::neo_hookean) return hex_neo_hookean_energy(mesh, x);
  double U = 0;
  const bool corotational = mesh.formulation == HexFormulation::corotational;
  for (int e = 0; e < mesh.element_count; ++e) {
    const auto& nodes = mesh.element_nodes[e];
    const int type = mesh.element_type[e];
    Mat3 R;
    if (corotational) R = hex_element_rotation(x, nodes, mesh.element_size[type]);
    const ElementVector u = element_displacement(rest, x, nodes, corotational ? &R : nullptr);
    U += 0.5 * u.dot(mesh.element_stiffness[type] * u);
  }
  return U;
}

void hex_linearize(const HexMesh& mesh, const Points& x, std::vector<double>& cached_rotation) {
  if (mesh.formulation == HexFormulation::neo_hookean) return hex_neo_hookean_linearize(mesh, x, cached_rotation);
  cached_rotation.resize(9 * static_cast<size_t>(mesh.element_count));
  for (int e = 0; e < mesh.element_count; ++e) {
    Eigen::Map<Mat3> R(&cached_rotation[9 * static_cast<size_t>(e)]);
    R = mesh.formulation == HexFormulation::corotational
            ? hex_element_rotation(x, mesh.element_nodes[e], mesh.element_size[mesh.element_type[e]])
            : Mat3::Identity();
  }
}

void hex_force_differential(const HexMesh& mesh, const std::vector<double>& cached_rotation, const Points& dx,
                            Points& df) {
  if (mesh.formulation == HexFormulation::neo_hookean)
    return hex_neo_hookean_force_differential(mesh, cached_rotation, dx, df);
  df.setZero();
  const bool corotational = mesh.formulation == HexFormulation::corotational;
  for (int e = 0; e < mesh.element_count; ++e) {
    const auto& nodes = mesh.element_nodes[e];
    const Eigen::Map<const Mat3> R(&cached_rotation[9 * static_cast<size_t>(e)]);
    ElementVector du;
    for (int a = 0; a < 8; ++a)
      du.segment<3>(3 * a) = corotational ? Vec3(R.transpose() * dx.col(nodes[a])) : Vec3(dx.col(nodes[a]));
    const ElementVector dfe = -(mesh.element_stiffness[mesh.element_type[e]] * du);
    for (int a = 0; a < 8; ++a)
      df.col(nodes[a]) += corotational ? Vec3(R * dfe.segment<3>(3 * a)) : Vec3(dfe.segment<3>(3 * a));
  }
}

}  // namespace palpate
