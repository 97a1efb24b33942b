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
  for (Points* p : {u_p_, b_, r_, z_, p_, Ap_, df_})
    for (int j = 0; j < 3; ++j) p[j].setZero(3, n);
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

void ContactStiffness::precondition(const Points& r, Points& z) const {
  for (int i = 0; i < n_; ++i) z.col(i) = diagonal_inverse_[i] * r.col(i);
  for (size_t a = 0; a < active_.size(); ++a) z.col(active_[a]) = active_precond_[a] * r.col(active_[a]);
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
  for (int j = 0; j < 3; ++j) {
    if (!running[j]) continue;
    r_[j] = b_[j] - Ap_[j];
    if (r_[j].norm() >= b_norm[j]) {  // the warm start is worse than none
      response_[j].setZero();
      r_[j] = b_[j];
    }
    precondition(r_[j], z_[j]);
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
    for (int q = 0; q < count; ++q) {
      const int j = index[q];
      Points &w = response_[j], &r = r_[j], &z = z_[j], &p = p_[j], &Ap = Ap_[j];
      const double pAp = (p.array() * Ap.array()).sum();
      ++iterations_of[j];
      if (!(pAp > 0.0)) {  // K_b - G is not positive on the subspace: no stable equilibrium to linearise
        converged = false;
        running[j] = false;
        continue;
      }
      const double alpha = rz[j] / pAp;
      w += alpha * p;
      r -= alpha * Ap;
      precondition(r, z);
      const double rz_next = (r.array() * z.array()).sum();
      p = z + (rz_next / rz[j]) * p;
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
    // the smallest spacing) active with zero multipliers.
    const double tie = 1e-3 * model.min_spacing;
    for (int j = 0; j < n; ++j) {
      if (!movable_[j]) continue;
      const Vec3 d = state.position.col(j) - c;
      const double r = d.norm();
      if (r - R <= nearest + tie && r > 0.0) add_active(j, 0.0, d / r, r);
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
