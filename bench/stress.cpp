// palpate-stress: the stable envelope of the models and integrators and the
// stress studies of issue #7 (docs/stability.md):
//   envelope     the largest stable dt by bisection (bench/stability.h) per model,
//                integrator, cloud and damping, against dt = c dx_min / c_p;
//   large_force  forces far beyond the Hertz sweep, sudden steps, a reversal;
//   inversion    compression to inversion, release with and without k_v;
//   zero_energy  checkerboard and velocity noise with and without hourglass control;
//   long_run     10^6 steps under a periodic force command.
// Progress on stderr; --json prints one object on stdout; --out DIR writes CSV files
// and runs scripts/plot_stability.py (Debian's /usr/bin/python3) for the PNG figures.
#include <algorithm>
#include <chrono>
#include <cstdarg>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "bench/stability.h"
#include "clients/cli.h"
#include "core/diagnostics.h"
#include "core/indentation.h"
#include "core/model.h"
#include "core/scene.h"
#include "core/state.h"
#include "core/solid.h"
#include "core/step.h"

namespace {

using namespace palpate;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

const char* kUsage = R"(usage: palpate-stress [options]
Maps the stable envelope and runs the stress studies (docs/stability.md).
  --quick           the two-minute version: 10^3 uniform and 11^3 graded clouds, the
                    scenes' damping only, a coarser bisection, 10^4 long-run steps
  --smoke           a few seconds: 6^3 / 7^3 clouds, short runs (checks the pipeline)
  --only LIST       comma-separated studies: envelope,large_force,inversion,zero_energy,long_run
  --long-steps N    steps of the long run (default 10^6; --quick 10^4; --smoke 500)
  --graded-implicit also map implicit Euler on the graded clouds (off by default: one
                    200-step trial costs minutes there: a CG solve per contact candidate
                    on a lattice with spacings from 0.025 m to ~0.2 m)
  --scenes DIR      folder of the default scenes (default: the source tree's scenes/)
  --json            print one JSON object on stdout (progress stays on stderr)
  --out DIR         write CSV files and the JSON there, then scripts/plot_stability.py
                    makes the PNG figures (needs /usr/bin/python3 with matplotlib)
  --quiet           no progress on stderr
)";

enum class Mode { full, quick, smoke };

struct Options {
  Mode mode = Mode::full;
  std::vector<std::string> only;
  long long long_steps = -1;
  std::filesystem::path scenes = std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes";
  bool json = false, quiet = false;
  bool graded_implicit = false;  // implicit Euler on the graded clouds: minutes per trial
  std::filesystem::path out;
  bool wants(const std::string& study) const {
    return only.empty() || std::find(only.begin(), only.end(), study) != only.end();
  }
};

bool g_quiet = false;
const Clock::time_point g_start = Clock::now();

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

void progress(const char* format, ...) __attribute__((format(printf, 1, 2)));
void progress(const char* format, ...) {
  if (g_quiet) return;
  std::fprintf(stderr, "[%6.1f s] ", seconds_since(g_start));
  va_list args;
  va_start(args, format);
  std::vfprintf(stderr, format, args);
  va_end(args);
  std::fputc('\n', stderr);
}

json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// ---------------------------------------------------------------------------
// Clouds and models
// ---------------------------------------------------------------------------

// A default scene, resized for --quick / --smoke.
struct Cloud {
  std::string name;        // "uniform" | "graded"
  std::string mls_scene;   // scene files
  std::string fem_scene;
  int per_edge = 0;        // 0: the scene's own
};

std::vector<Cloud> clouds(Mode mode) {
  const int uniform = mode == Mode::full ? 0 : mode == Mode::quick ? 10 : 6;
  const int graded = mode == Mode::full ? 0 : mode == Mode::quick ? 11 : 7;
  return {{"uniform", "hertz_cube.json", "hertz_cube_fem.json", uniform},
          {"graded", "hertz_cube_graded.json", "hertz_cube_graded_fem.json", graded}};
}

Scene load(const Options& opt, const std::string& file, int per_edge, SceneOverrides extra = {}) {
  if (per_edge > 0) extra.insert(extra.begin(), {"body.distribution.per_edge", std::to_string(per_edge)});
  return load_scene(opt.scenes / file, extra);
}

std::string cloud_label(const Model& m, const std::string& name) {
  const int per_edge = static_cast<int>(std::lround(std::cbrt(static_cast<double>(m.particle_count))));
  return name + " " + std::to_string(per_edge) + "^3";
}

const char* model_label(const Model& m) {
  if (m.solid == SolidKind::mls) return "mls";
  return m.scene.hex_fem.formulation == HexFormulation::linear ? "hex_fem" : "hex_fem_corotational";
}

double dt_estimate(const Model& m) { return 0.3 * m.min_spacing / m.wave_speed; }

double reference_force(const Model& m) { return m.scene.verify.forces.empty() ? 150.0 : m.scene.verify.forces.back(); }

// Smallest gap |x_i - c| - R over all particles (negative: a particle inside the sphere), m.
double geometric_gap(const Model& model, const State& s) {
  double g = INFINITY;
  for (int i = 0; i < model.particle_count; ++i)
    g = std::min(g, (s.position.col(i) - s.indenter_center).norm() - model.indenter_radius);
  return g;
}

double max_displacement(const Model& model, const State& s) {
  return (s.position - model.rest_position).colwise().norm().maxCoeff();
}

// ---------------------------------------------------------------------------
// CSV output
// ---------------------------------------------------------------------------

// Writes rows (JSON objects) as CSV with the given columns; nested values as JSON text.
void write_csv(const std::filesystem::path& file, const std::vector<std::string>& columns, const json& rows) {
  std::ofstream out(file);
  for (size_t c = 0; c < columns.size(); ++c) out << (c ? "," : "") << columns[c];
  out << "\n";
  for (const json& row : rows) {
    for (size_t c = 0; c < columns.size(); ++c) {
      if (c) out << ",";
      if (!row.contains(columns[c]) || row[columns[c]].is_null()) continue;
      const json& v = row[columns[c]];
      if (v.is_string()) out << '"' << v.get<std::string>() << '"';
      else if (v.is_boolean()) out << (v.get<bool>() ? 1 : 0);
      else out << v.dump();
    }
    out << "\n";
  }
}

// ---------------------------------------------------------------------------
// 1. The stable envelope
// ---------------------------------------------------------------------------

json envelope_study(const Options& opt, json& meta) {
  stability::TrialSpec trial;  // the standard load: the sweep's largest force, 1 s, at least 200 steps
  stability::SearchSpec search;
  search.ceiling = 0.1;
  search.tolerance = opt.mode == Mode::full ? 0.02 : opt.mode == Mode::quick ? 0.05 : 0.25;
  if (opt.mode == Mode::smoke) {
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
  for (const Cloud& cloud : clouds(opt.mode)) {
    for (const std::string& file : {cloud.mls_scene, cloud.fem_scene}) {
      const Scene scene = load(opt, file, cloud.per_edge);
      const Model model = build_model(scene);
      trial.force = reference_force(model);
      std::vector<double> dampings = {scene.integrator.damping};
      if (opt.mode == Mode::full && cloud.name == "uniform") dampings.push_back(0.0);
      for (const IntegratorType type : integrators) {
        if (type == IntegratorType::implicit_euler && cloud.name == "graded" && !opt.graded_implicit &&
            opt.mode != Mode::smoke) {
          progress("envelope: %s, %s, implicit_euler: skipped (--graded-implicit maps it; minutes per trial)",
                   model_label(model), cloud_label(model, cloud.name).c_str());
          continue;
        }
        for (const double damping : dampings) {
          const auto t0 = Clock::now();
          const double estimate = dt_estimate(model);
          const Model base = stability::with_integrator(model, type, estimate, damping);
          progress("envelope: %s, %s, %s, damping %g: bisection from %.3g s", model_label(model),
                   cloud_label(model, cloud.name).c_str(), to_string(type), damping, estimate);
          search.start = estimate;
          const stability::Search found = stability::find_stable_dt(base, trial, search, [](double dt, const stability::Trial& t) {
            progress("    dt = %.4e s: %s (%ld steps, d = %.4f m)", dt, t.reason.c_str(), t.steps, t.final_indentation);
          });
          // The paper's dt for this integrator, tried directly (stability need not be monotone in dt).
          const double paper_dt = type == IntegratorType::implicit_euler ? 1e-2 : 1e-3;
          const stability::Trial at_paper = stability::run_trial(stability::with_integrator(base, paper_dt), trial);
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

// ---------------------------------------------------------------------------
// Phases of a commanded-force history, with what happened during each
// ---------------------------------------------------------------------------

struct PhaseStats {
  double max_indentation = -INFINITY;
  double max_energy = 0;
  double max_speed = 0;
  double max_penetration = 0;  // largest geometric penetration of a particle into the sphere, m
  int max_inverted = 0;
  double min_jacobian = INFINITY;
  bool left_contact = false;   // no particle in contact at some step
  bool finite = true;
  long steps = 0;
  double seconds = 0;          // wall
  // at the end
  double indentation = NAN, speed = NAN, energy = NAN, displacement = NAN;
  int inverted = 0;
  json to_json() const {
    return {{"max_indentation_m", num(max_indentation)}, {"max_energy_j", num(max_energy)},
            {"max_speed_m_s", num(max_speed)},           {"max_penetration_m", num(max_penetration)},
            {"max_inverted", max_inverted},              {"min_jacobian", num(min_jacobian)},
            {"left_contact", left_contact},              {"finite", finite},
            {"steps", steps},                            {"final_indentation_m", num(indentation)},
            {"final_max_speed_m_s", num(speed)},         {"final_inverted", inverted},
            {"final_max_displacement_m", num(displacement)}};
  }
};

// Steps `seconds` of simulated time under the constant command `force`; the energy
// and the inversion are sampled every `sample` steps and at the end.
PhaseStats run_phase(const Model& model, State& state, double force, double seconds, int sample) {
  const auto t0 = Clock::now();
  PhaseStats p;
  state.force_command = force;
  const long steps = std::max(1L, std::lround(seconds / model.scene.integrator.dt));
  for (long k = 1; k <= steps; ++k) {
    p.steps = k;
    if (step(model, state) == StepStatus::non_finite) {
      p.finite = false;
      break;
    }
    p.max_indentation = std::max(p.max_indentation, indentation(model, state));
    p.max_speed = std::max(p.max_speed, max_particle_speed(state));
    p.max_penetration = std::max(p.max_penetration, -geometric_gap(model, state));
    if (state.contact_index.empty()) p.left_contact = true;
    if (k % sample == 0 || k == steps) {
      p.max_energy = std::max(p.max_energy, total_energy(model, state));
      const InversionSummary inv = inversion_summary(model, state.position);
      p.max_inverted = std::max(p.max_inverted, inv.inverted);
      p.min_jacobian = std::min(p.min_jacobian, inv.min_jacobian);
      p.inverted = inv.inverted;
    }
  }
  if (p.finite) {
    p.indentation = indentation(model, state);
    p.speed = max_particle_speed(state);
    p.energy = total_energy(model, state);
    p.displacement = max_displacement(model, state);
  }
  p.seconds = seconds_since(t0);
  return p;
}

// ---------------------------------------------------------------------------
// 2. Large forces, sudden steps, a reversal
// ---------------------------------------------------------------------------

json large_force_study(const Options& opt, json& meta) {
  const int per_edge = clouds(opt.mode)[0].per_edge;
  const double hold = opt.mode == Mode::smoke ? 0.1 : 1.5;  // s per phase (damping 10/s: e^-7.5 of the motion)
  const double pull = 0.1;                                  // s of reversed command
  std::vector<double> levels = {1000.0, 3663.0, 20000.0};
  if (opt.mode == Mode::quick) levels = {3663.0, 20000.0};
  if (opt.mode == Mode::smoke) levels = {3663.0};
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
    const Scene scene = load(opt, c.file, per_edge, c.set);
    const Model model = build_model(scene);
    const double F_ref = reference_force(model);
    const int sample = model.scene.integrator.type == IntegratorType::implicit_euler ? 1 : 10;
    State fresh = make_state(model);
    const PhaseStats ref = run_phase(model, fresh, F_ref, hold, sample);
    progress("large force: %s %s, %s at %g s: d_ref(%g N) = %.4f m", model_label(model),
             cloud_label(model, "uniform").c_str(), to_string(scene.integrator.type), scene.integrator.dt, F_ref,
             ref.indentation);
    for (const double F : levels) {
      State s = make_state(model);
      const PhaseStats up = run_phase(model, s, F, hold, sample);
      PhaseStats rev, back;
      if (up.finite) rev = run_phase(model, s, -F_ref, pull, sample);
      if (up.finite && rev.finite) back = run_phase(model, s, F_ref, hold, sample);
      const bool finite = up.finite && rev.finite && back.finite;
      const bool recovered = finite && back.inverted == 0 && std::abs(back.indentation - ref.indentation) <= 0.02 * ref.indentation &&
                             back.speed < 1e-3;
      progress("    F = %g N: max d = %.3f m (d/R %.2f), max penetration %.3g m, max inverted %d, %s, return: d = %.4f m, %s",
               F, up.max_indentation, up.max_indentation / model.indenter_radius, up.max_penetration, up.max_inverted,
               up.finite ? "finite" : "NON-FINITE", back.indentation, recovered ? "recovered" : "NOT recovered");
      json row;
      row["model"] = model_label(model);
      row["integrator"] = to_string(scene.integrator.type);
      row["dt_s"] = scene.integrator.dt;
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

// ---------------------------------------------------------------------------
// 3. Inversion with and without the volume term
// ---------------------------------------------------------------------------

json inversion_study(const Options& opt, json& meta) {
  // 14^3 is the smallest uniform cloud on which a released inversion stays stuck without k_v (10^3, 12^3 recover).
  const int per_edge = opt.mode == Mode::full ? 0 : opt.mode == Mode::quick ? 14 : 6;
  const Scene scene = load(opt, "hertz_cube.json", per_edge);
  const Model base = build_model(scene);
  const double E = scene.material.young_modulus;
  const double press_force = 6000.0;
  const double press = opt.mode == Mode::smoke ? 0.2 : 1.5, release = opt.mode == Mode::smoke ? 0.2 : 3.0;
  std::vector<double> kv_over_E = {0, 0.01, 0.1, 1, 10, 100, 1000, 3000, 10000};
  if (opt.mode == Mode::quick) kv_over_E = {0, 0.01, 1, 100, 3000};
  if (opt.mode == Mode::smoke) kv_over_E = {0, 1};
  json out;
  out["cloud"] = cloud_label(base, "uniform");
  out["particles"] = base.particle_count;
  out["integrator"] = to_string(scene.integrator.type);
  out["dt_s"] = scene.integrator.dt;
  out["press_force_n"] = press_force;
  meta["inversion_protocol"] =
      "MLS, the default scene's integrator and dt: (a) pressed from rest with " + std::to_string(press_force) +
      " N for " + std::to_string(press) + " s with k_v = 0 (inverted: det F <= 0); (b) that state released (command 0) for " +
      std::to_string(release) + " s with each k_v: recovered = no inverted particle and max |x - X| < 1 % of dx_min at the end; "
      "(c) the same press from rest with k_v = E: inverted particles under load; (d) the largest stable dt with each k_v "
      "(the envelope's bisection), against dt_max(0) sqrt((lambda + 2 mu) / (lambda + 2 mu + k_v))";

  // (a) the inverted state, made with k_v = 0.
  State pressed = make_state(base);
  const PhaseStats a = run_phase(base, pressed, press_force, press, 10);
  const InversionSummary inv0 = inversion_summary(base, pressed.position);
  progress("inversion: %s pressed with %g N, k_v = 0: d = %.3f m, %d of %d particles inverted (min det F %.3g)",
           cloud_label(base, "uniform").c_str(), press_force, a.indentation, inv0.inverted, inv0.points, inv0.min_jacobian);
  out["pressed"] = a.to_json();
  out["pressed_inverted"] = inv0.inverted;

  stability::TrialSpec trial;
  trial.force = reference_force(base);
  if (opt.mode == Mode::smoke) {
    trial.duration = 0.05;
    trial.min_steps = 40;
  }
  stability::SearchSpec search;
  search.start = dt_estimate(base);
  search.tolerance = opt.mode == Mode::full ? 0.02 : opt.mode == Mode::quick ? 0.05 : 0.25;
  double dt_max_0 = NAN;
  const double modulus = base.lame_lambda + 2 * base.lame_mu;
  json rows = json::array();
  for (const double ratio : kv_over_E) {
    const double kv = ratio * E;
    Model m = base;
    m.volume_stiffness = kv;
    m.scene.material.volume_stiffness = kv;
    // (b) release of the inverted state
    State s = pressed;
    double uninverted_at = NAN;
    PhaseStats b;
    const long steps = std::lround(release / scene.integrator.dt);
    const int chunk = 10;
    b.finite = true;
    for (long k = 0; k < steps; k += chunk) {
      const PhaseStats part = run_phase(m, s, 0.0, chunk * scene.integrator.dt, chunk);
      b.max_speed = std::max(b.max_speed, part.max_speed);
      b.max_energy = std::max(b.max_energy, part.max_energy);
      b.max_inverted = std::max(b.max_inverted, part.max_inverted);
      b.steps += part.steps;
      if (!part.finite) {
        b.finite = false;
        break;
      }
      if (part.inverted == 0 && std::isnan(uninverted_at)) uninverted_at = (k + chunk) * scene.integrator.dt;
      if (part.inverted > 0) uninverted_at = NAN;
    }
    const InversionSummary end = b.finite ? inversion_summary(m, s.position) : InversionSummary{NAN, -1, 0};
    const double residual = b.finite ? max_displacement(m, s) : NAN;
    const bool recovered = b.finite && end.inverted == 0 && residual < 0.01 * base.min_spacing;
    // (c) pressing with this k_v from rest (k_v = E only: a press costs minutes at 18^3)
    PhaseStats pc;
    pc.max_inverted = -1;
    pc.min_jacobian = pc.max_indentation = NAN;
    if (ratio == 1) {
      State c = make_state(m);
      pc = run_phase(m, c, press_force, press, 10);
    }
    // (d) the stable step with this k_v
    const stability::Search found = stability::find_stable_dt(m, trial, search);
    if (ratio == 0) dt_max_0 = found.dt_max_stable;
    const double predicted = dt_max_0 * std::sqrt(modulus / (modulus + kv));
    const stability::Trial at_scene_dt = stability::run_trial(m, trial);
    progress("    k_v = %g E: release %s (%s, %d inverted, max |x - X| %.3g m, un-inverted after %.3g s); "
             "pressed: %d inverted; dt_max %.4g s (predicted %.4g), at %g s: %s",
             ratio, recovered ? "recovered" : "NOT recovered", b.finite ? "finite" : "NON-FINITE", end.inverted, residual,
             uninverted_at, pc.max_inverted, found.dt_max_stable, predicted, scene.integrator.dt, at_scene_dt.reason.c_str());
    json row;
    row["kv_pa"] = kv;
    row["kv_over_e"] = ratio;
    row["release_finite"] = b.finite;
    row["release_final_inverted"] = end.inverted;
    row["release_min_jacobian"] = num(end.min_jacobian);
    row["release_residual_m"] = num(residual);
    row["release_uninverted_after_s"] = num(uninverted_at);
    row["recovered"] = recovered;
    row["pressed_max_inverted"] = pc.max_inverted >= 0 ? json(pc.max_inverted) : json(nullptr);
    row["pressed_min_jacobian"] = num(pc.min_jacobian);
    row["pressed_max_indentation_m"] = num(pc.max_indentation);
    row["pressed_finite"] = pc.finite;
    row["dt_max_stable_s"] = num(found.dt_max_stable);
    row["dt_predicted_s"] = num(predicted);
    row["stable_at_scene_dt"] = at_scene_dt.stable;
    row["scene_dt_s"] = scene.integrator.dt;
    rows.push_back(row);
  }
  out["rows"] = rows;
  // The envelope of k_v: recovered from inversion and stable at the scene's dt.
  double lo = NAN, hi = NAN;
  for (const json& r : rows)
    if (r["recovered"].get<bool>() && r["stable_at_scene_dt"].get<bool>() && r["kv_pa"].get<double>() > 0) {
      if (std::isnan(lo)) lo = r["kv_pa"];
      hi = r["kv_pa"];
    }
  out["kv_recovers_and_stable_min_pa"] = num(lo);
  out["kv_recovers_and_stable_max_pa"] = num(hi);
  return out;
}

// ---------------------------------------------------------------------------
// 4. Zero-energy modes
// ---------------------------------------------------------------------------

// Least-squares slope of log(y) against t.
double log_slope(const std::vector<double>& t, const std::vector<double>& y) {
  double st = 0, sy = 0, stt = 0, sty = 0;
  int n = 0;
  for (size_t k = 0; k < t.size(); ++k) {
    if (!(y[k] > 0)) continue;
    const double ly = std::log(y[k]);
    st += t[k];
    sy += ly;
    stt += t[k] * t[k];
    sty += t[k] * ly;
    ++n;
  }
  if (n < 2) return NAN;
  return (n * sty - st * sy) / (n * stt - st * st);
}

// The checkerboard s_i A phi(X_i) e with the smooth envelope phi = prod_a sin(pi (X_a - min_a) / L_a)
// (zero on every face) and e = (1,1,1)/sqrt3 on the free particles; sign = +1 everywhere gives the
// smooth field A phi e itself.
Points enveloped(const Model& m, const std::vector<double>& sign, double A) {
  const Points& X = m.rest_position;
  const Vec3 lo = X.rowwise().minCoeff(), hi = X.rowwise().maxCoeff();
  const Vec3 e = Vec3::Ones().normalized();
  Points u = Points::Zero(3, m.particle_count);
  for (int i = 0; i < m.particle_count; ++i) {
    if (m.inverse_mass[i] == 0.0) continue;
    double phi = 1;
    for (int a = 0; a < 3; ++a) phi *= std::sin(M_PI * (X(a, i) - lo[a]) / (hi[a] - lo[a]));
    u.col(i) = sign[i] * A * phi * e;
  }
  return u;
}

json zero_energy_study(const Options& opt, json& meta, json& series, json& ratios) {
  const double duration = opt.mode == Mode::full ? 3.0 : opt.mode == Mode::quick ? 1.5 : 0.1;
  const double window = 0.1;  // s: the envelope of |a| is the max over each window
  meta["zero_energy_protocol"] =
      "MLS (and, for the energy ratio, the hex FEM on the same lattice). Energy ratio: strain energy of the enveloped "
      "checkerboard u_i = s_i A phi(X_i) e over that of the smooth field A phi(X_i) e, s_i = (-1)^(a+b+c) of lattice node "
      "(a,b,c), phi = prod sin(pi (X - min) / L) over the axes, e = (1,1,1)/sqrt3, A = 1e-3 dx_min (linear range); "
      "force ratio: the same for the generalised force -f . u / A. A discretisation that sees the checkerboard's strain "
      "gives a ratio >> 1 (the hex FEM: its value on the lattice); 1 is a zero-energy mode (the checkerboard costs only "
      "its envelope). Dynamics: symplectic Euler at 1 ms, no force command, " + std::to_string(duration) +
      " s from (checkerboard) u = the enveloped checkerboard with A = 1 % of dx_min at rest or (noise) u = 0, "
      "v_i ~ N(0, (0.01 m/s)^2) per component (seed 7); a(t) = |sum_i s_i u_i| / free particles; rate = least-squares "
      "slope of log(max |a| over 0.1 s windows) against time (1/s; < 0 decays; noise: over the second half); "
      "ratio_end = a(T)/a(0) (checkerboard) or a(T) / a_free(T), a_free = a'(0) (1 - exp(-c T)) / c (a'(0) T when c = 0): "
      "the motion of a mode without any stiffness.";
  std::vector<Cloud> cl = clouds(opt.mode);
  if (opt.mode == Mode::smoke) cl.resize(1);
  // Energy and force ratios (cheap: a few energy evaluations).
  for (const Cloud& cloud : cl) {
    for (const double hg : {-1.0, 0.0, 0.02, 0.1, 0.5}) {  // -1: the hex FEM
      const Scene scene = hg < 0 ? load(opt, cloud.fem_scene, cloud.per_edge)
                                 : load(opt, cloud.mls_scene, cloud.per_edge, {{"mls.hourglass", std::to_string(hg)}});
      const Model model = build_model(scene);
      const std::vector<double> sign = checkerboard_sign(model), ones(model.particle_count, 1.0);
      const double A = 1e-3 * model.min_spacing;
      const Points uc = enveloped(model, sign, A), us = enveloped(model, ones, A);
      const Points xc = model.rest_position + uc, xs = model.rest_position + us;
      const double Uc = elastic_energy(model, xc), Us = elastic_energy(model, xs);
      Points f(3, model.particle_count);
      elastic_forces(model, xc, f);
      const double Qc = -(f.array() * uc.array()).sum() / A;
      elastic_forces(model, xs, f);
      const double Qs = -(f.array() * us.array()).sum() / A;
      progress("zero energy: %s %s, hourglass %s: energy ratio %.4g, force ratio %.4g", model_label(model),
               cloud_label(model, cloud.name).c_str(), hg < 0 ? "-" : std::to_string(hg).c_str(), Uc / Us, Qc / Qs);
      ratios.push_back({{"model", model_label(model)}, {"cloud", cloud_label(model, cloud.name)},
                        {"particles", model.particle_count}, {"hourglass", hg < 0 ? json(nullptr) : json(hg)},
                        {"energy_checkerboard_j", Uc}, {"energy_smooth_j", Us}, {"energy_ratio", Uc / Us},
                        {"force_ratio", Qc / Qs}});
    }
  }
  // Dynamics on the uniform cloud (the graded cloud's hourglass runs take minutes).
  json rows = json::array();
  const Cloud& cloud = cl[0];
  for (const double hg : {0.0, 0.1}) {
    const Scene scene = load(opt, cloud.mls_scene, cloud.per_edge, {{"mls.hourglass", std::to_string(hg)}});
    const Model built = build_model(scene);
    const std::vector<double> sign = checkerboard_sign(built);
    int free_count = 0;
    for (int i = 0; i < built.particle_count; ++i) free_count += built.inverse_mass[i] != 0.0;
    for (const double damping : {0.0, 10.0}) {
      const Model model = stability::with_integrator(built, IntegratorType::symplectic_euler, 1e-3, damping);
      for (const std::string perturbation : {"checkerboard", "noise"}) {
        const auto t0 = Clock::now();
        State s = make_state(model);
        s.force_command = 0;
        if (perturbation == "checkerboard") {
          s.position += enveloped(model, sign, 0.01 * model.min_spacing);
        } else {
          std::mt19937_64 rng(7);
          std::normal_distribution<double> noise(0.0, 0.01);
          for (int i = 0; i < model.particle_count; ++i)
            if (model.inverse_mass[i] != 0.0) s.velocity.col(i) = Vec3(noise(rng), noise(rng), noise(rng));
        }
        Vec3 vc = Vec3::Zero();  // a'(0): the checkerboard component of the initial velocity
        for (int i = 0; i < model.particle_count; ++i)
          if (model.inverse_mass[i] != 0.0) vc += sign[i] * s.velocity.col(i);
        const double a_dot0 = vc.norm() / free_count;
        const double a0 = checkerboard_amplitude(model, sign, s.position);
        std::vector<double> wt, wa;
        double wmax = 0;
        const long steps = std::lround(duration / 1e-3), per_window = std::lround(window / 1e-3);
        bool finite = true;
        json ts = json::array();
        for (long k = 1; k <= steps; ++k) {
          if (step(model, s) == StepStatus::non_finite) {
            finite = false;
            break;
          }
          const double a = checkerboard_amplitude(model, sign, s.position);
          wmax = std::max(wmax, a);
          if (k % 10 == 0) ts.push_back({k * 1e-3, a});
          if (k % per_window == 0) {
            wt.push_back((k - 0.5 * per_window) * 1e-3);
            wa.push_back(wmax);
            wmax = 0;
          }
        }
        const double T = steps * 1e-3;
        const double aT = finite ? checkerboard_amplitude(model, sign, s.position) : NAN;
        const size_t skip = perturbation == "noise" ? wt.size() / 2 : 0;
        const double rate = log_slope(std::vector<double>(wt.begin() + skip, wt.end()),
                                      std::vector<double>(wa.begin() + skip, wa.end()));
        const double a_free = damping > 0 ? a_dot0 * (1 - std::exp(-damping * T)) / damping : a_dot0 * T;
        const double ratio_end = perturbation == "noise" ? aT / a_free : aT / a0;
        progress("zero energy: %s, hourglass %g, damping %g, %s: a(0) = %.3g m, a'(0) = %.3g m/s, a(T) = %.3g m, "
                 "rate %.3g /s, ratio %.3g (%.1f s)",
                 cloud_label(model, cloud.name).c_str(), hg, damping, perturbation.c_str(), a0, a_dot0, aT, rate,
                 ratio_end, seconds_since(t0));
        json row;
        row["cloud"] = cloud_label(model, cloud.name);
        row["particles"] = model.particle_count;
        row["hourglass"] = hg;
        row["damping"] = damping;
        row["perturbation"] = perturbation;
        row["duration_s"] = T;
        row["finite"] = finite;
        row["a0_m"] = a0;
        row["a_dot0_m_s"] = a_dot0;
        row["a_end_m"] = num(aT);
        row["rate_per_s"] = num(rate);
        row["ratio_end"] = num(ratio_end);
        row["wall_s"] = seconds_since(t0);
        rows.push_back(row);
        series.push_back({{"cloud", row["cloud"]}, {"hourglass", hg}, {"damping", damping},
                          {"perturbation", perturbation}, {"a", ts}});
      }
    }
  }
  return rows;
}

// ---------------------------------------------------------------------------
// 5. The long run
// ---------------------------------------------------------------------------

json long_run_study(const Options& opt, json& meta, json& per_period) {
  const long long steps = opt.long_steps > 0 ? opt.long_steps : opt.mode == Mode::full ? 1000000 : opt.mode == Mode::quick ? 10000 : 500;
  const int per_edge = opt.mode == Mode::smoke ? 6 : 0;  // the default 18^3 even in --quick (10^4 steps are cheap)
  const Scene scene = load(opt, "hertz_cube.json", per_edge);
  const Model model = stability::with_integrator(build_model(scene), IntegratorType::symplectic_euler, 1e-3,
                                                 scene.integrator.damping);
  const double period = 1.0, F_mid = 170.0, F_amp = 157.0;  // 13 ... 327 N, the Hertz sweep's range
  const long per = std::lround(period / 1e-3);
  meta["long_run_protocol"] =
      "MLS " + cloud_label(model, "uniform") + ", symplectic Euler at 1 ms (the cheapest stable explicit step), damping " +
      std::to_string(scene.integrator.damping) + "/s; command F(t) = 170 + 157 sin(2 pi t / 1 s) N for the steps run; "
      "energy sampled at phase 0 of every period (drift: least-squares slope over the second half, relative to its mean); "
      "then F = 327.6 N until at rest (the scene's rest criteria) and 1 s more: the largest particle speed and travel in "
      "that second (residual motion) and the rest indentation against a fresh press to 327.6 N";
  const auto t0 = Clock::now();
  State s = make_state(model);
  bool finite = true;
  long long done = 0;
  double max_d = -INFINITY, max_speed = 0, max_energy = 0;
  std::vector<double> pt, pe;
  for (; done < steps; ++done) {
    s.force_command = F_mid + F_amp * std::sin(2 * M_PI * s.time / period);
    if (step(model, s) == StepStatus::non_finite) {
      finite = false;
      break;
    }
    max_d = std::max(max_d, indentation(model, s));
    max_speed = std::max(max_speed, max_particle_speed(s));
    if ((done + 1) % per == 0 || done + 1 == steps) {
      const double e = total_energy(model, s);
      max_energy = std::max(max_energy, e);
      const InversionSummary inv = inversion_summary(model, s.position);
      per_period.push_back({{"t_s", s.time}, {"energy_j", e}, {"indentation_m", indentation(model, s)},
                            {"max_speed_m_s", max_particle_speed(s)}, {"inverted", inv.inverted}});
      if ((done + 1) % per == 0) {
        pt.push_back(s.time);
        pe.push_back(e);
      }
      if ((done + 1) % (100 * per) == 0)
        progress("long run: %lld of %lld steps, E(phase 0) = %.6g J, d = %.4f m", done + 1, steps, e, indentation(model, s));
    }
  }
  json out;
  out["cloud"] = cloud_label(model, "uniform");
  out["particles"] = model.particle_count;
  out["integrator"] = "symplectic_euler";
  out["dt_s"] = 1e-3;
  out["steps"] = done;
  out["finite"] = finite;
  out["wall_s"] = seconds_since(t0);
  out["max_indentation_m"] = num(max_d);
  out["max_speed_m_s"] = max_speed;
  out["max_energy_j"] = max_energy;
  // drift of the stroboscopic energy over the second half
  double drift = NAN, mean = NAN, first = NAN, last = NAN;
  if (pe.size() >= 4) {
    const size_t h = pe.size() / 2;
    double st = 0, se = 0, stt = 0, ste = 0;
    const double n = static_cast<double>(pe.size() - h);
    for (size_t k = h; k < pe.size(); ++k) {
      st += pt[k];
      se += pe[k];
      stt += pt[k] * pt[k];
      ste += pt[k] * pe[k];
    }
    drift = (n * ste - st * se) / (n * stt - st * st);
    mean = se / n;
    first = pe[h];
    last = pe.back();
  }
  out["energy_phase0_mean_j"] = num(mean);
  out["energy_drift_j_per_s"] = num(drift);
  out["energy_drift_relative_per_1000_s"] = num(drift * 1000 / mean);
  out["energy_phase0_second_half_first_j"] = num(first);
  out["energy_phase0_last_j"] = num(last);
  out["periods"] = pe.size();
  if (finite) {
    const double F_ref = reference_force(model);
    const PressResult rest = press_to_rest(model, s, F_ref);
    const Points x0 = s.position;
    const double z0 = s.indenter_center[2];
    double speed = 0, indenter_speed = 0;
    const long window = std::lround(1.0 / 1e-3);
    for (long k = 0; k < window; ++k) {
      step(model, s);
      speed = std::max(speed, max_particle_speed(s));
      indenter_speed = std::max(indenter_speed, std::abs(s.indenter_velocity));
    }
    const double travel = (s.position - x0).colwise().norm().maxCoeff();
    State fresh = make_state(model);
    const PressResult fresh_rest = press_to_rest(model, fresh, F_ref);
    const std::vector<double> sign = checkerboard_sign(model);
    out["rest_reached"] = rest.at_rest;
    out["rest_steps"] = rest.steps;
    out["rest_indentation_m"] = rest.indentation;
    out["fresh_rest_indentation_m"] = fresh_rest.indentation;
    out["rest_indentation_difference_m"] = rest.indentation - fresh_rest.indentation;
    out["rest_max_position_difference_m"] = (x0 - fresh.position).colwise().norm().maxCoeff();
    out["residual_max_speed_m_s"] = speed;
    out["residual_max_travel_m"] = travel;
    out["residual_indenter_travel_m"] = std::abs(s.indenter_center[2] - z0);
    out["residual_indenter_max_speed_m_s"] = indenter_speed;
    out["rest_checkerboard_m"] = checkerboard_amplitude(model, sign, x0);
    out["rest_inverted"] = inversion_summary(model, x0).inverted;
    progress("long run: %lld steps in %.0f s, energy drift %.3g J/s (%.3g of the mean per 1000 s); at rest: max speed %.3g m/s, "
             "travel %.3g m in 1 s, d - d_fresh = %.3g m",
             done, seconds_since(t0), drift, drift * 1000 / mean, speed, travel, rest.indentation - fresh_rest.indentation);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  try {
    for (cli::Arguments args(argc, argv); args.next();) {
      const std::string& arg = args.flag();
      auto value = [&] { return args.value(); };
      if (arg == "--quick") opt.mode = Mode::quick;
      else if (arg == "--smoke") opt.mode = Mode::smoke;
      else if (arg == "--only") {
        std::stringstream ss(value());
        std::string item;
        while (std::getline(ss, item, ',')) {
          if (item != "envelope" && item != "large_force" && item != "inversion" && item != "zero_energy" && item != "long_run")
            throw std::invalid_argument("--only: unknown study '" + item + "'");
          opt.only.push_back(item);
        }
      } else if (arg == "--long-steps") opt.long_steps = cli::positive_list<long long>(value(), arg).at(0);
      else if (arg == "--scenes") opt.scenes = value();
      else if (arg == "--json") opt.json = true;
      else if (arg == "--graded-implicit") opt.graded_implicit = true;
      else if (arg == "--out") opt.out = value();
      else if (arg == "--quiet") opt.quiet = true;
      else if (arg == "--help" || arg == "-h") {
        std::cout << kUsage;
        return 0;
      } else throw std::invalid_argument("unknown option '" + arg + "'");
    }
  } catch (const std::exception& e) {
    std::cerr << "palpate-stress: " << e.what() << "\n\n" << kUsage;
    return 2;
  }
  g_quiet = opt.quiet;
  const char* mode = opt.mode == Mode::full ? "full" : opt.mode == Mode::quick ? "quick" : "smoke";
  json result, meta, zero_series = json::array(), zero_ratios = json::array(), long_periods = json::array();
  result["tool"] = "palpate-stress";
  result["mode"] = mode;
  result["clouds"] = opt.mode == Mode::full ? "the default scenes: uniform 18^3 and graded 21^3"
                     : opt.mode == Mode::quick
                         ? "--quick: the default scenes resized to uniform 10^3 and graded 11^3 (not the default clouds)"
                         : "--smoke: uniform 6^3 and graded 7^3 (a pipeline check, not results)";
  try {
    if (opt.wants("envelope")) result["envelope"] = envelope_study(opt, meta);
    if (opt.wants("large_force")) result["large_force"] = large_force_study(opt, meta);
    if (opt.wants("inversion")) result["inversion"] = inversion_study(opt, meta);
    if (opt.wants("zero_energy")) {
      result["zero_energy"] = zero_energy_study(opt, meta, zero_series, zero_ratios);
      result["zero_energy_ratios"] = zero_ratios;
    }
    if (opt.wants("long_run")) result["long_run"] = long_run_study(opt, meta, long_periods);
  } catch (const std::exception& e) {
    std::cerr << "palpate-stress: " << e.what() << "\n";
    return 1;
  }
  result["definitions"] = meta;
  result["wall_seconds"] = seconds_since(g_start);

  if (!opt.out.empty()) {
    std::filesystem::create_directories(opt.out);
    if (result.contains("envelope"))
      write_csv(opt.out / "envelope.csv",
                {"model", "integrator", "cloud", "particles", "damping", "scene_damping", "dt_max_stable_s",
                 "dt_min_unstable_s", "at_cap", "dt_estimate_s", "c", "dx_min_m", "wave_speed_m_s", "stable_at_paper_dt",
                 "unstable_because", "trials", "wall_s"},
                result["envelope"]);
    if (result.contains("large_force"))
      write_csv(opt.out / "large_force.csv",
                {"model", "integrator", "dt_s", "cloud", "force_n", "max_indentation_m", "d_over_r", "max_penetration_m",
                 "max_inverted", "points", "min_jacobian", "max_energy_j", "finite", "left_contact",
                 "return_indentation_m", "d_ref_m", "recovered", "wall_s"},
                result["large_force"]);
    if (result.contains("inversion"))
      write_csv(opt.out / "inversion.csv",
                {"kv_pa", "kv_over_e", "recovered", "release_finite", "release_final_inverted", "release_min_jacobian",
                 "release_residual_m", "release_uninverted_after_s", "pressed_max_inverted", "pressed_min_jacobian",
                 "pressed_max_indentation_m", "dt_max_stable_s", "dt_predicted_s", "stable_at_scene_dt"},
                result["inversion"]["rows"]);
    if (result.contains("zero_energy")) {
      write_csv(opt.out / "zero_energy.csv",
                {"cloud", "particles", "hourglass", "damping", "perturbation", "duration_s", "finite", "a0_m",
                 "a_dot0_m_s", "a_end_m", "rate_per_s", "ratio_end", "wall_s"},
                result["zero_energy"]);
      write_csv(opt.out / "zero_energy_ratios.csv",
                {"model", "cloud", "particles", "hourglass", "energy_checkerboard_j", "energy_smooth_j", "energy_ratio",
                 "force_ratio"},
                zero_ratios);
      std::ofstream ts(opt.out / "zero_energy_series.csv");
      ts << "cloud,hourglass,damping,perturbation,t_s,a_m\n";
      for (const json& run : zero_series)
        for (const json& p : run["a"])
          ts << '"' << run["cloud"].get<std::string>() << "\"," << run["hourglass"].get<double>() << ","
             << run["damping"].get<double>() << "," << run["perturbation"].get<std::string>() << "," << p[0].get<double>()
             << "," << p[1].get<double>() << "\n";
    }
    if (result.contains("long_run"))
      write_csv(opt.out / "long_run.csv", {"t_s", "energy_j", "indentation_m", "max_speed_m_s", "inverted"}, long_periods);
    std::ofstream(opt.out / "stress.json") << result.dump(2) << "\n";
    const std::filesystem::path script = std::filesystem::path(PALPATE_SOURCE_DIR) / "scripts" / "plot_stability.py";
    const std::string command = "/usr/bin/python3 '" + script.string() + "' '" + opt.out.string() + "' 1>&2";
    if (std::filesystem::exists("/usr/bin/python3") && std::filesystem::exists(script)) {
      progress("plots: %s", command.c_str());
      if (std::system(command.c_str()) != 0) std::cerr << "palpate-stress: the plot script failed: " << command << "\n";
    } else {
      std::cerr << "palpate-stress: no /usr/bin/python3 or no " << script << ": run " << command << " for the figures\n";
    }
  }
  if (opt.json) std::cout << result.dump(2) << "\n";
  else if (opt.out.empty()) std::cout << result.dump(2) << "\n";
  return 0;
}
