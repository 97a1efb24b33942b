#include "core/stress.h"

#include <cassert>
#include <cmath>

#include "core/laws/laws.h"
#include "core/mls_forces.h"
#include "core/neo_hookean.h"

namespace palpate {

double von_mises(const Mat3& sigma) {
  const Mat3 s = 0.5 * (sigma + sigma.transpose());
  const double d01 = s(0, 0) - s(1, 1), d12 = s(1, 1) - s(2, 2), d20 = s(2, 2) - s(0, 0);
  const double shear = s(0, 1) * s(0, 1) + s(1, 2) * s(1, 2) + s(2, 0) * s(2, 0);
  return std::sqrt(0.5 * (d01 * d01 + d12 * d12 + d20 * d20) + 3.0 * shear);
}

Mat3 mls_cauchy_stress(const Model& model, const Mat3& F, int particle) {
  Mat3 P;
  particle_first_piola_stress(model, F, particle, P);  // (1.4), (1.6), (1.8) or (1.14), + (A-12)
  if (mls::with_law(model.law, []<class Law>() { return Law::small_strain; })) return P;  // the small-strain stress itself
  const double J = F.determinant();
  // An inverted or flat particle has no Cauchy stress: report the Kirchhoff stress P F^T
  // (finite; zero for the neo-Hookean law, which exerts none there) rather than divide by J <= 0.
  if (!(J > 0)) return P * F.transpose();
  return (P * F.transpose()) / J;
}

namespace {

void mls_stress(const Model& model, const Points& x, std::vector<Mat3>& sigma) {
  for (int i = 0; i < model.particle_count; ++i)
    sigma[i] = mls_cauchy_stress(model, deformation_gradient(model, x, i), i);  // F_i
}

// Each element's stress at its centre (xi = 0), volume-weighted onto its nodes.
void hex_stress(const Model& model, const Points& x, std::vector<Mat3>& sigma) {
  const HexMesh& mesh = model.hex;
  const Points& X = model.rest_position;
  std::vector<double> weight(model.particle_count, 0.0);
  const double centre[3] = {0.0, 0.0, 0.0};
  for (int e = 0; e < mesh.element_count; ++e) {
    const std::array<int, 8>& nodes = mesh.element_nodes[e];
    const int type = mesh.element_type[e];
    const Eigen::Vector3d& size = mesh.element_size[type];
    const double lambda = mesh.element_lambda[type], mu = mesh.element_mu[type];
    const BrickGradients G = brick_shape_gradients(size, centre);
    Mat3 s;
    if (mesh.formulation == HexFormulation::neo_hookean) {
      Mat3 F = Mat3::Zero();  // F = sum_a x_a grad N_a^T (sum_a X_a grad N_a^T = I on a brick)
      for (int a = 0; a < 8; ++a) F += x.col(nodes[a]) * G.col(a).transpose();
      Mat3 P, inverse_transpose;
      hyperelastic::neo_hookean_stress(F, lambda, mu, P, inverse_transpose);  // (1.14)
      const double J = F.determinant();
      s = J > 0 ? Mat3((P * F.transpose()) / J) : Mat3::Zero();
    } else {
      const bool corotational = mesh.formulation == HexFormulation::corotational;
      const Mat3 R = corotational ? hex_element_rotation(x, nodes, size) : Mat3::Identity();
      Mat3 H = Mat3::Zero();  // grad u' (u'_a = R^T x_a - X_a), H_ij = du'_i / dX_j
      for (int a = 0; a < 8; ++a) H += (R.transpose() * x.col(nodes[a]) - X.col(nodes[a])) * G.col(a).transpose();
      const Mat3 eps = 0.5 * (H + H.transpose());
      Mat3 local = (2 * mu) * eps;
      local.diagonal().array() += lambda * eps.trace();
      s = R * local * R.transpose();
    }
    const double v = size.prod();
    for (int a = 0; a < 8; ++a) {
      sigma[nodes[a]] += v * s;
      weight[nodes[a]] += v;
    }
  }
  for (int i = 0; i < model.particle_count; ++i)
    if (weight[i] > 0) sigma[i] /= weight[i];
}

}  // namespace

void cauchy_stress(const Model& model, const Points& x, std::vector<Mat3>& sigma) {
  assert(x.cols() == model.particle_count);
  sigma.assign(static_cast<size_t>(model.particle_count), Mat3::Zero());
  if (model.solid == SolidKind::hex_fem) hex_stress(model, x, sigma);
  else mls_stress(model, x, sigma);
}

void von_mises_stress(const Model& model, const Points& x, std::vector<double>& out) {
  std::vector<Mat3> sigma;
  cauchy_stress(model, x, sigma);
  out.resize(sigma.size());
  for (size_t i = 0; i < sigma.size(); ++i) out[i] = von_mises(sigma[i]);
}

}  // namespace palpate
