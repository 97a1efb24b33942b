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
  const int n = n_;
  // The linearisation point's arrays at their final size (linearize_elastic resizes them
  // to exactly this, so it never allocates).
  const size_t tangent_size = 9 * static_cast<size_t>(model.solid == SolidKind::hex_fem ? model.hex.element_count : n);
  tangent_.tangent_F.resize(tangent_size);
  tangent_.tangent_S_or_R.resize(model.solid == SolidKind::hex_fem ? 0 : tangent_size);
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
  for (Points* p : {&u_p_, &Ku_, &b_, &r_, &z_, &p_, &Ap_, &df_}) p->setZero(3, n);
  for (Points& p : response_) p.setZero(3, n);
  multiplier_response_.setZero(n, 3);
}

void ContactStiffness::clear_warm_start() {
  for (Points& p : response_) p.setZero();
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

void ContactStiffness::apply_operator(const Model& model, const Points& w, Points& out) {
  // (2.10): P (K_b - G) P w for w in the admissible subspace. elastic_force_differential
  // gives -K_b w; G acts at the active particles only, where w is tangential.
  elastic_force_differential(model, tangent_, w, df_);
  out = -df_;
  for (size_t a = 0; a < active_.size(); ++a) out.col(active_[a]) -= geometric_[a] * w.col(active_[a]);
  project(out);
}

void ContactStiffness::precondition(const Points& r, Points& z) const {
  for (int i = 0; i < n_; ++i) z.col(i) = diagonal_inverse_[i] * r.col(i);
  for (size_t a = 0; a < active_.size(); ++a) z.col(active_[a]) = active_precond_[a] * r.col(active_[a]);
}

int ContactStiffness::solve(const Model& model, const Points& b, Points& w, bool& converged) {
  // Preconditioned CG on the admissible subspace (2.10); w comes in as the warm start.
  const double b_norm = b.norm();
  converged = true;
  if (b_norm == 0.0) {
    w.setZero();
    return 0;
  }
  const double target = settings_.tolerance * b_norm;
  project(w);
  apply_operator(model, w, Ap_);
  r_ = b - Ap_;
  if (r_.norm() >= b_norm) {  // the warm start is worse than none
    w.setZero();
    r_ = b;
  }
  precondition(r_, z_);
  p_ = z_;
  double rz = (r_.array() * z_.array()).sum();
  int iterations = 0;
  while (r_.norm() > target) {
    if (iterations == settings_.max_iterations) {
      converged = false;
      break;
    }
    apply_operator(model, p_, Ap_);
    const double pAp = (p_.array() * Ap_.array()).sum();
    ++iterations;
    if (!(pAp > 0.0)) {  // K_b - G is not positive on the subspace: no stable equilibrium to linearise
      converged = false;
      break;
    }
    const double alpha = rz / pAp;
    w += alpha * p_;
    r_ -= alpha * Ap_;
    precondition(r_, z_);
    const double rz_next = (r_.array() * z_.array()).sum();
    p_ = z_ + (rz_next / rz) * p_;
    rz = rz_next;
  }
  return iterations;
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
  const Vec3 c = state.indenter_center;
  const double R = model.indenter_radius;
  LocalContactModel out;
  out.origin = c;
  out.force = state.indenter_contact_force;
  out.tick = state.tick;

  // The active set A of (2.7): the particles with a positive multiplier.
  for (int i : active_) slot_[i] = -1;
  active_.clear();
  geometric_.clear();
  multiplier_.clear();
  active_precond_.clear();
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
    const Vec3 nrm = d / r;
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
  const int m = static_cast<int>(active_.size());
  out.active_count = m;

  if (m == 0) {
    // No contact (2.15): F0 = 0, K = 0, the radius is the distance to the nearest free particle.
    clear_warm_start();
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
    return out;
  }

  linearize_elastic(model, state.position, tangent_);
  for (int j = 0; j < 3; ++j) {
    const Vec3 e = Vec3::Unit(j);
    // u_p (2.10): the prescribed normal displacement (n_a . e) n_a at the active particles (2.7).
    u_p_.setZero();
    for (int a = 0; a < m; ++a) u_p_.col(active_[a]) = normal_.col(a).dot(e) * normal_.col(a);
    elastic_force_differential(model, tangent_, u_p_, df_);
    Ku_ = -df_;  // K_b u_p
    // b = -P K_b u_p - G dc (2.10); G dc is tangential at the active particles.
    b_ = -Ku_;
    for (int a = 0; a < m; ++a) {
      const Vec3 nrm = normal_.col(a);
      b_.col(active_[a]) -= geometric_[a] * (e - nrm.dot(e) * nrm);
    }
    project(b_);
    Points& dx = response_[j];  // holds the previous call's dx/dc_j: P of it is the warm start
    bool converged = true;
    out.cg_iterations += solve(model, b_, dx, converged);
    out.converged = out.converged && converged;
    dx += u_p_;
    // The reactions (2.11) and the change of the force on the tool (2.12).
    elastic_force_differential(model, tangent_, dx, df_);  // -K_b dx
    Vec3 dF = Vec3::Zero();
    for (int a = 0; a < m; ++a) {
      const int i = active_[a];
      const Vec3 nrm = normal_.col(a);
      const double dmu = -nrm.dot(df_.col(i));
      multiplier_response_(a, j) = dmu;
      const Vec3 rel = dx.col(i) - e;  // r_a dn_a = (I - n n^T)(dx_a - dc) (2.9)
      dF -= dmu * nrm + geometric_[a] * (rel - nrm.dot(rel) * nrm);
    }
    out.stiffness.col(j) = dF;
  }

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
