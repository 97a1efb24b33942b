#include "core/hex_neo_hookean.h"

#include "core/neo_hookean.h"

namespace palpate {

namespace {

constexpr int kCacheStride = 18 * 8;  // F and F^-T, column-major, per Gauss point

// F = sum_a x_a (grad N_a)^T at one Gauss point (5.4): the trilinear map's gradient. The
// brick's rest positions give sum_a X_a (grad N_a)^T = I, so this is I + grad u.
inline Mat3 deformation_gradient(const Points& x, const std::array<int, 8>& nodes, const BrickGradients& G) {
  Mat3 F = Mat3::Zero();
  for (int a = 0; a < 8; ++a) F.noalias() += x.col(nodes[a]) * G.col(a).transpose();
  return F;
}

}  // namespace

void hex_neo_hookean_add_forces(const HexMesh& mesh, const Points& x, Points& f) {
  for (int e = 0; e < mesh.element_count; ++e) {
    const auto& nodes = mesh.element_nodes[e];
    const int type = mesh.element_type[e];
    const double w = mesh.gauss_weight[type];
    for (int q = 0; q < 8; ++q) {
      const BrickGradients& G = mesh.gauss_gradients[type][q];
      Mat3 P, inverse_transpose;
      hyperelastic::neo_hookean_stress(deformation_gradient(x, nodes, G), mesh.element_lambda[type],
                                       mesh.element_mu[type], P, inverse_transpose);
      // (5.5): f_a = -sum_g w_g P_g grad N_a(xi_g).
      const Mat3 wP = w * P;
      for (int a = 0; a < 8; ++a) f.col(nodes[a]).noalias() -= wP * G.col(a);
    }
  }
}

double hex_neo_hookean_energy(const HexMesh& mesh, const Points& x) {
  double U = 0;
  for (int e = 0; e < mesh.element_count; ++e) {
    const int type = mesh.element_type[e];
    for (int q = 0; q < 8; ++q) {
      Mat3 P, inverse_transpose;
      U += mesh.gauss_weight[type] *
           hyperelastic::neo_hookean_stress(deformation_gradient(x, mesh.element_nodes[e], mesh.gauss_gradients[type][q]),
                                            mesh.element_lambda[type], mesh.element_mu[type], P, inverse_transpose);
    }
  }
  return U;
}

void hex_neo_hookean_linearize(const HexMesh& mesh, const Points& x, std::vector<double>& cache) {
  cache.resize(static_cast<size_t>(kCacheStride) * mesh.element_count);
  for (int e = 0; e < mesh.element_count; ++e) {
    const int type = mesh.element_type[e];
    for (int q = 0; q < 8; ++q) {
      double* slot = &cache[static_cast<size_t>(kCacheStride) * e + 18 * q];
      Eigen::Map<Mat3> F(slot), inverse_transpose(slot + 9);
      F = deformation_gradient(x, mesh.element_nodes[e], mesh.gauss_gradients[type][q]);
      Mat3 P, G;
      hyperelastic::neo_hookean_stress(F, mesh.element_lambda[type], mesh.element_mu[type], P, G);
      inverse_transpose = G;
    }
  }
}

void hex_neo_hookean_force_differential(const HexMesh& mesh, const std::vector<double>& cache, const Points& dx,
                                        Points& df) {
  df.setZero();
  for (int e = 0; e < mesh.element_count; ++e) {
    const auto& nodes = mesh.element_nodes[e];
    const int type = mesh.element_type[e];
    const double w = mesh.gauss_weight[type];
    for (int q = 0; q < 8; ++q) {
      const double* slot = &cache[static_cast<size_t>(kCacheStride) * e + 18 * q];
      const Eigen::Map<const Mat3> F(slot), inverse_transpose(slot + 9);
      const BrickGradients& G = mesh.gauss_gradients[type][q];
      // (5.6): df_a = -sum_g w_g dP(F_g; dF_g) grad N_a, dF_g = sum_b dx_b (grad N_b)^T.
      const Mat3 dP = hyperelastic::neo_hookean_differential(F, inverse_transpose, deformation_gradient(dx, nodes, G),
                                                             mesh.element_lambda[type], mesh.element_mu[type]);
      const Mat3 wdP = w * dP;
      for (int a = 0; a < 8; ++a) df.col(nodes[a]).noalias() -= wdP * G.col(a);
    }
  }
}

}  // namespace palpate
