// palpate-follow: the resolution that follows the tool, measured while the tool moves
// (docs/physics.md §7; issue #32's "Moving"). The scene's mesh is refined toward the tool
// (distribution.refine) and refocused as it moves by a FollowingModel (core/refocus.h:
// ask, build, shadow, swap with a fading force offset); the tool is pressed to rest at the
// start of a straight path on the top face with a constant normal force, then dragged along
// it at a constant speed by the virtual coupling (as palpate-slide drags it). It prints each
// swap's jump in the force a device would be given, the largest step of that force while the
// resolution changes, the cost of each part of a refocus, the caller's time per step, and
// the depth along the path against quasi-static references given at sites of the path
// (linear interpolation between them). Inline (default), a refocus is built on this thread
// and carried --latency later, so a run is deterministic; with --background it is built and
// shadowed on a worker thread as a session would, and --paced holds the steps to the
// wall clock (one step per dt), so that the latency is the real one.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "analysis/reference.h"
#include "analysis/rest.h"
#include "cli/arguments.h"
#include "cli/statistics.h"
#include "core/health.h"
#include "core/model.h"
#include "core/options.h"
#include "core/reference_file.h"
#include "core/refocus.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/step.h"

using namespace palpate;

namespace {

const char* kUsage = R"(usage: palpate-follow --scene FILE [options]
Drags the pressed tool along a straight path of the top face while the cloud's refinement
follows it (the scene's body.distribution.refine; core/refocus.h), and reports every
refocus: the jump of the force given at the swap, the time each part took, the time per
step, and the depth along the path against quasi-static references.
  --scene FILE          scene file (JSON) whose mesh distribution has "refine"
  --force F             commanded normal force, N (default 0.12)
  --speed V             target speed along the path, m/s (default 0.01)
  --from X,Y            start of the path on the top face, m (default -0.035,0)
  --to X,Y              its end, m (default 0.035,0)
  --refocus-distance D  refocus when the tool is D from the focus, m (default 0.0005)
  --latency S           inline: a refocus is carried to its new cloud S after it is asked
                        for, s (default 0.2, about a build's wall time here)
  --background          build and shadow on a worker thread (a session's way): the carry
                        follows the build, so the ticks depend on the machine
  --paced               one step per dt of wall time (with --background: the real latency)
  --settle N            shadow steps before a swap, at least (default 160)
  --fade N              steps over which the swap's force offset fades (default 40; 0: none)
  --lead                aim a refocus ahead along the tool's velocity, so that the tool passes
                        the new focus midway between its swap and the next (default)
  --no-lead             aim it at where the tool is
  --reference X,Y,FILE  the quasi-static reference at a site of the path (repeatable; ordered
                        along the path): the depth at --force is interpolated between them
  --stiffness K         coupling stiffness, N/m (default 100)
  --csv FILE            one row per step: s along the path, depth, F_z given, F_z of the
                        model, F_x, particles, swap, the caller's time for the step (ms)
  --set KEY=VALUE       override a scene field (repeatable)
  --json                one JSON object on stdout
  --quiet               no progress on stderr
)";

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

struct Swap {
  double s = 0;                              // m along the path at the swap
  double fz_before = 0, fz_after = 0;        // N, the force given the step before and after
  double depth_before = 0, depth_after = 0;  // m
  RefocusRecord record;
};

}  // namespace

int main(int argc, char** argv) {
  std::string scene_file, csv_file;
  SceneOverrides overrides;
  double force = 0.12, speed = 0.01, stiffness = 100;
  RefocusOptions refocus;
  Eigen::Vector2d from(-0.035, 0), to(0.035, 0);
  bool background = false, paced = false, json = false, quiet = false;
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
    auto whole = [&](const std::string& text) {
      const double n = cli::number_list(text, arg).at(0);
      if (n < 0 || n != std::floor(n) || n > 1e6) throw std::invalid_argument(arg + ": a whole number of steps >= 0");
      return static_cast<int>(n);
    };
    if (arg == "--scene") scene_file = value();
    else if (arg == "--force") force = cli::positive_list(value(), arg).at(0);
    else if (arg == "--speed") speed = cli::positive_list(value(), arg).at(0);
    else if (arg == "--from") from = point(value());
    else if (arg == "--to") to = point(value());
    else if (arg == "--refocus-distance") refocus.distance = cli::positive_list(value(), arg).at(0);
    else if (arg == "--latency") {
      refocus.latency = cli::number_list(value(), arg).at(0);
      if (!(refocus.latency >= 0)) throw std::invalid_argument("--latency must be >= 0 s");
    }
    else if (arg == "--background") background = true;
    else if (arg == "--paced") paced = true;
    else if (arg == "--settle") {
      refocus.settle_steps = whole(value());
      if (refocus.settle_steps < 1) throw std::invalid_argument("--settle: at least 1 step");
    }
    else if (arg == "--fade") refocus.fade_steps = whole(value());
    else if (arg == "--lead") refocus.lead = true;
    else if (arg == "--no-lead") refocus.lead = false;
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
    const Eigen::Vector2d direction = (to - from).normalized();
    const double length = (to - from).norm();
    place_indenter_at_site(scene, from[0], from[1], "--from");
    const Options opt = options_of(scene);
    const double dt = opt.integrator.dt;

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

    FollowingModel follow(scene, scene.indenter.position, refocus, background);
    State state = make_state(follow.model(), opt);
    Options guided = opt;
    guided.tool_guide = ToolGuide::vertical;
    guided.coupling = {};
    const PressResult press = press_to_rest(follow.model(), guided, scene.verify.rest, state, force);
    if (press.failure.status != StepStatus::ok) throw std::runtime_error("the press at the start diverged: " + describe(press.failure));
    if (!quiet)
      std::fprintf(stderr, "palpate-follow: pressed to rest at (%g, %g) with %g N in %ld steps (%d particles)\n", from[0],
                   from[1], force, press.steps, follow.model().particle_count);

    Options sliding = opt;
    sliding.tool_guide = ToolGuide::free;
    sliding.coupling.stiffness = stiffness;
    sliding.coupling.damping = 2.0 * std::sqrt(stiffness * opt.indenter_mass);
    reset_health(follow.model(), sliding, state);
    const Vec3 start = state.indenter_center;
    const double t0 = state.time;

    std::ofstream csv;
    if (!csv_file.empty()) {
      csv.open(csv_file);
      csv << "s_m,depth_m,depth_ref_m,fz_N,fz_model_N,fx_N,particles,swap,step_ms\n";
    }
    std::vector<Swap> swaps;
    std::vector<double> errors;  // relative depth error along the path where a reference exists
    const long max_steps = std::lround((length + 0.01) / (speed * dt)) + 20000;
    std::vector<double> step_ms;  // the caller's time per step: before_step and the step
    step_ms.reserve(max_steps);
    long misses = 0;              // paced: steps that ended after their tick's deadline
    double worst_change = 0, worst_change_s = NAN, fz_prev = 0, depth_prev = 0, worst_jump = 0, worst_jump_s = NAN;
    int64_t change_end_tick = -1;  // the last tick of the latest swap's fade
    std::string status = "ok";
    const auto wall_start = std::chrono::steady_clock::now();
    long k = 0;
    for (; k < max_steps; ++k) {
      const auto deadline = wall_start + std::chrono::duration<double>((k + 1) * dt);
      const double target_s = speed * (state.time - t0 + dt);
      state.tool_target = Vec3(start[0] + direction[0] * target_s, start[1] + direction[1] * target_s, state.indenter_center[2]);
      const double s = (Eigen::Vector2d(state.indenter_center[0], state.indenter_center[1]) - from).dot(direction);
      const auto step_start = std::chrono::steady_clock::now();
      const bool swapped = follow.before_step(sliding, state);
      const StepStatus st = step(follow.model(), sliding, state);
      step_ms.push_back(ms_since(step_start));
      if (is_fault(st)) {
        status = "diverged: " + describe(state.health.report);
        break;
      }
      if (paced) {
        if (std::chrono::steady_clock::now() > deadline) ++misses;
        std::this_thread::sleep_until(deadline);
      }
      const double fz_model = state.indenter_contact_force[2];  // the body pushes the tool up
      const double fz = fz_model + follow.force_offset(state)[2];  // what a device is given
      const double depth = indentation_at_tool(follow.model(), state);
      if (swapped) {
        Swap sw;
        sw.s = s;
        sw.fz_before = fz_prev;
        sw.depth_before = depth_prev;
        sw.fz_after = fz;
        sw.depth_after = depth;
        sw.record = follow.refocuses().back();
        swaps.push_back(sw);
        change_end_tick = state.tick + refocus.fade_steps;
        const double jump = std::abs(fz - fz_prev) / force;
        if (!(jump <= worst_jump)) {
          worst_jump = jump;
          worst_jump_s = s;
        }
      }
      const double s_now = (Eigen::Vector2d(state.indenter_center[0], state.indenter_center[1]) - from).dot(direction);
      // The largest step of the force given while the resolution changes (the swap and the fade).
      if (state.tick <= change_end_tick) {
        const double change = std::abs(fz - fz_prev) / force;
        if (change > worst_change) {
          worst_change = change;
          worst_change_s = s_now;
        }
      }
      const double d_ref = reference_depth(s_now);
      if (std::isfinite(d_ref)) errors.push_back(depth / d_ref - 1.0);
      if (csv.is_open())
        csv << s_now << ',' << depth << ',' << d_ref << ',' << fz << ',' << fz_model << ',' << state.indenter_contact_force[0] << ','
            << follow.model().particle_count << ',' << (swapped ? 1 : 0) << ',' << step_ms.back() << '\n';
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
    std::vector<double> refine_ms, build_ms, weights_ms, carry_ms, delay_ms;
    for (const Swap& sw : swaps) {
      refine_ms.push_back(sw.record.refine_ms);
      build_ms.push_back(sw.record.build_ms);
      weights_ms.push_back(sw.record.weights_ms);
      carry_ms.push_back(sw.record.carry_ms);
      delay_ms.push_back(1e3 * dt * (sw.record.swap_tick - sw.record.ask_tick));
    }
    const double step_median = cli::median(step_ms), step_p99 = cli::quantile(step_ms, 0.99),
                 step_max = step_ms.empty() ? NAN : *std::max_element(step_ms.begin(), step_ms.end());
    if (json) {
      nlohmann::json out;
      out["scene"] = scene_file;
      out["force"] = force;
      out["speed"] = speed;
      out["refocus_distance"] = refocus.distance;
      out["mode"] = background ? "background" : "inline";
      out["latency"] = background ? nlohmann::json("measured") : nlohmann::json(refocus.latency);
      out["paced"] = paced;
      out["lead"] = refocus.lead;
      out["settle_steps"] = refocus.settle_steps;
      out["fade_steps"] = refocus.fade_steps;
      out["status"] = status;
      out["steps"] = k;
      out["refocus_count"] = follow.refocus_count();
      out["dropped_count"] = follow.dropped_count();
      out["worst_jump_relative"] = worst_jump;
      out["worst_jump_s"] = worst_jump_s;
      out["worst_step_while_changing"] = worst_change;
      out["worst_step_while_changing_s"] = worst_change_s;
      out["worst_depth_error"] = errors.empty() ? NAN : worst_error;
      out["rms_depth_error"] = errors.empty() ? NAN : std::sqrt(sum2 / errors.size());
      out["step_ms"] = {{"median", step_median}, {"p99", step_p99}, {"max", step_max}};
      if (paced) out["deadline_misses"] = misses;
      out["median_ms"] = {{"refine", cli::median(refine_ms)}, {"build", cli::median(build_ms)},
                          {"weights", cli::median(weights_ms)}, {"carry", cli::median(carry_ms)},
                          {"ask_to_swap", cli::median(delay_ms)}};
      for (const Swap& sw : swaps)
        out["swaps"].push_back({{"s", sw.s},
                                {"particles", {sw.record.particles_before, sw.record.particles_after}},
                                {"fz", {sw.fz_before, sw.fz_after}},
                                {"depth", {sw.depth_before, sw.depth_after}},
                                {"force_offset_z", sw.record.force_offset[2]},
                                {"exact", sw.record.exact},
                                {"ticks", {sw.record.ask_tick, sw.record.carry_tick, sw.record.swap_tick}}});
      std::printf("%s\n", out.dump(2).c_str());
    } else {
      std::printf("palpate-follow: %s, %g N at %g m/s from (%g, %g) to (%g, %g), %s%s: %s, %ld steps, %lld refocus, %lld dropped\n",
                  scene_file.c_str(), force, speed, from[0], from[1], to[0], to[1], background ? "background" : "inline",
                  paced ? ", paced" : "", status.c_str(), k, static_cast<long long>(follow.refocus_count()),
                  static_cast<long long>(follow.dropped_count()));
      if (follow.dropped_count() > 0) std::printf("  last refocus dropped: %s\n", follow.last_error().c_str());
      std::printf("  largest jump of F_z at a swap: %.3f %% of F (at s = %.1f mm)\n", 100 * worst_jump, 1e3 * worst_jump_s);
      std::printf("  largest step of F_z while the resolution changes (swap and fade): %.3f %% of F (at s = %.1f mm)\n",
                  100 * worst_change, 1e3 * worst_change_s);
      if (!errors.empty())
        std::printf("  depth against the references along the path: worst %.2f %%, rms %.2f %%\n", 100 * worst_error,
                    100 * std::sqrt(sum2 / errors.size()));
      std::printf("  refocus, median ms: refine %.1f, model build %.1f, transfer weights %.1f, carry %.3f; ask to swap %.0f ms\n",
                  cli::median(refine_ms), cli::median(build_ms), cli::median(weights_ms), cli::median(carry_ms),
                  cli::median(delay_ms));
      std::printf("  this thread per step (before_step + step), ms: median %.3f, p99 %.3f, max %.3f (%.0f %% of dt at p99)",
                  step_median, step_p99, step_max, 100 * step_p99 / (1e3 * dt));
      if (paced) std::printf("; %ld deadline misses", misses);
      std::printf("\n");
    }
    return status == "ok" ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "palpate-follow: %s\n", e.what());
    return 2;
  }
}
