#pragma once
// The indentation measure and rest detection (physics.md §2).
#include <cmath>

#include "core/model.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {

// d = travel of the indenter below the height at which it touches the undeformed
// surface (Model::touch_height), m. Positive when pressing. On a lattice with the
// sphere centred between particles this includes the strain-free sinking between
// them (physics.md §2), as a continuum comparison with Hertz requires.
double indentation(const Model& model, const State& state);

// Largest particle speed, m/s.
double max_particle_speed(const State& state);

// Equilibrium (physics.md §2): over a window of `window` seconds of simulated time
// the contact force balanced the command to force_tolerance (relative) at every
// step, and no particle and not the indenter moved more than
// velocity_tolerance * window (a mean speed below velocity_tolerance). Judging
// displacements rather than instantaneous speeds ignores the O(dt^3) velocity
// residue that RK4's free motion leaves on particles held by the contact projection.
class RestMonitor {
 public:
  explicit RestMonitor(const RestSpec& spec) : spec_(spec) {}
  // Call after every step; true once the criteria have held over a whole window.
  bool update(const Model& model, const State& state);
  void reset() { held_ = -1.0; }

 private:
  void start_window(const State& state);
  RestSpec spec_;
  double held_ = -1.0;  // s since the window started, < 0: no window open
  Points window_start_position_;
  double window_start_indenter_ = 0.0;
};

// Presses the indenter with `force` from the current state and steps until
// RestMonitor reports rest, a health check fails (health.h), or rest.max_time of
// simulated time has passed (the quasi-static loading of palpate-verify). On a
// failed check the state is put back to the last good one (saved every 100 steps)
// and the failure is reported: a NaN never leaves.
struct PressResult {
  bool at_rest = false;
  StepStatus status = StepStatus::ok;  // the last step's status
  HealthReport failure;                // the failed check (status != ok), else empty
  long steps = 0;
  double indentation = 0.0;            // m, at the end
};
// `observer(state)` (optional) is called after every step.
template <class Observer>
PressResult press_to_rest(const Model& model, State& state, double force, Observer&& observer);
PressResult press_to_rest(const Model& model, State& state, double force);

}  // namespace palpate

#include "core/checkpoint.h"
#include "core/step.h"

namespace palpate {

template <class Observer>
PressResult press_to_rest(const Model& model, State& state, double force, Observer&& observer) {
  const RestSpec& spec = model.scene.verify.rest;
  RestMonitor rest(spec);
  state.force_command = force;
  Checkpoint last_good(state);
  PressResult result;
  const long max_steps = static_cast<long>(std::ceil(spec.max_time / model.scene.integrator.dt));
  for (; result.steps < max_steps && !result.at_rest;) {
    result.status = step(model, state);
    ++result.steps;
    if (is_fault(result.status)) {
      result.failure = state.health.report;
      last_good.restore(state);
      result.indentation = indentation(model, state);
      return result;
    }
    observer(state);
    if (result.steps % 100 == 0) last_good.save(state);
    result.at_rest = rest.update(model, state);
  }
  result.indentation = indentation(model, state);
  return result;
}

}  // namespace palpate
