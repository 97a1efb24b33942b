// palpate-verify: presses the scene's indenter with each force of a sweep, lets
// the body come to rest (docs/physics.md §2) and compares the indentation with Hertz
// theory, plain and corrected for the finite layer (docs/physics.md §3).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <spdlog/spdlog.h>
#include <stdexcept>
#include <string>
#include <vector>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "cli/arguments.h"
#include "core/node_cloud.h"
#include "core/vtk_writer.h"
#include "tools/verification_sweep.h"

namespace {

using namespace palpate;

const char* kUsage = R"(usage: palpate-verify --scene FILE [options]
Presses the indenter with each force of a sweep until the body is at rest and
compares the indentation d with Hertz theory.
  --scene FILE        scene file (JSON), e.g. scenes/hertz_cube.json
  --per-edge N        override body.distribution.per_edge
  --forces F1,F2,...  force sweep in N (default: the scene's verify.forces, or the
                      Hertz loads of depths d/R = 0.02 ... 0.2)
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
is ||d_sim - d_ref|| / ||d_ref|| over the sweep. A value that does not exist (no reference,
or no finite-layer solution with --surface-radius) prints "-" (null in --json).
Exit status: 0 when every force came to rest; 1 when the scene cannot be read or built (the
message names the file, the field and the reason); 2 for a wrong argument; 3 when a force's
row is not ok (its status: "not at rest" within the step limit, or "diverged").
)";

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

  tools::SweepRequest request;
  request.scene_file = scene_file;
  request.overrides = overrides;
  if (site) request.site = std::array<double, 2>{(*site)[0], (*site)[1]};
  request.forces = forces;
  request.static_solve = static_solve;
  request.reference = reference_choice;
  request.surface_radius = surface_radius;
  std::optional<tools::PreparedSweep> prepared;
  try {
    prepared = tools::prepare_sweep(request, [&](const std::string& m) {
      if (!quiet) std::fprintf(stderr, "palpate-verify: %s\n", m.c_str());
    });
  } catch (const std::exception& e) {
    std::cerr << "palpate-verify: " << e.what() << "\n";
    return 1;
  }
  const tools::PreparedSweep& sweep = *prepared;
  const Scene& scene = sweep.loaded.scene;
  const Model& model = sweep.loaded.model;
  const double site_x = sweep.site_x, site_y = sweep.site_y;
  const double R = model.indenter_radius;
  if (sweep.guide_overridden && !quiet)
    std::fprintf(stderr, "palpate-verify: indenter.guide is free in the scene; the sweep holds the tool on the "
                         "vertical guide\n");

  if (!quiet)
    std::fprintf(stderr,
                 "palpate-verify: %s (%s), %d particles (%d fixed, %d regularised, worst cond(A) %.3g), spacing "
                 "%.4g ... %.4g m, sum of volumes %.4g m^3 (box %.4g), integration residual %.2g (nodal %.2g), "
                 "%s dt = %g s, damping %g 1/s, site (%g, %g) m\n",
                 scene.name.c_str(), to_string(scene.model), model.particle_count, model.fixed_count,
                 model.regularized_count, model.worst_condition, model.min_spacing, model.max_spacing,
                 model.total_volume, model.box_volume, model.integration_residual,
                 model.integration_residual_nodal, to_string(scene.integrator.type), scene.integrator.dt,
                 scene.integrator.damping, site_x, site_y);
  if (!quiet && model.mass_floor_raised > 0) {
    double mass = 0.0;
    for (double m : model.mass) mass += m;
    std::fprintf(stderr, "palpate-verify: mass floor (mls.mass_floor %g): %d particles raised, %.3g %% of the mass added\n",
                 scene.mls.mass_floor, model.mass_floor_raised, 100.0 * model.mass_floor_added / (mass - model.mass_floor_added));
  }
  if (!quiet && model.mesh_tetrahedra > 0)
    std::fprintf(stderr, "palpate-verify: mesh of %lld tetrahedra (%lld unused nodes dropped)\n",
                 static_cast<long long>(model.mesh_tetrahedra), static_cast<long long>(model.mesh_unused_nodes));
  if (!quiet && !sweep.reference_note.empty())
    std::fprintf(stderr, "palpate-verify: %s\n", sweep.reference_note.c_str());

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

  tools::SweepObserver observer;
  const long trace_every = trace_interval > 0 ? std::max(1L, std::lround(trace_interval / scene.integrator.dt)) : 0;
  if (trace_every > 0)
    observer.after_step = [&](const State& s) {
      if (s.tick % trace_every == 0)
        std::fprintf(stderr, "    t = %8.3f s  d = %.6f m  contact %9.4f N (%zu particles)  v_ind = %+.2e  max v = %.2e m/s\n",
                     s.time, indentation_at_tool(model, s), s.indenter_contact_force[2], s.contact_index.size(),
                     s.indenter_velocity[2], max_particle_speed(s));
    };
  if (!quiet) observer.message = [](const std::string& m) { std::fprintf(stderr, "    %s\n", m.c_str()); };
  observer.after_force = [&](size_t k, const tools::SweepRow& row, const State& state) {
    if (!vtk_dir.empty() && row.status != "diverged") {
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
        throw std::runtime_error(std::string("--vtk: ") + e.what());
      }
    }
    if (!quiet)
      std::fprintf(stderr, "  [%zu/%zu] F = %8.3f N  d = %.5f m  (Hertz %.5f)  %ld steps, %.2f s  %s\n", k + 1,
                   sweep.forces.size(), row.force, row.d_sim, row.d_hertz, row.steps, row.wall_seconds,
                   row.status.c_str());
  };
  std::vector<tools::SweepRow> rows;
  try {
    rows = tools::run_sweep(sweep, observer);
  } catch (const std::exception& e) {
    std::cerr << "palpate-verify: " << e.what() << "\n";
    return 1;
  }

  const tools::SweepL2Errors l2 = tools::sweep_l2_errors(rows);
  const double l2_hertz = l2.hertz, l2_layer = l2.finite_layer, l2_reference = l2.reference;
  const bool all_ok = tools::sweep_all_ok(rows);
  const std::optional<Reference>& reference = sweep.reference;

  if (!csv_file.empty()) {
    std::ofstream csv(csv_file);
    csv << "site_x_m,site_y_m,force_N,d_sim_m,d_hertz_m,d_layer_m,d_ref_m,err_hertz,err_layer,err_ref,tool_x_m,tool_y_m,"
           "contact_force_N,steps,sim_time_s,wall_s,status\n";
    for (const tools::SweepRow& r : rows)
      csv << site_x << ',' << site_y << ',' << r.force << ',' << r.d_sim << ',' << r.d_hertz << ',' << r.d_layer << ',' << r.d_ref << ','
          << (r.d_sim - r.d_hertz) / r.d_hertz << ',' << (r.d_sim - r.d_layer) / r.d_layer << ','
          << (r.d_sim - r.d_ref) / r.d_ref << ',' << r.tool_x << ',' << r.tool_y << ',' << r.contact_force << ',' << r.steps << ',' << r.sim_time << ',' << r.wall_seconds << ',' << r.status
          << '\n';
  }

  if (json) {
    const nlohmann::json out = tools::sweep_json(sweep, rows);
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
    for (const tools::SweepRow& r : rows)
      std::printf("%10.3f %10.5f %10.5f %10s %10s %8.1f%% %9s %9s %8ld %9.2f  %s\n", r.force, r.d_sim, r.d_hertz,
                  cell(r.d_layer, "%.5f").c_str(), cell(r.d_ref, "%.5f").c_str(),
                  100 * (r.d_sim - r.d_hertz) / r.d_hertz, cell(100 * (r.d_sim - r.d_layer) / r.d_layer, "%.1f%%").c_str(),
                  cell(100 * (r.d_sim - r.d_ref) / r.d_ref, "%.1f%%").c_str(), r.steps, r.wall_seconds,
                  r.status.c_str());
    std::printf("L2 error against Hertz: %.2f %%", 100 * l2_hertz);
    if (std::isfinite(l2_layer)) std::printf(", against finite-layer Hertz: %.2f %%", 100 * l2_layer);
    if (std::isfinite(l2_reference)) std::printf(", against the converged reference: %.2f %%", 100 * l2_reference);
    std::printf("\n");
    // The method shows in the levels (lattices have nodes per edge, tetrahedral meshes none)
    // and in the key (the large-strain reference's ends with the held tool).
    const bool tetrahedra = reference && !reference->levels.empty() && reference->levels[0].per_edge == 0;
    const bool large_strain = reference && reference->key.ends_with(" held");
    const std::string method = tetrahedra     ? "linear tetrahedra, meshes refined at the site"
                               : large_strain ? "neo-Hookean hex FEM, graded, the tool held"
                                              : "linear hex FEM, graded";
    std::printf("d_ref: %s\n", reference ? (method + ", extrapolated (" + reference->key + ")").c_str()
                                         : sweep.reference_note.c_str());
  }
  return all_ok ? 0 : 3;
}
