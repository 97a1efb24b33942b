// palpate-follow: the resolution that follows the tool, measured while the tool moves
// (docs/physics.md §7; issue #32's "Moving"). The scene's mesh is refined toward the tool
// (distribution.refine, core/mesh_refinement.h); the tool is pressed to rest at the start of
// a straight path on the top face with a constant normal force, then dragged along it at a
// constant speed by the virtual coupling (as palpate-slide drags it). Whenever the point of
// the surface under the tool is more than --refocus-distance from the cloud's focus, a
// cloud refined toward where the tool will be is built (core/mesh_refinement.h, build_model)
// and swapped in --latency later (the time a build takes off the real-time thread), the state
// carried over by core/cloud_transfer.h. It prints each swap's jump in the contact force and
// depth, the cost of each part of a refocus, and the depth along the path against the
// quasi-static references given at sites of the path (linear interpolation between them).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "cli/arguments.h"
#include "cli/statistics.h"
#include "core/cloud_transfer.h"
#include "core/health.h"
#include "core/mesh_reader.h"
#include "core/model.h"
#include "core/node_cloud.h"
#include "core/options.h"
#include "core/reference_file.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"

using namespace palpate;

namespace {

const char* kUsage = R"(usage: palpate-follow --scene FILE [options]
Drags the pressed tool along a straight path of the top face while the cloud's refinement
follows it (the scene's body.distribution.refine), and reports every refocus: the jump of
the contact force and depth at the swap, the time each part took, and the depth along the
path against quasi-static references.
  --scene FILE          scene file (JSON) whose mesh distribution has "refine"
  --force F             commanded normal force, N (default 0.12)
  --speed V             target speed along the path, m/s (default 0.01)
  --from X,Y            start of the path on the top face, m (default -0.035,0)
  --to X,Y              its end, m (default 0.035,0)
  --refocus-distance D  refocus when the tool is D from the focus, m (default 0.0005)
  --latency S           a refocus's new cloud is ready S after it is asked for, s (default:
                        the wall time its refinement and model build took here, as if built
                        on the second core beside the running one)
  --settle N            steps the new cloud runs beside the current one, the tool shared,
                        before it takes over (default 40)
  --blend N             after the swap the old cloud keeps stepping for N steps, the tool
                        shared, and the force reported (what a device would be given) moves
                        linearly from its contact force to the new cloud's (default 40; 0: none)
  --lead                aim a refocus ahead along the tool's velocity, so that the tool passes
                        the new focus midway between its swap and the next (default)
  --no-lead             aim it at where the tool is
  --reference X,Y,FILE  the quasi-static reference at a site of the path (repeatable; ordered
                        along the path): the depth at --force is interpolated between them
  --stiffness K         coupling stiffness, N/m (default 100)
  --csv FILE            one row per step: s along the path, depth, F_z, F_x, particles, swap
  --set KEY=VALUE       override a scene field (repeatable)
  --json                one JSON object on stdout
  --quiet               no progress on stderr
)";

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

struct Cloud {
  NodeCloud cloud;
  Model model;
  Vec3 focus;
  double refine_ms = 0, build_ms = 0;
};

struct Swap {
  double s = 0;                 // m along the path at the swap
  int particles_before = 0, particles_after = 0;
  double fz_before = 0, fz_after = 0;      // N, the contact force's z the step before and after
  double depth_before = 0, depth_after = 0;  // m
  double refine_ms = 0, build_ms = 0, transfer_ms = 0, apply_ms = 0;
  int exact = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, csv_file;
  SceneOverrides overrides;
  double force = 0.12, speed = 0.01, refocus_distance = 0.0005, latency = -1, stiffness = 100;
  long settle_steps = 40, blend_steps = 40;
  Eigen::Vector2d from(-0.035, 0), to(0.035, 0);
  bool lead = true, json = false, quiet = false;
  struct Site {
    double s;
    double depth;
  };
  std::vector<std::pair<Eigen::Vector2d, std::string>> reference_files;
  cli::parse_or_exit(argc, argv, "palpate-follow", kUsage, [&](cli::Arguments& args) {
    const std::string& arg = args.flag();
    auto value = [&] { return args.value(); };
    auto point = [&](const std::string& text) {
      const auto v = cli::number_list(text, arg);
      if (v.size() != 2) throw std::invalid_argument(arg + ": expected X,Y (m)");
      return Eigen::Vector2d(v[0], v[1]);
    };
    if (arg == "--scene") scene_file = value();
    else if (arg == "--force") force = cli::positive_list(value(), arg).at(0);
    else if (arg == "--speed") speed = cli::positive_list(value(), arg).at(0);
    else if (arg == "--from") from = point(value());
    else if (arg == "--to") to = point(value());
    else if (arg == "--refocus-distance") refocus_distance = cli::positive_list(value(), arg).at(0);
    else if (arg == "--latency") {
      latency = cli::number_list(value(), arg).at(0);
      if (latency < 0) throw std::invalid_argument("--latency must be >= 0 s");
    }
    else if (arg == "--settle") settle_steps = cli::positive_list<long>(value(), arg).at(0);
    else if (arg == "--blend") {
      const double n = cli::number_list(value(), arg).at(0);
      if (n < 0 || n != std::floor(n)) throw std::invalid_argument("--blend: a whole number of steps >= 0");
      blend_steps = static_cast<long>(n);
    }
    else if (arg == "--lead") lead = true;
    else if (arg == "--no-lead") lead = false;
    else if (arg == "--reference") {
      const std::string text = value();
      const size_t second = text.find(',', text.find(',') + 1);
      if (second == std::string::npos) throw std::invalid_argument("--reference: expected X,Y,FILE");
      reference_files.emplace_back(point(text.substr(0, second)), text.substr(second + 1));
    } else if (arg == "--stiffness") stiffness = cli::positive_list(value(), arg).at(0);
    else if (arg == "--csv") csv_file = value();
    else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
    else if (arg == "--json") json = true;
    else if (arg == "--quiet") quiet = true;
    else return false;
    return true;
  });
  if (scene_file.empty()) cli::usage_error("palpate-follow", "--scene is required", kUsage);

  try {
    Scene scene = load_scene(scene_file, overrides);
    if (!scene.distribution.refine.enabled() || scene.distribution.focus_given)
      throw std::invalid_argument(scene_file + ": the scene's mesh must be refined toward the tool "
                                  "(body.distribution.refine, without distribution.focus)");
    const Eigen::Vector2d direction = (to - from).normalized();
    const double length = (to - from).norm();
    place_indenter_at_site(scene, from[0], from[1], "--from");
    const Options opt = options_of(scene);
    const double dt = opt.integrator.dt;
    const TetMesh base = read_mesh(scene.distribution.mesh_file);

    // The references along the path: d_ref(force) at each site, by its distance along the path.
    std::vector<Site> sites;
    for (const auto& [xy, file] : reference_files) {
      const Reference ref = load_reference(file);
      sites.push_back({(xy - from).dot(direction), reference_indentation(ref, force)});
    }
    std::sort(sites.begin(), sites.end(), [](const Site& a, const Site& b) { return a.s < b.s; });
    auto reference_depth = [&](double s) -> double {
      if (sites.size() < 2 || s < sites.front().s || s > sites.back().s) return NAN;
      for (size_t k = 1; k < sites.size(); ++k)
        if (s <= sites[k].s) return sites[k - 1].depth + (s - sites[k - 1].s) / (sites[k].s - sites[k - 1].s) * (sites[k].depth - sites[k - 1].depth);
      return NAN;
    };

    auto make_cloud = [&](const Vec3& tool) {
      Cloud c;
      auto t0 = std::chrono::steady_clock::now();
      c.focus = refinement_focus(scene, base, tool);
      c.cloud = refined_mesh_cloud(scene, base, tool);
      c.refine_ms = ms_since(t0);
      t0 = std::chrono::steady_clock::now();
      c.model = build_model(scene, c.cloud);
      c.build_ms = ms_since(t0);
      return c;
    };

    Cloud current = make_cloud(scene.indenter.position);
    State state = make_state(current.model, opt);
    Options guided = opt;
    guided.tool_guide = ToolGuide::vertical;
    guided.coupling = {};
    const PressResult press = press_to_rest(current.model, guided, scene.verify.rest, state, force);
    if (press.failure.status != StepStatus::ok) throw std::runtime_error("the press at the start diverged: " + describe(press.failure));
    if (!quiet)
      std::fprintf(stderr, "palpate-follow: pressed to rest at (%g, %g) with %g N in %ld steps (%d particles)\n", from[0],
                   from[1], force, press.steps, current.model.particle_count);

    Options sliding = opt;
    sliding.tool_guide = ToolGuide::free;
    sliding.coupling.stiffness = stiffness;
    sliding.coupling.damping = 2.0 * std::sqrt(stiffness * opt.indenter_mass);
    reset_health(current.model, sliding, state);
    const Vec3 start = state.indenter_center;
    const double t0 = state.time;
    // The expected delay from asking for a refocus to its swap (for the aim): the last build's.
    double expected_delay = latency >= 0 ? latency : 0.2;

    std::ofstream csv;
    if (!csv_file.empty()) {
      csv.open(csv_file);
      csv << "s_m,depth_m,depth_ref_m,fz_N,fz_model_N,fx_N,particles,swap\n";
    }
    std::vector<Swap> swaps;
    std::vector<double> errors;  // relative depth error along the path where a reference exists
    bool pending = false;
    long swap_at = 0;
    CloudTransfer transfer;
    State shadow, retired_state;
    Cloud retired;
    long blend_from = -1, blend_end = -1;
    double worst_change = 0, worst_change_s = NAN;
    double last_transfer_ms = 0, last_apply_ms = 0;
    Cloud next;
    double fz_prev = 0, depth_prev = 0, worst_jump = 0, worst_jump_s = NAN;
    std::string status = "ok";
    const long max_steps = std::lround((length + 0.01) / (speed * dt)) + 20000;
    long k = 0;
    for (; k < max_steps; ++k) {
      const double target_s = speed * (state.time - t0 + dt);
      const Vec3 target(start[0] + direction[0] * target_s, start[1] + direction[1] * target_s, state.indenter_center[2]);
      state.tool_target = target;
      const Vec3 c = state.indenter_center;
      const double s = (Eigen::Vector2d(c[0], c[1]) - from).dot(direction);
      // Refocus: asked for when the surface point under the tool is far from the focus.
      if (!pending && (refinement_focus(scene, base, c) - current.focus).norm() > refocus_distance) {
        // Aimed ahead along the tool's velocity by 1.5 times the delay to the swap: if the next
        // refocus is asked for at once, the tool is half a delay behind the focus at this swap
        // and half a delay past it at the next.
        Vec3 aim = c;
        const Vec3 v(state.indenter_velocity[0], state.indenter_velocity[1], 0.0);
        const double delay = expected_delay + settle_steps * dt;  // until the swap
        if (lead && v.norm() > 0) aim += 1.5 * delay * v;
        next = make_cloud(aim);
        const double build_s = 1e-3 * (next.refine_ms + next.build_ms);
        if (latency < 0) expected_delay = build_s;
        pending = true;
        swap_at = k + std::lround((latency >= 0 ? latency : build_s) / dt);
      }
      bool swapped = false;
      // The shadow: the new cloud, carried over from the state at the end of the latency, is
      // stepped beside the current one for --settle steps with the tool where the current
      // one has it, and takes over from it only then (its transient behind it).
      if (pending && k == swap_at) {
        const auto t = std::chrono::steady_clock::now();
        transfer = make_cloud_transfer(current.model.rest_position, current.cloud.tetrahedra, next.model.rest_position,
                                       next.cloud.tetrahedra);
        last_transfer_ms = ms_since(t);
        shadow = make_state(next.model, sliding);
        const auto t2 = std::chrono::steady_clock::now();
        transfer_state(transfer, current.model, state, next.model, shadow);
        last_apply_ms = ms_since(t2);
      }
      if (pending && k >= swap_at && k < swap_at + settle_steps) {
        copy_tool(state, shadow);
        shadow.tool_target = target;
        if (is_fault(step(next.model, sliding, shadow))) {
          status = "the shadow diverged: " + describe(shadow.health.report);
          break;
        }
      }
      if (pending && k >= swap_at + settle_steps) {
        Swap sw;
        sw.s = s;
        sw.particles_before = current.model.particle_count;
        sw.fz_before = fz_prev;
        sw.depth_before = depth_prev;
        sw.refine_ms = next.refine_ms;
        sw.build_ms = next.build_ms;
        sw.transfer_ms = last_transfer_ms;
        sw.apply_ms = last_apply_ms;
        sw.exact = transfer.exact;
        // The tool stays the current one's; the body is the shadow's.
        copy_tool(state, shadow);
        shadow.health = state.health;
        State fresh = std::move(shadow);
        shadow = State();
        retired_state = std::move(state);
        state = std::move(fresh);
        retired = std::move(current);
        blend_from = k;
        blend_end = k + blend_steps;
        current = std::move(next);
        sw.particles_after = current.model.particle_count;
        swaps.push_back(sw);
        pending = false;
        swapped = true;
      }
      // The retired cloud keeps stepping beside the new one for --blend steps, the tool shared,
      // and the force rendered moves from its contact force to the new one's linearly.
      const bool blending = blend_from >= 0 && k < blend_from + blend_steps;
      double fz_retired = 0;
      if (blending) {
        copy_tool(state, retired_state);
        retired_state.tool_target = target;
        if (is_fault(step(retired.model, sliding, retired_state))) blend_from = -1;  // let it go
        fz_retired = retired_state.indenter_contact_force[2];
      }
      const StepStatus st = step(current.model, sliding, state);
      if (is_fault(st)) {
        status = "diverged: " + describe(state.health.report);
        break;
      }
      const double fz_model = state.indenter_contact_force[2];  // the body pushes the tool up
      double fz = fz_model;  // what a device would be given
      if (blending && blend_from >= 0) {
        const double alpha = static_cast<double>(k - blend_from + 1) / (blend_steps + 1);
        fz = (1 - alpha) * fz_retired + alpha * fz_model;
      }
      if (blend_from >= 0 && k + 1 >= blend_from + blend_steps) {
        retired = Cloud();
        retired_state = State();
        blend_from = -1;
      }
      const double depth = indentation_at_tool(current.model, state);
      // The largest step of the force given while the resolution changes (the swap and the blend).
      if (!swaps.empty() && k <= blend_end) {
        const double change = std::abs(fz - fz_prev) / force;
        if (change > worst_change) {
          worst_change = change;
          worst_change_s = (Eigen::Vector2d(state.indenter_center[0], state.indenter_center[1]) - from).dot(direction);
        }
      }
      if (swapped) {
        Swap& sw = swaps.back();
        sw.fz_after = fz;
        sw.depth_after = depth;
        const double jump = std::abs(fz - fz_prev) / force;
        if (!(jump <= worst_jump)) {
          worst_jump = jump;
          worst_jump_s = sw.s;
        }
      }
      const double s_now = (Eigen::Vector2d(state.indenter_center[0], state.indenter_center[1]) - from).dot(direction);
      const double d_ref = reference_depth(s_now);
      if (std::isfinite(d_ref)) errors.push_back(depth / d_ref - 1.0);
      if (csv.is_open())
        csv << s_now << ',' << depth << ',' << d_ref << ',' << fz << ',' << fz_model << ',' << state.indenter_contact_force[0] << ','
            << current.model.particle_count << ',' << (swapped ? 1 : 0) << '\n';
      fz_prev = fz;
      depth_prev = depth;
      if (s_now >= length) break;
      if (!quiet && k % 2000 == 0)
        std::fprintf(stderr, "  s = %6.1f mm  depth %.4f mm  F_z %.4f N  %zu refocus\n", 1e3 * s_now, 1e3 * depth, fz,
                     swaps.size());
    }
    double worst_error = 0, sum2 = 0;
    for (double e : errors) {
      worst_error = std::max(worst_error, std::abs(e));
      sum2 += e * e;
    }
    // Per-step changes of F_z away from swaps: the ripple a homogeneous path shows.
    std::vector<double> refine_ms, build_ms, transfer_ms, apply_ms;
    for (const Swap& sw : swaps) {
      refine_ms.push_back(sw.refine_ms);
      build_ms.push_back(sw.build_ms);
      transfer_ms.push_back(sw.transfer_ms);
      apply_ms.push_back(sw.apply_ms);
    }
    if (json) {
      nlohmann::json out;
      out["scene"] = scene_file;
      out["force"] = force;
      out["speed"] = speed;
      out["refocus_distance"] = refocus_distance;
      out["latency"] = latency >= 0 ? nlohmann::json(latency) : nlohmann::json("measured");
      out["lead"] = lead;
      out["status"] = status;
      out["steps"] = k;
      out["refocus_count"] = swaps.size();
      out["worst_jump_relative"] = worst_jump;
      out["worst_step_while_changing"] = worst_change;
      out["worst_step_while_changing_s"] = worst_change_s;
      out["worst_jump_s"] = worst_jump_s;
      out["worst_depth_error"] = errors.empty() ? NAN : worst_error;
      out["rms_depth_error"] = errors.empty() ? NAN : std::sqrt(sum2 / errors.size());
      out["median_ms"] = {{"refine", cli::median(refine_ms)}, {"build", cli::median(build_ms)},
                          {"transfer", cli::median(transfer_ms)}, {"apply", cli::median(apply_ms)}};
      for (const Swap& sw : swaps)
        out["swaps"].push_back({{"s", sw.s}, {"particles", {sw.particles_before, sw.particles_after}},
                                {"fz", {sw.fz_before, sw.fz_after}}, {"depth", {sw.depth_before, sw.depth_after}},
                                {"exact", sw.exact}, {"refine_ms", sw.refine_ms}, {"build_ms", sw.build_ms},
                                {"transfer_ms", sw.transfer_ms}, {"apply_ms", sw.apply_ms}});
      std::printf("%s\n", out.dump(2).c_str());
    } else {
      std::printf("palpate-follow: %s, %g N at %g m/s from (%g, %g) to (%g, %g): %s, %ld steps, %zu refocus\n",
                  scene_file.c_str(), force, speed, from[0], from[1], to[0], to[1], status.c_str(), k, swaps.size());
      std::printf("  largest jump of F_z at a swap: %.3f %% of F (at s = %.1f mm)\n", 100 * worst_jump, 1e3 * worst_jump_s);
      std::printf("  largest step of F_z while the resolution changes (swap and blend): %.3f %% of F (at s = %.1f mm)\n",
                  100 * worst_change, 1e3 * worst_change_s);
      if (!errors.empty())
        std::printf("  depth against the references along the path: worst %.2f %%, rms %.2f %%\n", 100 * worst_error,
                    100 * std::sqrt(sum2 / errors.size()));
      std::printf("  refocus, median ms: refine %.1f, model build %.1f, transfer weights %.1f, apply %.3f\n",
                  cli::median(refine_ms), cli::median(build_ms), cli::median(transfer_ms), cli::median(apply_ms));
    }
    return status == "ok" ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-follow: %s\n", e.what());
    return 2;
  }
}
