#include "core/health.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <Eigen/LU>

#include "core/mls_forces.h"
#include "core/solid.h"
#include "core/step.h"

namespace palpate {

namespace {

// Kinetic energy 1/2 sum m_i |v_i|^2 + 1/2 M v_c^2 (J), and the gravity potential
// sum m_i g . x_i + M g . c (J) when gravity is on. NaN in, NaN out: the sums carry it.
struct EnergyPass {
  double kinetic = 0.0;
  double gravity_potential = 0.0;
  double position_sum = 0.0;
};

EnergyPass energy_pass(const Model& model, const Options& opt, const State& state) {
  const int n = model.particle_count;
  const auto mass = Eigen::Map<const Eigen::VectorXd>(model.mass.data(), n);
  EnergyPass e;
  // Flat, vectorisable reductions over the 3 x n arrays the step has just written.
  e.kinetic = 0.5 * state.velocity.colwise().squaredNorm().dot(mass.transpose()) +
              0.5 * opt.indenter_mass * state.indenter_velocity.squaredNorm();
  e.position_sum = state.position.sum();
  const Vec3& g = opt.gravity;
  if (g.squaredNorm() > 0) {  // a plain loop: the matrix product would allocate a 1 x n temporary
    const double* x = state.position.data();
    double potential = 0.0;
    for (int i = 0; i < n; ++i) potential += mass[i] * (g[0] * x[3 * i] + g[1] * x[3 * i + 1] + g[2] * x[3 * i + 2]);
    e.gravity_potential = potential + opt.indenter_mass * g.dot(state.indenter_center);
  }
  return e;
}

// The strain of the p-wave whose particle speed sets the energy floor.
constexpr double kEnergyFloorStrain = 1.0 / 400.0;

// The smallest gap |x_i - c| - R between the sphere and a particle, m: one pass, taken only
// when the tool is faster than max_indenter_speed.
double nearest_gap(const Model& model, const State& state) {
  const int n = model.particle_count;
  double nearest2 = INFINITY;
  const Vec3& c = state.indenter_center;
  for (int i = 0; i < n; ++i) nearest2 = std::min(nearest2, (state.position.col(i) - c).squaredNorm());
  return std::sqrt(nearest2) - model.indenter_radius;
}

StepStatus fail(State& state, StepStatus status, int particle, double value, double limit) {
  state.health.report = {status, state.tick, particle, value, limit};
  return status;
}

}  // namespace

HealthLimits health_limits(const Model& model, const Options& opt) {
  const HealthSpec& spec = opt.health;
  const double dt = opt.integrator.dt;
  HealthLimits l;
  l.energy_factor = spec.energy_factor;
  // docs/scene-format.md, "health": 1/2 M (c_p / 400)^2, the kinetic energy of the free
  // body moving at the particle speed of a p-wave of strain 1/400 (c_p of docs/physics.md (1.10);
  // 0.92 cm/s in the default material). It scales with the scene: M ~ L^3, c_p from the material.
  // (The matrix material's c_p: the floor is a scale of the bulk body, not of its inclusions.)
  const double c_p = std::sqrt((model.lame_lambda + 2 * model.lame_mu) / model.density);
  l.energy_floor = 0.5 * model.free_mass * std::pow(kEnergyFloorStrain * c_p, 2);
  l.max_indenter_speed = spec.max_indenter_speed > 0 ? spec.max_indenter_speed : model.min_spacing / dt;
  l.max_penetration =
      spec.max_penetration > 0 ? spec.max_penetration : opt.contact.tolerance + 0.05 * model.min_spacing;
  if (model.solid == SolidKind::mls)
    l.inversion_window = (model.particle_count + spec.inversion_sweep_ticks - 1) / spec.inversion_sweep_ticks;
  return l;
}

void reset_health(const Model& model, const Options& opt, State& state) {
  HealthMonitor& h = state.health;
  const EnergyPass e = energy_pass(model, opt, state);
  const double strain = elastic_energy(model, state.position);
  h.energy_input = e.kinetic + strain;
  h.energy_budget = h.energy_input;
  h.kinetic_energy = e.kinetic;
  h.indenter_position = state.indenter_center;
  h.gravity_potential = e.gravity_potential;
  h.inversion_cursor = 0;
}

StepStatus check_health(const Model& model, const Options& opt, State& state, StepStatus status) {
  HealthMonitor& h = state.health;
  const HealthLimits limits = health_limits(model, opt);

  // Non-finite values, with the kinetic energy: from the explicit integrators' update
  // pass when they took it (its velocities are before the contact impulses, which touch
  // a few particles: the energy limit is a factor 10 wide), else one pass here.
  EnergyPass e;
  StepOutputs& out = state.out;
  if (out.free_motion_sums_valid && opt.gravity.squaredNorm() == 0) {
    e.kinetic = out.free_motion_kinetic + 0.5 * opt.indenter_mass * state.indenter_velocity.squaredNorm();
    e.position_sum = out.free_motion_position_sum;
  } else {
    e = energy_pass(model, opt, state);
  }
  out.free_motion_sums_valid = false;
  if (!std::isfinite(e.kinetic + e.position_sum + state.indenter_center.sum() + state.indenter_contact_force.sum() +
                     state.indenter_velocity.sum()))
    return fail(state, StepStatus::non_finite, -1, NAN, 0.0);
  if (status != StepStatus::ok) return fail(state, status, -1, 0.0, 0.0);

  // Energy: work of the command (F . travel of the tool) and of gravity since the last check.
  const Vec3& c = state.indenter_center;
  h.energy_input += (state.force_command + state.out.coupling_force).dot(c - h.indenter_position) +
                    (e.gravity_potential - h.gravity_potential);
  h.energy_budget = std::max(h.energy_budget, h.energy_input);
  h.indenter_position = c;
  h.gravity_potential = e.gravity_potential;
  h.kinetic_energy = e.kinetic;
  const double energy_limit = limits.energy_factor * h.energy_budget + limits.energy_floor;
  if (e.kinetic > energy_limit) return fail(state, StepStatus::energy_jump, -1, e.kinetic, energy_limit);

  // The speed limit is about contact (the sphere must not pass more than one spacing of the
  // body per step): a tool farther from every particle than it travels in two steps is in
  // free flight (lifted off, the workspace box keeps it in reach) and is not judged.
  if (const double speed = state.indenter_velocity.norm(); speed > limits.max_indenter_speed)
    if (nearest_gap(model, state) <= 2 * speed * opt.integrator.dt)
      return fail(state, StepStatus::indenter_speed, -1, speed, limits.max_indenter_speed);

  // Penetration: the true gap |x_i - c| - R of this step's contact candidates.
  const double R = model.indenter_radius;
  for (const int i : state.out.contact_candidate) {
    const double gap = (state.position.col(i) - state.indenter_center).norm() - R;
    if (!std::isfinite(gap)) return fail(state, StepStatus::non_finite, i, gap, 0.0);
    if (-gap > limits.max_penetration) return fail(state, StepStatus::penetration, i, -gap, limits.max_penetration);
  }

  // Inversion: det F over a rotating window of MLS particles.
  if (limits.inversion_window > 0) {
    const int n = model.particle_count;
    int i = h.inversion_cursor;
    for (int c = 0; c < limits.inversion_window; ++c, ++i) {
      if (i >= n) i = 0;
      if (model.fixed[i]) continue;
      const double J = deformation_gradient(model, state.position, i).determinant();
      if (J <= 0) {
        if (model.volume_stiffness > 0) {
          ++h.inverted;
        } else {
          h.inversion_cursor = i + 1;
          return fail(state, StepStatus::inverted_particle, i, J, 0.0);
        }
      }
    }
    h.inversion_cursor = i >= n ? 0 : i;
  }
  return StepStatus::ok;
}

std::string describe(const HealthReport& r) {
  char text[256];
  const long long tick = static_cast<long long>(r.tick);
  switch (r.status) {
    case StepStatus::ok: std::snprintf(text, sizeof text, "healthy at tick %lld", tick); break;
    case StepStatus::non_finite:
      std::snprintf(text, sizeof text, "non-finite state (NaN or Inf) at tick %lld", tick);
      break;
    case StepStatus::contact_not_converged:
      std::snprintf(text, sizeof text, "contact solve did not converge at tick %lld", tick);
      break;
    case StepStatus::energy_jump:
      std::snprintf(text, sizeof text,
                    "energy jump at tick %lld: kinetic energy %.4g J above the limit %.4g J "
                    "(health.energy_factor x (initial energy + work done) + floor)",
                    tick, r.value, r.limit);
      break;
    case StepStatus::indenter_speed:
      std::snprintf(text, sizeof text,
                    "indenter speed %.4g m/s above the limit %.4g m/s at tick %lld (health.max_indenter_speed)",
                    r.value, r.limit, tick);
      break;
    case StepStatus::penetration:
      std::snprintf(text, sizeof text,
                    "particle %d is %.4g m inside the sphere at tick %lld, beyond the limit %.4g m "
                    "(health.max_penetration)",
                    r.particle, r.value, tick, r.limit);
      break;
    case StepStatus::inverted_particle:
      std::snprintf(text, sizeof text,
                    "particle %d inverted (det F = %.4g) at tick %lld, and the scene has no volume term "
                    "(material.volume_stiffness = 0) to restore it",
                    r.particle, r.value, tick);
      break;
  }
  return text;
}

}  // namespace palpate
