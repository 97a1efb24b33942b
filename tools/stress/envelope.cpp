// palpate-stress, study 1: the stable envelope. The largest stable dt by bisection
// (analysis/stability.h) per model, integrator, cloud and damping, against the
// estimate dt = 0.3 dx_min / c_p, and a trial at the paper's dt.
#include <string>
#include <vector>

#include "analysis/stability.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "tools/stress/studies.h"

namespace palpate::stress {

json envelope_study(const StressOptions& stress, json& meta) {
  stability::TrialSpec trial;  // the standard load: the sweep's largest force, 1 s, at least 200 steps
  stability::SearchSpec search;
  search.ceiling = 0.1;
  search.tolerance = stress.mode == Mode::full ? 0.02 : stress.mode == Mode::quick ? 0.05 : 0.25;
  if (stress.mode == Mode::smoke) {
    trial.duration = 0.05;
    trial.min_steps = 40;
  }
  meta["envelope_definition"] = stability::definition(trial);
  meta["envelope_search"] = {{"ceiling_s", search.ceiling},
                             {"floor_s", search.floor},
                             {"tolerance", search.tolerance},
                             {"start", "0.3 dx_min / c_p"},
                             {"paper_dt_s", {{"explicit", 1e-3}, {"implicit_euler", 1e-2}}}};
  json rows = json::array();
  const IntegratorType integrators[] = {IntegratorType::rk4, IntegratorType::symplectic_euler,
                                        IntegratorType::implicit_euler};
  for (const Cloud& cloud : clouds(stress.mode)) {
    for (const std::string& file : {cloud.mls_scene, cloud.fem_scene}) {
      const Scene scene = load(stress, file, cloud.per_edge);
      const Model model = build_model(scene);
      trial.force = reference_force(scene);
      std::vector<double> dampings = {scene.integrator.damping};
      if (stress.mode == Mode::full && cloud.name == "uniform") dampings.push_back(0.0);
      for (const IntegratorType type : integrators) {
        if (type == IntegratorType::implicit_euler && cloud.name == "graded" && !stress.graded_implicit &&
            stress.mode != Mode::smoke) {
          progress("envelope: %s, %s, implicit_euler: skipped (--graded-implicit maps it; minutes per trial)",
                   model_label(model), cloud_label(model, cloud.name).c_str());
          continue;
        }
        for (const double damping : dampings) {
          const auto t0 = Clock::now();
          const double estimate = dt_estimate(model);
          Options base = options_of(scene);
          base.integrator.type = type;
          base.integrator.dt = estimate;
          base.integrator.damping = damping;
          progress("envelope: %s, %s, %s, damping %g: bisection from %.3g s", model_label(model),
                   cloud_label(model, cloud.name).c_str(), to_string(type), damping, estimate);
          search.start = estimate;
          const stability::Search found = stability::find_stable_dt(model, base, trial, search, [](double dt, const stability::Trial& t) {
            progress("    dt = %.4e s: %s (%ld steps, d = %.4f m)", dt, t.reason.c_str(), t.steps, t.final_indentation);
          });
          // The paper's dt for this integrator, tried directly (stability need not be monotone in dt).
          const double paper_dt = type == IntegratorType::implicit_euler ? 1e-2 : 1e-3;
          Options at_paper_dt = base;
          at_paper_dt.integrator.dt = paper_dt;
          const stability::Trial at_paper = stability::run_trial(model, at_paper_dt, trial);
          progress("    dt_max = %.4g s (c = %.3f)%s; at the paper's %g s: %s", found.dt_max_stable,
                   found.dt_max_stable * model.wave_speed / model.min_spacing, found.at_ceiling() ? " = the cap" : "",
                   paper_dt, at_paper.reason.c_str());
          json row;
          row["model"] = model_label(model);
          row["scene"] = scene.name;
          row["integrator"] = to_string(type);
          row["cloud"] = cloud_label(model, cloud.name);
          row["particles"] = model.particle_count;
          row["damping"] = damping;
          row["scene_damping"] = damping == scene.integrator.damping;
          row["dt_max_stable_s"] = num(found.dt_max_stable);
          row["dt_min_unstable_s"] = num(found.dt_min_unstable);
          row["at_cap"] = found.at_ceiling();
          row["dt_cap_s"] = search.ceiling;
          row["unstable_because"] = found.unstable_because;
          row["dt_estimate_s"] = estimate;
          row["c"] = num(found.dt_max_stable * model.wave_speed / model.min_spacing);
          row["dx_min_m"] = model.min_spacing;
          row["wave_speed_m_s"] = model.wave_speed;
          row["force_n"] = trial.force;
          row["paper_dt_s"] = paper_dt;
          row["stable_at_paper_dt"] = at_paper.stable;
          row["trials"] = found.trials + 1;
          row["wall_s"] = seconds_since(t0);
          rows.push_back(row);
        }
      }
    }
  }
  return rows;
}

}  // namespace palpate::stress
