// palpate-stress, study 5: the long run. 10^6 steps (--long-steps) of symplectic
// Euler under a periodic force command (the energy drift), then the rest state
// under the sweep's largest force against a fresh press (the residual motion).
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "analysis/diagnostics.h"
#include "analysis/rest.h"
#include "core/indentation.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"
#include "tools/stress/studies.h"

namespace palpate::stress {

json long_run_study(const StressOptions& stress, json& meta, json& per_period) {
  const long long steps = stress.long_steps > 0 ? stress.long_steps : stress.mode == Mode::full ? 1000000 : stress.mode == Mode::quick ? 10000 : 500;
  const int per_edge = stress.mode == Mode::smoke ? 6 : 0;  // the default 18^3 even in --quick (10^4 steps are cheap)
  const Scene scene = load(stress, "hertz_cube.json", per_edge);
  const Model model = build_model(scene);
  Options opt = options_of(scene);  // the scene's damping
  opt.integrator.type = IntegratorType::symplectic_euler;
  opt.integrator.dt = 1e-3;
  const double period = 1.0, F_mid = 170.0, F_amp = 157.0;  // 13 ... 327 N, the Hertz sweep's range
  const long per = std::lround(period / 1e-3);
  meta["long_run_protocol"] =
      "MLS " + cloud_label(model, "uniform") + ", symplectic Euler at 1 ms (the cheapest stable explicit step), damping " +
      std::to_string(scene.integrator.damping) + "/s; command F(t) = 170 + 157 sin(2 pi t / 1 s) N for the steps run; "
      "energy sampled at phase 0 of every period (drift: least-squares slope over the second half, relative to its mean); "
      "then F = 327.6 N until at rest (the scene's rest criteria) and 1 s more: the largest particle speed and travel in "
      "that second (residual motion) and the rest indentation against a fresh press to 327.6 N";
  const auto t0 = Clock::now();
  State s = make_state(model, opt);
  bool finite = true;
  long long done = 0;
  double max_d = -INFINITY, max_speed = 0, max_energy = 0;
  std::vector<double> pt, pe;
  for (; done < steps; ++done) {
    s.force_command = press_down(F_mid + F_amp * std::sin(2 * M_PI * s.time / period));
    if (step(model, opt, s) == StepStatus::non_finite) {
      finite = false;
      break;
    }
    max_d = std::max(max_d, indentation(model, s));
    max_speed = std::max(max_speed, max_particle_speed(s));
    if ((done + 1) % per == 0 || done + 1 == steps) {
      const double e = total_energy(model, opt, s);
      max_energy = std::max(max_energy, e);
      const InversionSummary inv = inversion_summary(model, s.position);
      per_period.push_back({{"t_s", s.time}, {"energy_j", e}, {"indentation_m", indentation(model, s)},
                            {"max_speed_m_s", max_particle_speed(s)}, {"inverted", inv.inverted}});
      if ((done + 1) % per == 0) {
        pt.push_back(s.time);
        pe.push_back(e);
      }
      if ((done + 1) % (100 * per) == 0)
        progress("long run: %lld of %lld steps, E(phase 0) = %.6g J, d = %.4f m", done + 1, steps, e, indentation(model, s));
    }
  }
  json out;
  out["cloud"] = cloud_label(model, "uniform");
  out["particles"] = model.particle_count;
  out["integrator"] = "symplectic_euler";
  out["dt_s"] = 1e-3;
  out["steps"] = done;
  out["finite"] = finite;
  out["wall_s"] = seconds_since(t0);
  out["max_indentation_m"] = num(max_d);
  out["max_speed_m_s"] = max_speed;
  out["max_energy_j"] = max_energy;
  // drift of the stroboscopic energy over the second half
  double drift = NAN, mean = NAN, first = NAN, last = NAN;
  if (pe.size() >= 4) {
    const size_t h = pe.size() / 2;
    double st = 0, se = 0, stt = 0, ste = 0;
    const double n = static_cast<double>(pe.size() - h);
    for (size_t k = h; k < pe.size(); ++k) {
      st += pt[k];
      se += pe[k];
      stt += pt[k] * pt[k];
      ste += pt[k] * pe[k];
    }
    drift = (n * ste - st * se) / (n * stt - st * st);
    mean = se / n;
    first = pe[h];
    last = pe.back();
  }
  out["energy_phase0_mean_j"] = num(mean);
  out["energy_drift_j_per_s"] = num(drift);
  out["energy_drift_relative_per_1000_s"] = num(drift * 1000 / mean);
  out["energy_phase0_second_half_first_j"] = num(first);
  out["energy_phase0_last_j"] = num(last);
  out["periods"] = pe.size();
  if (finite) {
    const double F_ref = reference_force(scene);
    const PressResult rest = press_to_rest(model, opt, scene.verify.rest, s, F_ref);
    const Points x0 = s.position;
    const double z0 = s.indenter_center[2];
    double speed = 0, indenter_speed = 0;
    const long window = std::lround(1.0 / 1e-3);
    for (long k = 0; k < window; ++k) {
      step(model, opt, s);
      speed = std::max(speed, max_particle_speed(s));
      indenter_speed = std::max(indenter_speed, s.indenter_velocity.norm());
    }
    const double travel = (s.position - x0).colwise().norm().maxCoeff();
    State fresh = make_state(model, opt);
    const PressResult fresh_rest = press_to_rest(model, opt, scene.verify.rest, fresh, F_ref);
    const std::vector<double> sign = checkerboard_sign(model);
    out["rest_reached"] = rest.at_rest;
    out["rest_steps"] = rest.steps;
    out["rest_indentation_m"] = rest.indentation;
    out["fresh_rest_indentation_m"] = fresh_rest.indentation;
    out["rest_indentation_difference_m"] = rest.indentation - fresh_rest.indentation;
    out["rest_max_position_difference_m"] = (x0 - fresh.position).colwise().norm().maxCoeff();
    out["residual_max_speed_m_s"] = speed;
    out["residual_max_travel_m"] = travel;
    out["residual_indenter_travel_m"] = std::abs(s.indenter_center[2] - z0);
    out["residual_indenter_max_speed_m_s"] = indenter_speed;
    out["rest_checkerboard_m"] = checkerboard_amplitude(model, sign, x0);
    out["rest_inverted"] = inversion_summary(model, x0).inverted;
    progress("long run: %lld steps in %.0f s, energy drift %.3g J/s (%.3g of the mean per 1000 s); at rest: max speed %.3g m/s, "
             "travel %.3g m in 1 s, d - d_fresh = %.3g m",
             done, seconds_since(t0), drift, drift * 1000 / mean, speed, travel, rest.indentation - fresh_rest.indentation);
  }
  return out;
}

}  // namespace palpate::stress
