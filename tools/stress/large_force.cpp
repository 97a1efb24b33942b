// palpate-stress, study 2: large forces, sudden steps, a reversal. From rest the
// command jumps to forces far beyond the Hertz sweep, is reversed (the indenter
// leaves contact), then returns to the sweep's largest force: does the model recover?
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "tools/stress/studies.h"

namespace palpate::stress {

json large_force_study(const StressOptions& stress, json& meta) {
  const int per_edge = clouds(stress.mode)[0].per_edge;
  const double hold = stress.mode == Mode::smoke ? 0.1 : 1.5;  // s per phase (damping 10/s: e^-7.5 of the motion)
  const double pull = 0.1;                                  // s of reversed command
  std::vector<double> levels = {1000.0, 3663.0, 20000.0};
  if (stress.mode == Mode::quick) levels = {3663.0, 20000.0};
  if (stress.mode == Mode::smoke) levels = {3663.0};
  meta["large_force_protocol"] =
      "from rest: the command jumps 0 -> F and is held " + std::to_string(hold) +
      " s (step); then -F_ref (the sweep's largest, 327.6 N) for " + std::to_string(pull) +
      " s (reversal: the indenter leaves contact), then +F_ref held " + std::to_string(hold) +
      " s (return). recovered: finite, no inverted point, |d - d_ref| <= 2 % of d_ref (d_ref: a fresh step to F_ref "
      "held as long) and max particle speed < 1e-3 m/s at the end. 3663 N: Hertz d/R = 1 for R = 0.5 m. "
      "Penetration: largest distance of a particle inside the sphere (geometric, all particles).";
  struct Case {
    std::string file;
    SceneOverrides set;
  };
  const std::vector<Case> cases = {{"hertz_cube.json", {}},
                                   {"hertz_cube_fem.json", {}},
                                   {"hertz_cube_fem.json", {{"hex_fem.formulation", "corotational"}}}};
  json rows = json::array();
  for (const Case& c : cases) {
    const Scene scene = load(stress, c.file, per_edge, c.set);
    const Model model = build_model(scene);
    const Options opt = options_of(scene);
    const double F_ref = reference_force(scene);
    const int sample = opt.integrator.type == IntegratorType::implicit_euler ? 1 : 10;
    State fresh = make_state(model, opt);
    const PhaseStats ref = run_phase(model, opt, fresh, F_ref, hold, sample);
    progress("large force: %s %s, %s at %g s: d_ref(%g N) = %.4f m", model_label(model),
             cloud_label(model, "uniform").c_str(), to_string(opt.integrator.type), opt.integrator.dt, F_ref,
             ref.indentation);
    for (const double F : levels) {
      State s = make_state(model, opt);
      const PhaseStats up = run_phase(model, opt, s, F, hold, sample);
      PhaseStats rev, back;
      if (up.finite) rev = run_phase(model, opt, s, -F_ref, pull, sample);
      if (up.finite && rev.finite) back = run_phase(model, opt, s, F_ref, hold, sample);
      const bool finite = up.finite && rev.finite && back.finite;
      const bool recovered = finite && back.inverted == 0 && std::abs(back.indentation - ref.indentation) <= 0.02 * ref.indentation &&
                             back.speed < 1e-3;
      progress("    F = %g N: max d = %.3f m (d/R %.2f), max penetration %.3g m, max inverted %d, %s, return: d = %.4f m, %s",
               F, up.max_indentation, up.max_indentation / model.indenter_radius, up.max_penetration, up.max_inverted,
               up.finite ? "finite" : "NON-FINITE", back.indentation, recovered ? "recovered" : "NOT recovered");
      json row;
      row["model"] = model_label(model);
      row["integrator"] = to_string(opt.integrator.type);
      row["dt_s"] = opt.integrator.dt;
      row["cloud"] = cloud_label(model, "uniform");
      row["particles"] = model.particle_count;
      row["force_n"] = F;
      row["d_over_r"] = num(up.max_indentation / model.indenter_radius);
      row["step"] = up.to_json();
      row["reversal"] = rev.to_json();
      row["return"] = back.to_json();
      row["d_ref_m"] = ref.indentation;
      row["recovered"] = recovered;
      row["wall_s"] = up.seconds + rev.seconds + back.seconds;
      // flat copies for the CSV
      row["max_indentation_m"] = num(up.max_indentation);
      row["max_penetration_m"] = num(up.max_penetration);
      row["max_inverted"] = up.max_inverted;
      row["points"] = model.solid == SolidKind::mls ? model.particle_count : model.hex.element_count;
      row["min_jacobian"] = num(up.min_jacobian);
      row["max_energy_j"] = num(std::max({up.max_energy, rev.max_energy, back.max_energy}));
      row["finite"] = finite;
      row["left_contact"] = rev.left_contact;
      row["return_indentation_m"] = num(back.indentation);
      rows.push_back(row);
    }
  }
  return rows;
}

}  // namespace palpate::stress
