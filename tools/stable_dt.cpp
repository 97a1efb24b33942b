// palpate-stable-dt: the largest stable time step of a scene's integrator, found
// by bisection on trial runs under a constant commanded force (docs/physics.md §1,
// "Time step": measure the real limit and compare it with 0.3 dx_min / c_p).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "analysis/stability.h"
#include "cli/arguments.h"
#include "tools/load_scene.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"

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
A scene's free tool (indenter.guide "free") is held on a vertical guide for the
measurement, and the output says so: pushed by a constant vertical force it slides
off a curved or sloping surface (the dome) at any time step, which no dt cures and a
trial would count as unstable. --set indenter.guide=free measures it free all the same.
)";

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file;
  SceneOverrides overrides;
  double force = NAN, duration = 1.0;
  double tolerance = 0.01;
  bool json = false, quiet = false;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--scene") scene_file = value();
      else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
      else if (arg == "--force") force = args.number();
      else if (arg == "--duration") duration = args.number();
      else if (arg == "--tolerance") tolerance = args.number();
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

  std::optional<tools::LoadedScene> loaded = tools::load_scene_and_model("palpate-stable-dt", scene_file, overrides);
  if (!loaded) return 1;
  const Scene& scene = loaded->scene;
  const Model& model = loaded->model;
  if (std::isnan(force)) force = scene.verify.forces.empty() ? 150.0 : scene.verify.forces.back();
  // The trials press with a constant vertical force: a free tool slides down a curved surface
  // away from the site until the indentation leaves [-R, R], at every dt. The stable step is the
  // body's and the integrator's, so the tool is guided vertically unless the caller insists.
  Options opt = loaded->opt;
  const bool guide_asked = std::any_of(overrides.begin(), overrides.end(),
                                       [](const auto& o) { return o.first == "indenter.guide"; });
  const bool guided_for_measurement = opt.tool_guide == ToolGuide::free && !guide_asked;
  if (guided_for_measurement) opt.tool_guide = ToolGuide::vertical;
  const char* guide_note =
      guided_for_measurement
          ? "the scene's free tool held on a vertical guide for the measurement (a free tool pushed down "
            "slides off a curved surface at any dt; --set indenter.guide=free to measure it free)"
          : (opt.tool_guide == ToolGuide::free ? "free (as asked)" : "vertical");
  const double dt_estimate = 0.3 * model.min_spacing / model.wave_speed;
  const char* integrator = to_string(scene.integrator.type);
  if (!quiet)
    std::fprintf(stderr, "palpate-stable-dt: %s, %d particles, %s, F = %g N, %g s per trial; tool: %s\n",
                 scene.name.c_str(), model.particle_count, integrator, force, duration, guide_note);

  // The trial and the search are analysis/stability.h's (shared with palpate-stress).
  stability::TrialSpec trial;
  trial.force = force;
  trial.duration = duration;
  stability::SearchSpec search;
  search.start = scene.integrator.dt;
  search.tolerance = tolerance;
  const double dt_floor = search.floor;
  const std::string definition = stability::definition(trial);
  const auto start = std::chrono::steady_clock::now();
  const stability::Search found =
      stability::find_stable_dt(model, opt, trial, search, [&](double dt, const stability::Trial& t) {
        if (!quiet) std::fprintf(stderr, "  dt = %.4e s: %s (d = %.5f m)\n", dt, t.reason.c_str(), t.final_indentation);
      });
  const double lo = found.dt_max_stable, hi = found.dt_min_unstable;
  const int trials = found.trials;
  const std::string& failure = found.unstable_because;
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
    out["indenter_mass"] = scene.indenter.mass;
    out["tool_guide"] = opt.tool_guide == ToolGuide::free ? "free" : "vertical";
    out["tool_guided_for_measurement"] = guided_for_measurement;
    out["damping"] = scene.integrator.damping;
    out["tolerance"] = tolerance;
    out["trials"] = trials;
    out["wall_seconds"] = wall;
    out["definition"] = definition;
    std::cout << out.dump(2) << "\n";
  } else {
    std::printf("\nstable time step, scene %s: %d particles, %s, F = %g N, %g s per trial\n", scene.name.c_str(),
                model.particle_count, integrator, force, duration);
    std::printf("  %s\n", definition.c_str());
    std::printf("  tool: %s\n", guide_note);
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
  if (!std::isfinite(lo) && opt.tool_guide == ToolGuide::free && failure == "indentation outside [-R, R]")
    std::fprintf(stderr,
                 "palpate-stable-dt: the free tool left [-R, R] at every dt down to %g s: it slides off the surface "
                 "under the vertical force rather than blowing up; measure with the tool guided (leave out "
                 "--set indenter.guide=free)\n",
                 dt_floor);
  return std::isfinite(lo) ? 0 : 3;
}
