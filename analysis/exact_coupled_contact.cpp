#include "analysis/exact_coupled_contact.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/contact.h"
#include "core/health.h"
#include "core/integrators.h"
#include "core/step.h"

namespace palpate {

StepStatus solve_contact_exact_delassus(const Model& model, const Options& opt, State& state) {
  Workspace& work = state.work;
  const int n = model.particle_count;
  const double dt = opt.integrator.dt;
  const double tolerance = opt.contact.tolerance;
  const int max_iterations = opt.contact.max_iterations;
  const std::vector<int>& candidate = state.out.contact_candidate;

  // The candidates, their gaps, normals and previous forces p: core's own first stage.
  const int m = gather_contact_candidates(model, state);
  if (m == 0) return StepStatus::ok;
  std::vector<double>& gap = work.gap;
  const std::vector<double>& previous = work.previous_multiplier;
  const Points& normal = work.normal;
  const Points& previous_force = work.previous_force;

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
  return end_step(model, opt, state, solve_contact_exact_delassus(model, opt, state));
}

}  // namespace palpate
