#include "core/consistent_integration.h"

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>
#include <cmath>
#include <stdexcept>

// libgomp's (CHOLMOD's OpenMP runtime; declared here rather than through <omp.h>, which not
// every compiler ships).
extern "C" void omp_set_max_active_levels(int levels);

namespace palpate {

namespace {

// r_j = sum_i v_i g_ij (3 x n): neighbour entries scatter to j, self entries to i.
Points integration_sums(const Model& m) {
  Points r = Points::Zero(3, m.particle_count);
  for (int i = 0; i < m.particle_count; ++i)
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 vg = m.volume[i] * m.gradient_weight.col(a);
      r.col(m.neighbor_index[a]) += vg;
      r.col(i) -= vg;  // g_ii = -sum_j g_ij
    }
  return r;
}

double mean_term(const Model& m) {
  double sum = 0;
  const int nnz = m.neighbor_offset[m.particle_count];
  for (int i = 0; i < m.particle_count; ++i)
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a)
      sum += m.volume[i] * m.gradient_weight.col(a).norm();
  return nnz > 0 ? sum / nnz : 1.0;
}

}  // namespace

double integration_residual(const Model& m, const std::vector<uint8_t>& interior) {
  const Points r = integration_sums(m);
  double worst = 0;
  for (int j = 0; j < m.particle_count; ++j)
    if (interior[j]) worst = std::max(worst, r.col(j).norm());
  return worst / mean_term(m);
}

IntegrationCorrection make_integration_consistent(Model& m, const std::vector<uint8_t>& interior) {
  IntegrationCorrection out;
  const int n = m.particle_count;
  const int nnz = m.neighbor_offset[n];
  out.residual_before = integration_residual(m, interior);
  // Constraint rows: 3 per particle (linear exactness), 1 per interior node (IC).
  std::vector<int> ic_row(n, -1);
  int rows = 3 * n;
  for (int j = 0; j < n; ++j)
    if (interior[j]) ic_row[j] = rows++;
  out.interior_nodes = rows - 3 * n;
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(static_cast<size_t>(nnz) * 5);
  for (int i = 0; i < n; ++i)
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const int j = m.neighbor_index[a];
      const Vec3 X_ij = m.rest_position.col(j) - m.rest_position.col(i);
      for (int e = 0; e < 3; ++e) t.emplace_back(3 * i + e, a, X_ij[e]);  // (a)
      if (ic_row[j] >= 0) t.emplace_back(ic_row[j], a, m.volume[i]);     // (c), entry at j
      if (ic_row[i] >= 0) t.emplace_back(ic_row[i], a, -m.volume[i]);    // (c) through g_ii, (b)
    }
  Eigen::SparseMatrix<double> B(rows, nnz);
  B.setFromTriplets(t.begin(), t.end());
  t = {};
  // Rows of (a) and (c) have different units (m against m^3): scale each row to unit
  // norm so that the regularisation below is relative for all of them.
  Eigen::VectorXd row_norm = Eigen::VectorXd::Zero(rows);
  for (int k = 0; k < B.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(B, k); it; ++it) row_norm[it.row()] += it.value() * it.value();
  for (int r = 0; r < rows; ++r) row_norm[r] = row_norm[r] > 0 ? 1.0 / std::sqrt(row_norm[r]) : 0.0;
  const Eigen::SparseMatrix<double> Bs = row_norm.asDiagonal() * B;
  Eigen::SparseMatrix<double> BBt = Bs * Bs.transpose();
  // A tiny Tikhonov term keeps the factorisation defined if constraints are dependent.
  for (int r = 0; r < rows; ++r) BBt.coeffRef(r, r) += 1e-12;
  // Supernodal Cholesky (CHOLMOD): most of a model's build time went to this factorisation.
  // On the calling thread only, and one thread: CHOLMOD's OpenMP loops would start worker
  // threads that inherit a session thread's real-time priority and core, spin after the
  // build, and are invisible to ThreadSanitizer. No active parallel level: every OpenMP region
  // this thread meets runs on it alone (the setting is this thread's own ICV).
  omp_set_max_active_levels(0);
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholesky;
  cholesky.cholmod().print = 0;
  cholesky.compute(BBt);
  if (cholesky.info() != Eigen::Success) throw std::runtime_error("consistent integration: the constraint system is singular");
  const Points r = integration_sums(m);
  double change2 = 0, g2 = m.gradient_weight.squaredNorm();
  for (int c = 0; c < 3; ++c) {
    Eigen::VectorXd b = Eigen::VectorXd::Zero(rows);
    for (int j = 0; j < n; ++j)
      if (ic_row[j] >= 0) b[ic_row[j]] = -r(c, j) * row_norm[ic_row[j]];
    const Eigen::VectorXd lambda = cholesky.solve(b);
    const Eigen::VectorXd delta = Bs.transpose() * lambda;
    for (int a = 0; a < nnz; ++a) m.gradient_weight(c, a) += delta[a];
    change2 += delta.squaredNorm();
  }
  out.relative_change = std::sqrt(change2 / g2);
  out.residual_after = integration_residual(m, interior);
  return out;
}

}  // namespace palpate
