#include "core/contact.h"

#include "core/integrators.h"

#include <algorithm>
#include <cmath>

namespace palpate {

namespace {

// In-place Cholesky factorisation of the k x k SPD matrix L (row-major, lower
// triangle used) and solve L L^T x = b. Returns false if not positive definite.
bool cholesky_solve(int k, double* L, double* b) {
  for (int r = 0; r < k; ++r) {
    for (int c = 0; c <= r; ++c) {
      double s = L[r * k + c];
      for (int q = 0; q < c; ++q) s -= L[r * k + q] * L[c * k + q];
      if (r == c) {
        if (s <= 0) return false;
        L[r * k + r] = std::sqrt(s);
      } else {
        L[r * k + c] = s / L[c * k + c];
      }
    }
  }
  for (int r = 0; r < k; ++r) {  // forward
    double s = b[r];
    for (int q = 0; q < r; ++q) s -= L[r * k + q] * b[q];
    b[r] = s / L[r * k + r];
  }
  for (int r = k - 1; r >= 0; --r) {  // backward
    double s = b[r];
    for (int q = r + 1; q < k; ++q) s -= L[q * k + r] * b[q];
    b[r] = s / L[r * k + r];
  }
  return true;
}

int projected_gauss_seidel(int m, const double* W, const double* g, double* lambda, double tolerance,
                           int max_sweeps) {
  for (int sweep = 1; sweep <= max_sweeps; ++sweep) {
    double worst = 0;
    for (int a = 0; a < m; ++a) {
      double w = g[a];
      for (int b = 0; b < m; ++b) w += W[a * m + b] * lambda[b];
      const double updated = std::max(0.0, lambda[a] - w / W[a * m + a]);
      if (updated > 0 || w < 0) worst = std::max(worst, std::abs(w));
      lambda[a] = updated;
    }
    if (worst <= tolerance) return sweep;
  }
  return -1;
}

}  // namespace

int solve_signorini_lcp(int m, const double* W, const double* g, double* lambda, double tolerance,
                        int max_iterations, Workspace& work) {
  // Principal pivoting: guess the active set {g < 0}, solve W_AA lambda_A = -g_A,
  // drop the most negative multiplier or add the most violated gap, repeat.
  std::vector<int>& active = work.active;
  std::vector<double>& buf = work.solve_buffer;
  active.assign(m, 0);
  if (buf.size() < static_cast<size_t>(m * m + m)) buf.resize(static_cast<size_t>(m * m + m));
  double* L = buf.data();
  double* rhs = L + m * m;
  work.members.resize(m);
  int* members = work.members.data();
  for (int a = 0; a < m; ++a) active[a] = g[a] < 0;
  for (int iteration = 1; iteration <= max_iterations; ++iteration) {
    int k = 0;
    for (int a = 0; a < m; ++a)
      if (active[a]) members[k++] = a;
    for (int r = 0; r < k; ++r) {
      for (int c = 0; c <= r; ++c) L[r * k + c] = W[members[r] * m + members[c]];
      rhs[r] = -g[members[r]];
    }
    std::fill(lambda, lambda + m, 0.0);
    if (k > 0 && !cholesky_solve(k, L, rhs)) break;
    int drop = -1;
    double most_negative = 0;
    for (int r = 0; r < k; ++r) {
      lambda[members[r]] = rhs[r];
      if (rhs[r] < most_negative) {
        most_negative = rhs[r];
        drop = members[r];
      }
    }
    if (drop >= 0) {
      active[drop] = 0;
      continue;
    }
    int add = -1;
    double most_violated = -tolerance;
    for (int a = 0; a < m; ++a) {
      if (active[a]) continue;
      double w = g[a];
      for (int r = 0; r < k; ++r) w += W[a * m + members[r]] * lambda[members[r]];
      if (w < most_violated) {
        most_violated = w;
        add = a;
      }
    }
    if (add < 0) return iteration;
    active[add] = 1;
  }
  // Pivoting did not settle: finish with projected Gauss-Seidel from the clipped iterate.
  for (int a = 0; a < m; ++a) lambda[a] = std::max(0.0, lambda[a]);
  const int sweeps = projected_gauss_seidel(m, W, g, lambda, tolerance, 100 * max_iterations);
  return sweeps < 0 ? -1 : max_iterations + sweeps;
}

StepStatus solve_contact(const Model& model, const Options& opt, State& state, LinearResponse* coupled) {
  Workspace& work = state.work;
  const int n = model.particle_count;
  const double R = model.indenter_radius;
  const double dt = opt.integrator.dt;
  const Vec3 c = state.indenter_center;
  const double tolerance = opt.contact.tolerance;
  const int max_iterations = opt.contact.max_iterations;
  std::vector<int>& candidate = state.out.contact_candidate;

  // Candidates: free particles inside the sphere after the free motion, and the
  // particles in contact at the previous step (their force was part of the free motion).
  candidate.clear();
  work.gap.clear();
  work.previous_multiplier.clear();
  auto add_candidate = [&](int i) {
    const Vec3 r = state.position.col(i) - c;
    const double dist = r.norm();
    const int a = static_cast<int>(candidate.size());
    candidate.push_back(i);
    work.gap.push_back(dist - R);
    work.normal.col(a) = dist > 0 ? Vec3(r / dist) : Vec3(0, 0, -1);
    work.previous_multiplier.push_back(0.0);
    work.previous_force.col(a).setZero();
    work.candidate_slot[i] = a;
  };
  for (int i = 0; i < n; ++i) {
    if (model.inverse_mass[i] == 0.0) continue;
    if ((state.position.col(i) - c).squaredNorm() < R * R) add_candidate(i);
  }
  for (size_t k = 0; k < state.contact_index.size(); ++k) {
    const int i = state.contact_index[k];
    if (work.candidate_slot[i] < 0) add_candidate(i);
    const int a = work.candidate_slot[i];
    const Vec3 f = state.contact_force.col(static_cast<Eigen::Index>(k));
    work.previous_force.col(a) = f;
    work.previous_multiplier[a] = f.dot(work.normal.col(a));  // along this step's normal
  }
  const int m = static_cast<int>(candidate.size());
  for (int a = 0; a < m; ++a) work.candidate_slot[candidate[a]] = -1;
  state.contact_index.clear();
  state.contact_normal_force.clear();
  state.indenter_contact_force.setZero();
  state.out.contact_iterations = 0;
  state.out.contact_max_penetration = 0.0;
  if (m == 0) return StepStatus::ok;

  // Delassus operator W = dt^2 J M^-1 J^T, the sphere's translations included:
  // W_ab = dt^2 [ n_a . (response of particle a to a unit force n_b on b) + n_a . P n_b / M ],
  // P = diag(tool_axes): the axes the tool moves along (a guided axis has infinite mass).
  const double dt2 = dt * dt;
  const double inv_sphere_mass = 1.0 / tool_effective_mass(opt);  // with a coupling: implicit in it
  const Vec3 axes = tool_axes(opt);
  work.delassus.resize(static_cast<size_t>(m) * m);
  double* W = work.delassus.data();
  if (coupled) {
    if (work.contact_response.cols() < static_cast<Eigen::Index>(n) * m)
      work.contact_response.resize(3, static_cast<Eigen::Index>(n) * m);
    for (int b = 0; b < m; ++b) {
      work.rhs.setZero();
      work.rhs.col(candidate[b]) = work.normal.col(b);
      Eigen::Map<Points> response(work.contact_response.data() + 3 * static_cast<size_t>(n) * b, 3, n);
      coupled->solve(work.rhs, work.dv);
      response = work.dv;
      for (int a = 0; a < m; ++a) W[a * m + b] = dt2 * work.normal.col(a).dot(response.col(candidate[a]));
    }
    for (int a = 0; a < m; ++a)  // symmetrise the CG round-off
      for (int b = 0; b < a; ++b) W[a * m + b] = W[b * m + a] = 0.5 * (W[a * m + b] + W[b * m + a]);
  } else {
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) W[a * m + b] = (a == b) ? dt2 * model.inverse_mass[candidate[a]] : 0.0;
  }
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b)
      W[a * m + b] += dt2 * inv_sphere_mass * work.normal.col(a).dot(axes.cwiseProduct(work.normal.col(b)));

  // Replaces the previous contact forces (held over the free motion) by `total`:
  // particles += gain M^-1 (total_a n_a - f_prev,a), the tool likewise with the
  // reactions. Returns the contact force of `total` on the tool.
  const double* previous = work.previous_multiplier.data();
  auto apply = [&](const double* total, double gain, Points& particles, Vec3& indenter) {
    Vec3 sphere_force = Vec3::Zero(), sphere_previous = Vec3::Zero();
    for (int a = 0; a < m; ++a) {
      const int i = candidate[a];
      const Vec3 f = total[a] * work.normal.col(a);
      if (!coupled) {
        particles.col(i) += (gain * model.inverse_mass[i]) * (f - work.previous_force.col(a));
      } else if (total[a] != previous[a]) {
        Eigen::Map<const Points> response(work.contact_response.data() + 3 * static_cast<size_t>(n) * a, 3, n);
        particles += (gain * (total[a] - previous[a])) * response;
      }
      sphere_force -= f;
      sphere_previous -= work.previous_force.col(a);
    }
    indenter += gain * inv_sphere_mass * axes.cwiseProduct(sphere_force - sphere_previous);
    return sphere_force;
  };
  // The LCPs are posed in the total multipliers: g' = (g - W p) + W lambda, p the previous ones.
  auto shift_by_previous = [&](double* g) {
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) g[a] -= W[a * m + b] * previous[b];
  };

  // 1. Position projection.
  work.multiplier.resize(m);
  double* lambda = work.multiplier.data();
  shift_by_previous(work.gap.data());
  int iterations = solve_signorini_lcp(m, W, work.gap.data(), lambda, tolerance, max_iterations, work);
  bool converged = iterations >= 0;
  state.out.contact_iterations = std::max(iterations, 0);
  apply(lambda, dt2, state.position, state.indenter_center);

  // Gaps after the projection: who is touching, and the penetration left.
  for (int a = 0; a < m; ++a) {
    double w = work.gap[a];
    for (int b = 0; b < m; ++b) w += W[a * m + b] * lambda[b];
    work.gap[a] = w;
    state.out.contact_max_penetration = std::max(state.out.contact_max_penetration, -w);
  }

  // 2. Velocity projection on the touching particles; the others are given an
  // infinite separating velocity so that the LCP leaves them at zero force.
  // u_a = n_a . (v_i - v_tool), posed as u dt with W (= W_v dt).
  for (int a = 0; a < m; ++a) {
    const bool touching = work.gap[a] <= 10 * tolerance;
    const Vec3 v_rel = state.velocity.col(candidate[a]) - state.indenter_velocity;
    work.gap[a] = work.normal.col(a).dot(v_rel) * dt;
    if (!touching) work.gap[a] = INFINITY;
  }
  shift_by_previous(work.gap.data());
  double* mu = lambda;  // lambda has been applied: reuse its buffer
  iterations = solve_signorini_lcp(m, W, work.gap.data(), mu, tolerance, max_iterations, work);
  converged = converged && iterations >= 0;
  state.out.contact_iterations += std::max(iterations, 0);
  // mu is the contact force of the step (momentum exchanged / dt): the state reports it.
  state.indenter_contact_force = apply(mu, dt, state.velocity, state.indenter_velocity);
  for (int a = 0; a < m; ++a) {
    if (mu[a] <= 0.0) continue;
    const int slot = static_cast<int>(state.contact_index.size());
    state.contact_index.push_back(candidate[a]);
    state.contact_normal_force.push_back(mu[a]);
    state.contact_force.col(slot) = mu[a] * work.normal.col(a);
  }
  return converged ? StepStatus::ok : StepStatus::contact_not_converged;
}

}  // namespace palpate
