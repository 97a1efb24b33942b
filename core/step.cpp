#include "core/step.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "core/contact.h"
#include "core/health.h"
#include "core/integrators.h"

namespace palpate {

StepStatus step(const Model& model, const Options& opt, State& state) {
  StepStatus status = StepStatus::ok;
  use_threads(model, opt, state);
  const int max_interval = opt.integrator.max_interval;
  if (max_interval > 1 && (opt.integrator.type != IntegratorType::symplectic_euler ||
                           model.rate_schedule.period != max_interval ||
                           opt.integrator.dt > model.rate_schedule.dt))
    throw std::invalid_argument(
        "integrator.max_interval " + std::to_string(max_interval) +
        " needs symplectic Euler, at most the dt and a model whose schedule was built for it (the "
        "scene's integrator: this model's schedule has max_interval " + std::to_string(model.rate_schedule.period) +
        " and dt " + std::to_string(model.rate_schedule.dt) + " s)");
  switch (opt.integrator.type) {
    case IntegratorType::rk4:
      free_motion_rk4(model, opt, state);
      status = solve_contact(model, opt, state);
      break;
    case IntegratorType::symplectic_euler:
      if (opt.integrator.max_interval > 1)
        free_motion_multirate_symplectic_euler(model, opt, state);
      else
        free_motion_symplectic_euler(model, opt, state);
      status = solve_contact(model, opt, state);
      break;
    case IntegratorType::implicit_euler: {
      free_motion_implicit_euler(model, opt, state);
      ImplicitEulerOperator response(model, opt, state);  // A, for the coupled contact response
      status = solve_contact(model, opt, state, &response);
      break;
    }
  }
  return end_step(model, opt, state, status);
}

StepStatus end_step(const Model& model, const Options& opt, State& state, StepStatus status) {
  state.time += opt.integrator.dt;
  ++state.tick;
  if (opt.health.enabled) return check_health(model, opt, state, status);
  // Checks off: only finiteness (a NaN or Inf anywhere in the positions makes their sum non-finite).
  if (!std::isfinite(state.position.sum() + state.indenter_center.sum() + state.indenter_velocity.sum()))
    return StepStatus::non_finite;
  return status;
}

const char* to_string(StepStatus s) {
  switch (s) {
    case StepStatus::ok: return "ok";
    case StepStatus::non_finite: return "non-finite state";
    case StepStatus::contact_not_converged: return "contact solve did not converge";
    case StepStatus::energy_jump: return "energy jump";
    case StepStatus::indenter_speed: return "indenter too fast";
    case StepStatus::penetration: return "penetration beyond tolerance";
    case StepStatus::inverted_particle: return "inverted particle";
  }
  return "?";
}

}  // namespace palpate
