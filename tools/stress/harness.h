#pragma once
// The shared harness of palpate-stress (docs/stability.md): the tool's options, the
// progress lines on stderr, the clouds and scene loading, the labels of a model and a
// cloud, the phases of a commanded-force history (run_phase), and the output: JSON
// numbers, the CSV files and the plot script. The studies are in studies.h.
#include <chrono>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/model.h"
#include "core/options.h"
#include "core/scene.h"
#include "core/state.h"

namespace palpate::stress {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

// ---------------------------------------------------------------------------
// The tool's options (the step options are palpate::Options)
// ---------------------------------------------------------------------------

enum class Mode { full, quick, smoke };

struct StressOptions {
  Mode mode = Mode::full;
  std::vector<std::string> only;
  long long long_steps = -1;
  std::filesystem::path scenes = std::filesystem::path(PALPATE_SOURCE_DIR) / "scenes";
  bool json = false, quiet = false;
  bool graded_implicit = false;  // implicit Euler on the graded clouds: minutes per trial
  std::filesystem::path out;
  std::filesystem::path raw;  // --raw: where stress.json goes (empty: `out`)
  bool wants(const std::string& study) const;
};

// ---------------------------------------------------------------------------
// Progress and timing
// ---------------------------------------------------------------------------

double seconds_since(Clock::time_point t);
// Wall seconds since the program started (the time stamp of the progress lines).
double seconds_since_start();
// No progress lines from now on (--quiet).
void set_quiet(bool quiet);
// One line on stderr, "[  12.3 s] ..." (printf format), unless quiet.
void progress(const char* format, ...) __attribute__((format(printf, 1, 2)));

// A finite number, or null.
inline json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

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

std::vector<Cloud> clouds(Mode mode);

// A scene of the --scenes folder, with per_edge particles per edge (0: the file's own).
Scene load(const StressOptions& stress, const std::string& file, int per_edge, SceneOverrides extra = {});

// "uniform 18^3".
std::string cloud_label(const Model& m, const std::string& name);
// "mls" | "hex_fem" | "hex_fem_corotational".
const char* model_label(const Model& m);

// The first dt of a bisection, 0.3 dx_min / c_p, s.
double dt_estimate(const Model& m);
// The largest force of the scene's sweep (150 N if it has none), N.
double reference_force(const Scene& scene);

// Smallest gap |x_i - c| - R over all particles (negative: a particle inside the sphere), m.
double geometric_gap(const Model& model, const State& s);
// Largest |x_i - X_i|, m.
double max_displacement(const Model& model, const State& s);

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
  json to_json() const;
};

// Steps `seconds` of simulated time (at opt.integrator.dt) under the constant command
// `force`; the energy and the inversion are sampled every `sample` steps and at the end.
PhaseStats run_phase(const Model& model, const Options& opt, State& state, double force, double seconds, int sample);

// ---------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------

// Writes rows (JSON objects) as CSV with the given columns; nested values as JSON text.
void write_csv(const std::filesystem::path& file, const std::vector<std::string>& columns, const json& rows);

// --out DIR: the CSV file of every study in `result`, the series and ratios CSV files,
// stress.json (in `raw_dir`, --raw, when not empty), then scripts/plot_stability.py for the figures.
void write_out_dir(const std::filesystem::path& dir, const std::filesystem::path& raw_dir, const json& result,
                   const json& zero_series, const json& zero_ratios, const json& long_periods);

}  // namespace palpate::stress
