// palpate-bench-contact-stiffness: the cost of the local contact model
// (core/contact_stiffness.h, docs/physics.md §2 "The local contact model") on a scene
// pressed into its rest state, then run at the scene's own rate with a command that
// varies slowly (a haptic session's frame-to-frame change), single thread:
//   - warm: ContactStiffness::evaluate() after every step, warm-started from the
//     previous tick's solution (what a server computing it every tick pays);
//   - cold: the same states with the warm starts cleared before each evaluation;
//   - step: one step() of the scene's integrator on the same run, for comparison;
//   - the tangent product of the three directions at the last state, as three products
//     and as one sweep (elastic_force_differentials, what the solves use).
// Figures are medians (and 90th percentiles, maxima) over the ticks (std::chrono::steady_clock).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "analysis/rest.h"
#include "cli/arguments.h"
#include "core/checkpoint.h"
#include "core/contact_stiffness.h"
#include "core/indentation.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "tools/load_scene.h"

namespace {

using namespace palpate;
using Clock = std::chrono::steady_clock;

const char* kUsage = R"(usage: palpate-bench-contact-stiffness [options]
Times the local contact model (K = dF/dx, its validity radius) on a pressed scene:
cold (no warm start) and warm-started from the previous tick while the scene runs at
its own dt under a slowly varying command; prints medians.
  --scene FILE        scene file (default: scenes/hertz_cube_haptic.json of the source tree)
  --per-edge N        override body.distribution.per_edge
  --set KEY=VALUE     override a scene field by its dotted path (repeatable)
  --force N           pressing force of the rest state (default 100)
  --amplitude N       amplitude of the command's variation about --force (default 5)
  --period SECONDS    its period (default 0.5)
  --ticks N           steps timed (default 200)
  --tolerance X       relative residual of the projected CG (default: the server's,
                      kRenderingStiffness, 1e-2)
  --max-iterations N  per solve (default 2000)
  --coarse N          nodes per axis of the preconditioner's coarse lattice, 0 (block
                      Jacobi alone) or 2 ... 12 (default: the server's, 6)
  --json              print one JSON object instead of the table
Exit status: 0, 1 on a scene that does not load or a press that fails, 2 on a wrong argument.
)";

struct Stats {
  double min = 0, p10 = 0, median = 0, p90 = 0, max = 0;
};
Stats stats(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  const size_t k = v.size() / 2;
  s.median = v.size() % 2 ? v[k] : 0.5 * (v[k - 1] + v[k]);
  s.p90 = v[std::min(v.size() - 1, static_cast<size_t>(0.9 * static_cast<double>(v.size())))];
  s.min = v.front();
  s.p10 = v[static_cast<size_t>(0.1 * static_cast<double>(v.size()))];
  s.max = v.back();
  return s;
}
nlohmann::json to_json(const Stats& s) {
  return {{"min", s.min}, {"p10", s.p10}, {"median", s.median}, {"p90", s.p90}, {"max", s.max}};
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path scene_file = std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube_haptic.json";
  SceneOverrides overrides;
  double force = 100.0, amplitude = 5.0, period = 0.5;
  int ticks = 200;
  ContactStiffnessSettings settings = kRenderingStiffness;
  bool json_out = false;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      if (arg == "--scene") scene_file = args.value();
      else if (arg == "--per-edge") overrides.emplace_back("body.distribution.per_edge", args.value());
      else if (arg == "--set") overrides.push_back(cli::scene_override(args.value()));
      else if (arg == "--force") force = args.number(0.0, 1e6);
      else if (arg == "--amplitude") amplitude = args.number(0.0, 1e6);
      else if (arg == "--period") period = args.number(1e-6, 1e6);
      else if (arg == "--ticks") ticks = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--tolerance") settings.tolerance = args.number(1e-15, 0.5);
      else if (arg == "--max-iterations") settings.max_iterations = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--coarse") settings.coarse_per_axis = static_cast<int>(args.integer(0, 12));
      else if (arg == "--json") json_out = true;
      else if (args.help()) {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-bench-contact-stiffness: " << e.what() << "\n\n" << kUsage;
    return 2;
  }
  std::optional<tools::LoadedScene> loaded =
      tools::load_scene_and_model("palpate-bench-contact-stiffness", scene_file, overrides);
  if (!loaded) return 1;
  const Model& model = loaded->model;
  const Options& opt = loaded->opt;

  // The rest state under --force: the scene's own damped dynamics until the rest criteria
  // hold (palpate-verify's dynamic settle; untimed).
  State state = make_state(model, opt);
  const auto p0 = Clock::now();
  const PressResult rest = press_to_rest(model, opt, loaded->scene.verify.rest, state, force);
  const double press_s = std::chrono::duration<double>(Clock::now() - p0).count();
  if (!rest.at_rest || state.contact_index.empty()) {
    std::cerr << "palpate-bench-contact-stiffness: pressing to rest at " << force << " N failed after " << rest.steps
              << " steps (" << state.contact_index.size() << " contacts)\n";
    return 1;
  }

  const auto b0 = Clock::now();
  ContactStiffness stiffness(model, settings);
  const double build_ms = std::chrono::duration<double, std::milli>(Clock::now() - b0).count();
  ContactStiffness cold(model, settings);
  std::vector<double> warm_ms, cold_ms, step_ms, warm_it, cold_it, radius, active;
  int not_converged = 0, bad_steps = 0, limited_by_entering = 0, limited_by_leaving = 0;
  LocalContactModel first = stiffness.evaluate(model, state);  // the first call: at rest, from zero
  LocalContactModel last = first;
  for (int k = 0; k < ticks; ++k) {
    state.force_command = press_down(force + amplitude * std::sin(2 * M_PI * state.time / period));
    const auto t0 = Clock::now();
    if (step(model, opt, state) != StepStatus::ok) ++bad_steps;
    const auto t1 = Clock::now();
    last = stiffness.evaluate(model, state);
    const auto t2 = Clock::now();
    cold.clear_warm_start();
    const auto t3 = Clock::now();
    const LocalContactModel c = cold.evaluate(model, state);
    const auto t4 = Clock::now();
    step_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    warm_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    cold_ms.push_back(std::chrono::duration<double, std::milli>(t4 - t3).count());
    warm_it.push_back(last.cg_iterations);
    cold_it.push_back(c.cg_iterations);
    radius.push_back(last.valid_radius);
    active.push_back(last.active_count);
    if (!last.converged || !c.converged) ++not_converged;
    limited_by_entering += last.limited_by == LocalContactModel::Limit::entering;
    limited_by_leaving += last.limited_by == LocalContactModel::Limit::leaving;
  }
  // The last tick's warm-started K against a solve of the same state to 1e-10, the truth the
  // tolerance is judged by (tests/contact_stiffness_test.cpp checks that one against finite differences).
  ContactStiffness tight(model, {1e-10, 20000});
  const LocalContactModel truth = tight.evaluate(model, state);
  const double K_scale = truth.stiffness.cwiseAbs().maxCoeff();
  const double K_error = K_scale > 0 ? (last.stiffness - truth.stiffness).cwiseAbs().maxCoeff() / K_scale : 0.0;
  const double radius_error =
      truth.valid_radius > 0 ? std::abs(last.valid_radius - truth.valid_radius) / truth.valid_radius : 0.0;
  // The tangent product of the three directions at the last state (the solves' unit of
  // work): three elastic_force_differential calls against one elastic_force_differentials sweep.
  std::vector<double> three_ms, sweep_ms;
  {
    Workspace w;
    linearize_elastic(model, state.position, w);
    Points dx[3], df[3];
    for (int q = 0; q < 3; ++q) {
      dx[q] = stiffness.displacement_response(q);
      df[q].setZero(3, model.particle_count);
    }
    const Points* in[3] = {&dx[0], &dx[1], &dx[2]};
    Points* out[3] = {&df[0], &df[1], &df[2]};
    for (int r = 0; r < 21; ++r) {
      const auto t0 = Clock::now();
      for (int q = 0; q < 3; ++q) elastic_force_differential(model, w, dx[q], df[q]);
      const auto t1 = Clock::now();
      elastic_force_differentials(model, w, 3, in, out);
      const auto t2 = Clock::now();
      three_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      sweep_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    }
  }
  const Stats three = stats(three_ms), sweep = stats(sweep_ms);
  const Stats warm = stats(warm_ms), cold_s = stats(cold_ms), stp = stats(step_ms), wi = stats(warm_it),
              ci = stats(cold_it), rad = stats(radius), act = stats(active);
  nlohmann::json j;
  j["scene"] = model.name;
  j["particles"] = model.particle_count;
  j["dt"] = opt.integrator.dt;
  j["force"] = force;
  j["amplitude"] = amplitude;
  j["period"] = period;
  j["ticks"] = ticks;
  j["tolerance"] = settings.tolerance;
  j["coarse_per_axis"] = settings.coarse_per_axis;
  j["coarse_lattice"] = {stiffness.coarse_lattice()[0], stiffness.coarse_lattice()[1], stiffness.coarse_lattice()[2]};
  j["construction_ms"] = build_ms;
  j["press_seconds"] = press_s;
  j["rest_indentation"] = rest.indentation;
  j["rest_active"] = first.active_count;
  j["rest_stiffness_zz"] = first.stiffness(2, 2);
  j["rest_valid_radius"] = first.valid_radius;
  j["rest_limited_by"] = to_string(first.limited_by);
  j["rest_cg_iterations"] = first.cg_iterations;
  j["warm_ms"] = to_json(warm);
  j["cold_ms"] = to_json(cold_s);
  j["step_ms"] = to_json(stp);
  j["warm_cg_iterations"] = to_json(wi);
  j["cold_cg_iterations"] = to_json(ci);
  j["valid_radius"] = to_json(rad);
  j["active"] = to_json(act);
  j["limited_by_entering"] = limited_by_entering;
  j["limited_by_leaving"] = limited_by_leaving;
  j["stiffness_error"] = K_error;
  j["valid_radius_error"] = radius_error;
  j["tangent_three_products_ms"] = to_json(three);
  j["tangent_one_sweep_ms"] = to_json(sweep);
  j["not_converged"] = not_converged;
  j["failed_steps"] = bad_steps;
  if (json_out) {
    std::cout << j.dump() << "\n";
    return 0;
  }
  std::printf("palpate-bench-contact-stiffness: %s, %d particles, dt %g s\n", model.name.c_str(),
              model.particle_count, opt.integrator.dt);
  std::printf("rest at %g N (%.2f s to press): d = %.5f m, %d active, K_zz = %.1f N/m, radius %.3g m (%s), %d CG "
              "iterations from zero\n",
              force, press_s, rest.indentation, first.active_count, first.stiffness(2, 2), first.valid_radius,
              to_string(first.limited_by), first.cg_iterations);
  const Eigen::Vector3i lattice = stiffness.coarse_lattice();
  std::printf("preconditioner: block Jacobi%s (construction %.1f ms)\n",
              lattice[0] > 0 ? (" + coarse lattice " + std::to_string(lattice[0]) + " x " + std::to_string(lattice[1]) +
                                " x " + std::to_string(lattice[2]))
                                   .c_str()
                             : "",
              build_ms);
  std::printf("%d ticks, command %g +- %g N over %g s; medians (p90, max), single thread:\n", ticks, force, amplitude,
              period);
  std::printf("  %-28s %9.3f ms (%.3f, %.3f)\n", "step()", stp.median, stp.p90, stp.max);
  std::printf("  %-28s %9.3f ms (%.3f, %.3f)   CG iterations %g (%g, %g)\n", "evaluate(), warm-started", warm.median,
              warm.p90, warm.max, wi.median, wi.p90, wi.max);
  std::printf("  %-28s %9.3f ms (%.3f, %.3f)   CG iterations %g (%g, %g)\n", "evaluate(), cold", cold_s.median,
              cold_s.p90, cold_s.max, ci.median, ci.p90, ci.max);
  std::printf("  %-28s %9.3g m (min %.3g, p10 %.3g, p90 %.3g, max %.3g); active %g (%g, %g)\n", "valid radius",
              rad.median, rad.min, rad.p10, rad.p90, rad.max, act.median, act.p90, act.max);
  std::printf("  %-28s entering %d, leaving %d of %d ticks\n", "radius limited by", limited_by_entering,
              limited_by_leaving, ticks);
  std::printf("  %-28s %.2e of its largest entry; valid radius %.2e (relative)\n", "K against a 1e-10 solve", K_error,
              radius_error);
  std::printf("  %-28s %9.3f ms as 3 products, %.3f ms in one sweep (medians of 21)\n", "tangent, 3 directions",
              three.median, sweep.median);
  if (not_converged || bad_steps)
    std::printf("warning: %d evaluations did not converge, %d steps were not ok\n", not_converged, bad_steps);
  return 0;
}
