// palpate-verify: presses the scene's indenter with each force of a sweep, lets
// the body come to rest (docs/physics.md §2) and compares the indentation with Hertz
// theory, plain and corrected for the finite layer (docs/physics.md §3).
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>
#include <sstream>
#include <string>
#include <vector>

#include "cli/arguments.h"
#include "tools/load_scene.h"
#include "core/health.h"
#include "core/hertz.h"
#include "core/indentation.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/vtk_writer.h"
#include "analysis/reference.h"
#include "analysis/static_contact.h"
#include "analysis/rest.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"

namespace {

using namespace palpate;

const char* kUsage = R"(usage: palpate-verify --scene FILE [options]
Presses the indenter with each force of a sweep until the body is at rest and
compares the indentation d with Hertz theory.
  --scene FILE        scene file (JSON), e.g. scenes/hertz_cube.json
  --per-edge N        override body.distribution.per_edge
  --forces F1,F2,...  force sweep in N (default: the scene's verify.forces, or the
                      loads of Hertz depths 0.01 ... 0.1 m)
  --set KEY=VALUE     override a scene field by its dotted path (repeatable),
                      e.g. --set integrator.type=implicit_euler
  --json              print one JSON summary on stdout (progress stays on stderr)
  --csv FILE          write the rows as CSV
  --quiet             no progress on stderr
  --trace SECONDS     print the state every SECONDS of simulated time (stderr)
  --log-level LEVEL   spdlog level (default: warn)
  --site X,Y          indent at (X, Y) on the top face (m) instead of its centre: sets
                      indenter.position to (X, Y) just touching the body (a scene may
                      give the site itself in indenter.position); refused off the top
                      face or closer than R to a side wall
  --solve MODE        dynamic (default): step the scene's integrator until rest;
                      static: the quasi-static solve (exact for the linear hex FEM,
                      pseudo-transient continuation for the nonlinear models)
  --surface-radius RB the body's surface under the tool is a sphere of radius RB (a dome
                      pressed at its pole): Hertz with the radius R RB / (R + RB) of the
                      two curvatures, docs/physics.md (3.6); no finite-layer column
  --reference WHAT    the finite-block reference (palpate-reference) the errors are
                      also measured against: auto (default; a stored reference with the
                      scene's key in the scene folder's references/), FILE, compute
                      (compute it now: minutes), or none
  --vtk DIR           ParaView files in DIR (created): per force k of the sweep (from 0)
                      the body at rest, DIR/body_K.vtu (displacement, von Mises, contact
                      force per particle; the tool's position and force as field data),
                      the sphere, DIR/tool_K.vtu, and DIR/verify.pvd, the series of both
                      with time = k (the force itself is field data force_n)
  --vtk-ascii         write the .vtu files as text (default: base64 binary, smaller)
The tool is held on the vertical guide (the Hertz experiment; a scene's "free" guide
is overridden), so it stays over the site.
Indentation d: travel of the indenter below the height at which it touches the
undeformed surface (the highest particle under the tool's (x, y)); with the sphere centred
between lattice particles d includes the strain-free sinking between them. Errors: (d_sim - d_ref) / d_ref; the L2 error
is ||d_sim - d_ref|| / ||d_ref|| over the sweep.
)";

struct Row {
  double force = 0, d_sim = NAN, d_hertz = 0, d_layer = 0, d_ref = NAN, d_ref_uncertainty = NAN;
  double contact_force = 0;
  double tool_x = NAN, tool_y = NAN;  // the tool's (x, y) at rest, m (the site)
  long steps = 0;
  double sim_time = 0, wall_seconds = 0;
  bool at_rest = false;
  std::string status = "ok";  // ok, not at rest, diverged (a failed health check: `failure` says which)
  std::string failure;
};

double l2_error(const std::vector<Row>& rows, double Row::*ref) {
  double num = 0, den = 0;
  for (const Row& r : rows) {
    if (!std::isfinite(r.d_sim)) return NAN;
    num += (r.d_sim - r.*ref) * (r.d_sim - r.*ref);
    den += (r.*ref) * (r.*ref);
  }
  return std::sqrt(num / den);
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, csv_file, log_level = "warn";
  SceneOverrides overrides;
  std::vector<double> forces;
  bool json = false, quiet = false, static_solve = false;
  std::string reference_choice = "auto";
  double surface_radius = 0;  // m, 0: a flat body
  double trace_interval = 0;
  std::optional<std::vector<double>> site;  // --site X,Y
  std::string vtk_dir;  // --vtk DIR
  vtk::Encoding vtk_encoding = vtk::Encoding::binary;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--scene") scene_file = value();
      else if (arg == "--per-edge") overrides.emplace_back("body.distribution.per_edge", value());
      else if (arg == "--forces") forces = cli::positive_list(value(), "--forces");
      else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
      else if (arg == "--json") json = true;
      else if (arg == "--csv") csv_file = value();
      else if (arg == "--quiet") quiet = true;
      else if (arg == "--trace") trace_interval = args.number();
      else if (arg == "--log-level") log_level = value();
      else if (arg == "--vtk") vtk_dir = value();
      else if (arg == "--vtk-ascii") vtk_encoding = vtk::Encoding::ascii;
      else if (arg == "--solve") {
        const std::string mode = value();
        if (mode != "dynamic" && mode != "static")
          throw std::invalid_argument("--solve: expected dynamic or static, got '" + mode + "'");
        static_solve = mode == "static";
      } else if (arg == "--reference") reference_choice = value();
      else if (arg == "--surface-radius") surface_radius = args.number(1e-9, 1e9);
      else if (arg == "--site") {
        site = cli::number_list(value(), "--site");
        if (site->size() != 2) throw std::invalid_argument("--site: expected X,Y (two numbers, m)");
      }
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
    if (scene_file.empty()) throw std::invalid_argument("--scene FILE is required");
  } catch (const std::exception& e) {
    std::cerr << "palpate-verify: " << e.what() << "\n\n" << kUsage;
    return 2;
  }
  spdlog::set_level(spdlog::level::from_str(log_level));

  // The scene, at its site: --site sets indenter.position (analysis/reference.h), a scene
  // may give it; either way it is checked before the model is built.
  std::optional<tools::LoadedScene> loaded;
  try {
    Scene scene = load_scene(scene_file, overrides);
    if (site)
      place_indenter_at_site(scene, (*site)[0], (*site)[1], "--site");
    else
      check_site(scene, scene_file + ": /indenter/position");
    Model model = build_model(scene);
    Options opt = options_of(scene);
    if (opt.tool_guide != ToolGuide::vertical && !quiet)
      std::fprintf(stderr, "palpate-verify: indenter.guide is free in the scene; the sweep holds the tool on the "
                           "vertical guide\n");
    opt.tool_guide = ToolGuide::vertical;  // the Hertz experiment: the guide holds (x, y) at the site
    loaded = tools::LoadedScene{std::move(scene), std::move(model), opt};
  } catch (const std::exception& e) {
    std::cerr << "palpate-verify: " << e.what() << "\n";
    return 1;
  }
  const Scene& scene = loaded->scene;
  const Model& model = loaded->model;
  const double site_x = model.indenter_start[0], site_y = model.indenter_start[1];

  const MaterialSpec& mat = scene.material;
  const double R = model.indenter_radius;
  // Hertz's radius: the tool's, or with a curved body the two curvatures' (3.6).
  const double R_hertz = surface_radius > 0 ? R * surface_radius / (R + surface_radius) : R;
  const double E_star = hertz::effective_modulus(mat.young_modulus, mat.poisson_ratio);
  // The layer of the finite-layer column: the box's height, or a box-less mesh body's extent in z.
  const double thickness = scene.box_given ? scene.box.max[2] - scene.box.min[2]
                                           : model.rest_position.row(2).maxCoeff() - model.rest_position.row(2).minCoeff();
  if (forces.empty()) forces = scene.verify.forces;
  if (forces.empty())
    for (int k = 1; k <= 10; ++k) forces.push_back(hertz::force(0.01 * k, R, E_star));

  if (!quiet)
    std::fprintf(stderr,
                 "palpate-verify: %s (%s), %d particles (%d fixed, %d regularised, worst cond(A) %.3g), spacing "
                 "%.4g ... %.4g m, sum of volumes %.4g m^3 (box %.4g), integration residual %.2g (nodal %.2g), "
                 "%s dt = %g s, damping %g 1/s, site (%g, %g) m\n",
                 scene.name.c_str(), scene.model.c_str(), model.particle_count, model.fixed_count,
                 model.regularized_count, model.worst_condition, model.min_spacing, model.max_spacing,
                 model.total_volume, model.box_volume, model.integration_residual,
                 model.integration_residual_nodal, to_string(scene.integrator.type), scene.integrator.dt,
                 scene.integrator.damping, site_x, site_y);
  if (!quiet && model.mesh_tetrahedra > 0)
    std::fprintf(stderr, "palpate-verify: mesh of %lld tetrahedra (%lld unused nodes dropped)\n",
                 static_cast<long long>(model.mesh_tetrahedra), static_cast<long long>(model.mesh_unused_nodes));

  // The finite-block reference (analysis/reference.h).
  std::optional<Reference> reference;
  std::string reference_note;
  try {
    if (reference_choice == "auto") {
      const auto folder = std::filesystem::path(scene_file).parent_path() / "references";
      reference = find_reference(scene, folder);
      if (!reference)
        reference_note = "no stored reference for this scene in " + folder.string() +
                         " (palpate-reference --scene ... --out, or --reference compute)";
    } else if (reference_choice == "compute") {
      reference = finite_cube_reference(scene, forces, {}, [&](const std::string& m) {
        if (!quiet) std::fprintf(stderr, "palpate-verify: %s\n", m.c_str());
      });
    } else if (reference_choice == "none") {
      reference_note = "none (--reference none)";
    } else {
      reference = load_reference(reference_choice);
      // A neo-Hookean scene may also be measured against the large-strain reference.
      const bool large_strain = scene.material.law == MaterialLaw::neo_hookean &&
                                reference->key == large_strain_reference_key(scene);
      if (reference->key != reference_key(scene) && !large_strain)
        throw std::runtime_error("--reference: " + reference_choice + " is for '" + reference->key +
                                 "', the scene is '" + reference_key(scene) + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-verify: " << e.what() << "\n";
    return 1;
  }
  if (!quiet && !reference_note.empty()) std::fprintf(stderr, "palpate-verify: %s\n", reference_note.c_str());

  // ParaView export (core/vtk_writer.h): the body's cells once, from its cloud.
  vtk::UnstructuredGrid body_cells;
  std::vector<vtk::CollectionEntry> vtk_series;
  if (!vtk_dir.empty()) {
    try {
      std::filesystem::create_directories(vtk_dir);
      body_cells.points.assign(3 * static_cast<size_t>(model.particle_count), 0.0);
      vtk::add_cloud_cells(body_cells, make_node_cloud(scene));
    } catch (const std::exception& e) {
      std::cerr << "palpate-verify: --vtk " << vtk_dir << ": " << e.what() << "\n";
      return 1;
    }
  }

  const Options& opt = loaded->opt;
  State state = make_state(model, opt);
  std::unique_ptr<LinearStaticContact> linear_static;
  if (static_solve && has_linear_static_solve(model)) linear_static = std::make_unique<LinearStaticContact>(model);
  std::vector<Row> rows;
  for (size_t k = 0; k < forces.size(); ++k) {
    Row row;
    row.force = forces[k];
    row.d_hertz = hertz::depth(row.force, R_hertz, E_star);
    try {
      row.d_layer = surface_radius > 0
                        ? NAN  // the finite layer is a flat one
                        : hertz::depth_finite_layer(row.force, R, mat.young_modulus, mat.poisson_ratio, thickness);
    } catch (const std::domain_error&) {
      row.d_layer = NAN;
    }
    if (reference) {
      row.d_ref = reference_indentation(*reference, row.force);
      for (size_t f = 0; f < reference->forces.size(); ++f)
        if (std::abs(reference->forces[f] - row.force) <= 1e-9 * row.force)
          row.d_ref_uncertainty = reference->uncertainty[f];
    }
    const auto start = std::chrono::steady_clock::now();
    const double t0 = state.time;
    if (static_solve) {
      const StaticSolution sol =
          linear_static ? linear_static->solve(row.force, &state) : relax_to_rest(model, opt, scene.verify.rest, state, row.force);
      row.steps = sol.iterations;
      row.at_rest = sol.converged;
      if (!sol.converged && !quiet) std::fprintf(stderr, "    static solve: %s\n", sol.message.c_str());
    } else {
    const long trace_every = trace_interval > 0 ? std::max(1L, std::lround(trace_interval / scene.integrator.dt)) : 0;
    const PressResult press = press_to_rest(model, opt, scene.verify.rest, state, row.force, [&](const State& s) {
      if (trace_every > 0 && s.tick % trace_every == 0)
        std::fprintf(stderr, "    t = %8.3f s  d = %.6f m  contact %9.4f N (%zu particles)  v_ind = %+.2e  max v = %.2e m/s\n",
                     s.time, indentation_at_tool(model, s), s.indenter_contact_force[2], s.contact_index.size(),
                     s.indenter_velocity[2], max_particle_speed(s));
    });
    row.steps = press.steps;
    row.at_rest = press.at_rest;
    if (press.failure.status != StepStatus::ok) {
      row.status = "diverged";
      row.failure = describe(press.failure);
      if (!quiet) std::fprintf(stderr, "    %s: restored the last good state\n", row.failure.c_str());
    }
    }
    row.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    row.sim_time = state.time - t0;
    if (row.status == "diverged") {
      state = make_state(model, opt);  // start the next force from the rest state
    } else {
      // (2.5) under the tool's actual (x, y); the guide keeps it at the site.
      row.d_sim = indentation_at_tool(model, state);
      row.tool_x = state.indenter_center[0];
      row.tool_y = state.indenter_center[1];
      row.contact_force = state.indenter_contact_force[2];
      if (!row.at_rest) row.status = "not at rest";
      if (!vtk_dir.empty()) {
        try {
          vtk::UnstructuredGrid body = vtk::body_state_grid(body_cells, model, state);
          body.field_data.push_back({"force_n", 1, {row.force}});
          vtk::UnstructuredGrid tool = vtk::sphere_surface(state.indenter_center, R);
          tool.field_data = body.field_data;
          const std::string name = std::to_string(k);
          vtk::write_vtu(std::filesystem::path(vtk_dir) / ("body_" + name + ".vtu"), body, vtk_encoding);
          vtk::write_vtu(std::filesystem::path(vtk_dir) / ("tool_" + name + ".vtu"), tool, vtk_encoding);
          vtk_series.push_back({static_cast<double>(k), 0, "body_" + name + ".vtu"});
          vtk_series.push_back({static_cast<double>(k), 1, "tool_" + name + ".vtu"});
          vtk::write_pvd(std::filesystem::path(vtk_dir) / "verify.pvd", vtk_series);
        } catch (const std::exception& e) {
          std::cerr << "palpate-verify: --vtk: " << e.what() << "\n";
          return 1;
        }
      }
    }
    rows.push_back(row);
    if (!quiet)
      std::fprintf(stderr, "  [%zu/%zu] F = %8.3f N  d = %.5f m  (Hertz %.5f)  %ld steps, %.2f s  %s\n", k + 1,
                   forces.size(), row.force, row.d_sim, row.d_hertz, row.steps, row.wall_seconds,
                   row.status.c_str());
  }

  const double l2_hertz = l2_error(rows, &Row::d_hertz);
  const double l2_layer = l2_error(rows, &Row::d_layer);
  const double l2_reference = l2_error(rows, &Row::d_ref);
  bool all_ok = true;
  for (const Row& r : rows) all_ok = all_ok && r.status == "ok";

  if (!csv_file.empty()) {
    std::ofstream csv(csv_file);
    csv << "site_x_m,site_y_m,force_N,d_sim_m,d_hertz_m,d_layer_m,d_ref_m,err_hertz,err_layer,err_ref,tool_x_m,tool_y_m,"
           "contact_force_N,steps,sim_time_s,wall_s,status\n";
    for (const Row& r : rows)
      csv << site_x << ',' << site_y << ',' << r.force << ',' << r.d_sim << ',' << r.d_hertz << ',' << r.d_layer << ',' << r.d_ref << ','
          << (r.d_sim - r.d_hertz) / r.d_hertz << ',' << (r.d_sim - r.d_layer) / r.d_layer << ','
          << (r.d_sim - r.d_ref) / r.d_ref << ',' << r.tool_x << ',' << r.tool_y << ',' << r.contact_force << ',' << r.steps << ',' << r.sim_time << ',' << r.wall_seconds << ',' << r.status
          << '\n';
  }

  if (json) {
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
    out["model"] = scene.model;
    // The continuum simulated: the MLS material law, or the hex FEM formulation.
    out["law"] = scene.model == "hex_fem" ? to_string(scene.hex_fem.formulation) : to_string(scene.material.law);
    out["poisson_ratio"] = scene.material.poisson_ratio;
    out["indenter_radius"] = scene.indenter.radius;
    out["site"] = {site_x, site_y};  // m, the (x, y) of the top face pressed
    out["hertz_radius"] = R_hertz;   // m, R, or (3.6) with --surface-radius
    out["total_volume"] = model.total_volume;
    out["box_volume"] = model.box_volume;
    out["mesh_tetrahedra"] = model.mesh_tetrahedra;
    out["mesh_unused_nodes"] = model.mesh_unused_nodes;
    out["integrator"] = to_string(scene.integrator.type);
    out["dt"] = scene.integrator.dt;
    out["neighbors"] = scene.mls.neighbors;
    out["support_factor"] = scene.mls.support_factor;
    auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    out["l2_error_hertz"] = num(l2_hertz);
    out["l2_error_finite_layer"] = num(l2_layer);
    out["l2_error_reference"] = num(l2_reference);
    out["reference"] = reference ? nlohmann::json(reference->key) : nlohmann::json(nullptr);
    out["solve"] = static_solve ? "static" : "dynamic";
    out["all_at_rest"] = all_ok;
    nlohmann::json list = nlohmann::json::array();
    for (const Row& r : rows)
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
    std::cout << out.dump(2) << "\n";
  } else {
    std::printf("\nHertz indentation, scene %s: %d particles, k = %d, alpha = %g, %s dt = %g s, site (%g, %g) m\n",
                scene.name.c_str(), model.particle_count, scene.mls.neighbors, scene.mls.support_factor,
                to_string(scene.integrator.type), scene.integrator.dt, site_x, site_y);
    std::printf("%10s %10s %10s %10s %10s %9s %9s %9s %8s %9s  %s\n", "F [N]", "d_sim [m]", "d_Hertz", "d_layer",
                "d_ref", "err_H", "err_layer", "err_ref", "steps", "wall [s]", "status");
    // A value that does not exist (no reference, or a force outside its range) prints "-", never "nan".
    auto cell = [](double v, const char* format) {
      char text[32];
      if (!std::isfinite(v)) return std::string("-");
      std::snprintf(text, sizeof text, format, v);
      return std::string(text);
    };
    for (const Row& r : rows)
      std::printf("%10.3f %10.5f %10.5f %10.5f %10s %8.1f%% %8.1f%% %9s %8ld %9.2f  %s\n", r.force, r.d_sim,
                  r.d_hertz, r.d_layer, cell(r.d_ref, "%.5f").c_str(), 100 * (r.d_sim - r.d_hertz) / r.d_hertz,
                  100 * (r.d_sim - r.d_layer) / r.d_layer,
                  cell(100 * (r.d_sim - r.d_ref) / r.d_ref, "%.1f%%").c_str(), r.steps, r.wall_seconds,
                  r.status.c_str());
    std::printf("L2 error against Hertz: %.2f %%, against finite-layer Hertz: %.2f %%", 100 * l2_hertz, 100 * l2_layer);
    if (std::isfinite(l2_reference)) std::printf(", against the finite-block reference: %.2f %%", 100 * l2_reference);
    std::printf("\n");
    std::printf("d_ref: %s\n", reference ? ("linear hex FEM, graded, extrapolated (" + reference->key + ")").c_str()
                                         : reference_note.c_str());
  }
  return all_ok ? 0 : 3;
}
