// palpate-stress, study 3: inversion with and without the volume term. Compression
// to inversion with k_v = 0, release of that state with each k_v, a press with
// k_v = E, and the stable dt with each k_v against the predicted scaling.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "analysis/diagnostics.h"
#include "analysis/stability.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "tools/stress/studies.h"

namespace palpate::stress {

json inversion_study(const StressOptions& stress, json& meta) {
  // 14^3 is the smallest uniform cloud on which a released inversion stays stuck without k_v (10^3, 12^3 recover).
  const int per_edge = stress.mode == Mode::full ? 0 : stress.mode == Mode::quick ? 14 : 6;
  const Scene scene = load(stress, "hertz_cube.json", per_edge);
  const Model base = build_model(scene);
  const Options opt = options_of(scene);
  const double E = scene.material.young_modulus;
  const double press_force = 6000.0;
  const double press = stress.mode == Mode::smoke ? 0.2 : 1.5, release = stress.mode == Mode::smoke ? 0.2 : 3.0;
  std::vector<double> kv_over_E = {0, 0.01, 0.1, 1, 10, 100, 1000, 3000, 10000};
  if (stress.mode == Mode::quick) kv_over_E = {0, 0.01, 1, 100, 3000};
  if (stress.mode == Mode::smoke) kv_over_E = {0, 1};
  json out;
  out["cloud"] = cloud_label(base, "uniform");
  out["particles"] = base.particle_count;
  out["integrator"] = to_string(opt.integrator.type);
  out["dt_s"] = opt.integrator.dt;
  out["press_force_n"] = press_force;
  meta["inversion_protocol"] =
      "MLS, the default scene's integrator and dt: (a) pressed from rest with " + std::to_string(press_force) +
      " N for " + std::to_string(press) + " s with k_v = 0 (inverted: det F <= 0); (b) that state released (command 0) for " +
      std::to_string(release) + " s with each k_v: recovered = no inverted particle and max |x - X| < 1 % of dx_min at the end; "
      "(c) the same press from rest with k_v = E: inverted particles under load; (d) the largest stable dt with each k_v "
      "(the envelope's bisection), against dt_max(0) sqrt((lambda + 2 mu) / (lambda + 2 mu + k_v))";

  // (a) the inverted state, made with k_v = 0.
  State pressed = make_state(base, opt);
  const PhaseStats a = run_phase(base, opt, pressed, press_force, press, 10);
  const InversionSummary inv0 = inversion_summary(base, pressed.position);
  progress("inversion: %s pressed with %g N, k_v = 0: d = %.3f m, %d of %d particles inverted (min det F %.3g)",
           cloud_label(base, "uniform").c_str(), press_force, a.indentation, inv0.inverted, inv0.points, inv0.min_jacobian);
  out["pressed"] = a.to_json();
  out["pressed_inverted"] = inv0.inverted;

  stability::TrialSpec trial;
  trial.force = reference_force(scene);
  if (stress.mode == Mode::smoke) {
    trial.duration = 0.05;
    trial.min_steps = 40;
  }
  stability::SearchSpec search;
  search.start = dt_estimate(base);
  search.tolerance = stress.mode == Mode::full ? 0.02 : stress.mode == Mode::quick ? 0.05 : 0.25;
  double dt_max_0 = NAN;
  const double modulus = base.lame_lambda + 2 * base.lame_mu;
  json rows = json::array();
  for (const double ratio : kv_over_E) {
    const double kv = ratio * E;
    Model m = base;
    m.volume_stiffness = kv;  // a model constant (the only copy of the material), not an option
    // (b) release of the inverted state
    State s = pressed;
    double uninverted_at = NAN;
    PhaseStats b;
    const long steps = std::lround(release / opt.integrator.dt);
    const int chunk = 10;
    b.finite = true;
    for (long k = 0; k < steps; k += chunk) {
      const PhaseStats part = run_phase(m, opt, s, 0.0, chunk * opt.integrator.dt, chunk);
      b.max_speed = std::max(b.max_speed, part.max_speed);
      b.max_energy = std::max(b.max_energy, part.max_energy);
      b.max_inverted = std::max(b.max_inverted, part.max_inverted);
      b.steps += part.steps;
      if (!part.finite) {
        b.finite = false;
        break;
      }
      if (part.inverted == 0 && std::isnan(uninverted_at)) uninverted_at = (k + chunk) * opt.integrator.dt;
      if (part.inverted > 0) uninverted_at = NAN;
    }
    const InversionSummary end = b.finite ? inversion_summary(m, s.position) : InversionSummary{NAN, -1, 0};
    const double residual = b.finite ? max_displacement(m, s) : NAN;
    const bool recovered = b.finite && end.inverted == 0 && residual < 0.01 * base.min_spacing;
    // (c) pressing with this k_v from rest (k_v = E only: a press costs minutes at 18^3)
    PhaseStats pc;
    pc.max_inverted = -1;
    pc.min_jacobian = pc.max_indentation = NAN;
    if (ratio == 1) {
      State c = make_state(m, opt);
      pc = run_phase(m, opt, c, press_force, press, 10);
    }
    // (d) the stable step with this k_v
    const stability::Search found = stability::find_stable_dt(m, opt, trial, search);
    if (ratio == 0) dt_max_0 = found.dt_max_stable;
    const double predicted = dt_max_0 * std::sqrt(modulus / (modulus + kv));
    const stability::Trial at_scene_dt = stability::run_trial(m, opt, trial);
    progress("    k_v = %g E: release %s (%s, %d inverted, max |x - X| %.3g m, un-inverted after %.3g s); "
             "pressed: %d inverted; dt_max %.4g s (predicted %.4g), at %g s: %s",
             ratio, recovered ? "recovered" : "NOT recovered", b.finite ? "finite" : "NON-FINITE", end.inverted, residual,
             uninverted_at, pc.max_inverted, found.dt_max_stable, predicted, opt.integrator.dt, at_scene_dt.reason.c_str());
    json row;
    row["kv_pa"] = kv;
    row["kv_over_e"] = ratio;
    row["release_finite"] = b.finite;
    row["release_final_inverted"] = end.inverted;
    row["release_min_jacobian"] = num(end.min_jacobian);
    row["release_residual_m"] = num(residual);
    row["release_uninverted_after_s"] = num(uninverted_at);
    row["recovered"] = recovered;
    row["pressed_max_inverted"] = pc.max_inverted >= 0 ? json(pc.max_inverted) : json(nullptr);
    row["pressed_min_jacobian"] = num(pc.min_jacobian);
    row["pressed_max_indentation_m"] = num(pc.max_indentation);
    row["pressed_finite"] = pc.finite;
    row["dt_max_stable_s"] = num(found.dt_max_stable);
    row["dt_predicted_s"] = num(predicted);
    row["stable_at_scene_dt"] = at_scene_dt.stable;
    row["scene_dt_s"] = opt.integrator.dt;
    rows.push_back(row);
  }
  out["rows"] = rows;
  // The envelope of k_v: recovered from inversion and stable at the scene's dt.
  double lo = NAN, hi = NAN;
  for (const json& r : rows)
    if (r["recovered"].get<bool>() && r["stable_at_scene_dt"].get<bool>() && r["kv_pa"].get<double>() > 0) {
      if (std::isnan(lo)) lo = r["kv_pa"];
      hi = r["kv_pa"];
    }
  out["kv_recovers_and_stable_min_pa"] = num(lo);
  out["kv_recovers_and_stable_max_pa"] = num(hi);
  return out;
}

}  // namespace palpate::stress
