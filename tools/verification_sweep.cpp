#include "tools/verification_sweep.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <stdexcept>

#include "analysis/rest.h"
#include "analysis/static_contact.h"
#include "core/health.h"
#include "core/hertz.h"
#include "core/model.h"
#include "core/options.h"
#include "core/step.h"

namespace palpate::tools {

PreparedSweep prepare_sweep(const SweepRequest& request, const std::function<void(const std::string&)>& progress) {
  // The scene, at its site: a request's site sets indenter.position (analysis/reference.h),
  // a scene may give it; either way it is checked before the model is built.
  Scene scene = load_scene(request.scene_file, request.overrides);
  if (request.site)
    place_indenter_at_site(scene, (*request.site)[0], (*request.site)[1], request.site_origin);
  else
    check_site(scene, request.scene_file + ": /indenter/position");
  Model model = build_model(scene);
  Options opt = options_of(scene);
  PreparedSweep sweep;
  sweep.guide_overridden = opt.tool_guide != ToolGuide::vertical;
  opt.tool_guide = ToolGuide::vertical;  // the Hertz experiment: the guide holds (x, y) at the site
  sweep.loaded = LoadedScene{std::move(scene), std::move(model), opt};
  const Scene& s = sweep.loaded.scene;
  const Model& m = sweep.loaded.model;
  sweep.site_x = m.indenter_start[0];
  sweep.site_y = m.indenter_start[1];
  sweep.static_solve = request.static_solve;
  sweep.surface_radius = request.surface_radius;

  const double R = m.indenter_radius;
  // Hertz's radius: the tool's, or with a curved body the two curvatures' (3.6).
  const double RB = request.surface_radius;
  sweep.hertz_radius = RB > 0 ? R * RB / (R + RB) : R;
  sweep.effective_modulus = hertz::effective_modulus(s.material.young_modulus, s.material.poisson_ratio);
  // The layer of the finite-layer column: the box's height, or a box-less mesh body's extent in z.
  sweep.layer_thickness = s.box_given ? s.box.max[2] - s.box.min[2]
                                      : m.rest_position.row(2).maxCoeff() - m.rest_position.row(2).minCoeff();
  sweep.forces = request.forces.empty() ? s.verify.forces : request.forces;
  if (sweep.forces.empty())
    for (int k = 1; k <= 10; ++k) sweep.forces.push_back(hertz::force(0.01 * k, R, sweep.effective_modulus));

  // The finite-block reference (analysis/reference.h).
  const std::string& choice = request.reference;
  if (choice == "auto") {
    const auto folder = std::filesystem::path(request.scene_file).parent_path() / "references";
    sweep.reference = find_reference(s, folder);
    if (!sweep.reference)
      sweep.reference_note = "no stored reference for this scene in " + folder.string() +
                             " (palpate-reference --scene ... --out, or --reference compute)";
  } else if (choice == "compute") {
    sweep.reference = finite_cube_reference(s, sweep.forces, {}, progress);
  } else if (choice == "none") {
    sweep.reference_note = "none (--reference none)";
  } else {
    sweep.reference = load_reference(choice);
    // A neo-Hookean scene may also be measured against the large-strain reference.
    const bool large_strain =
        s.material.law == MaterialLaw::neo_hookean && sweep.reference->key == large_strain_reference_key(s);
    if (sweep.reference->key != reference_key(s) && !large_strain)
      throw std::runtime_error("--reference: " + choice + " is for '" + sweep.reference->key + "', the scene is '" +
                               reference_key(s) + "'");
  }
  return sweep;
}

std::vector<SweepRow> run_sweep(const PreparedSweep& sweep, const SweepObserver& observer) {
  const Scene& scene = sweep.loaded.scene;
  const Model& model = sweep.loaded.model;
  const Options& opt = sweep.loaded.opt;
  const MaterialSpec& mat = scene.material;
  State state = make_state(model, opt);
  std::unique_ptr<LinearStaticContact> linear_static;
  if (sweep.static_solve && has_linear_static_solve(model))
    linear_static = std::make_unique<LinearStaticContact>(model);
  std::vector<SweepRow> rows;
  for (std::size_t k = 0; k < sweep.forces.size(); ++k) {
    SweepRow row;
    row.force = sweep.forces[k];
    row.d_hertz = hertz::depth(row.force, sweep.hertz_radius, sweep.effective_modulus);
    try {
      row.d_layer = sweep.surface_radius > 0 ? NAN  // the finite layer is a flat one
                                             : hertz::depth_finite_layer(row.force, model.indenter_radius,
                                                                         mat.young_modulus, mat.poisson_ratio,
                                                                         sweep.layer_thickness);
    } catch (const std::domain_error&) {
      row.d_layer = NAN;
    }
    if (sweep.reference) {
      const Reference& reference = *sweep.reference;
      row.d_ref = reference_indentation(reference, row.force);
      for (std::size_t f = 0; f < reference.forces.size(); ++f)
        if (std::abs(reference.forces[f] - row.force) <= 1e-9 * row.force)
          row.d_ref_uncertainty = reference.uncertainty[f];
    }
    const auto start = std::chrono::steady_clock::now();
    const double t0 = state.time;
    if (sweep.static_solve) {
      const StaticSolution sol = linear_static ? linear_static->solve(row.force, &state)
                                               : relax_to_rest(model, opt, scene.verify.rest, state, row.force);
      row.steps = sol.iterations;
      row.at_rest = sol.converged;
      if (!sol.converged && observer.message) observer.message("static solve: " + sol.message);
    } else {
      const PressResult press = press_to_rest(model, opt, scene.verify.rest, state, row.force, [&](const State& s) {
        if (observer.after_step) observer.after_step(s);
      });
      row.steps = press.steps;
      row.at_rest = press.at_rest;
      if (press.failure.status != StepStatus::ok) {
        row.status = "diverged";
        row.failure = describe(press.failure);
        if (observer.message) observer.message(row.failure + ": restored the last good state");
      }
    }
    row.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    row.sim_time = state.time - t0;
    if (row.status != "diverged") {
      // (2.5) under the tool's actual (x, y); the guide keeps it at the site.
      row.d_sim = indentation_at_tool(model, state);
      row.tool_x = state.indenter_center[0];
      row.tool_y = state.indenter_center[1];
      row.contact_force = state.indenter_contact_force[2];
      if (!row.at_rest) row.status = "not at rest";
    }
    rows.push_back(row);
    if (observer.after_force) observer.after_force(k, row, state);
    if (row.status == "diverged") state = make_state(model, opt);  // start the next force from the rest state
  }
  return rows;
}

namespace {

double l2_error(const std::vector<SweepRow>& rows, double SweepRow::*ref) {
  double num = 0, den = 0;
  for (const SweepRow& r : rows) {
    if (!std::isfinite(r.d_sim)) return NAN;
    num += (r.d_sim - r.*ref) * (r.d_sim - r.*ref);
    den += (r.*ref) * (r.*ref);
  }
  return std::sqrt(num / den);
}

}  // namespace

SweepL2Errors sweep_l2_errors(const std::vector<SweepRow>& rows) {
  return {l2_error(rows, &SweepRow::d_hertz), l2_error(rows, &SweepRow::d_layer), l2_error(rows, &SweepRow::d_ref)};
}

bool sweep_all_ok(const std::vector<SweepRow>& rows) {
  for (const SweepRow& r : rows)
    if (r.status != "ok") return false;
  return true;
}

nlohmann::json sweep_json(const PreparedSweep& sweep, const std::vector<SweepRow>& rows) {
  const Scene& scene = sweep.loaded.scene;
  const Model& model = sweep.loaded.model;
  const SweepL2Errors l2 = sweep_l2_errors(rows);
  nlohmann::json out;
  out["scene"] = scene.name;
  out["particles"] = model.particle_count;
  out["fixed_particles"] = model.fixed_count;
  out["regularized_particles"] = model.regularized_count;
  out["worst_moment_condition"] = model.worst_condition;
  out["min_spacing"] = model.min_spacing;
  out["max_spacing"] = model.max_spacing;
  out["integration_residual"] = model.integration_residual;
  out["integration_residual_nodal"] = model.integration_residual_nodal;
  out["model"] = to_string(scene.model);
  // The continuum simulated: the MLS material law, or the hex FEM formulation.
  out["law"] = scene.model == SolidKind::hex_fem ? to_string(scene.hex_fem.formulation) : to_string(scene.material.law);
  out["poisson_ratio"] = scene.material.poisson_ratio;
  out["indenter_radius"] = scene.indenter.radius;
  out["site"] = {sweep.site_x, sweep.site_y};  // m, the (x, y) of the top face pressed
  out["hertz_radius"] = sweep.hertz_radius;    // m, R, or (3.6) with --surface-radius
  out["total_volume"] = model.total_volume;
  out["mass_floor_raised"] = model.mass_floor_raised;
  out["mass_floor_added"] = model.mass_floor_added;  // kg
  out["box_volume"] = model.box_volume;
  out["mesh_tetrahedra"] = model.mesh_tetrahedra;
  out["mesh_unused_nodes"] = model.mesh_unused_nodes;
  out["integrator"] = to_string(scene.integrator.type);
  out["dt"] = scene.integrator.dt;
  out["neighbors"] = scene.mls.neighbors;
  out["support_factor"] = scene.mls.support_factor;
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  out["l2_error_hertz"] = num(l2.hertz);
  out["l2_error_finite_layer"] = num(l2.finite_layer);
  out["l2_error_reference"] = num(l2.reference);
  out["reference"] = sweep.reference ? nlohmann::json(sweep.reference->key) : nlohmann::json(nullptr);
  out["solve"] = sweep.static_solve ? "static" : "dynamic";
  out["all_at_rest"] = sweep_all_ok(rows);
  nlohmann::json list = nlohmann::json::array();
  for (const SweepRow& r : rows)
    list.push_back({{"force", r.force},
                    {"d_sim", num(r.d_sim)},
                    {"d_hertz", r.d_hertz},
                    {"d_finite_layer", num(r.d_layer)},
                    {"error_hertz", num((r.d_sim - r.d_hertz) / r.d_hertz)},
                    {"error_finite_layer", num((r.d_sim - r.d_layer) / r.d_layer)},
                    {"d_reference", num(r.d_ref)},
                    {"d_reference_uncertainty", num(r.d_ref_uncertainty)},
                    {"error_reference", num((r.d_sim - r.d_ref) / r.d_ref)},
                    {"contact_force", r.contact_force},
                    {"tool_xy", {num(r.tool_x), num(r.tool_y)}},
                    {"steps", r.steps},
                    {"sim_time", r.sim_time},
                    {"wall_seconds", r.wall_seconds},
                    {"status", r.status},
                    {"failure", r.failure}});
  out["rows"] = list;
  return out;
}

}  // namespace palpate::tools
