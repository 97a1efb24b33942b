// palpate-bench-step: timings of the simulation's hot paths on a scene with the
// indenter pressed into the body (contact active), on one thread and, with --threads N,
// on N threads in the same run (integrator.threads = N, core/thread_pool.h):
//   one internal-force evaluation, one RK4 step, one symplectic-Euler step and one
//   linearly implicit Euler step (step() with the scene's other settings; the second of a
//   running implicit-Euler simulation, and the first of a fresh State);
//   and, in the same run, the core's FMA peak (bench/fma_peak.h), of which the force
//   evaluation's GFLOP/s (flops counted per law, mls_internal_forces_flops) is a fraction.
// Every timed call starts from the same pressed state (restored, untimed, before
// each repetition), so every repetition does the same work; the figures are the
// medians over the repetitions (std::chrono::steady_clock).
#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/fma_peak.h"
#include "cli/arguments.h"
#include "cli/statistics.h"
#include "tools/load_scene.h"
#include "core/rate_schedule.h"
#include "core/checkpoint.h"
#include "core/contact.h"
#include "core/health.h"
#include "core/integrators.h"
#include "core/mls_forces.h"
#include "core/model.h"
#include "core/scene.h"
#include "core/solid.h"
#include "core/state.h"
#include "core/step.h"
#include "core/thread_pool.h"

namespace {

using namespace palpate;
using Clock = std::chrono::steady_clock;

const char* kUsage = R"(usage: palpate-bench-step [options]
Times one internal-force evaluation and one step of each integrator with the
indenter pressed into the body, on one thread (and on N with --threads N, in the
same run, interleaved); prints medians.
  --scene FILE      scene file (default: scenes/hertz_cube.json of the source tree)
  --per-edge N      override body.distribution.per_edge
  --set KEY=VALUE   override a scene field by its dotted path (repeatable)
  --repeats N       repetitions of the force evaluation, RK4 and symplectic-Euler
                    steps (default 300)
  --ie-repeats N    repetitions of each implicit-Euler step: the second of a running
                    simulation, and the first of a fresh State (default 10)
  --ie-dt SECONDS   time step of the implicit-Euler step (default 0.01)
  --press-force N   force pressing the indenter in before timing (default: the
                    largest force of the scene's verify.forces, 327.6 N for hertz_cube)
  --press-steps N   RK4 steps of pressing in (default 300), then more (up to 20x)
                    until at least --min-contacts particles are in contact
  --min-contacts N  (default 4)
  --threads N       also time everything on N threads (integrator.threads = N) and
                    print the speed-up over one thread (default 1: one thread only)
  --json            print one JSON object instead of the table
With the scene's integrator.max_interval above 1 (--set integrator.max_interval=8), also
times the multirate symplectic-Euler step (core/rate_schedule.h) over a period of
ticks (on N threads too with --threads N), and prints the pair work its ticks evaluate.
)";

using cli::median;

// How full the blocked force loop's lanes are: the weighted pairs over 4 x the neighbour slots
// (a block's four lists padded to its longest), and over 4 x the union of the four lists -- the
// slots a loop would need that wrote each f_j once per block of four (one x_j broadcast, one
// f_j update per distinct neighbour, every lane's weight for it, zero where it is not its
// neighbour).
struct LaneFill {
  double slots = NAN, block_union = NAN;
};
LaneFill lane_fill(const Model& m) {
  LaneFill fill;
  if (!detail::uses_blocked_loops(m)) return fill;
  const double pairs = m.neighbor_offset.back();
  int64_t union_size = 0;
  std::vector<int> neighbours;
  for (size_t b = 0; b < m.blocks.size(); ++b) {
    neighbours.clear();
    for (int l = 0; l < m.blocks[b].lanes; ++l) {
      const int i = m.blocks[b].particle[l];
      neighbours.insert(neighbours.end(), m.neighbor_index.begin() + m.neighbor_offset[i],
                        m.neighbor_index.begin() + m.neighbor_offset[i + 1]);
    }
    std::sort(neighbours.begin(), neighbours.end());
    union_size += std::unique(neighbours.begin(), neighbours.end()) - neighbours.begin();
  }
  fill.slots = pairs / (Model::block_width * static_cast<double>(m.block_slots.size()));
  fill.block_union = pairs / (Model::block_width * static_cast<double>(union_size));
  return fill;
}

// The pair work a tick would do if each particle's forces were evaluated at its own stable
// rate, as a multi-time-step scheme would: the stable step of a region grows with its spacing
// (at one density and modulus, dt ~ h / c), so particle i could step floor(h_i / h_min) ticks
// at a time, h its support radius. Returns the fraction of a tick's pair work that remains: the
// least such a scheme would do (it ignores the coupling at the interfaces between rates). NAN
// for a hexahedral model.
double own_rate_pair_work(const Model& m) {
  if (m.support_radius.empty() || m.neighbor_offset.back() == 0) return NAN;
  const double h_min = *std::min_element(m.support_radius.begin(), m.support_radius.end());
  double work = 0;
  for (int i = 0; i < m.particle_count; ++i)
    work += (m.neighbor_offset[i + 1] - m.neighbor_offset[i]) / std::max(1.0, std::floor(m.support_radius[i] / h_min));
  return work / m.neighbor_offset.back();
}

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path scene_file = std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes" / "hertz_cube.json";
  SceneOverrides overrides;
  int repeats = 300, ie_repeats = 10, press_steps = 300, min_contacts = 4, threads = 1;
  double ie_dt = 0.01, press_force = NAN;  // NAN: the scene's largest verification force
  bool json_out = false;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--scene") scene_file = value();
      else if (arg == "--per-edge") overrides.emplace_back("body.distribution.per_edge", value());
      else if (arg == "--set") overrides.push_back(cli::scene_override(value()));
      else if (arg == "--repeats") repeats = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--ie-repeats") ie_repeats = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--press-steps") press_steps = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--min-contacts") min_contacts = static_cast<int>(args.integer(1, 100000000));
      else if (arg == "--ie-dt") ie_dt = args.number();
      else if (arg == "--press-force") press_force = args.number();
      else if (arg == "--threads") threads = static_cast<int>(args.integer(1, kMaxThreads));
      else if (arg == "--json") json_out = true;
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-bench-step: " << e.what() << "\n\n" << kUsage;
    return 2;
  }

  std::optional<tools::LoadedScene> loaded = tools::load_scene_and_model("palpate-bench-step", scene_file, overrides);
  if (!loaded) return 1;
  const Model& model = loaded->model;
  const Options& scene_options = loaded->opt;
  const int n = model.particle_count;
  const bool is_mls = model.solid == SolidKind::mls;
  // Neighbour pairs of the MLS supports (the hex FEM has none: its particles are lattice nodes).
  const int nnz = is_mls && !model.neighbor_offset.empty() ? model.neighbor_offset.back() : 0;

  // One set of options per integrator (the scene's dt and damping; implicit Euler at --ie-dt).
  // The tool on the vertical guide: pressed free on a curved body (a dome) it slides off.
  Options held = scene_options;
  held.tool_guide = ToolGuide::vertical;
  held.integrator.threads = 1;  // pressing in; the timed variants set their own
  held.integrator.max_interval = 1;  // one rate; the multirate step's options below
  Options rk4_opt = held, se_opt = held, ie_opt = held;
  Options multirate_opt = se_opt;
  multirate_opt.integrator.max_interval = model.rate_schedule.period;
  const bool multirate = model.rate_schedule.period > 1;
  rk4_opt.integrator.type = IntegratorType::rk4;
  se_opt.integrator.type = IntegratorType::symplectic_euler;
  ie_opt.integrator.type = IntegratorType::implicit_euler;
  ie_opt.integrator.dt = ie_dt;

  // Press the indenter in with RK4 until it touches.
  if (std::isnan(press_force))
    press_force = *std::max_element(loaded->scene.verify.forces.begin(), loaded->scene.verify.forces.end());
  State pressed = make_state(model, rk4_opt);
  pressed.force_command = press_down(press_force);
  int pressing = 0;
  auto too_few = [&] { return static_cast<int>(pressed.contact_index.size()) < min_contacts; };
  for (; pressing < press_steps || (too_few() && pressing < 20 * press_steps); ++pressing) {
    const StepStatus st = step(model, rk4_opt, pressed);
    if (st != StepStatus::ok) {
      std::cerr << "palpate-bench-step: pressing in failed at step " << pressing << ": " << to_string(st) << "\n";
      return 1;
    }
  }
  const int contacts = static_cast<int>(pressed.contact_index.size());
  if (contacts < min_contacts) {
    std::cerr << "palpate-bench-step: " << contacts << " particles in contact after " << pressing
              << " steps of pressing (want " << min_contacts << ")\n";
    return 1;
  }
  // Every timed operation starts from the pressed state (positions, velocities, indenter
  // and contact set), restored without allocation; one State per thread count serves all
  // integrators.
  const Checkpoint start(pressed);
  // The first timed operation whose step did not return ok, with its status ("" when all did).
  std::string first_fault;
  auto check = [&](StepStatus st, const char* what) {
    if (st != StepStatus::ok && first_fault.empty()) first_fault = std::string(what) + ": " + to_string(st);
  };
  const Points& start_position = start.saved().position;

  // The timed operations, run round-robin (each after its untimed setup) so that
  // a disturbance of the machine spreads over all of them alike -- and over both thread
  // counts alike.
  struct Op {
    std::function<void()> setup, run;
    int repeats;
    std::vector<double> ms;
  };
  enum { force_eval, tangent, rk4_step, rk4_free, rk4_contact, se_step, se_free, ie_step, ie_first, ie_free, health,
         pair_floor, multirate_step, op_count };
  // The blocked force loop's memory work alone (detail::pair_loop_floor), one thread.
  const bool floor_timed = is_mls && detail::uses_blocked_loops(model);
  // Everything timed at one thread count: its own State (and pool), force buffers, options.
  struct Variant {
    int threads;
    State timed;
    WorkerThreads force_threads;
    Points f, df;
    Workspace linearized;
    Options rk4_opt, se_opt, ie_opt, multirate_opt;
    std::optional<State> fresh;  // the fresh State of the first implicit-Euler step
    std::vector<Op> ops;
  };
  std::vector<int> thread_counts = {1};
  if (threads > 1) thread_counts.push_back(threads);
  std::vector<std::unique_ptr<Variant>> variants;
  for (int c : thread_counts) {
    auto v = std::make_unique<Variant>();
    v->threads = c;
    v->rk4_opt = rk4_opt;
    v->se_opt = se_opt;
    v->ie_opt = ie_opt;
    v->multirate_opt = multirate_opt;
    for (Options* o : {&v->rk4_opt, &v->se_opt, &v->ie_opt, &v->multirate_opt}) o->integrator.threads = c;
    v->timed = make_state(model, v->rk4_opt);  // its pool: c threads
    v->force_threads.resize(c, n);
    v->f.resize(3, n);
    v->df.resize(3, n);
    v->linearized.threads.resize(c, n);
    linearize_elastic(model, start_position, v->linearized);
    Variant& w = *v;
    State& timed = w.timed;
    std::vector<Op>& ops = w.ops;
    ops.resize(op_count);
    auto restore = [&w, &start] { start.restore(w.timed); };
    // The force evaluation is timed warm (after an untimed one), as in the stages of a step.
    auto evaluate_forces = [&model, &start_position, &w] { elastic_forces(model, start_position, w.f, w.force_threads); };
    ops[force_eval] = {evaluate_forces, evaluate_forces, repeats, {}};
    auto pair_loop_alone = [&model, &start_position, &w] { (void)detail::pair_loop_floor(model, start_position, w.f, w.force_threads); };
    ops[pair_floor] = {pair_loop_alone, pair_loop_alone, floor_timed && c == 1 ? repeats : 0, {}};
    // One application of the tangent stiffness (the work of a CG iteration of implicit Euler).
    auto apply_tangent = [&model, &start, &w] { elastic_force_differential(model, w.linearized, start.saved().velocity, w.df); };
    ops[tangent] = {apply_tangent, apply_tangent, repeats, {}};
    ops[rk4_step] = {restore, [&] { check(step(model, w.rk4_opt, timed), "RK4 step"); }, repeats, {}};
    ops[rk4_free] = {restore, [&] { free_motion_rk4(model, w.rk4_opt, timed); }, repeats, {}};
    ops[rk4_contact] = {[&, restore] { restore(); free_motion_rk4(model, w.rk4_opt, timed); },
                        [&] { check(solve_contact(model, w.rk4_opt, timed), "RK4 contact solve"); }, repeats, {}};
    ops[se_step] = {restore, [&] { check(step(model, w.se_opt, timed), "symplectic-Euler step"); }, repeats, {}};
    ops[se_free] = {restore, [&] { free_motion_symplectic_euler(model, w.se_opt, timed); }, repeats, {}};
    // Linearly implicit Euler with a larger step: CG for the free motion plus the coupled
    // contact response. Timed as a step of a running implicit-Euler simulation: the second
    // implicit-Euler step from the pressed state (the first, untimed, is the setup; the
    // workspace carries whatever the previous step left in it), and as the first implicit-Euler
    // step of a fresh State (its workspace as make_state leaves it; set up untimed).
    ops[ie_step] = {[&, restore] { restore(); check(step(model, w.ie_opt, timed), "implicit-Euler step"); },
                    [&] { check(step(model, w.ie_opt, timed), "implicit-Euler step"); }, ie_repeats, {}};
    ops[ie_first] = {[&] { w.fresh.emplace(make_state(model, w.ie_opt)); start.restore(*w.fresh); },
                     [&] { check(step(model, w.ie_opt, *w.fresh), "implicit-Euler first step"); }, ie_repeats, {}};
    ops[ie_free] = {restore, [&] { free_motion_implicit_euler(model, w.ie_opt, timed); }, ie_repeats, {}};
    // The per-step health checks alone (core/health.h; part of every step above).
    ops[health] = {[&, restore] {
                     restore();
                     free_motion_symplectic_euler(model, w.se_opt, timed);
                     check(solve_contact(model, w.se_opt, timed), "symplectic-Euler contact solve");
                   },
                   [&] { (void)check_health(model, w.se_opt, timed, StepStatus::ok); }, repeats, {}};
    // The multirate step at the ticks of a period in turn (each its own phase's work).
    auto multirate_setup = [&, restore, phase = int64_t{0}]() mutable {
      restore();
      timed.tick += phase++;
      std::fill(timed.elastic_update_tick.begin(), timed.elastic_update_tick.end(), timed.tick - 1);
    };
    ops[multirate_step] = {multirate_setup, [&] { check(step(model, w.multirate_opt, timed), "multirate symplectic-Euler step"); },
                           multirate ? repeats : 0, {}};
    for (Op& op : ops) op.ms.reserve(op.repeats);
    variants.push_back(std::move(v));
  }
  // The peak before and after the timed operations; the larger counts (a disturbance only slows).
  bench::FmaPeak peak = bench::measure_fma_peak();
  for (int r = 0; r < std::max(repeats, ie_repeats); ++r)
    for (auto& v : variants)
      for (Op& op : v->ops) {
        if (r >= op.repeats) continue;
        op.setup();
        const auto t0 = Clock::now();
        op.run();
        const auto t1 = Clock::now();
        op.ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      }
  {
    const bench::FmaPeak after = bench::measure_fma_peak();
    peak.double_gflops = std::max(peak.double_gflops, after.double_gflops);
    peak.single_gflops = std::max(peak.single_gflops, after.single_gflops);
  }
  const std::vector<Op>& ops = variants[0]->ops;
  State& timed = variants[0]->timed;
  auto restore = [&] { start.restore(timed); };
  auto med = [&](int k) { return median(ops[k].ms); };
  // Counted for the MLS solid, every law (the corotational polar iterations at the timed positions).
  const bool flops_counted = is_mls;
  const double flops = flops_counted ? mls_internal_forces_flops(model, start_position) : 0.0;
  const double force_eval_ms = med(force_eval), tangent_ms = med(tangent), rk4_ms = med(rk4_step), rk4_free_ms = med(rk4_free),
               rk4_contact_ms = med(rk4_contact), se_ms = med(se_step), se_free_ms = med(se_free),
               ie_ms = med(ie_step), ie_first_ms = med(ie_first), ie_free_ms = med(ie_free), health_ms = med(health);
  const double multirate_ms = multirate ? med(multirate_step) : NAN;
  // The pair work of the multirate step's ticks: the mean and the largest over the period, of all.
  double multirate_work_mean = NAN, multirate_work_max = NAN;
  int multirate_near = 0;  // coarse particles near the pressed tool, which update every tick
  double multirate_extra = 0;  // the pair work their domains add to a tick, of all
  if (multirate) {
    const RateSchedule& rs = model.rate_schedule;
    restore();
    std::fill(timed.elastic_update_tick.begin(), timed.elastic_update_tick.end(), timed.tick - 1);
    check(step(model, multirate_opt, timed), "multirate symplectic-Euler step");
    multirate_near = static_cast<int>(timed.work.subcycle_near.size());
    for (int b : timed.work.subcycle_extra)
      multirate_extra += static_cast<double>(model.blocks[b].slot_end - model.blocks[b].slot_begin) / rs.slots_total;
    multirate_work_mean = multirate_work_max = 0;
    for (int64_t slots : rs.slots_at_phase) {
      const double w = static_cast<double>(slots) / static_cast<double>(rs.slots_total);
      multirate_work_mean += w / rs.period;
      multirate_work_max = std::max(multirate_work_max, w);
    }
  }

  // What the last timed steps did (every repetition does the same).
  restore();
  check(step(model, rk4_opt, timed), "RK4 step");
  const int rk4_contacts = static_cast<int>(timed.contact_index.size());
  const int rk4_candidates = static_cast<int>(timed.out.contact_candidate.size());
  const int rk4_pivots = timed.out.contact_iterations;  // both projections' LCP iterations
  restore();
  check(step(model, ie_opt, timed), "implicit-Euler step");
  check(step(model, ie_opt, timed), "implicit-Euler step");
  const int ie_cg_iterations = timed.out.cg_iterations;
  const int ie_candidates = static_cast<int>(timed.out.contact_candidate.size());
  const int ie_contacts = static_cast<int>(timed.contact_index.size());
  const StepOutputs ie_out = timed.out;
  State first = make_state(model, ie_opt);
  start.restore(first);
  check(step(model, ie_opt, first), "implicit-Euler first step");
  const StepOutputs ie_first_out = first.out;
  // The contact stage's CG work (core/contact.h): solves, iterations, compliance columns, splitting iterations.
  auto contact_work = [](const StepOutputs& o) {
    return nlohmann::json{{"cg_solves", o.contact_cg_solves},
                          {"cg_iterations", o.contact_cg_iterations},
                          {"columns", o.contact_columns},
                          {"splitting_iterations", o.contact_splitting_iterations},
                          {"candidates", o.contact_candidate.size()}};
  };

  // The floor under the force evaluation: its gathers, F and scatters with P = F; the law's loop
  // at that time would reach `ceiling` of the double peak.
  double floor_ms = NAN, floor_ceiling = NAN;
  if (floor_timed) {
    floor_ms = med(pair_floor);
    if (peak.double_gflops > 0) floor_ceiling = flops / (floor_ms * 1e6) / peak.double_gflops;
  }
  const double gflops = flops / (force_eval_ms * 1e6);
  const double fraction_of_peak = peak.double_gflops > 0 ? gflops / peak.double_gflops : NAN;
  const double ns_per_pair = nnz > 0 ? force_eval_ms * 1e6 / nnz : NAN;
  nlohmann::json j;
  j["scene"] = model.name;
  j["model"] = is_mls ? "mls" : "hex_fem";
  j["law"] = is_mls ? nlohmann::json(to_string(model.law)) : nlohmann::json(nullptr);
  j["particles"] = n;
  j["fixed_particles"] = model.fixed_count;
  j["neighbor_pairs"] = nnz;
  j["contacts"] = contacts;
  j["press_steps"] = pressing;
  j["repeats"] = repeats;
  j["dt"] = scene_options.integrator.dt;
  j["force_eval_ms"] = force_eval_ms;
  j["force_eval_flops"] = flops_counted ? nlohmann::json(flops) : nlohmann::json(nullptr);
  j["force_eval_gflops"] = flops_counted ? nlohmann::json(gflops) : nlohmann::json(nullptr);
  j["force_eval_fraction_of_peak"] = flops_counted && peak.double_gflops > 0 ? nlohmann::json(fraction_of_peak) : nlohmann::json(nullptr);
  j["force_eval_ns_per_pair"] = nnz > 0 ? nlohmann::json(ns_per_pair) : nlohmann::json(nullptr);
  j["peak_double_gflops"] = peak.double_gflops;
  j["peak_single_gflops"] = peak.single_gflops;
  j["pair_loop_floor_ms"] = floor_timed ? nlohmann::json(floor_ms) : nlohmann::json(nullptr);
  j["pair_loop_floor_ns_per_pair"] = floor_timed && nnz > 0 ? nlohmann::json(floor_ms * 1e6 / nnz) : nlohmann::json(nullptr);
  j["force_eval_ceiling_fraction_of_peak"] =
      floor_timed && peak.double_gflops > 0 ? nlohmann::json(floor_ceiling) : nlohmann::json(nullptr);
  const LaneFill fill = lane_fill(model);
  j["slot_fill"] = std::isnan(fill.slots) ? nlohmann::json(nullptr) : nlohmann::json(fill.slots);
  j["block_union_fill"] = std::isnan(fill.block_union) ? nlohmann::json(nullptr) : nlohmann::json(fill.block_union);
  const double own_rate = own_rate_pair_work(model);
  j["own_rate_pair_work"] = std::isnan(own_rate) ? nlohmann::json(nullptr) : nlohmann::json(own_rate);
  j["force_differential_ms"] = tangent_ms;
  j["rk4_step_ms"] = rk4_ms;
  j["rk4_step_contacts"] = rk4_contacts;
  j["rk4_step_breakdown"] = {
      {"force_evals_ms", 4 * force_eval_ms},
      {"free_motion_ms", rk4_free_ms},
      {"vector_updates_ms", rk4_free_ms - 4 * force_eval_ms},
      {"contact_ms", rk4_contact_ms},
      {"contact_candidates", rk4_candidates},
      {"contact_pivots", rk4_pivots},
      {"other_ms", rk4_ms - rk4_free_ms - rk4_contact_ms},
  };
  j["symplectic_euler_step_ms"] = se_ms;
  j["symplectic_euler_step_breakdown"] = {
      {"force_eval_ms", force_eval_ms},
      {"free_motion_ms", se_free_ms},
      {"vector_updates_ms", se_free_ms - force_eval_ms},
      {"contact_and_other_ms", se_ms - se_free_ms},
  };
  if (multirate) {
    j["multirate_max_interval"] = model.rate_schedule.period;
    j["multirate_step_ms"] = multirate_ms;
    j["multirate_pair_work_mean"] = multirate_work_mean;
    j["multirate_pair_work_max"] = multirate_work_max;
    j["multirate_near_tool"] = multirate_near;
    j["multirate_near_tool_pair_work"] = multirate_extra;
  }
  j["implicit_euler_step_ms"] = ie_ms;
  j["implicit_euler_first_step_ms"] = ie_first_ms;
  j["implicit_euler_dt"] = ie_dt;
  j["implicit_euler_repeats"] = ie_repeats;
  j["implicit_euler_cg_iterations"] = ie_cg_iterations;
  j["implicit_euler_contact_solves"] = ie_out.contact_cg_solves;
  j["implicit_euler_contact_candidates"] = ie_candidates;
  j["implicit_euler_contact_work"] = contact_work(ie_out);
  j["implicit_euler_first_step_contact_work"] = contact_work(ie_first_out);
  j["implicit_euler_contacts"] = ie_contacts;
  j["implicit_euler_step_breakdown"] = {
      {"free_motion_ms", ie_free_ms},
      {"contact_and_other_ms", ie_ms - ie_free_ms},
  };
  j["health_check_ms"] = health_ms;
  j["health_check_fraction_rk4"] = health_ms / rk4_ms;
  j["health_check_fraction_symplectic_euler"] = health_ms / se_ms;
  j["all_steps_ok"] = first_fault.empty();
  j["first_fault"] = first_fault.empty() ? nlohmann::json(nullptr) : nlohmann::json(first_fault);
  // The other thread count: its medians and the speed-up (one thread's time over its).
  const char* kCompared[][2] = {{"force_eval_ms", "internal forces"},
                                {"force_differential_ms", "tangent K dx"},
                                {"rk4_step_ms", "RK4 step"},
                                {"symplectic_euler_step_ms", "symplectic-Euler step"},
                                {"implicit_euler_step_ms", "implicit-Euler step"},
                                {"multirate_step_ms", "multirate symplectic-Euler step"}};
  const int compared_op[] = {force_eval, tangent, rk4_step, se_step, ie_step, multirate_step};
  const int compared = multirate ? 6 : 5;  // the multirate step where the model has a schedule
  if (variants.size() > 1) {
    const Variant& v = *variants[1];
    nlohmann::json t;
    t["threads"] = v.threads;
    for (int k = 0; k < compared; ++k) {
      const double ms = median(v.ops[compared_op[k]].ms);
      t[kCompared[k][0]] = ms;
      t[std::string(kCompared[k][0]).replace(std::string(kCompared[k][0]).size() - 3, 3, "_speedup")] =
          median(ops[compared_op[k]].ms) / ms;
    }
    j["threads"] = t;
  }

  if (json_out) {
    std::cout << j.dump() << "\n";
  } else {
    std::printf("palpate-bench-step: %s, %d particles (%d fixed), %d neighbour pairs (%.2f per particle)\n",
                model.name.c_str(), n, model.fixed_count, nnz, double(nnz) / n);
    std::printf("pressed in with %g N for %d RK4 steps: %d particles in contact\n", press_force, pressing, contacts);
    std::printf("medians of %d repetitions (implicit Euler: %d), one thread\n\n", repeats, ie_repeats);
    std::printf("FMA peak of one core (AVX2, measured in this run): %.1f GFLOP/s double, %.1f GFLOP/s single\n\n",
                peak.double_gflops, peak.single_gflops);
    if (flops_counted)
      std::printf("  %-34s %10.4f ms   %.2f GFLOP/s (%.3g flop, %s law), %.0f %% of the double peak, %.2f ns per pair\n",
                  "mls_internal_forces", force_eval_ms, gflops, flops, to_string(model.law),
                  100 * fraction_of_peak, ns_per_pair);
    else
      std::printf("  %-34s %10.4f ms\n", "mls_internal_forces", force_eval_ms);
    if (floor_timed)
      std::printf("  %-34s %10.4f ms   %.2f ns per pair (%.0f %% of the force evaluation): at this time the\n"
                  "  %-34s %10s      force evaluation's flops would reach %.0f %% of the double peak\n",
                  "  its pair loop alone (P = F)", floor_ms, floor_ms * 1e6 / nnz, 100 * floor_ms / force_eval_ms, "",
                  "", 100 * floor_ceiling);
    if (!std::isnan(fill.slots))
      std::printf("  %-34s %10.0f %%   of their lanes hold a pair (a loop writing each f_j once per block\n"
                  "  %-34s %10s      would fill %.0f %%: the union of the block's four lists)\n",
                  "  its neighbour slots", 100 * fill.slots, "", "", 100 * fill.block_union);
    if (!std::isnan(own_rate))
      std::printf("  %-34s %10.0f %%   of a tick's pairs, each particle's forces at its own stable rate\n"
                  "  %-34s %10s      (every floor(h_i / h_min) ticks: the least a step with several rates would do)\n",
                  "  its pairs at their own rates", 100 * own_rate, "", "");
    std::printf("  %-34s %10.4f ms\n", "mls_force_differential (K dx)", tangent_ms);
    std::printf("  %-34s %10.4f ms   (%d contacts)\n", "RK4 step", rk4_ms, rk4_contacts);
    std::printf("  %-34s %10.4f ms\n", "  4 force evaluations", 4 * force_eval_ms);
    std::printf("  %-34s %10.4f ms\n", "  vector updates (free motion rest)", rk4_free_ms - 4 * force_eval_ms);
    std::printf("  %-34s %10.4f ms   (%d candidates, %d pivots)\n", "  contact solve", rk4_contact_ms, rk4_candidates,
                rk4_pivots);
    std::printf("  %-34s %10.4f ms\n", "  other", rk4_ms - rk4_free_ms - rk4_contact_ms);
    std::printf("  %-34s %10.4f ms\n", "symplectic-Euler step", se_ms);
    std::printf("  %-34s %10.4f ms\n", "  free motion", se_free_ms);
    if (multirate) {
      std::printf("  %-34s %10.4f ms   (max interval %d, over the ticks of its period)\n", "multirate symplectic-Euler step",
                  multirate_ms, model.rate_schedule.period);
      std::printf("  %-34s %10.0f %%   of the force blocks' pairs a tick, mean (largest %.0f %%)\n", "  its pair work",
                  100 * multirate_work_mean, 100 * multirate_work_max);
      std::printf("  %-34s %10.0f %%   more for the %d coarse particles near the pressed tool (every tick)\n",
                  "  near the tool", 100 * multirate_extra, multirate_near);
    }
    std::printf("  %-34s %10.4f ms   (dt %g s, %d CG iterations, %d candidates, %d contacts)\n", "implicit-Euler step",
                ie_ms, ie_dt, ie_cg_iterations, ie_candidates, ie_contacts);
    std::printf("  %-34s %10.4f ms\n", "  free motion", ie_free_ms);
    std::printf("  %-34s              (%d CG solves, %d iterations, %d columns, %d splitting iterations)\n",
                "  contact", ie_out.contact_cg_solves, ie_out.contact_cg_iterations, ie_out.contact_columns,
                ie_out.contact_splitting_iterations);
    std::printf("  %-34s %10.4f ms   (contact: %d CG solves, %d iterations, %d columns, %d splitting iterations)\n",
                "implicit-Euler first step (fresh)", ie_first_ms, ie_first_out.contact_cg_solves,
                ie_first_out.contact_cg_iterations, ie_first_out.contact_columns, ie_first_out.contact_splitting_iterations);
    std::printf("  %-34s %10.4f ms   (%.2f %% of an RK4 step, %.2f %% of a symplectic-Euler step)\n",
                "health checks (in every step)", health_ms, 100 * health_ms / rk4_ms, 100 * health_ms / se_ms);
    if (variants.size() > 1) {
      const Variant& v = *variants[1];
      std::printf("\non %d threads (integrator.threads = %d; the same repetitions, interleaved with the above)\n\n",
                  v.threads, v.threads);
      std::printf("  %-34s %10s %10s %9s\n", "", "1 thread", "threads", "speed-up");
      for (int k = 0; k < compared; ++k) {
        const double one = median(ops[compared_op[k]].ms), many = median(v.ops[compared_op[k]].ms);
        std::printf("  %-34s %7.4f ms %7.4f ms %8.2fx\n", kCompared[k][1], one, many, one / many);
      }
    }
    if (!first_fault.empty())
      std::printf("\nwarning: some timed steps did not return ok; the first: %s\n", first_fault.c_str());
  }
  return 0;
}
