#pragma once
// Rest detection and the quasi-static loading of a verification run (docs/physics.md §2):
// what palpate-verify and the static solve need and a real-time loop never runs.
#include <cmath>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate {

// Largest particle speed, m/s.
double max_particle_speed(const State& state);

// Equilibrium (docs/physics.md §2): over a window of `window` seconds of simulated time
// the contact force on the tool balanced the command (|F_contact + F_command| relative
// to |F_command|) to force_tolerance at every
// step, and no particle and not the indenter moved more than
// velocity_tolerance * window (a mean speed below velocity_tolerance). Judging
// displacements rather than instantaneous speeds ignores the O(dt^3) velocity
// residue that RK4's free motion leaves on particles held by the contact projection.
class RestMonitor {
 public:
  explicit RestMonitor(const RestSpec& spec) : spec_(spec) {}
  // Call after every step taken with `opt`; true once the criteria have held over a
  // whole window. The balance is judged on the axes the tool has (a guide takes the rest).
  bool update(const State& state, const Options& opt);
  void reset() { held_ = -1.0; }

 private:
  void start_window(const State& state);
  RestSpec spec_;
  double held_ = -1.0;  // s since the window started, < 0: no window open
  Points window_start_position_;
  Vec3 window_start_indenter_{0, 0, 0};
};

// Presses the indenter down (-z) with `force` from the current state and steps until
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
PressResult press_to_rest(const Model& model, const Options& opt, const RestSpec& rest, State& state, double force,
                          Observer&& observer);
PressResult press_to_rest(const Model& model, const Options& opt, const RestSpec& rest, State& state, double force);

}  // namespace palpate

#include "core/checkpoint.h"
#include "core/indentation.h"
#include "core/step.h"

namespace palpate {

template <class Observer>
PressResult press_to_rest(const Model& model, const Options& opt, const RestSpec& spec, State& state, double force,
                          Observer&& observer) {
  RestMonitor rest(spec);
  state.force_command = press_down(force);
  Checkpoint last_good(state);
  PressResult result;
  const long max_steps = static_cast<long>(std::ceil(spec.max_time / opt.integrator.dt));
  for (; result.steps < max_steps && !result.at_rest;) {
    result.status = step(model, opt, state);
    ++result.steps;
    if (is_fault(result.status)) {
      result.failure = state.health.report;
      last_good.restore(state);
      result.indentation = indentation(model, state);
      return result;
    }
    observer(state);
    if (result.steps % 100 == 0) last_good.save(state);
    result.at_rest = rest.update(state, opt);
  }
  result.indentation = indentation(model, state);
  return result;
}

}  // namespace palpate
