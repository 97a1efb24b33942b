// palpate-stable-dt: the largest stable time step of a scene's integrator, found
// by bisection on trial runs under a constant commanded force (physics.md §1,
// "Time step": measure the real limit and compare it with 0.3 dx_min / c_p).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "clients/cli.h"
#include "core/indentation.h"
#include "core/mls_forces.h"
#include "core/model.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"

namespace {

using namespace palpate;

const char* kUsage = R"(usage: palpate-stable-dt --scene FILE [options]
Finds the largest stable time step of the scene's integrator by bisection.
  --scene FILE      scene file (JSON)
  --set KEY=VALUE   override a scene field by its dotted path (repeatable)
  --force F         commanded force in N (default: the scene's last verify force, else 150)
  --duration S      simulated seconds per trial (default 1; at least 200 steps are run)
  --tolerance T     stop bisecting when dt_unstable / dt_stable <= 1 + T (default 0.01)
  --json            print one JSON object on stdout (progress stays on stderr)
  --quiet           no progress on stderr
)";

// A trial at time step dt is stable when, at every step of max(duration, 200 dt):
//  - the state is finite (step() never reports non_finite),
//  - no particle moves faster than kMaxSpeed,
//  - the indentation stays in [-R, R],
//  - the total energy (kinetic of body and indenter + strain energy) stays below
//    10 x (initial energy + F |indenter travel|), checked every 1/50 of the run
//    and at its end (the strain energy costs a force evaluation).
constexpr long kMinSteps = 200;     // a slowly growing instability needs steps, not seconds, to show
constexpr double kMaxSpeed = 10.0;  // m/s; the quasi-static runs stay below ~0.1 m/s
const char* kDefinition =
    "stable: over max(duration, 200 steps) from rest under the constant force F, no non-finite state, max particle speed <= 10 m/s, indentation in [-R, R], "
    "and total energy (body + indenter kinetic + strain energy) <= 10 x (initial energy + F |travel|), "
    "checked every 1/50 of the run and at its end";

struct Trial {
  bool stable = true;
  std::string reason = "stable";
  double final_indentation = 0;
};

double kinetic_energy(const Model& model, const State& s) {
  double e = 0.5 * model.indenter_mass * s.indenter_velocity * s.indenter_velocity;
  for (int i = 0; i < model.particle_count; ++i)
    if (model.inverse_mass[i] != 0.0) e += 0.5 * model.mass[i] * s.velocity.col(i).squaredNorm();
  return e;
}

Trial run_trial(const Scene& base, double dt, double force, double duration) {
  Scene scene = base;
  scene.integrator.dt = dt;
  const Model model = build_model(scene);
  State state = make_state(model);
  state.force_command = force;
  const double R = model.indenter_radius;
  const double z0 = state.indenter_center[2];
  const double e0 = kinetic_energy(model, state) + strain_energy(model, state.position);
  const long steps = std::max(kMinSteps, std::lround(duration / dt));
  const long check_every = std::max(1L, steps / 50);
  Trial t;
  for (long k = 1; k <= steps; ++k) {
    if (step(model, state) == StepStatus::non_finite) return {false, "non-finite state", NAN};
    const double d = indentation(model, state);
    if (max_particle_speed(state) > kMaxSpeed) return {false, "particle speed above 10 m/s", d};
    if (d < -R || d > R) return {false, "indentation outside [-R, R]", d};
    if (k % check_every == 0 || k == steps) {
      const double energy = kinetic_energy(model, state) + strain_energy(model, state.position);
      const double bound = 10.0 * (e0 + std::abs(force * (state.indenter_center[2] - z0)));
      if (!(energy <= bound)) return {false, "energy above 10 x (initial + work)", d};
    }
    t.final_indentation = d;
  }
  return t;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file;
  SceneOverrides overrides;
  double force = NAN, duration = 1.0;
  double tolerance = 0.01;
  bool json = false, quiet = false;
  try {
    for (int a = 1; a < argc; ++a) {
      const std::string arg = argv[a];
      auto value = [&]() -> std::string {
        if (a + 1 >= argc) throw std::invalid_argument(arg + " needs a value");
        return argv[++a];
      };
      if (arg == "--scene") scene_file = value();
      else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
      else if (arg == "--force") force = std::stod(value());
      else if (arg == "--duration") duration = std::stod(value());
      else if (arg == "--tolerance") tolerance = std::stod(value());
      else if (arg == "--json") json = true;
      else if (arg == "--quiet") quiet = true;
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
    if (scene_file.empty()) throw std::invalid_argument("--scene FILE is required");
    if (!(duration > 0) || !(tolerance > 0)) throw std::invalid_argument("--duration and --tolerance must be positive");
  } catch (const std::exception& e) {
    std::cerr << "palpate-stable-dt: " << e.what() << "\n\n" << kUsage;
    return 2;
  }

  Scene scene;
  Model model;
  try {
    scene = load_scene(scene_file, overrides);
    model = build_model(scene);
  } catch (const std::exception& e) {
    std::cerr << "palpate-stable-dt: " << e.what() << "\n";
    return 1;
  }
  if (std::isnan(force)) force = scene.verify.forces.empty() ? 150.0 : scene.verify.forces.back();
  const double dt_estimate = 0.3 * model.min_spacing / model.wave_speed;
  const char* integrator = to_string(scene.integrator.type);
  if (!quiet)
    std::fprintf(stderr, "palpate-stable-dt: %s, %d particles, %s, F = %g N, %g s per trial\n", scene.name.c_str(),
                 model.particle_count, integrator, force, duration);

  constexpr double dt_floor = 1e-5, dt_ceiling = 0.1;
  const auto start = std::chrono::steady_clock::now();
  int trials = 0;
  std::string failure;  // why the smallest unstable dt failed
  double failure_dt = INFINITY;
  auto stable = [&](double dt) {
    const Trial t = run_trial(scene, dt, force, duration);
    ++trials;
    if (!t.stable && dt < failure_dt) {
      failure_dt = dt;
      failure = t.reason;
    }
    if (!quiet) std::fprintf(stderr, "  dt = %.4e s: %s (d = %.5f m)\n", dt, t.reason.c_str(), t.final_indentation);
    return t.stable;
  };
  // Bracket [lo stable, hi unstable]: double up from the scene's dt, or halve down.
  double lo = NAN, hi = NAN;
  double dt = std::clamp(scene.integrator.dt, dt_floor, dt_ceiling);
  if (stable(dt)) {
    lo = dt;
    while (lo < dt_ceiling) {
      const double next = std::min(2 * lo, dt_ceiling);
      if (!stable(next)) {
        hi = next;
        break;
      }
      lo = next;
    }
  } else {
    hi = dt;
    while (hi > dt_floor) {
      const double next = std::max(0.5 * hi, dt_floor);
      if (stable(next)) {
        lo = next;
        break;
      }
      hi = next;
    }
  }
  // Geometric bisection of the bracket.
  if (std::isfinite(lo) && std::isfinite(hi))
    while (hi > (1 + tolerance) * lo) {
      const double mid = std::sqrt(lo * hi);
      (stable(mid) ? lo : hi) = mid;
    }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double courant = lo * model.wave_speed / model.min_spacing;  // NaN if nothing was stable
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };

  if (json) {
    nlohmann::json out;
    out["scene"] = scene.name;
    out["particles"] = model.particle_count;
    out["integrator"] = integrator;
    out["force"] = force;
    out["duration"] = duration;
    out["dt_max_stable_s"] = num(lo);
    out["dt_min_unstable_s"] = num(hi);
    out["unstable_because"] = failure;
    out["dt_estimate_s"] = dt_estimate;
    out["courant"] = num(courant);
    out["min_spacing"] = model.min_spacing;
    out["wave_speed"] = model.wave_speed;
    out["neighbors"] = scene.mls.neighbors;
    out["support_factor"] = scene.mls.support_factor;
    out["hourglass"] = scene.mls.hourglass;
    out["indenter_mass"] = model.indenter_mass;
    out["damping"] = scene.integrator.damping;
    out["tolerance"] = tolerance;
    out["trials"] = trials;
    out["wall_seconds"] = wall;
    out["definition"] = kDefinition;
    std::cout << out.dump(2) << "\n";
  } else {
    std::printf("\nstable time step, scene %s: %d particles, %s, F = %g N, %g s per trial\n", scene.name.c_str(),
                model.particle_count, integrator, force, duration);
    std::printf("  %s\n", kDefinition);
    if (std::isfinite(lo))
      std::printf("  dt_max (largest stable)   %.4e s%s\n", lo, std::isfinite(hi) ? "" : " (the ceiling: nothing failed)");
    else
      std::printf("  dt_max (largest stable)   none above %.0e s\n", dt_floor);
    if (std::isfinite(hi)) std::printf("  smallest unstable dt      %.4e s (%s)\n", hi, failure.c_str());
    std::printf("  estimate 0.3 dx_min / c_p %.4e s  (dx_min = %.4g m, c_p = %.4g m/s)\n", dt_estimate,
                model.min_spacing, model.wave_speed);
    std::printf("  c = dt_max c_p / dx_min   %.3f  (estimate: 0.3)\n", courant);
    std::printf("  %d trials, %.1f s\n", trials, wall);
  }
  return std::isfinite(lo) ? 0 : 3;
}
