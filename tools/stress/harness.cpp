#include "tools/stress/harness.h"

#include <algorithm>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>

#include "analysis/diagnostics.h"
#include "analysis/rest.h"
#include "core/indentation.h"
#include "core/step.h"

namespace palpate::stress {

namespace {
bool g_quiet = false;
const Clock::time_point g_start = Clock::now();
}  // namespace

bool StressOptions::wants(const std::string& study) const {
  return only.empty() || std::find(only.begin(), only.end(), study) != only.end();
}

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double seconds_since_start() { return seconds_since(g_start); }

void set_quiet(bool quiet) { g_quiet = quiet; }

void progress(const char* format, ...) {
  if (g_quiet) return;
  std::fprintf(stderr, "[%6.1f s] ", seconds_since(g_start));
  va_list args;
  va_start(args, format);
  std::vfprintf(stderr, format, args);
  va_end(args);
  std::fputc('\n', stderr);
}

// ---------------------------------------------------------------------------
// Clouds and models
// ---------------------------------------------------------------------------

std::vector<Cloud> clouds(Mode mode) {
  const int uniform = mode == Mode::full ? 0 : mode == Mode::quick ? 10 : 6;
  const int graded = mode == Mode::full ? 0 : mode == Mode::quick ? 11 : 7;
  return {{"uniform", "hertz_cube.json", "hertz_cube_fem.json", uniform},
          {"graded", "hertz_cube_graded.json", "hertz_cube_graded_fem.json", graded}};
}

Scene load(const StressOptions& stress, const std::string& file, int per_edge, SceneOverrides extra) {
  if (per_edge > 0) extra.insert(extra.begin(), {"body.distribution.per_edge", std::to_string(per_edge)});
  return load_scene(stress.scenes / file, extra);
}

std::string cloud_label(const Model& m, const std::string& name) {
  const int per_edge = static_cast<int>(std::lround(std::cbrt(static_cast<double>(m.particle_count))));
  return name + " " + std::to_string(per_edge) + "^3";
}

const char* model_label(const Model& m) {
  if (m.solid == SolidKind::mls) return "mls";
  return m.hex.formulation == HexFormulation::linear ? "hex_fem" : "hex_fem_corotational";
}

double dt_estimate(const Model& m) { return 0.3 * m.min_spacing / m.wave_speed; }

double reference_force(const Scene& scene) { return scene.verify.forces.empty() ? 150.0 : scene.verify.forces.back(); }

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
// Phases
// ---------------------------------------------------------------------------

json PhaseStats::to_json() const {
  return {{"max_indentation_m", num(max_indentation)}, {"max_energy_j", num(max_energy)},
          {"max_speed_m_s", num(max_speed)},           {"max_penetration_m", num(max_penetration)},
          {"max_inverted", max_inverted},              {"min_jacobian", num(min_jacobian)},
          {"left_contact", left_contact},              {"finite", finite},
          {"steps", steps},                            {"final_indentation_m", num(indentation)},
          {"final_max_speed_m_s", num(speed)},         {"final_inverted", inverted},
          {"final_max_displacement_m", num(displacement)}};
}

PhaseStats run_phase(const Model& model, const Options& opt, State& state, double force, double seconds, int sample) {
  const auto t0 = Clock::now();
  PhaseStats p;
  state.force_command = press_down(force);
  const long steps = std::max(1L, std::lround(seconds / opt.integrator.dt));
  for (long k = 1; k <= steps; ++k) {
    p.steps = k;
    if (step(model, opt, state) == StepStatus::non_finite) {
      p.finite = false;
      break;
    }
    p.max_indentation = std::max(p.max_indentation, indentation(model, state));
    p.max_speed = std::max(p.max_speed, max_particle_speed(state));
    p.max_penetration = std::max(p.max_penetration, -geometric_gap(model, state));
    if (state.contact_index.empty()) p.left_contact = true;
    if (k % sample == 0 || k == steps) {
      p.max_energy = std::max(p.max_energy, total_energy(model, opt, state));
      const InversionSummary inv = inversion_summary(model, state.position);
      p.max_inverted = std::max(p.max_inverted, inv.inverted);
      p.min_jacobian = std::min(p.min_jacobian, inv.min_jacobian);
      p.inverted = inv.inverted;
    }
  }
  if (p.finite) {
    p.indentation = indentation(model, state);
    p.speed = max_particle_speed(state);
    p.energy = total_energy(model, opt, state);
    p.displacement = max_displacement(model, state);
  }
  p.seconds = seconds_since(t0);
  return p;
}

// ---------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------

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

void write_out_dir(const std::filesystem::path& dir, const std::filesystem::path& raw_dir, const json& result,
                   const json& zero_series, const json& zero_ratios, const json& long_periods) {
  std::filesystem::create_directories(dir);
  if (result.contains("envelope"))
    write_csv(dir / "envelope.csv",
              {"model", "integrator", "cloud", "particles", "damping", "scene_damping", "dt_max_stable_s",
               "dt_min_unstable_s", "at_cap", "dt_estimate_s", "c", "dx_min_m", "wave_speed_m_s", "stable_at_paper_dt",
               "unstable_because", "trials", "wall_s"},
              result["envelope"]);
  if (result.contains("large_force"))
    write_csv(dir / "large_force.csv",
              {"model", "integrator", "dt_s", "cloud", "force_n", "max_indentation_m", "d_over_r", "max_penetration_m",
               "max_inverted", "points", "min_jacobian", "max_energy_j", "finite", "left_contact",
               "return_indentation_m", "d_ref_m", "recovered", "wall_s"},
              result["large_force"]);
  if (result.contains("inversion"))
    write_csv(dir / "inversion.csv",
              {"kv_pa", "kv_over_e", "recovered", "release_finite", "release_final_inverted", "release_min_jacobian",
               "release_residual_m", "release_uninverted_after_s", "pressed_max_inverted", "pressed_min_jacobian",
               "pressed_max_indentation_m", "dt_max_stable_s", "dt_predicted_s", "stable_at_scene_dt"},
              result["inversion"]["rows"]);
  if (result.contains("zero_energy")) {
    write_csv(dir / "zero_energy.csv",
              {"cloud", "particles", "hourglass", "damping", "perturbation", "duration_s", "finite", "a0_m",
               "a_dot0_m_s", "a_end_m", "rate_per_s", "ratio_end", "wall_s"},
              result["zero_energy"]);
    write_csv(dir / "zero_energy_ratios.csv",
              {"model", "cloud", "particles", "hourglass", "energy_checkerboard_j", "energy_smooth_j", "energy_ratio",
               "force_ratio"},
              zero_ratios);
    std::ofstream ts(dir / "zero_energy_series.csv");
    ts << "cloud,hourglass,damping,perturbation,t_s,a_m\n";
    for (const json& run : zero_series)
      for (const json& p : run["a"])
        ts << '"' << run["cloud"].get<std::string>() << "\"," << run["hourglass"].get<double>() << ","
           << run["damping"].get<double>() << "," << run["perturbation"].get<std::string>() << "," << p[0].get<double>()
           << "," << p[1].get<double>() << "\n";
  }
  if (result.contains("long_run"))
    write_csv(dir / "long_run.csv", {"t_s", "energy_j", "indentation_m", "max_speed_m_s", "inverted"}, long_periods);
  const std::filesystem::path json_dir = raw_dir.empty() ? dir : raw_dir;
  std::filesystem::create_directories(json_dir);
  std::ofstream(json_dir / "stress.json") << result.dump(2) << "\n";
  const std::filesystem::path script = std::filesystem::path(PALPATE_SOURCE_DIR) / "scripts" / "plot_stability.py";
  const std::string command = "/usr/bin/python3 '" + script.string() + "' '" + dir.string() + "' 1>&2";
  if (std::filesystem::exists("/usr/bin/python3") && std::filesystem::exists(script)) {
    progress("plots: %s", command.c_str());
    if (std::system(command.c_str()) != 0) std::cerr << "palpate-stress: the plot script failed: " << command << "\n";
  } else {
    std::cerr << "palpate-stress: no /usr/bin/python3 or no " << script << ": run " << command << " for the figures\n";
  }
}

}  // namespace palpate::stress
