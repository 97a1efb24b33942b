#include "core/contact_stiffness.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/solid.h"

namespace palpate {

const char* to_string(LocalContactModel::Limit limit) {
  switch (limit) {
    case LocalContactModel::Limit::no_contact: return "no_contact";
    case LocalContactModel::Limit::entering: return "entering";
    case LocalContactModel::Limit::leaving: return "leaving";
  }
  return "?";
}

namespace {

// The inverse of a symmetric positive definite 3x3 block; a block that is not (a
// particle no stencil weights) gets the identity scaled by its trace, or 0.
Mat3 spd_inverse(const Mat3& D) {
  Eigen::LLT<Mat3> llt(D);
  if (llt.info() == Eigen::Success) return llt.solve(Mat3::Identity());
  const double t = D.trace();
  return t > 0 ? Mat3(Mat3::Identity() * (3.0 / t)) : Mat3(Mat3::Zero());
}

// The 3x3 diagonal blocks of the body's tangent in the reference configuration, the
// preconditioner of (2.10). MLS: node a's block sums, over the particles i whose stencil
// holds a (and i = a with d_i = -sum_j d_j, (A-11)), v_i times the linear law's
// d-contracted tangent, mu |d|^2 I + (lambda + mu + k_v) d d^T, plus the hourglass
// springs' kappa w I on both ends (1.9). Hex FEM: the element matrices' node blocks.
std::vector<Mat3> reference_diagonal(const Model& m) {
  const int n = m.particle_count;
  std::vector<Mat3> D(n, Mat3::Zero());
  if (m.solid == SolidKind::hex_fem) {
    for (int e = 0; e < m.hex.element_count; ++e) {
      const ElementMatrix& K = m.hex.element_stiffness[m.hex.element_type[e]];
      for (int a = 0; a < 8; ++a) D[m.hex.element_nodes[e][a]] += K.block<3, 3>(3 * a, 3 * a);
    }
    return D;
  }
  auto add = [&](int node, double v, int i, const Vec3& d) {  // particle i's own Lame parameters
    const double mu = m.particle_mu[i], lm = m.particle_lambda[i] + m.particle_mu[i] + m.volume_stiffness;
    D[node] += v * (mu * d.squaredNorm() * Mat3::Identity() + lm * d * d.transpose());
  };
  const bool hourglass = !m.hourglass_weight.empty();
  for (int i = 0; i < n; ++i) {
    Vec3 d_self = Vec3::Zero();
    for (int a = m.neighbor_offset[i]; a < m.neighbor_offset[i + 1]; ++a) {
      const Vec3 d = m.gradient_weight.col(a);
      add(m.neighbor_index[a], m.volume[i], i, d);
      d_self -= d;
      if (hourglass) {
        D[i] += m.hourglass_weight[a] * Mat3::Identity();
        D[m.neighbor_index[a]] += m.hourglass_weight[a] * Mat3::Identity();
      }
    }
    add(i, m.volume[i], i, d_self);
  }
  return D;
}

}  // namespace

ContactStiffness::ContactStiffness(const Model& model, ContactStiffnessSettings settings)
    : n_(model.particle_count), settings_(settings) {
  if (!(settings.tolerance > 0.0 && settings.tolerance < 1.0))
    throw std::invalid_argument("ContactStiffnessSettings::tolerance: must be in (0, 1), got " +
                                std::to_string(settings.tolerance));
  if (settings.max_iterations < 1)
    throw std::invalid_argument("ContactStiffnessSettings::max_iterations: must be >= 1, got " +
                                std::to_string(settings.max_iterations));
  if (settings.coarse_per_axis != 0 && !(settings.coarse_per_axis >= 2 && settings.coarse_per_axis <= 12))
    throw std::invalid_argument("ContactStiffnessSettings::coarse_per_axis: must be 0 (none) or in [2, 12], got " +
                                std::to_string(settings.coarse_per_axis));
  const int n = n_;
  // The linearisation point's arrays at their final size (linearize_elastic resizes them
  // to exactly this, so it never allocates).
  const size_t tangent_size = 9 * static_cast<size_t>(model.solid == SolidKind::hex_fem ? model.hex.element_count : n);
  tangent_.tangent_F.resize(tangent_size);
  tangent_.tangent_law_factor.resize(model.solid == SolidKind::hex_fem ? 0 : tangent_size);
  tangent_.threads.resize(1, n);  // the blocked loops' scratch (mls_loops.h), allocated now
  diagonal_ = reference_diagonal(model);
  diagonal_inverse_.resize(n);
  movable_.resize(n);
  for (int i = 0; i < n; ++i) {
    movable_[i] = model.inverse_mass[i] > 0.0;
    diagonal_inverse_[i] = movable_[i] ? spd_inverse(diagonal_[i]) : Mat3::Zero();
  }
  active_.reserve(n);
  slot_.assign(n, -1);
  normal_.resize(3, n);
  geometric_.reserve(n);
  multiplier_.reserve(n);
  active_precond_.reserve(n);
  for (Points* p : {u_p_, b_, r_, z_, p_, Ap_, df_})
    for (int j = 0; j < 3; ++j) p[j].setZero(3, n);
  for (Points& p : response_) p.setZero(3, n);
  multiplier_response_.setZero(n, 3);
  last_position_.setZero(3, n);
  last_contact_index_.reserve(n);
  last_multiplier_.reserve(n);
  if (settings.coarse_per_axis > 0) {
    // At most about a third of the cloud's nodes per axis: a coarser lattice than that costs
    // more per iteration than it saves (2.21).
    const int cap = std::max(2, static_cast<int>(std::lround(std::cbrt(static_cast<double>(n)) / 3.0)));
    build_coarse_correction(model, std::min(settings.coarse_per_axis, cap));
  }
}

void ContactStiffness::build_coarse_correction(const Model& model, int per_axis) {
  // (2.21): the lattice's nodes along each axis at the quantiles of the particles'
  // coordinates, so that a graded cloud gets a graded lattice.
  const int n = n_;
  const Points& X = model.rest_position;
  std::vector<double> axis[3], sorted(static_cast<size_t>(n));
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < n; ++i) sorted[i] = X(c, i);
    std::sort(sorted.begin(), sorted.end());
    for (int k = 0; k < per_axis; ++k) {
      const double q = sorted[static_cast<size_t>(std::lround(static_cast<double>(k) * (n - 1) / (per_axis - 1)))];
      if (axis[c].empty() || q > axis[c].back()) axis[c].push_back(q);
    }
    if (axis[c].size() < 2) return;  // a flat cloud: block Jacobi alone
  }
  const int nx = static_cast<int>(axis[0].size()), ny = static_cast<int>(axis[1].size());
  const int nodes = nx * ny * static_cast<int>(axis[2].size());
  // T: each free particle interpolates the 8 nodes of its cell trilinearly; fixed ones nothing.
  coarse_node_.assign(8 * static_cast<size_t>(n), 0);
  coarse_weight_.assign(8 * static_cast<size_t>(n), 0.0);
  for (int i = 0; i < n; ++i) {
    if (!movable_[i]) continue;
    int cell[3];
    double t[3];
    for (int c = 0; c < 3; ++c) {
      const std::vector<double>& a = axis[c];
      const int k = std::clamp(static_cast<int>(std::upper_bound(a.begin(), a.end(), X(c, i)) - a.begin()) - 1, 0,
                               static_cast<int>(a.size()) - 2);
      cell[c] = k;
      t[c] = std::clamp((X(c, i) - a[k]) / (a[k + 1] - a[k]), 0.0, 1.0);
    }
    for (int corner = 0; corner < 8; ++corner) {
      const int b[3] = {corner & 1, (corner >> 1) & 1, (corner >> 2) & 1};
      double w = 1.0;
      for (int c = 0; c < 3; ++c) w *= b[c] ? t[c] : 1.0 - t[c];
      coarse_node_[8 * i + corner] = ((cell[2] + b[2]) * ny + cell[1] + b[1]) * nx + cell[0] + b[0];
      coarse_weight_[8 * i + corner] = w;
    }
  }
  // A_c = T^T K_0 T, three columns per tangent sweep (u_p_ and df_ serve as scratch).
  const int unknowns = 3 * nodes;
  linearize_elastic(model, X, tangent_);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(unknowns, unknowns);
  for (int first = 0; first < unknowns; first += 3) {
    const int count = std::min(3, unknowns - first);
    const Points* in[3] = {&u_p_[0], &u_p_[1], &u_p_[2]};
    Points* df[3] = {&df_[0], &df_[1], &df_[2]};
    for (int q = 0; q < count; ++q) {
      const int node = (first + q) / 3, component = (first + q) % 3;
      u_p_[q].setZero();
      for (size_t k = 0; k < coarse_node_.size(); ++k)
        if (coarse_node_[k] == node) u_p_[q](component, static_cast<Eigen::Index>(k / 8)) += coarse_weight_[k];
    }
    elastic_force_differentials(model, tangent_, count, in, df);  // -K_0 T e_k
    for (int q = 0; q < count; ++q)
      for (size_t k = 0; k < coarse_node_.size(); ++k)
        if (coarse_weight_[k] != 0.0)
          A.block<3, 1>(3 * coarse_node_[k], first + q) -= coarse_weight_[k] * df_[q].col(static_cast<Eigen::Index>(k / 8));
  }
  A = 0.5 * (A + A.transpose()).eval();
  // A node whose cells hold no free particle has no coarse unknowns: decoupled.
  const double largest = A.diagonal().maxCoeff();
  for (int k = 0; k < unknowns; ++k)
    if (!(A(k, k) > 1e-12 * largest)) {
      A.row(k).setZero();
      A.col(k).setZero();
      A(k, k) = 1.0;
    }
  const Eigen::LLT<Eigen::MatrixXd> factor(A);
  if (factor.info() != Eigen::Success) return;  // not positive definite: block Jacobi alone
  coarse_inverse_ = factor.solve(Eigen::MatrixXd::Identity(unknowns, unknowns));
  coarse_rhs_.setZero(unknowns, 3);
  coarse_solution_.setZero(unknowns, 3);
  coarse_nodes_ = nodes;
  coarse_lattice_ = Eigen::Vector3i(nx, ny, static_cast<int>(axis[2].size()));
}

void ContactStiffness::set_touch_lookahead(double seconds) {
  if (!(seconds >= 0.0 && std::isfinite(seconds)))
    throw std::invalid_argument("ContactStiffness::set_touch_lookahead: must be a finite time >= 0 s, got " +
                                std::to_string(seconds));
  touch_lookahead_ = seconds;
}

void ContactStiffness::clear_warm_start() {
  for (Points& p : response_) p.setZero();
  have_last_ = false;
}

double ContactStiffness::touch_depth(const CarriedState& state, const Vec3& nearest) const {
  return 0.5 * std::max(0.0, state.indenter_velocity.dot(nearest)) * touch_lookahead_;
}

bool ContactStiffness::same_as_last(const Model& model, const CarriedState& state) const {
  const double tolerance = 1e-6 * model.min_spacing;
  if ((state.indenter_center - last_centre_).cwiseAbs().maxCoeff() > tolerance) return false;
  if (state.contact_index != last_contact_index_) return false;
  double largest = 0.0;
  for (const double mu : last_multiplier_) largest = std::max(largest, std::abs(mu));
  for (size_t k = 0; k < last_multiplier_.size(); ++k)
    if (std::abs(state.contact_normal_force[k] - last_multiplier_[k]) > 1e-6 * largest) return false;
  if (last_.active_count == 0 && last_.touch_count > 0 &&
      std::abs(touch_depth(state, last_.limiting_direction) - last_touch_depth_) > tolerance)
    return false;
  return (state.position - last_position_).cwiseAbs().maxCoeff() <= tolerance;
}

void ContactStiffness::remember(const CarriedState& state, const LocalContactModel& result) {
  last_position_ = state.position;  // the same size: no allocation
  last_centre_ = state.indenter_center;
  last_contact_index_.assign(state.contact_index.begin(), state.contact_index.end());  // capacity n
  last_multiplier_.assign(state.contact_normal_force.begin(), state.contact_normal_force.end());
  last_touch_depth_ = touch_depth(state, result.limiting_direction);
  last_ = result;
  have_last_ = true;
}

void ContactStiffness::project(Points& w) const {
  // P of (2.10): no motion at fixed particles, no normal motion at active ones.
  for (int i = 0; i < n_; ++i)
    if (!movable_[i]) w.col(i).setZero();
  for (size_t a = 0; a < active_.size(); ++a) {
    const Vec3 n = normal_.col(static_cast<Eigen::Index>(a));
    w.col(active_[a]) -= n.dot(w.col(active_[a])) * n;
  }
}

void ContactStiffness::apply_operator(const Model& model, int count, const Points* const* w, Points* const* out) {
  // (2.10): P (K_b - G) P w for w in the admissible subspace. elastic_force_differentials
  // gives -K_b w; G acts at the active particles only, where w is tangential.
  Points* df[3] = {&df_[0], &df_[1], &df_[2]};
  elastic_force_differentials(model, tangent_, count, w, df);
  for (int q = 0; q < count; ++q) {
    Points& o = *out[q];
    o = -df_[q];
    for (size_t a = 0; a < active_.size(); ++a) o.col(active_[a]) -= geometric_[a] * w[q]->col(active_[a]);
    project(o);
  }
}

void ContactStiffness::precondition(int count, const Points* const* r, Points* const* z) {
  if (count == 0) return;  // every direction stopped: no pass over the particles for nothing
  // (2.21): block Jacobi, restricted to the tangent plane at the active particles ...
  for (int q = 0; q < count; ++q) {
    const Points& rq = *r[q];
    Points& zq = *z[q];
    for (int i = 0; i < n_; ++i) zq.col(i) = diagonal_inverse_[i] * rq.col(i);
    for (size_t a = 0; a < active_.size(); ++a) zq.col(active_[a]) = active_precond_[a] * rq.col(active_[a]);
  }
  if (coarse_nodes_ == 0) return;
  // ... plus the coarse correction P T A_c^-1 T^T r, every direction in one pass over A_c^-1.
  coarse_rhs_.setZero();
  for (int i = 0; i < n_; ++i)
    for (int k = 8 * i; k < 8 * i + 8; ++k) {
      const double w = coarse_weight_[k];
      if (w == 0.0) continue;
      for (int q = 0; q < count; ++q) coarse_rhs_.block<3, 1>(3 * coarse_node_[k], q) += w * r[q]->col(i);
    }
  coarse_solution_.setZero();
  for (Eigen::Index j = 0; j < coarse_inverse_.cols(); ++j)
    for (int q = 0; q < count; ++q)
      if (const double v = coarse_rhs_(j, q); v != 0.0) coarse_solution_.col(q) += v * coarse_inverse_.col(j);
  for (int i = 0; i < n_; ++i) {
    if (!movable_[i]) continue;
    for (int q = 0; q < count; ++q) {
      Vec3 s = Vec3::Zero();
      for (int k = 8 * i; k < 8 * i + 8; ++k)
        s += coarse_weight_[k] * coarse_solution_.block<3, 1>(3 * coarse_node_[k], q);
      if (slot_[i] >= 0) {
        const Vec3 nrm = normal_.col(slot_[i]);
        s -= nrm.dot(s) * nrm;
      }
      z[q]->col(i) += s;
    }
  }
}

void ContactStiffness::solve(const Model& model, int& iterations, bool& converged) {
  // Preconditioned CG on the admissible subspace (2.10), one per direction j, in lockstep;
  // response_[j] comes in as the warm start.
  double b_norm[3], target[3], rz[3];
  bool running[3];
  int iterations_of[3] = {0, 0, 0};
  const Points* in[3];
  Points* out[3];
  int count = 0;
  int index[3];
  for (int j = 0; j < 3; ++j) {
    b_norm[j] = b_[j].norm();
    running[j] = b_norm[j] != 0.0;
    if (!running[j]) {
      response_[j].setZero();
      continue;
    }
    target[j] = settings_.tolerance * b_norm[j];
    project(response_[j]);
    in[count] = &response_[j];
    out[count] = &Ap_[j];
    ++count;
  }
  apply_operator(model, count, in, out);
  const Points* residuals[3];
  Points* preconditioned[3];
  count = 0;
  for (int j = 0; j < 3; ++j) {
    if (!running[j]) continue;
    r_[j] = b_[j] - Ap_[j];
    if (r_[j].norm() >= b_norm[j]) {  // the warm start is worse than none
      response_[j].setZero();
      r_[j] = b_[j];
    }
    index[count] = j;
    residuals[count] = &r_[j];
    preconditioned[count++] = &z_[j];
  }
  precondition(count, residuals, preconditioned);
  for (int q = 0; q < count; ++q) {
    const int j = index[q];
    p_[j] = z_[j];
    rz[j] = (r_[j].array() * z_[j].array()).sum();
  }
  for (;;) {
    // The directions that iterate once more: not converged, not stopped.
    count = 0;
    for (int j = 0; j < 3; ++j) {
      if (!running[j]) continue;
      if (!(r_[j].norm() > target[j])) {
        running[j] = false;
        continue;
      }
      if (iterations_of[j] == settings_.max_iterations) {
        converged = false;
        running[j] = false;
        continue;
      }
      index[count] = j;
      in[count] = &p_[j];
      out[count] = &Ap_[j];
      ++count;
    }
    if (count == 0) break;
    apply_operator(model, count, in, out);
    int stepped = 0;
    int stepped_index[3];
    for (int q = 0; q < count; ++q) {
      const int j = index[q];
      const double pAp = (p_[j].array() * Ap_[j].array()).sum();
      ++iterations_of[j];
      if (!(pAp > 0.0)) {  // K_b - G is not positive on the subspace: no stable equilibrium to linearise
        converged = false;
        running[j] = false;
        continue;
      }
      const double alpha = rz[j] / pAp;
      response_[j] += alpha * p_[j];
      r_[j] -= alpha * Ap_[j];
      stepped_index[stepped] = j;
      residuals[stepped] = &r_[j];
      preconditioned[stepped++] = &z_[j];
    }
    precondition(stepped, residuals, preconditioned);
    for (int q = 0; q < stepped; ++q) {
      const int j = stepped_index[q];
      const double rz_next = (r_[j].array() * z_[j].array()).sum();
      p_[j] = z_[j] + (rz_next / rz[j]) * p_[j];
      rz[j] = rz_next;
    }
  }
  for (int j = 0; j < 3; ++j) iterations += iterations_of[j];
}

void ContactStiffness::begin_active_set() {
  for (int i : active_) slot_[i] = -1;
  active_.clear();
  geometric_.clear();
  multiplier_.clear();
  active_precond_.clear();
}

void ContactStiffness::add_active(int i, double mu, const Vec3& nrm, double r) {
  slot_[i] = static_cast<int>(active_.size());
  normal_.col(static_cast<Eigen::Index>(active_.size())) = nrm;
  active_.push_back(i);
  multiplier_.push_back(mu);
  geometric_.push_back(mu / r);  // (2.8)
  // The projected block-Jacobi inverse at an active particle: (P D P)^+ on its tangent plane.
  const Mat3 P = Mat3::Identity() - nrm * nrm.transpose();
  const Mat3& D = diagonal_[i];
  const Mat3 Dp = P * D * P + (D.trace() / 3.0) * nrm * nrm.transpose();
  active_precond_.push_back(P * spd_inverse(Dp) * P);
}

Mat3 ContactStiffness::stiffness_of_active_set(const Model& model, const CarriedState& state, int& iterations,
                                               bool& converged) {
  const int m = static_cast<int>(active_.size());
  linearize_elastic(model, state.position, tangent_);
  // u_p (2.10): the prescribed normal displacement (n_a . e_j) n_a at the active particles (2.7).
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = Vec3::Unit(j);
    u_p_[j].setZero();
    for (int a = 0; a < m; ++a) u_p_[j].col(active_[a]) = normal_.col(a).dot(e) * normal_.col(a);
  }
  {
    const Points* in[3] = {&u_p_[0], &u_p_[1], &u_p_[2]};
    Points* df[3] = {&df_[0], &df_[1], &df_[2]};
    elastic_force_differentials(model, tangent_, 3, in, df);  // -K_b u_p
  }
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = Vec3::Unit(j);
    // b = -P K_b u_p - G dc (2.10); G dc is tangential at the active particles.
    b_[j] = df_[j];
    for (int a = 0; a < m; ++a) {
      const Vec3 nrm = normal_.col(a);
      b_[j].col(active_[a]) -= geometric_[a] * (e - nrm.dot(e) * nrm);
    }
    project(b_[j]);
  }
  // response_[j] holds the previous call's dx/dc_j: P of it is the warm start.
  solve(model, iterations, converged);
  for (int j = 0; j < 3; ++j) response_[j] += u_p_[j];
  {
    const Points* in[3] = {&response_[0], &response_[1], &response_[2]};
    Points* df[3] = {&df_[0], &df_[1], &df_[2]};
    elastic_force_differentials(model, tangent_, 3, in, df);  // -K_b dx
  }
  Mat3 K;
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = Vec3::Unit(j);
    const Points& dx = response_[j];
    // The reactions (2.11) and the change of the force on the tool (2.12).
    Vec3 dF = Vec3::Zero();
    for (int a = 0; a < m; ++a) {
      const int i = active_[a];
      const Vec3 nrm = normal_.col(a);
      const double dmu = -nrm.dot(df_[j].col(i));
      multiplier_response_(a, j) = dmu;
      const Vec3 rel = dx.col(i) - e;  // r_a dn_a = (I - n n^T)(dx_a - dc) (2.9)
      dF -= dmu * nrm + geometric_[a] * (rel - nrm.dot(rel) * nrm);
    }
    K.col(j) = dF;
  }
  return K;
}

LocalContactModel ContactStiffness::evaluate(const Model& model, const CarriedState& state) {
  const int n = n_;
  if (model.particle_count != n)
    throw std::invalid_argument("ContactStiffness::evaluate: the model has " + std::to_string(model.particle_count) +
                                " particles, the instance was built for " + std::to_string(n));
  if (state.position.cols() != n)
    throw std::invalid_argument("ContactStiffness::evaluate: state.position has " +
                                std::to_string(state.position.cols()) + " columns, the model " +
                                std::to_string(n) + " particles");
  if (state.contact_normal_force.size() != state.contact_index.size())
    throw std::invalid_argument("ContactStiffness::evaluate: state.contact_normal_force has " +
                                std::to_string(state.contact_normal_force.size()) +
                                " entries, state.contact_index " + std::to_string(state.contact_index.size()));
  if (state.contact_index.size() > static_cast<size_t>(n))
    throw std::invalid_argument("ContactStiffness::evaluate: state.contact_index has " +
                                std::to_string(state.contact_index.size()) + " entries, more than the " +
                                std::to_string(n) + " particles");
  if (have_last_ && same_as_last(model, state)) {
    LocalContactModel out = last_;
    out.tick = state.tick;
    out.origin = state.indenter_center;
    out.force = state.indenter_contact_force;
    out.cg_iterations = 0;
    out.reused = true;
    return out;
  }
  const LocalContactModel out = evaluate_anew(model, state);
  remember(state, out);
  return out;
}

LocalContactModel ContactStiffness::evaluate_anew(const Model& model, const CarriedState& state) {
  const int n = n_;
  const Vec3 c = state.indenter_center;
  const double R = model.indenter_radius;
  LocalContactModel out;
  out.origin = c;
  out.force = state.indenter_contact_force;
  out.tick = state.tick;

  // The active set A of (2.7): the particles with a positive multiplier.
  begin_active_set();
  for (size_t k = 0; k < state.contact_index.size(); ++k) {
    const int i = state.contact_index[k];
    const double mu = state.contact_normal_force[k];
    if (i < 0 || i >= n || !movable_[i] || slot_[i] >= 0)
      throw std::invalid_argument("ContactStiffness::evaluate: state.contact_index[" + std::to_string(k) +
                                  "] = " + std::to_string(i) + " is not a free particle listed once");
    if (!(mu > 0.0)) continue;
    const Vec3 d = state.position.col(i) - c;
    const double r = d.norm();
    if (!(r > 0.0)) continue;  // a particle at the centre has no normal
    add_active(i, mu, d / r, r);
  }
  const int m = static_cast<int>(active_.size());
  out.active_count = m;

  if (m == 0) {
    // No contact (2.15): F0 = 0, K = 0, the radius is the distance to the nearest free particle.
    double nearest = std::numeric_limits<double>::infinity();
    for (int j = 0; j < n; ++j) {
      if (!movable_[j]) continue;
      const Vec3 d = state.position.col(j) - c;
      const double g = d.norm() - R;
      if (g < nearest) {
        nearest = g;
        out.limiting_particle = j;
        out.limiting_direction = d.normalized();
      }
    }
    out.valid_radius = std::max(0.0, nearest);
    out.limited_by = LocalContactModel::Limit::no_contact;
    if (!settings_.touch_stiffness || out.limiting_particle < 0) {
      clear_warm_start();
      return out;
    }
    // The stiffness at first touch (2.20): the nearest free particles (ties within 10^-3 of
    // the smallest spacing) active with zero multipliers; with a lookahead (2.22), those
    // within half the depth d* = v_n T / 2 the tool reaches halfway through the time T it
    // will serve, at its approach speed v_n toward the nearest particle.
    const double band = std::max(1e-3 * model.min_spacing, 0.5 * touch_depth(state, out.limiting_direction));
    for (int j = 0; j < n; ++j) {
      if (!movable_[j]) continue;
      const Vec3 d = state.position.col(j) - c;
      const double r = d.norm();
      if (r - R <= nearest + band && r > 0.0) add_active(j, 0.0, d / r, r);
    }
    out.touch_stiffness = stiffness_of_active_set(model, state, out.cg_iterations, out.converged);
    out.touch_count = static_cast<int>(active_.size());
    begin_active_set();  // the next evaluation's warm start is response_, its active set its own
    return out;
  }

  out.stiffness = stiffness_of_active_set(model, state, out.cg_iterations, out.converged);

  // The validity radius (2.14): the smallest tool displacement that changes the active set,
  // to first order, over every direction.
  out.valid_radius = std::numeric_limits<double>::infinity();
  for (int a = 0; a < m; ++a) {  // an active particle leaves when mu_a + grad mu_a . dc reaches 0
    const Vec3 grad = multiplier_response_.row(a).transpose();
    const double rate = grad.norm();
    if (!(rate > 0.0)) continue;
    const double t = multiplier_[a] / rate;
    if (t < out.valid_radius) {
      out.valid_radius = t;
      out.limited_by = LocalContactModel::Limit::leaving;
      out.limiting_particle = active_[a];
      out.limiting_direction = -grad / rate;
    }
  }
  for (int j = 0; j < n; ++j) {  // a free particle enters when g_j + grad g_j . dc reaches 0
    if (!movable_[j] || slot_[j] >= 0) continue;
    const Vec3 d = state.position.col(j) - c;
    const double r = d.norm();
    if (!(r > 0.0)) continue;
    const Vec3 nrm = d / r;
    const double g = r - R;
    Vec3 grad;
    for (int k = 0; k < 3; ++k) grad[k] = nrm.dot(response_[k].col(j)) - nrm[k];
    const double rate = grad.norm();
    if (!(rate > 0.0)) continue;
    const double t = std::max(0.0, g) / rate;
    if (t < out.valid_radius) {
      out.valid_radius = t;
      out.limited_by = LocalContactModel::Limit::entering;
      out.limiting_particle = j;
      out.limiting_direction = -grad / rate;
    }
  }
  if (!std::isfinite(out.valid_radius)) out.valid_radius = 0.0;
  return out;
}

}  // namespace palpate
