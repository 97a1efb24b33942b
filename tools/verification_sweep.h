#pragma once
// The Hertz verification sweep of one scene (docs/physics.md §2, §3): what palpate-verify
// runs and what each case of palpate-study runs. Load the scene at its site and find the
// reference (prepare_sweep), press the indenter with each force until the body is at
// rest (run_sweep), and summarise the rows (sweep_l2_errors, sweep_json).
#include <array>
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/reference.h"
#include "core/scene.h"
#include "core/state.h"
#include "tools/load_scene.h"

namespace palpate::tools {

// What to sweep.
struct SweepRequest {
  std::string scene_file;
  SceneOverrides overrides;               // --set KEY=VALUE, in order
  std::optional<std::array<double, 2>> site;  // (x, y) of the top face, m; nullopt: the scene's own
  std::string site_origin = "--site";     // where the site came from, for messages
  std::vector<double> forces;             // N; empty: the scene's verify.forces (else the Hertz loads of d = 0.01 ... 0.1 m)
  bool static_solve = false;              // the quasi-static solve instead of the dynamic press to rest
  // The finite-block reference: "auto" (a stored one with the scene's key in the scene
  // folder's references/), "none", "compute" (minutes), or a reference file.
  std::string reference = "auto";
  double surface_radius = 0;              // m, the body's surface radius under the tool (a dome); 0: flat
};

// The scene loaded at its site, with everything the rows are compared against.
struct PreparedSweep {
  LoadedScene loaded;                     // the tool held on the vertical guide (the Hertz experiment)
  bool guide_overridden = false;          // the scene's guide was free
  double site_x = 0, site_y = 0;          // m
  double hertz_radius = 0;                // m, R, or R RB / (R + RB) on a curved body (3.6)
  double effective_modulus = 0;           // Pa, E*
  double layer_thickness = 0;             // m, the box's height (a box-less mesh: its extent in z)
  double surface_radius = 0;              // m, 0: flat
  std::vector<double> forces;             // N, the sweep
  std::optional<Reference> reference;
  std::string reference_note;             // why there is no reference, when there is none
  bool static_solve = false;
};

// One force of the sweep.
struct SweepRow {
  double force = 0, d_sim = NAN, d_hertz = 0, d_layer = 0, d_ref = NAN, d_ref_uncertainty = NAN;
  double contact_force = 0;
  double tool_x = NAN, tool_y = NAN;  // the tool's (x, y) at rest, m (the site)
  long steps = 0;
  double sim_time = 0, wall_seconds = 0;
  bool at_rest = false;
  std::string status = "ok";  // ok, not at rest, diverged (a failed health check: `failure` says which)
  std::string failure;
};

// Loads and validates the scene with its overrides, places the tool at the site and
// builds the model; finds, loads or computes the reference. Throws std::exception with
// a message that names the file, the field and the reason. `progress` (optional)
// reports the reference's computation.
PreparedSweep prepare_sweep(const SweepRequest& request,
                            const std::function<void(const std::string&)>& progress = {});

// What run_sweep reports while it runs (each optional).
struct SweepObserver {
  std::function<void(const State&)> after_step;  // after every dynamic step
  // after each force, with the state at rest (or as restored after a failed health check)
  std::function<void(std::size_t index, const SweepRow&, const State&)> after_force;
  std::function<void(const std::string&)> message;  // a diagnostic line (a static solve that did not converge, ...)
};

// Presses with each force in turn, each from the previous force's rest state (after a
// failed health check: from the rest state of the model).
std::vector<SweepRow> run_sweep(const PreparedSweep& sweep, const SweepObserver& observer = {});

struct SweepL2Errors {
  double hertz = NAN, finite_layer = NAN, reference = NAN;  // ||d_sim - d|| / ||d||; NaN where a row has none
};
SweepL2Errors sweep_l2_errors(const std::vector<SweepRow>& rows);

// True when every row is "ok".
bool sweep_all_ok(const std::vector<SweepRow>& rows);

// The summary palpate-verify --json prints: the scene and its model, the L2 errors and the
// rows (docs/verification.md). Numbers that do not exist are null.
nlohmann::json sweep_json(const PreparedSweep& sweep, const std::vector<SweepRow>& rows);

}  // namespace palpate::tools
