#include "core/integrators.h"

#include <cmath>

#include "core/mls_forces.h"

namespace palpate {

void add_contact_forces(const State& state, Points& force) {
  for (size_t c = 0; c < state.contact_index.size(); ++c)
    force.col(state.contact_index[c]) += state.contact_force.col(static_cast<Eigen::Index>(c));
}

void particle_accelerations(const Model& model, const State& state, const Points& x, const Points& v, Points& force,
                            Points& acceleration) {
  internal_forces(model, x, force);
  add_contact_forces(state, force);
  const double c = model.scene.integrator.damping;
  const Vec3 g = model.scene.gravity;
  const bool gravity = !g.isZero();
  for (int i = 0; i < model.particle_count; ++i) {
    const double inv_m = model.inverse_mass[i];
    if (inv_m == 0.0) {
      acceleration.col(i).setZero();
      continue;
    }
    acceleration.col(i) = inv_m * force.col(i) - c * v.col(i);
    if (gravity) acceleration.col(i) += g;
  }
}

double indenter_free_acceleration(const Model& model, const State& state) {
  return (state.indenter_contact_force - state.force_command) / model.indenter_mass + model.scene.gravity[2];
}

namespace {

// The indenter under a constant force over the step, integrated exactly.
void indenter_free_motion(const Model& model, State& state, double dt) {
  const double a = indenter_free_acceleration(model, state);
  state.indenter_center[2] += dt * state.indenter_velocity + 0.5 * dt * dt * a;
  state.indenter_velocity += dt * a;
}

}  // namespace

void free_motion_rk4(const Model& model, State& state) {
  const double dt = model.scene.integrator.dt;
  Workspace& w = state.work;
  w.x0 = state.position;
  w.v0 = state.velocity;
  // Stage s: slope of x is v, slope of v is a(x, v).
  const double stage_dt[4] = {0.0, 0.5 * dt, 0.5 * dt, dt};
  for (int s = 0; s < 4; ++s) {
    if (s == 0) {
      w.rk_x[0] = w.v0;
      particle_accelerations(model, state, w.x0, w.v0, w.force, w.rk_v[0]);
    } else {
      state.position = w.x0 + stage_dt[s] * w.rk_x[s - 1];
      state.velocity = w.v0 + stage_dt[s] * w.rk_v[s - 1];
      w.rk_x[s] = state.velocity;
      particle_accelerations(model, state, state.position, state.velocity, w.force, w.rk_v[s]);
    }
  }
  state.position = w.x0 + (dt / 6.0) * (w.rk_x[0] + 2.0 * w.rk_x[1] + 2.0 * w.rk_x[2] + w.rk_x[3]);
  state.velocity = w.v0 + (dt / 6.0) * (w.rk_v[0] + 2.0 * w.rk_v[1] + 2.0 * w.rk_v[2] + w.rk_v[3]);
  indenter_free_motion(model, state, dt);

}

void free_motion_symplectic_euler(const Model& model, State& state) {
  const double dt = model.scene.integrator.dt;
  Workspace& w = state.work;
  particle_accelerations(model, state, state.position, state.velocity, w.force, w.rk_v[0]);
  state.velocity += dt * w.rk_v[0];
  state.position += dt * state.velocity;
  state.indenter_velocity += dt * indenter_free_acceleration(model, state);
  state.indenter_center[2] += dt * state.indenter_velocity;
}

ImplicitEulerOperator::ImplicitEulerOperator(const Model& model, State& state) : model_(model), state_(state) {}

void ImplicitEulerOperator::apply(const Points& p, Points& Ap) {
  const double dt = model_.scene.integrator.dt;
  const double mass_factor = 1.0 + dt * model_.scene.integrator.damping;
  force_differential(model_, state_.work.cached_F, state_.work.cached_S, p, Ap);  // -K p
  for (int i = 0; i < model_.particle_count; ++i) {
    if (model_.inverse_mass[i] == 0.0)
      Ap.col(i).setZero();
    else
      Ap.col(i) = mass_factor * model_.mass[i] * p.col(i) - dt * dt * Ap.col(i);
  }
}

int ImplicitEulerOperator::conjugate_gradient(const Points& b, Points& x) {
  Workspace& w = state_.work;
  const double dt = model_.scene.integrator.dt;
  const double mass_factor = 1.0 + dt * model_.scene.integrator.damping;
  const int n = model_.particle_count;
  x.setZero();
  w.cg_r = b;
  for (int i = 0; i < n; ++i)
    if (model_.inverse_mass[i] == 0.0) w.cg_r.col(i).setZero();
  const double b_norm = w.cg_r.norm();
  if (b_norm == 0.0) return 0;
  auto precondition = [&](const Points& r, Points& z) {  // Jacobi on the mass part
    for (int i = 0; i < n; ++i) z.col(i) = r.col(i) * (model_.inverse_mass[i] / mass_factor);
  };
  precondition(w.cg_r, w.cg_z);
  w.cg_p = w.cg_z;
  double rz = (w.cg_r.array() * w.cg_z.array()).sum();
  const double tolerance = model_.scene.integrator.cg_tolerance * b_norm;
  const int max_iterations = model_.scene.integrator.cg_max_iterations;
  for (int it = 1; it <= max_iterations; ++it) {
    apply(w.cg_p, w.cg_Ap);
    const double alpha = rz / (w.cg_p.array() * w.cg_Ap.array()).sum();
    x += alpha * w.cg_p;
    w.cg_r -= alpha * w.cg_Ap;
    if (w.cg_r.norm() <= tolerance) return it;
    precondition(w.cg_r, w.cg_z);
    const double rz_next = (w.cg_r.array() * w.cg_z.array()).sum();
    w.cg_p = w.cg_z + (rz_next / rz) * w.cg_p;
    rz = rz_next;
  }
  return -1;
}

void ImplicitEulerOperator::solve(const Points& load, Points& out) { conjugate_gradient(load, out); }

void free_motion_implicit_euler(const Model& model, State& state) {
  const double dt = model.scene.integrator.dt;
  const double c = model.scene.integrator.damping;
  Workspace& w = state.work;
  const Vec3 g = model.scene.gravity;
  linearize_forces(model, state.position, w.cached_F, w.cached_S);
  internal_forces(model, state.position, w.force);
  add_contact_forces(state, w.force);
  force_differential(model, w.cached_F, w.cached_S, state.velocity, w.cg_Ap);  // -K v
  for (int i = 0; i < model.particle_count; ++i) {
    const double m_i = model.mass[i];
    w.rhs.col(i) = dt * (w.force.col(i) + m_i * g - c * m_i * state.velocity.col(i)) + dt * dt * w.cg_Ap.col(i);
  }
  ImplicitEulerOperator op(model, state);
  state.cg_iterations = op.conjugate_gradient(w.rhs, w.dv);
  state.velocity += w.dv;
  state.position += dt * state.velocity;
  state.indenter_velocity += dt * indenter_free_acceleration(model, state);
  state.indenter_center[2] += dt * state.indenter_velocity;
}

}  // namespace palpate
