#pragma once
// Time integrators: the free motion of one step (elastic, damping, gravity and
// the commanded indenter force); contact is projected afterwards by solve_contact.
#include "core/contact.h"
#include "core/model.h"
#include "core/options.h"
#include "core/state.h"

namespace palpate {

// The free motion carries the contact forces of the previous step as external
// forces held over the step; the contact projections then correct them to the
// forces of this step (solve_contact). At rest nothing needs correcting, so the
// rest state of every integrator is the static equilibrium.

// force += the contact forces of state (previous step) on their particles.
void add_contact_forces(const State& state, Points& force);

// a = M^-1 (f_int(x) + f_contact + m g) - c v for the particles (zero for fixed
// ones); writes 3 x n. f_contact from state's previous contact forces.
void particle_accelerations(const Model& model, const Options& opt, const State& state, const Points& x,
                            const Points& v, Points& force_scratch, Points& acceleration);

// The tool's free acceleration: (F_contact,previous + F_command) / M + g on the axes the
// tool has (tool_axes), 0 on the ones its guide holds.
Vec3 indenter_free_acceleration(const Options& opt, const State& state);

// The tool's mass as the contact sees it over one step: M, or with the virtual coupling
// on, M + dt b + dt^2 k (the coupling is implicit in the tool's step), kg.
double tool_effective_mass(const Options& opt);

// The tool's free motion of symplectic and implicit Euler: v += dt a, x += dt v; with
// the coupling on, implicit in it (docs/physics.md §2, "The indenter (the tool)", (2.6)). Writes
// state.out.coupling_force; ends with keep_tool_in_workspace.
void tool_free_motion(const Model& model, const Options& opt, State& state);

// Puts a tool centre outside Model's tool workspace back on its boundary and removes
// the outward component of its velocity (the free motion's last stage).
void keep_tool_in_workspace(const Model& model, State& state);

// Classical fourth-order Runge-Kutta on (x, v) (the paper's integrator).
void free_motion_rk4(const Model& model, const Options& opt, State& state);
// Symplectic (semi-implicit) Euler: v += dt a(x, v); x += dt v.
void free_motion_symplectic_euler(const Model& model, const Options& opt, State& state);
// Multirate symplectic Euler (opt.integrator.max_interval > 1, Model::rate_schedule; docs/physics.md
// (1.21)): at tick t the particles whose phase is t mod k_i, and the coarse ones near the tool,
// take their elastic force times the ticks since their last update (State::elastic_update_tick),
// the others none; contact, damping and gravity act on all; then v += dt a; x += dt v.
void free_motion_multirate_symplectic_euler(const Model& model, const Options& opt, State& state);
// The step operator of linearly implicit Euler, A = (1 + dt c) M + dt^2 K over the
// free particles, K the tangent stiffness cached in state.work by linearize_elastic (solid.h).
// It is also the coupled response of the contact solve of that step.
class ImplicitEulerOperator final : public LinearResponse {
 public:
  ImplicitEulerOperator(const Model& model, const Options& opt, State& state);
  void apply(const Points& p, Points& Ap);
  // Jacobi-preconditioned CG for A x = b from x = 0, until the residual over the free
  // particles is at most residual_norm (N), or cg_tolerance |b| when residual_norm < 0;
  // iterations used (0 when x = 0 is close enough), -1 if not converged.
  int conjugate_gradient(const Points& b, Points& x, double residual_norm = -1.0);
  int solve(const Points& load, Points& out, double residual_norm) override;

 private:
  const Model& model_;
  const Options& opt_;
  State& state_;
};

// Linearly implicit Euler (one Newton step, Baraff-Witkin form):
// [(1 + dt c) M + dt^2 K] dv = dt (f + M g - c M v) - dt^2 K v;  v += dv; x += dt v.
void free_motion_implicit_euler(const Model& model, const Options& opt, State& state);

}  // namespace palpate
