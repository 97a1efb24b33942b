#include "analysis/stability.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "analysis/diagnostics.h"
#include "analysis/rest.h"
#include "core/indentation.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"

namespace palpate::stability {

std::string definition(const TrialSpec& s) {
  char text[512];
  std::snprintf(text, sizeof text,
                "stable: over max(%g s, %ld steps) from rest under the constant force F, no non-finite state, "
                "max particle speed <= %g m/s, indentation in [-R, R], and total energy (body + indenter kinetic + "
                "strain energy) <= %g x (initial energy + F |travel|), checked every 1/50 of the run and at its end",
                s.duration, s.min_steps, s.max_speed, s.energy_factor);
  return text;
}

Trial run_trial(const Model& model, const Options& opt, const TrialSpec& spec) {
  State state = make_state(model, opt);
  state.force_command = press_down(spec.force);
  const double dt = opt.integrator.dt;
  const double R = model.indenter_radius;
  const double z0 = state.indenter_center[2];
  const double e0 = total_energy(model, opt, state);
  const long steps = std::max(spec.min_steps, std::lround(spec.duration / dt));
  const long check_every = std::max(1L, steps / 50);
  Trial t;
  for (long k = 1; k <= steps; ++k) {
    t.steps = k;
    if (step(model, opt, state) == StepStatus::non_finite) {
      t.stable = false;
      t.reason = "non-finite state";
      t.final_indentation = NAN;
      return t;
    }
    const double d = indentation(model, state);
    t.final_indentation = d;
    if (max_particle_speed(state) > spec.max_speed) {
      t.stable = false;
      char reason[64];
      std::snprintf(reason, sizeof reason, "particle speed above %g m/s", spec.max_speed);
      t.reason = reason;
      return t;
    }
    if (d < -R || d > R) {
      t.stable = false;
      t.reason = "indentation outside [-R, R]";
      return t;
    }
    if (k % check_every == 0 || k == steps) {
      const double energy = total_energy(model, opt, state);
      const double bound = spec.energy_factor * (e0 + std::abs(spec.force * (state.indenter_center[2] - z0)));
      if (!(energy <= bound)) {
        t.stable = false;
        char reason[64];
        std::snprintf(reason, sizeof reason, "energy above %g x (initial + work)", spec.energy_factor);
        t.reason = reason;
        return t;
      }
    }
  }
  return t;
}

Search find_stable_dt(const Model& model, const Options& opt, const TrialSpec& trial, const SearchSpec& search,
                      const std::function<void(double, const Trial&)>& progress) {
  Search out;
  double lo = NAN, hi = NAN;
  double failure_dt = INFINITY;  // the smallest unstable dt so far
  auto stable = [&](double dt) {
    Options at_dt = opt;
    at_dt.integrator.dt = dt;
    // One rate: a subcycled scene's schedule is built for its own dt (core/rate_schedule.h).
    at_dt.integrator.max_interval = 1;
    const Trial t = run_trial(model, at_dt, trial);
    ++out.trials;
    if (!t.stable && dt < failure_dt) {
      failure_dt = dt;
      out.unstable_because = t.reason;
    }
    if (progress) progress(dt, t);
    return t.stable;
  };
  const double dt = std::clamp(search.start, search.floor, search.ceiling);
  if (stable(dt)) {
    lo = dt;
    while (lo < search.ceiling) {
      const double next = std::min(2 * lo, search.ceiling);
      if (!stable(next)) {
        hi = next;
        break;
      }
      lo = next;
    }
  } else {
    hi = dt;
    while (hi > search.floor) {
      const double next = std::max(0.5 * hi, search.floor);
      if (stable(next)) {
        lo = next;
        break;
      }
      hi = next;
    }
  }
  if (std::isfinite(lo) && std::isfinite(hi))
    while (hi > (1 + search.tolerance) * lo) {
      const double mid = std::sqrt(lo * hi);
      (stable(mid) ? lo : hi) = mid;
    }
  out.dt_max_stable = lo;
  out.dt_min_unstable = hi;
  return out;
}

}  // namespace palpate::stability
