#include "analysis/exact_coupled_contact.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/contact.h"
#include "core/health.h"
#include "core/integrators.h"

namespace palpate {

StepStatus solve_contact_exact_delassus(const Model& model, const Options& opt, State& state) {
  Workspace& work = state.work;
  const int n = model.particle_count;
  const double R = model.indenter_radius;
  const double dt = opt.integrator.dt;
  const Vec3 c = state.indenter_center;
  const double tolerance = opt.contact.tolerance;
  const int max_iterations = opt.contact.max_iterations;
  std::vector<int>& candidate = state.out.contact_candidate;

  // Candidates: free particles inside the sphere after the free motion, and those in
  // contact at the previous step, whose forces p the free motion carried.
  std::vector<double> gap, previous;
  Points normal(3, n), previous_force(3, n);
  std::vector<int> slot(n, -1);
  candidate.clear();
  auto add_candidate = [&](int i) {
    const Vec3 r = state.position.col(i) - c;
    const double dist = r.norm();
    const int a = static_cast<int>(candidate.size());
    candidate.push_back(i);
    gap.push_back(dist - R);
    normal.col(a) = dist > 0 ? Vec3(r / dist) : Vec3(0, 0, -1);
    previous.push_back(0.0);
    previous_force.col(a).setZero();
    slot[i] = a;
  };
  for (int i = 0; i < n; ++i)
    if (model.inverse_mass[i] != 0.0 && (state.position.col(i) - c).squaredNorm() < R * R) add_candidate(i);
  for (size_t k = 0; k < state.contact_index.size(); ++k) {
    const int i = state.contact_index[k];
    if (slot[i] < 0) add_candidate(i);
    const int a = slot[i];
    previous_force.col(a) = state.contact_force.col(static_cast<Eigen::Index>(k));
    previous[a] = previous_force.col(a).dot(normal.col(a));
  }
  const int m = static_cast<int>(candidate.size());
  state.contact_index.clear();
  state.contact_normal_force.clear();
  state.indenter_contact_force.setZero();
  state.out.contact_iterations = 0;
  state.out.contact_max_penetration = 0.0;
  if (m == 0) return StepStatus::ok;

  // W_ab = dt^2 [n_a . r^(b)_a + n_a . P n_b / M], r^(b) = A^-1 (unit force n_b on particle b).
  const double dt2 = dt * dt;
  const double inv_sphere_mass = 1.0 / tool_effective_mass(opt);
  const Vec3 axes = tool_axes(opt);
  ImplicitEulerOperator A(model, opt, state);
  std::vector<Points> response(m, Points(3, n));
  std::vector<double> W(static_cast<size_t>(m) * m);
  Points load(3, n);
  for (int b = 0; b < m; ++b) {
    load.setZero();
    load.col(candidate[b]) = normal.col(b);
    A.conjugate_gradient(load, response[b]);
    for (int a = 0; a < m; ++a) W[a * m + b] = dt2 * normal.col(a).dot(response[b].col(candidate[a]));
  }
  for (int a = 0; a < m; ++a)  // symmetrise the CG round-off
    for (int b = 0; b < a; ++b) W[a * m + b] = W[b * m + a] = 0.5 * (W[a * m + b] + W[b * m + a]);
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b) W[a * m + b] += dt2 * inv_sphere_mass * normal.col(a).dot(axes.cwiseProduct(normal.col(b)));

  // Replaces the contact forces p held over the free motion by `total` (particles through
  // the responses, the tool through its mass); returns the contact force on the tool.
  auto apply = [&](const std::vector<double>& total, double gain, Points& particles, Vec3& indenter) {
    Vec3 sphere_force = Vec3::Zero(), sphere_previous = Vec3::Zero();
    for (int a = 0; a < m; ++a) {
      if (total[a] != previous[a]) particles += (gain * (total[a] - previous[a])) * response[a];
      sphere_force -= total[a] * normal.col(a);
      sphere_previous -= previous_force.col(a);
    }
    indenter += gain * inv_sphere_mass * axes.cwiseProduct(sphere_force - sphere_previous);
    return sphere_force;
  };
  auto shift_by_previous = [&](std::vector<double>& g) {  // the LCPs in the total multipliers
    for (int a = 0; a < m; ++a)
      for (int b = 0; b < m; ++b) g[a] -= W[a * m + b] * previous[b];
  };

  // Positions.
  std::vector<double> lambda(m);
  shift_by_previous(gap);
  int iterations = solve_signorini_lcp(m, W.data(), gap.data(), lambda.data(), tolerance, max_iterations, work);
  bool converged = iterations >= 0;
  state.out.contact_iterations = std::max(iterations, 0);
  apply(lambda, dt2, state.position, state.indenter_center);
  for (int a = 0; a < m; ++a) {
    for (int b = 0; b < m; ++b) gap[a] += W[a * m + b] * lambda[b];
    state.out.contact_max_penetration = std::max(state.out.contact_max_penetration, -gap[a]);
  }

  // Velocities of the touching particles.
  for (int a = 0; a < m; ++a) {
    const bool touching = gap[a] <= 10 * tolerance;
    gap[a] = touching ? normal.col(a).dot(state.velocity.col(candidate[a]) - state.indenter_velocity) * dt : INFINITY;
  }
  shift_by_previous(gap);
  std::vector<double> mu(m);
  iterations = solve_signorini_lcp(m, W.data(), gap.data(), mu.data(), tolerance, max_iterations, work);
  converged = converged && iterations >= 0;
  state.out.contact_iterations += std::max(iterations, 0);
  state.indenter_contact_force = apply(mu, dt, state.velocity, state.indenter_velocity);
  for (int a = 0; a < m; ++a) {
    if (mu[a] <= 0.0) continue;
    const int k = static_cast<int>(state.contact_index.size());
    state.contact_index.push_back(candidate[a]);
    state.contact_normal_force.push_back(mu[a]);
    state.contact_force.col(k) = mu[a] * normal.col(a);
  }
  return converged ? StepStatus::ok : StepStatus::contact_not_converged;
}

StepStatus step_implicit_euler_exact(const Model& model, const Options& opt, State& state) {
  free_motion_implicit_euler(model, opt, state);
  StepStatus status = solve_contact_exact_delassus(model, opt, state);
  state.time += opt.integrator.dt;
  ++state.tick;
  if (opt.health.enabled) return check_health(model, opt, state, status);
  if (!std::isfinite(state.position.sum() + state.indenter_center.sum() + state.indenter_velocity.sum()))
    return StepStatus::non_finite;
  return status;
}

}  // namespace palpate
