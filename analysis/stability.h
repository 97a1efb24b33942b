#pragma once
// The stable time step of a model by bisection on trial runs: one definition of
// "stable" and one search, shared by palpate-stable-dt and palpate-stress
// (docs/physics.md §1, "Time step": measure the real limit, compare with c dx_min / c_p).
#include <cmath>
#include <functional>
#include <string>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

namespace palpate::stability {

// A trial at time step dt runs max(duration, min_steps dt) from rest under the
// constant commanded force F and is stable when, at every step:
//  - the state is finite (step() never reports non_finite),
//  - no particle moves faster than max_speed,
//  - the indentation stays in [-R, R],
//  - the total energy (kinetic of body and indenter + strain energy) stays below
//    energy_factor x (initial energy + F |indenter travel|), checked every 1/50 of
//    the run and at its end (the strain energy costs a force evaluation).
struct TrialSpec {
  double force = 150.0;       // N
  double duration = 1.0;      // s of simulated time (at least min_steps steps)
  long min_steps = 200;       // a slowly growing instability needs steps, not seconds, to show
  double max_speed = 10.0;    // m/s; the quasi-static runs stay below ~0.1 m/s
  double energy_factor = 10.0;
};
// The definition above with the numbers of `spec`, for the tools' output.
std::string definition(const TrialSpec& spec);

struct Trial {
  bool stable = true;
  std::string reason = "stable";
  double final_indentation = 0;
  long steps = 0;  // steps run (fewer than planned when it failed)
};

// One trial of `model` with the options `opt` (at opt.integrator.dt).
Trial run_trial(const Model& model, const Options& opt, const TrialSpec& spec);

struct SearchSpec {
  double start = 1e-3;        // s, the first dt tried (the bracket doubles up or halves down from it)
  double floor = 1e-5;        // s, the smallest dt tried
  double ceiling = 0.1;       // s, the largest dt tried: "stable at the ceiling" means >= ceiling
  double tolerance = 0.01;    // stop when dt_unstable / dt_stable <= 1 + tolerance
};

struct Search {
  double dt_max_stable = NAN;    // largest stable dt found (NaN: none down to the floor)
  double dt_min_unstable = NAN;  // smallest unstable dt found (NaN: stable up to the ceiling)
  std::string unstable_because;  // why dt_min_unstable failed
  int trials = 0;
  bool at_ceiling() const { return dt_max_stable == dt_max_stable && dt_min_unstable != dt_min_unstable; }
};

// Brackets [stable, unstable] by doubling up or halving down from search.start,
// then bisects geometrically; every trial runs `opt` with its dt replaced.
// `progress(dt, trial)` (optional) after every trial.
Search find_stable_dt(const Model& model, const Options& opt, const TrialSpec& trial, const SearchSpec& search,
                      const std::function<void(double, const Trial&)>& progress = {});

}  // namespace palpate::stability
