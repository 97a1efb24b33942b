#include "analysis/diagnostics.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "core/hex_fem.h"
#include "core/mls_forces.h"
#include "core/solid.h"

namespace palpate {

double kinetic_energy(const Model& model, const Options& opt, const State& state) {
  double e = 0.5 * opt.indenter_mass * state.indenter_velocity.squaredNorm();
  for (int i = 0; i < model.particle_count; ++i)
    if (model.inverse_mass[i] != 0.0) e += 0.5 * model.mass[i] * state.velocity.col(i).squaredNorm();
  return e;
}

double total_energy(const Model& model, const Options& opt, const State& state) {
  return kinetic_energy(model, opt, state) + elastic_energy(model, state.position);
}

namespace {

// det F at the eight Gauss points of a trilinear brick (edges hx, hy, hz along the
// axes, local node order of hex_fem.h); returns the smallest.
double brick_min_jacobian(const Points& x, const std::array<int, 8>& nodes, const Eigen::Vector3d& size) {
  const double g = 1.0 / std::sqrt(3.0);
  double smallest = INFINITY;
  for (int q = 0; q < 8; ++q) {  // Gauss points (+-g)^3
    const double xi[3] = {(q & 1) ? g : -g, (q & 2) ? g : -g, (q & 4) ? g : -g};
    const BrickGradients grad = brick_shape_gradients(size, xi);
    Mat3 F = Mat3::Zero();
    for (int a = 0; a < 8; ++a) F += x.col(nodes[a]) * grad.col(a).transpose();
    smallest = std::min(smallest, F.determinant());
  }
  return smallest;
}

// Index of each coordinate value along one axis (distinct values within tol).
std::vector<int> axis_index(const Points& X, int axis, double tol, int& count) {
  std::vector<double> values(X.cols());
  for (int i = 0; i < X.cols(); ++i) values[i] = X(axis, i);
  std::vector<double> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  std::vector<double> distinct;
  for (double v : sorted)
    if (distinct.empty() || v - distinct.back() > tol) distinct.push_back(v);
  count = static_cast<int>(distinct.size());
  std::vector<int> index(X.cols());
  for (int i = 0; i < X.cols(); ++i)
    index[i] = static_cast<int>(std::lower_bound(distinct.begin(), distinct.end(), values[i] - tol) - distinct.begin());
  return index;
}

}  // namespace

void jacobian_determinants(const Model& model, const Points& x, std::vector<double>& out) {
  if (model.solid == SolidKind::hex_fem) {
    const HexMesh& mesh = model.hex;
    out.resize(mesh.element_count);
    for (int e = 0; e < mesh.element_count; ++e)
      out[e] = brick_min_jacobian(x, mesh.element_nodes[e], mesh.element_size[mesh.element_type[e]]);
    return;
  }
  out.resize(model.particle_count);
  for (int i = 0; i < model.particle_count; ++i) out[i] = deformation_gradient(model, x, i).determinant();
}

InversionSummary inversion_summary(const Model& model, const Points& x) {
  std::vector<double> det;
  jacobian_determinants(model, x, det);
  InversionSummary s;
  s.points = static_cast<int>(det.size());
  s.min_jacobian = det.empty() ? 1.0 : *std::min_element(det.begin(), det.end());
  s.inverted = static_cast<int>(std::count_if(det.begin(), det.end(), [](double J) { return !(J > 0); }));
  return s;
}

std::vector<double> checkerboard_sign(const Model& model) {
  const Points& X = model.rest_position;
  const double tol = 1e-6 * std::max(model.min_spacing, 1e-12);
  int count[3];
  std::vector<int> index[3];
  for (int axis = 0; axis < 3; ++axis) index[axis] = axis_index(X, axis, tol, count[axis]);
  if (static_cast<long>(count[0]) * count[1] * count[2] != model.particle_count)
    throw std::invalid_argument("checkerboard_sign: the particles do not form a lattice");
  std::vector<double> sign(model.particle_count);
  for (int i = 0; i < model.particle_count; ++i)
    sign[i] = ((index[0][i] + index[1][i] + index[2][i]) % 2 == 0) ? 1.0 : -1.0;
  return sign;
}

double checkerboard_amplitude(const Model& model, const std::vector<double>& sign, const Points& x) {
  Vec3 sum = Vec3::Zero();
  int free_count = 0;
  for (int i = 0; i < model.particle_count; ++i) {
    if (model.inverse_mass[i] == 0.0) continue;
    sum += sign[i] * (x.col(i) - model.rest_position.col(i));
    ++free_count;
  }
  return free_count > 0 ? sum.norm() / free_count : 0.0;
}

}  // namespace palpate
