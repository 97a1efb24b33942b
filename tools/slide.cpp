// palpate-slide: the sliding study (docs/physics.md §4, "The sliding test";
// tools/sliding.h). The tool, free in three translations, is pressed with a constant
// normal force and dragged across the middle of the top face by the virtual coupling at
// several speeds; with frictionless contact the tangential force must vanish as the
// speed falls, and the depth at the middle must approach the static indentation there.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "analysis/reference.h"
#include "cli/arguments.h"
#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "tools/sliding.h"

using namespace palpate;

namespace {

const char* kUsage = R"(usage: palpate-slide --scene FILE [options]
Drags the tool across the middle of the top face at a constant commanded normal force
(guide free, the virtual coupling pulling sideways) at each speed, and prints
|mean F_x| / |mean F_z| of the contact force on the tool over the window and the depth
at the middle against the static indentation there.
  --scene FILE        scene file (JSON), e.g. scenes/hertz_cube_haptic.json
  --force F           commanded normal force, N (default 82.88)
  --speeds V1,V2,...  target speeds along +x, m/s (default 1,0.1,0.01,0.001)
  --middle X,Y        middle of the path on the top face, m (default 0,0)
  --half-window W     the window is [X - W, X + W] (default 0.1 m)
  --run-in L          sliding before the window, m (default 0.05)
  --stiffness K       coupling stiffness, N/m (default 1e4)
  --damping B         coupling damping, N s/m (default critical: 2 sqrt(K M))
  --per-edge N        override body.distribution.per_edge
  --set KEY=VALUE     override a scene field (repeatable)
  --json              one JSON object on stdout
  --csv FILE          the rows as CSV
  --quiet             no progress on stderr
)";

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, csv_file;
  SceneOverrides overrides;
  SlideSpec spec;
  std::vector<double> speeds{1.0, 0.1, 0.01, 0.001};
  bool json = false, quiet = false;
  cli::parse_or_exit(argc, argv, "palpate-slide", kUsage, [&](cli::Arguments& args) {
    const std::string& arg = args.flag();
    auto value = [&] { return args.value(); };
    if (arg == "--scene") scene_file = value();
    else if (arg == "--force") spec.force = cli::positive_list(value(), arg).at(0);
    else if (arg == "--speeds") speeds = cli::positive_list(value(), arg);
    else if (arg == "--middle") {
      const std::vector<double> m = cli::number_list(value(), arg);
      if (m.size() != 2) throw std::invalid_argument("--middle: expected X,Y (two numbers, m)");
      spec.middle = Eigen::Vector2d(m[0], m[1]);
    } else if (arg == "--half-window") spec.half_window = cli::positive_list(value(), arg).at(0);
    else if (arg == "--run-in") spec.run_in = cli::positive_list(value(), arg).at(0);
    else if (arg == "--stiffness") spec.stiffness = cli::positive_list(value(), arg).at(0);
    else if (arg == "--damping") spec.damping = cli::number(value(), arg);
    else if (arg == "--per-edge") overrides.emplace_back("body.distribution.per_edge", value());
    else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
    else if (arg == "--json") json = true;
    else if (arg == "--csv") csv_file = value();
    else if (arg == "--quiet") quiet = true;
    else return false;
    return true;
  });
  if (scene_file.empty()) cli::usage_error("palpate-slide", "--scene FILE is required", kUsage);

  std::optional<Scene> scene;
  std::optional<Model> model;
  Options opt;
  try {
    scene = load_scene(scene_file, overrides);
    // Both ends of the path must be valid sites (on the face, R from the walls).
    Scene end = *scene;
    place_indenter_at_site(end, spec.middle[0] + spec.half_window, spec.middle[1], "--middle/--half-window");
    const Eigen::Vector2d s0 = slide_start(spec);
    place_indenter_at_site(*scene, s0[0], s0[1], "--middle/--half-window/--run-in");
    model.emplace(build_model(*scene));
    opt = options_of(*scene);
  } catch (const std::exception& e) {
    std::cerr << "palpate-slide: " << e.what() << "\n";
    return 1;
  }
  if (!quiet)
    std::fprintf(stderr, "palpate-slide: %s, %d particles, %s dt = %g s, damping %g 1/s, F = %g N, path x %g ... %g m at y = %g m\n",
                 scene->name.c_str(), model->particle_count, to_string(opt.integrator.type), opt.integrator.dt,
                 opt.integrator.damping, spec.force, slide_start(spec)[0], spec.middle[0] + spec.half_window,
                 spec.middle[1]);

  const StaticDepth truth = static_depth_at_middle(*model, opt, scene->verify.rest, spec);
  if (!quiet)
    std::fprintf(stderr, "palpate-slide: static depth at the middle %.6f m%s\n", truth.depth,
                 truth.converged ? "" : (" (" + truth.message + ")").c_str());
  std::vector<SlideResult> rows;
  for (double v : speeds) {
    SlideSpec s = spec;
    s.speed = v;
    rows.push_back(slide(*model, opt, scene->verify.rest, s));
    const SlideResult& r = rows.back();
    if (!quiet)
      std::fprintf(stderr, "  v = %g m/s: |F_x|/|F_z| = %.3e (rms %.3e), d_middle = %.6f m, %ld steps, %.1f s  %s\n", v,
                   r.ratio, r.rms_ratio, r.depth_middle, r.steps, r.wall_seconds, r.status.c_str());
  }

  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  bool all_ok = truth.converged;
  for (const auto& r : rows) all_ok = all_ok && r.status == "ok";
  if (!csv_file.empty()) {
    std::ofstream csv(csv_file);
    csv << "speed_m_s,mean_fx_N,mean_fz_N,ratio,rms_ratio,depth_middle_m,static_depth_m,depth_error,lag_m,"
           "max_offset_y_m,steps,sim_time_s,wall_s,status\n";
    for (const auto& r : rows)
      csv << r.speed << ',' << r.mean_fx << ',' << r.mean_fz << ',' << r.ratio << ',' << r.rms_ratio << ','
          << r.depth_middle << ',' << truth.depth << ',' << (r.depth_middle - truth.depth) / truth.depth << ',' << r.lag
          << ',' << r.max_offset_y << ',' << r.steps << ',' << r.sim_time << ',' << r.wall_seconds << ',' << r.status
          << '\n';
  }
  if (json) {
    nlohmann::json out;
    out["scene"] = scene->name;
    out["particles"] = model->particle_count;
    out["integrator"] = to_string(opt.integrator.type);
    out["dt"] = opt.integrator.dt;
    out["damping"] = opt.integrator.damping;
    out["force"] = spec.force;
    out["middle"] = {spec.middle[0], spec.middle[1]};
    out["half_window"] = spec.half_window;
    out["run_in"] = spec.run_in;
    out["coupling_stiffness"] = spec.stiffness;
    out["coupling_damping"] =
        spec.damping >= 0 ? spec.damping : 2.0 * std::sqrt(spec.stiffness * opt.indenter_mass);
    out["static_depth"] = num(truth.depth);
    out["static_converged"] = truth.converged;
    nlohmann::json list = nlohmann::json::array();
    for (const auto& r : rows)
      list.push_back({{"speed", r.speed},
                      {"mean_fx", num(r.mean_fx)},
                      {"mean_fz", num(r.mean_fz)},
                      {"ratio", num(r.ratio)},
                      {"rms_ratio", num(r.rms_ratio)},
                      {"depth_middle", num(r.depth_middle)},
                      {"depth_error", num((r.depth_middle - truth.depth) / truth.depth)},
                      {"lag", num(r.lag)},
                      {"max_offset_y", r.max_offset_y},
                      {"steps", r.steps},
                      {"press_steps", r.press_steps},
                      {"sim_time", r.sim_time},
                      {"wall_seconds", r.wall_seconds},
                      {"status", r.status}});
    out["rows"] = list;
    std::cout << out.dump(2) << "\n";
  } else {
    std::printf("\nSliding at F = %g N, scene %s (%d particles), path x %g ... %g m at y = %g m, window +-%g m\n",
                spec.force, scene->name.c_str(), model->particle_count, slide_start(spec)[0],
                spec.middle[0] + spec.half_window, spec.middle[1], spec.half_window);
    std::printf("%10s %11s %11s %11s %11s %12s %12s %10s %9s %8s  %s\n", "v [m/s]", "mean F_x", "mean F_z",
                "|Fx|/|Fz|", "rms Fx/Fz", "d_mid [m]", "d_static [m]", "d err", "steps", "wall [s]", "status");
    for (const auto& r : rows)
      std::printf("%10g %11.4g %11.5g %11.3e %11.3e %12.6f %12.6f %9.3f%% %9ld %8.1f  %s\n", r.speed, r.mean_fx,
                  r.mean_fz, r.ratio, r.rms_ratio, r.depth_middle, truth.depth,
                  100 * (r.depth_middle - truth.depth) / truth.depth, r.steps, r.wall_seconds, r.status.c_str());
  }
  return all_ok ? 0 : 3;
}
